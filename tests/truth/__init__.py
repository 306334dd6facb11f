"""Independent ground truth for pianobot's identification and discovery.

A second, separately written simulator of the lab (UR moveL arm, soft finger, key, digital piano,
Motive mocap) with its own functional forms, its own base numbers and its own integrator. It
imports nothing from pianobot (a test parses every module's imports), and writes what a lab
records — Motive CSV takes and ctrl_midi keystroke logs — with `truth.json` beside each.

    from tests.truth import suite, small_suite, materialise, scenario
    for made in suite(tmp_path):                      # every scenario → tmp_path/<name>/
        made.data_file, made.truth["family"], made.truth["strength"]
    made = materialise(scenario("mocap-keybed-power_law-strong"), tmp_path)

Command line: `python -m tests.truth OUT_DIR [--small] [--only TEXT ...] [--list]`.
See tests/truth/README.md for the suite, the formats and the answer key.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from .base import BASE_SETS, BaseParams
from .catalogue import (
    control_scenarios,
    effect_scenarios,
    full_suite,
    noisy_suite,
    scenario,
    small_suite,
    variant_suite,
    with_seed,
)
from .forms import FAMILY_OF, FORMS, Effect, FormInfo
from .materialise import Materialised, materialise, truth_dict
from .scenario import GridSchedule, Scenario, TakeSchedule


def write_suite(
    out_dir: Path | str,
    scenarios: Iterable[Scenario] | None = None,
    on_done: Callable[[Materialised, float], None] | None = None,
) -> list[Materialised]:
    """Materialise scenarios (default: the full suite) into `out_dir/<name>/`.

    `on_done(made, seconds)` is called after each one (progress for the command line).
    """
    import time

    out = []
    for s in full_suite() if scenarios is None else scenarios:
        t0 = time.perf_counter()
        made = materialise(s, out_dir)
        if on_done is not None:
            on_done(made, time.perf_counter() - t0)
        out.append(made)
    return out


def suite(out_dir: Path | str, subset: str = "full") -> list[Materialised]:
    """The suite written to `out_dir`: subset "full" or "small" (a clean take, a clean log and
    two effects whose forms differ from pianobot's candidates)."""
    if subset not in ("full", "small"):
        raise ValueError(f"subset should be 'full' or 'small', got {subset!r}")
    return write_suite(out_dir, full_suite() if subset == "full" else small_suite())


__all__ = [
    "BASE_SETS",
    "FAMILY_OF",
    "FORMS",
    "BaseParams",
    "Effect",
    "FormInfo",
    "GridSchedule",
    "Materialised",
    "Scenario",
    "TakeSchedule",
    "control_scenarios",
    "effect_scenarios",
    "full_suite",
    "materialise",
    "noisy_suite",
    "scenario",
    "small_suite",
    "suite",
    "truth_dict",
    "variant_suite",
    "with_seed",
    "write_suite",
]
