"""Keystroke-log import: speed, memory and accuracy. `python benchmarks/bench_import.py` (JSON).

Logs are written by the independent lab simulation of the tests (`tests/io/log_truth.py`): the
soft sweep (70 % of strokes sound, 10 % double strikes: backlogs of 1-2 events) and the named-key
sequence log (notes, 5 % double strikes).

- assignment: the old dense assignment (`_old_assignment.py`, the pre-issue-12 algorithm) and
  the new one on the same presses and lines, at growing log sizes; ratio old/new in CPU time,
  and the growth exponent of each (time ∝ lines^k);
- end to end: `read_keystroke_log` of 20k- and 300k-line logs, each in a fresh process, with
  wall time, CPU time and peak resident memory (the numba kernels' JIT cache is warmed first);
- accuracy: per scenario, the share of generated logs assigned exactly (every printed event on
  the stroke that made it), and the shares of lines wrong and undecided. The hard case - unlogged
  pauses inside a backlog, in a log without notes whose lines repeat with a period - is included.

The JSON also goes to benchmarks/results/import.json. `--quick` uses smaller logs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "io"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _old_assignment  # noqa: E402
from log_truth import Scenario, check_assignment, make_log, undecided  # noqa: E402

import pianobot.io.keystroke_sessions as sessions  # noqa: E402
from pianobot.io.keystroke_log import read_keystroke_log  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "import.json"
SOFT = {"layout": "soft", "sound": 0.7, "double_strike": 0.1}
NAMED = {"layout": "named", "sound": 0.95, "double_strike": 0.05}


def write_log(folder: Path, name: str, kind: dict[str, Any], lines: int) -> Path:
    path = folder / f"{name}-{lines}.txt"
    if not path.exists():
        path.write_text(make_log(Scenario(n=lines, seed=1, **kind)).text)
    return path


def assignment_times(path: Path) -> dict[str, Any]:
    """CPU seconds of the new and the old assignment on the presses and lines of one log."""
    captured: list[tuple[Any, Any, float]] = []
    original = sessions.assign_session

    def timed(presses: Any, lines: Any) -> Any:
        c0 = time.process_time()
        result = original(presses, lines)
        captured.append((presses, lines, time.process_time() - c0))
        return result

    sessions.assign_session = timed
    try:
        read_keystroke_log(path)
    finally:
        sessions.assign_session = original
    new_s = sum(c[2] for c in captured)
    old_s = 0.0
    for presses, lines, _ in captured:
        drains = list(lines.reads < lines.read_size)
        c0 = time.process_time()
        _old_assignment.assign(presses.t_s, presses.read_line, len(lines), drains,
                               lines.timing.motion_s, lines.timing.on_late_s)  # fmt: skip
        old_s += time.process_time() - c0
    return {"new_cpu_s": round(new_s, 4), "old_cpu_s": round(old_s, 4), "ratio_old_over_new": round(old_s / new_s, 1)}


# Peak memory is the kernel's high-water mark of this process's address space (VmHWM): unlike
# ru_maxrss it does not carry over the parent's size from before the exec.
CHILD = """
import json, sys, time
def memory_mb(field):
    for line in open("/proc/self/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
from pianobot.io.keystroke_log import read_keystroke_log
before = memory_mb("VmRSS")
t0, c0 = time.perf_counter(), time.process_time()
log = read_keystroke_log(sys.argv[1])
out = {"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
       "peak_rss_mb": memory_mb("VmHWM"), "rss_after_imports_mb": before,
       "lines": len(log.trials), "moved": log.assignment["moved"], "undecided": log.assignment["undecided"]}
print(json.dumps(out))
"""


def end_to_end(path: Path) -> dict[str, Any]:
    """Import in a fresh process: wall, CPU, peak memory."""
    done = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, check=True)
    out = json.loads(done.stdout.strip().splitlines()[-1])
    return {k: round(v, 3) if isinstance(v, float) else v for k, v in out.items()}


def accuracy(seeds: int) -> dict[str, Any]:
    scenarios = {
        "soft, sparse": {"layout": "soft", "sound": 0.1},
        "soft, dense, backlogs": {"layout": "soft", "sound": 0.9, "double_strike": 0.3},
        "soft, restarts, backlogs": {"layout": "soft", "sound": 0.8, "double_strike": 0.3, "restarts": (25, 50)},
        "rigid acc sweep, every stroke double": {"layout": "rigid-acc", "sound": 1.0, "double_strike": 1.0},
        "named keys, backlogs, pauses": {"layout": "named", "sound": 0.95, "double_strike": 0.2, "pause": 0.03},
        "soft, pauses, no backlog": {"layout": "soft", "sound": 0.7, "late_release": 0.2, "pause": 0.03},
        "HARD soft, backlogs + pauses": {"layout": "soft", "sound": 0.7, "double_strike": 0.3, "pause": 0.03},
        "HARD rigid acc, backlogs + pauses": {"layout": "rigid-acc", "sound": 0.9, "double_strike": 0.5, "pause": 0.03},
    }
    out = {}
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "log.txt"
        for name, kind in scenarios.items():
            exact = wrong = doubt = total = 0
            for seed in range(seeds):
                truth = make_log(Scenario(n=80, seed=seed, **kind))  # type: ignore[arg-type]
                path.write_text(truth.text)
                log = read_keystroke_log(path)
                problems = check_assignment(truth, log.trials, log.midi)
                exact += not problems
                wrong += len(problems)
                doubt += undecided(log.trials)
                total += len(log.trials)
            out[name] = {"logs": seeds, "logs_exact": exact, "lines": total,
                         "lines_wrong_pct": round(100 * wrong / total, 2),
                         "lines_undecided_pct": round(100 * doubt / total, 2)}  # fmt: skip
    return out


def exponent(sizes: list[int], seconds: list[float]) -> float:
    return float(np.polyfit(np.log(sizes), np.log(np.maximum(seconds, 1e-6)), 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller logs (a smoke run)")
    args = parser.parse_args()
    scale = [500, 1000, 2000] if args.quick else [1000, 2000, 4000, 8000]
    big = [5000, 20000] if args.quick else [20000, 300000]
    out: dict[str, Any] = {"cpu_count": os.cpu_count(), "assignment": {}, "end_to_end": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        read_keystroke_log(write_log(folder, "soft", SOFT, 200))  # compile / load the kernels once
        for lines in scale:
            out["assignment"][f"soft {lines} lines"] = assignment_times(write_log(folder, "soft", SOFT, lines))
        rows = list(out["assignment"].values())
        out["assignment_growth_exponent"] = {
            "new": round(exponent(scale, [r["new_cpu_s"] for r in rows]), 2),
            "old": round(exponent(scale, [r["old_cpu_s"] for r in rows]), 2),
        }
        for name, kind in (("soft", SOFT), ("named", NAMED)):
            for lines in big:
                out["end_to_end"][f"{name} {lines} lines"] = end_to_end(write_log(folder, name, kind, lines))
    out["accuracy_generated_truth"] = accuracy(5 if args.quick else 20)
    last = out["assignment"][f"soft {scale[-1]} lines"]
    out["summary"] = (f"assignment {last['ratio_old_over_new']}x faster than the old one at {scale[-1]} lines "
                      f"(growth exponent new {out['assignment_growth_exponent']['new']}, old "
                      f"{out['assignment_growth_exponent']['old']}); end to end: "
                      + ", ".join(f"{k}: {v['wall_s']} s, {v['peak_rss_mb']:.0f} MB" for k, v in out["end_to_end"].items()))  # fmt: skip
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
