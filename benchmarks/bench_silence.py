"""Benchmark what a researcher sees: the longest silent stretch of every command on a terminal.

Each command runs as a new user would type it, on an 80-column pseudo-terminal (stdout and stderr
both on the terminal, so progress displays are drawn), in a fresh temporary data folder. The
harness timestamps every chunk of output and reports, per command, the wall time and the longest
stretch with nothing written (start → first output, between outputs, last output → exit). A
progress display that redraws its elapsed clock counts as output: the screen is visibly alive.

`--pianobot EXE` (repeatable) measures other installations (e.g. main's, as the baseline) with
the same scenarios in the same run, interleaved command by command; `--only NAME` limits the
scenarios. Writes JSON to
benchmarks/results/silence.json (and a table on stdout).

    .venv/bin/python benchmarks/bench_silence.py [--pianobot EXE ...] [--only identify ...]
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import pty
import select
import struct
import subprocess
import sys
import tempfile
import termios
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results" / "silence.json"
FIXTURES = ROOT.parent / "shared" / "fixtures" / "zhang2022"
COLUMNS, ROWS = 80, 40


@dataclass(frozen=True)
class Scenario:
    """One command line; `{name}` fields are filled with run ids made by earlier scenarios."""

    name: str
    args: tuple[str, ...]
    makes_run: str | None = None  # remember the run this command creates under this key
    needs_fixtures: bool = False


def scenarios() -> list[Scenario]:
    soft = FIXTURES / "data" / "soft"
    return [
        Scenario("sweep", ("sweep", "experiments/soft_lhs.yaml"), makes_run="sweep"),
        Scenario("sweep (quickstart)", ("sweep", "experiments/quickstart.yaml"), makes_run="quick"),
        Scenario("sweep --dry-run", ("sweep", "experiments/soft_finger_grid.yaml", "--dry-run",
                                     "--rig", "experiments/rigs/sim-extended.yaml")),
        Scenario("runs", ("runs",)),
        Scenario("runs show", ("runs", "show", "{sweep}")),
        Scenario("import keystroke-log", ("import", "keystroke-log",
                                          str(soft / "ctrl_midi" / "soft_60_angle_45.txt")),
                 makes_run="log", needs_fixtures=True),
        Scenario("import force-log", ("import", "force-log", str(soft / "force" / "P60A45.txt")),
                 needs_fixtures=True),
        Scenario("import mocap", ("import", "mocap", str(FIXTURES / "zzz" / "zzz40.csv"),
                                  "--vacuum-kpa", "-40"), makes_run="mocap", needs_fixtures=True),
        Scenario("identify", ("identify", "{mocap}", "--out", "{tmp}/model.json"),
                 needs_fixtures=True),
        Scenario("fit", ("fit", "{sweep}", "--model", "gp", "--model", "poly",
                         "--out-dir", "{tmp}/models")),
        Scenario("report", ("report", "{sweep}", "--out", "{tmp}/report.html")),
        Scenario("discover", ("discover", "{mocap}", "--out", "{tmp}/discover.html"),
                 needs_fixtures=True),
        Scenario("discover (sim sweep)", ("discover", "{quick}", "--out", "{tmp}/discover-sim.html")),
        Scenario("play --dry-run", ("play", "experiments/songs/twinkle.mid", "--dry-run")),
        Scenario("play", ("play", "experiments/songs/twinkle.mid"), makes_run="play"),
        Scenario("model bode", ("model", "bode", "--plot", "{tmp}/bode.png")),
        Scenario("model simulate", ("model", "simulate", "--plot", "{tmp}/keystroke.png")),
    ]


def _run_ids(data: Path) -> set[str]:
    runs = data / "runs"
    return {p.name for p in runs.iterdir()} if runs.is_dir() else set()


def run_on_terminal(argv: list[str], cwd: Path) -> dict[str, Any]:
    """Run `argv` with stdout and stderr on an 80x40 pty; time every chunk of output."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", ROWS, COLUMNS, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES", "NO_COLOR")}
    env["TERM"] = "xterm-256color"
    start = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=slave, stderr=slave,
                            env=env, close_fds=True)
    os.close(slave)
    stamps: list[float] = []
    tail = bytearray()
    while True:
        ready, _, _ = select.select([master], [], [], 0.05)
        if ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                chunk = b""
            if not chunk:
                break
            if chunk.strip():
                stamps.append(time.perf_counter() - start)
            tail = (tail + chunk)[-4000:]
        elif proc.poll() is not None:
            break
    code = proc.wait()
    end = time.perf_counter() - start
    os.close(master)
    edges = [0.0, *stamps, end]
    gaps = [b - a for a, b in zip(edges[:-1], edges[1:], strict=True)]
    longest = max(range(len(gaps)), key=gaps.__getitem__)
    return {
        "exit_code": code,
        "wall_s": round(end, 2),
        "first_output_s": round(stamps[0], 2) if stamps else None,
        "longest_silence_s": round(gaps[longest], 2),
        "silence_from_s": round(edges[longest], 2),
        "writes": len(stamps),
        "tail": tail.decode("utf-8", "replace")[-600:],
    }


def measure(exes: list[str], only: set[str] | None) -> dict[str, list[dict[str, Any]]]:
    """Every scenario on every installation, interleaved (scenario by scenario), so that the
    machine's changing load hits all installations alike; each has its own data folder."""
    rows: dict[str, list[dict[str, Any]]] = {exe: [] for exe in exes}
    with tempfile.TemporaryDirectory() as tmp:
        made: dict[str, dict[str, str]] = {}
        for n, exe in enumerate(exes):
            (Path(tmp) / str(n)).mkdir()
            made[exe] = {"tmp": str(Path(tmp) / str(n))}
        for sc in scenarios():
            if sc.needs_fixtures and not FIXTURES.is_dir():
                continue
            wanted = only is None or sc.name in only
            if not wanted and sc.makes_run is None:
                continue
            for exe in exes:
                try:
                    args = [a.format(**made[exe]) for a in sc.args]
                except KeyError:
                    continue  # a run this command needs was not made
                data = Path(made[exe]["tmp"]) / "data"
                before = _run_ids(data)
                result = run_on_terminal([exe, *args, "--data", str(data)], ROOT)
                new = sorted(_run_ids(data) - before)
                if sc.makes_run and new:
                    made[exe][sc.makes_run] = new[-1]
                if wanted:
                    rows[exe].append({"command": sc.name, "argv": args, **result})
                    print(f"{sc.name:24s} {Path(exe).parent.parent.parent.name:>6s}  exit {result['exit_code']:3d}  "
                          f"wall {result['wall_s']:7.1f} s  longest silence {result['longest_silence_s']:6.1f} s",
                          flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pianobot", action="append", default=None,
                        help="pianobot executable(s) to measure (default: this checkout's)")
    parser.add_argument("--only", action="append", default=None, help="scenario name(s)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    ns = parser.parse_args()
    exes = ns.pianobot or [str(ROOT / ".venv" / "bin" / "pianobot")]
    only = set(ns.only) if ns.only else None
    report: dict[str, Any] = {"columns": COLUMNS, "installations": measure(exes, only)}
    ns.out.parent.mkdir(parents=True, exist_ok=True)
    ns.out.write_text(json.dumps(report, indent=2))
    print(f"wrote {ns.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
