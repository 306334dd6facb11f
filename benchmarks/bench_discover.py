"""Benchmark `pianobot discover`: time per 24-keystroke dataset and hit rates of the scenario suite.

Runs every scenario of `tests/analysis/own_world.py full_suite()` (hidden effects strong
and weak, structural mismatch, controls, MIDI-only, several effects at once), scores it, and
writes JSON to benchmarks/results/discover.json (and stdout).

    .venv/bin/python benchmarks/bench_discover.py [--only NAME ...] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import own_world as sc  # noqa: E402

from pianobot.analysis.discover.decide import family_of
from pianobot.analysis.discover.loop import discover
from pianobot.analysis.discover.result import DiscoveryResult

RESULTS = Path(__file__).resolve().parent / "results" / "discover.json"


def _shrink(before: float, after: float) -> float:
    if not math.isfinite(before) or before <= 0:
        return float("nan")
    return float(before / after) if after > 0 else float("inf")


def score(scenario: sc.Scenario, result: DiscoveryResult) -> dict[str, Any]:
    """Whether discovery gave the scenario's answer, with the figures it is judged by."""
    found = list(result.accepted_effects)
    families = {family_of(e) for e in found}
    first, last = result.iterations[0], result.iterations[-1]
    g0, g1 = first.before.gap, (last.after or last.before).gap
    # Judge on the measure the effect shows in: position, unless it stayed at the noise floor
    # (a velocity curve changes only the sound).
    measure = (
        "position_m"
        if g0.primary_name == "position_m" and g0.position_m > 0.3 * g0.sigma_m
        else "on_velocity"
    )
    gap_before, gap_after = getattr(g0, measure), getattr(g1, measure)
    shrink = _shrink(gap_before, gap_after)
    row: dict[str, Any] = {
        "scenario": scenario.name,
        "kind": scenario.kind,
        "expected": list(scenario.expected),
        "found": found,
        "gap_name": measure,
        "gap_before": gap_before,
        "gap_after": gap_after,
        "shrink": shrink,
        "verdict": result.verdict,
    }
    if scenario.kind == "control":
        row["hit"] = not found
    elif scenario.kind == "hidden":
        row["hit"] = family_of(scenario.expected[0]) in families
        row["shrink_ok"] = shrink >= 5.0
    elif scenario.kind == "structural":
        row["hit"] = family_of(scenario.expected[0]) in families
        row["shrink_ok"] = shrink >= 3.0 or "unexplained" in result.verdict
    elif scenario.kind == "midi":
        before_v = first.before.gap.on_velocity
        after_v = (last.after or last.before).gap.on_velocity
        row["hit"] = "arm_acceleration" in found
        row["shrink_ok"] = bool(after_v < before_v)
    else:  # several effects: each accepted step must shrink the gap
        steps = [it for it in result.iterations if it.accepted and it.after]
        gaps = [first.before.gap.primary] + [it.after.gap.primary for it in steps if it.after]
        expected = {family_of(e) for e in scenario.expected}
        row["hit"] = len(families & expected) >= 2
        row["shrink_ok"] = all(b > a for b, a in zip(gaps, gaps[1:], strict=False))
        row["sequence"] = found
    return row


def _rate(rows: list[dict[str, Any]], kind: str, key: str = "hit", suffix: str = "") -> str:
    chosen = [r for r in rows if r["kind"] == kind and r["scenario"].endswith(suffix)]
    return f"{sum(bool(r.get(key)) for r in chosen)}/{len(chosen)}"


def _finite(value: Any) -> Any:
    """JSON has no inf/NaN: a gap shrunk to the noise floor (÷0) is written as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="scenario names to run")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    suite = sc.full_suite()
    if args.only:
        suite = [sc.named(suite, name) for name in args.only]
    rows, times = [], []
    for scenario in suite:
        keystrokes = sc.generate(scenario)
        start = time.perf_counter()
        result = discover(keystrokes, scenario.start)
        elapsed = time.perf_counter() - start
        times.append(elapsed)
        row = score(scenario, result)
        row["seconds"] = elapsed
        row["n_keystrokes"] = len(keystrokes)
        rows.append(row)
        print(
            f"{scenario.name:32s} {elapsed:6.1f}s found={row['found']} hit={row['hit']} shrink={row['shrink']:.3g}",
            flush=True,
        )
    summary = {
        "seconds_per_dataset_median": float(np.median(times)) if times else float("nan"),
        "seconds_per_dataset_max": float(np.max(times)) if times else float("nan"),
        "keystrokes_per_dataset": 24,
        "hidden_strong_hits": _rate(rows, "hidden", suffix="-strong"),
        "hidden_weak_hits": _rate(rows, "hidden", suffix="-weak"),
        "hidden_strong_shrink_5x": _rate(rows, "hidden", "shrink_ok", "-strong"),
        "hidden_weak_shrink_5x": _rate(rows, "hidden", "shrink_ok", "-weak"),
        "structural_family_hits": _rate(rows, "structural"),
        "structural_shrink_3x_or_unexplained": _rate(rows, "structural", "shrink_ok"),
        "controls_without_discovery": _rate(rows, "control"),
        "midi_only_arm_acceleration": _rate(rows, "midi"),
        "several_effects": _rate(rows, "multi"),
    }
    payload = {"benchmark": "discover", "summary": summary, "scenarios": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(_finite(payload), indent=2, default=str)
    args.out.write_text(text + "\n", encoding="utf-8")
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
