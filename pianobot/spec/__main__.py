"""`python -m pianobot.spec --write-schemas DIR` regenerates the committed JSON schemas."""

from __future__ import annotations

import argparse

from pianobot.spec.schema import write_schemas


def main() -> None:
    """Parse the arguments and write the schemas."""
    parser = argparse.ArgumentParser(prog="python -m pianobot.spec", description=__doc__)
    parser.add_argument(
        "--write-schemas", metavar="DIR", required=True, help="folder for *.schema.json"
    )
    args = parser.parse_args()
    for path in write_schemas(args.write_schemas):
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
