"""`python -m tests.truth OUT_DIR [--small | --variants | --noisy] [--only TEXT ...] [--list]`: write the truth suite."""

from __future__ import annotations

import argparse
import sys

from . import Materialised, full_suite, noisy_suite, small_suite, variant_suite, write_suite


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tests.truth",
        description="Write the independent truth suite (lab files + truth.json per scenario).",
    )
    parser.add_argument("out_dir", nargs="?", help="folder to write into (one folder per scenario)")
    parser.add_argument("--small", action="store_true", help="only the small test subset")
    parser.add_argument("--variants", action="store_true",
                        help="suite takes recorded otherwise (other frame rates, fewer keystrokes, faster presses)")
    parser.add_argument("--noisy", action="store_true",
                        help="the suite's mocap takes with 30 um of marker noise instead of 3 um")
    parser.add_argument("--only", action="append", default=[], metavar="TEXT",
                        help="only scenarios whose name contains TEXT (repeatable)")  # fmt: skip
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")
    args = parser.parse_args(argv)
    chosen = (small_suite() if args.small else variant_suite() if args.variants
              else noisy_suite() if args.noisy else full_suite())
    if args.only:
        chosen = [s for s in chosen if any(text in s.name for text in args.only)]
    if args.list:
        for s in chosen:
            form = "-" if s.effect is None else f"{s.effect.kind}/{s.effect.form}"
            print(f"{s.name}\t{s.kind}\t{s.strength}\t{form}\t{s.base}\t{s.vacuum_kpa:g} kPa")
        return 0
    if not args.out_dir:
        print("error: OUT_DIR: give a folder to write into (or --list)", file=sys.stderr)
        return 2
    if not chosen:
        print(f"error: --only: no scenario name contains {args.only}", file=sys.stderr)
        return 2

    def report(made: Materialised, seconds: float) -> None:
        print(f"{made.scenario.name}: {made.data_file} ({seconds:.1f} s)", flush=True)

    write_suite(args.out_dir, chosen, on_done=report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
