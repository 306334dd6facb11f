"""CLI start-up: `pianobot --version`, `--help` and `runs`, against a bare Python start.

    python benchmarks/bench_startup.py      # JSON on stdout and in benchmarks/results/startup.json

Each command runs 10 times in a fresh process; the best (least disturbed) wall time counts, and
the median is given too, with the CPU time the process used (user + system: what the command
costs, little changed by other load on a shared machine). `python -c pass` from the same
interpreter is the floor no command can go below, measured in the same run; `runs` lists a
data folder with two small runs.
"""

from __future__ import annotations

import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results" / "startup.json"
REPEATS = 10
TARGET_S = 0.5


def _times(args: list[str]) -> tuple[list[float], list[float]]:
    """Wall and CPU seconds of each of REPEATS runs."""
    wall, cpu = [], []
    for _ in range(REPEATS):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run(args, check=True, capture_output=True)
        wall.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    pianobot = [sys.executable, "-m", "pianobot"]
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        quick = REPO / "experiments" / "quickstart.yaml"
        for _ in range(2):
            subprocess.run([*pianobot, "sweep", str(quick), "--data", str(data), "--json"],
                           check=True, capture_output=True)
        commands = {
            "python -c pass": [sys.executable, "-c", "pass"],
            "pianobot --version": [*pianobot, "--version"],
            "pianobot --help": [*pianobot, "--help"],
            "pianobot runs": [*pianobot, "runs", "--data", str(data)],
        }
        times = {name: _times(args) for name, args in commands.items()}
    floor = min(times["python -c pass"][0])
    result = {
        "benchmark": "startup",
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_average": os.getloadavg()},
        "target_s": TARGET_S,
        "commands": {
            name: {"best_s": round(min(wall), 3), "median_s": round(statistics.median(wall), 3),
                   "cpu_best_s": round(min(cpu), 3), "cpu_median_s": round(statistics.median(cpu), 3),
                   "best_minus_python_s": round(min(wall) - floor, 3),
                   "under_target": min(wall) < TARGET_S, "cpu_under_target": min(cpu) < TARGET_S}
            for name, (wall, cpu) in times.items()
        },
    }
    text = json.dumps(result, indent=2)
    print(text)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(text + "\n")


if __name__ == "__main__":
    main()
