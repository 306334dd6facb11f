"""The parameter table (`spec.parameters.PARAMETERS`) is the one list of keystroke parameters.

Everything that needs the parameters derives them from it: the spec's `ParameterName`, the
trials table's Parquet columns, `Trial`'s fields, the predictors' inputs, the progress line,
`press_from`. A tuple, list, set or Literal (its subscript is a tuple) of three or more parameter names written out
anywhere else in pianobot/ fails `test_no_parameter_list_outside_the_table`, as does a dict of
per-parameter constants (a property of each parameter belongs in the table).
"""

from __future__ import annotations

import ast
import math
from dataclasses import fields
from pathlib import Path

import pytest

from pianobot.analysis.learn.predictors import DEFAULT_INPUTS, INPUT_COLUMNS, complete_inputs
from pianobot.physics.trajectory import Press
from pianobot.plan.trial import MOTION_COLUMNS, Trial, press_from, trial_from
from pianobot.spec.parameters import (
    ENVELOPE_PARAMETERS,
    FINGER_ENVELOPES,
    PARAMETER_NAMES,
    PARAMETERS,
    PRESS_PARAMETERS,
    input_default,
)
from pianobot.store.schema import TRIALS_SCHEMA

PACKAGE = Path(__file__).resolve().parents[2] / "pianobot"
TABLE = PACKAGE / "spec" / "parameters.py"
NAMES = set(PARAMETER_NAMES)

# (file under pianobot/, name assigned at module level) → why a written-out list is right there.
ALLOWED: dict[tuple[str, str], str] = {
    ("io/keystroke_layouts.py", "_PAPER"): "the order of values in the 2022 study's log lines (a file format)",
    ("io/keystroke_layouts.py", "LAYOUTS"): "the order of values in old scripts' log lines (file formats)",
    ("io/keystroke_layouts.py", "_RANGES"): "plausible values of old scripts' logs, which tell their layouts apart",
    ("reports/figures.py", "silent_fraction"): "a figure's three grouping columns, a choice",
    # Not yet derived (owned by other issues this session; see the issue-18 report):
    ("play/song_plan.py", "SONG_PLAN_COLUMNS"): "the song plan's column order (issue 16 owns play/)",
    ("cli/play.py", "SONG_PLAN_TABLE"): "headings of the song plan's columns (issue 16 owns play)",
    ("play/report.py", "_warmup"): "the warm-up table's columns, a choice (issue 16 owns play/)",
    ("play/figure.py", "warmup_fit_figure"): "a stroke's geometry columns (issue 16 owns play/)",
}


def _names_in(elements: list[ast.expr]) -> list[str]:
    """Parameter names among the elements: bare strings, or the first item of a (name, ...) pair."""
    found = []
    for e in elements:
        if isinstance(e, ast.Tuple) and e.elts:
            e = e.elts[0]
        if isinstance(e, ast.Constant) and e.value in NAMES:
            found.append(e.value)
    return found


def _constant(node: ast.expr | None) -> bool:
    return node is not None and all(isinstance(n, ast.Constant | ast.Tuple | ast.UnaryOp | ast.Load | ast.USub)
                                    for n in ast.walk(node))


def _lists(tree: ast.Module) -> list[tuple[int, str, list[str]]]:
    """(line, enclosing module-level name, names) of every list of ≥ 3 parameter names."""
    found = []
    for top in tree.body:
        owner = ""  # the module-level name the list sits in: a constant, a function, a class
        if isinstance(top, ast.Assign | ast.AnnAssign):
            target = top.targets[0] if isinstance(top, ast.Assign) else top.target
            owner = target.id if isinstance(target, ast.Name) else ""
        elif isinstance(top, ast.FunctionDef | ast.ClassDef):
            owner = top.name
        for node in ast.walk(top):
            if isinstance(node, ast.Tuple | ast.List | ast.Set):
                names = _names_in(node.elts)
            elif isinstance(node, ast.Dict) and all(_constant(v) for v in node.values):
                names = _names_in([k for k in node.keys if k is not None])
            else:
                continue
            if len(set(names)) >= 3:
                found.append((node.lineno, owner, names))
    return found


def test_no_parameter_list_outside_the_table() -> None:
    offenders, used = [], set()
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == TABLE:
            continue
        rel = path.relative_to(PACKAGE).as_posix()
        for line, owner, names in _lists(ast.parse(path.read_text(encoding="utf-8"))):
            if (rel, owner) in ALLOWED:
                used.add((rel, owner))
                continue
            offenders.append(f"pianobot/{rel}:{line} lists {', '.join(names)}")
    assert not offenders, "derive these from spec.parameters.PARAMETERS:\n" + "\n".join(offenders)
    assert used == set(ALLOWED), f"stale allowances: {set(ALLOWED) - used}"


def test_the_scan_finds_a_list() -> None:
    """The scan is not blind: a tuple, a schema of pairs, a Literal and a constant dict are found."""
    source = (
        'A = ("depth_m", "hold_s", "distance_m")\n'
        'B = [("note", 1), ("depth_m", 2), ("hold_s", 3)]\n'
        'C = Literal["note", "depth_m", "hold_s"]\n'
        'D = {"note": (0, 1), "depth_m": (0, 1), "hold_s": (-1, 1)}\n'
        'E = {"note": x, "depth_m": y, "hold_s": z}\n'  # values passed by name: not a list
        'F = ("depth_m", "hold_s")\n'
        'def g():\n    return [c for c in ("note", "depth_m", "hold_s")]\n'
    )
    assert [owner for _, owner, _ in _lists(ast.parse(source))] == ["A", "B", "C", "D", "g"]


def test_trial_fields_are_the_table() -> None:
    names = [f.name for f in fields(Trial)]
    assert tuple(names[3:3 + len(PARAMETER_NAMES)]) == PARAMETER_NAMES
    assert tuple(names[3 + len(PARAMETER_NAMES):]) == MOTION_COLUMNS
    assert set(PRESS_PARAMETERS) | set(MOTION_COLUMNS) == {f.name for f in fields(Press)}


def test_derived_lists_follow_the_table() -> None:
    schema = [(f.name, str(f.type)) for f in TRIALS_SCHEMA if f.name in NAMES]
    assert schema == [(n, "int64" if PARAMETERS[n].integer else "double") for n in PARAMETER_NAMES]
    assert INPUT_COLUMNS == ENVELOPE_PARAMETERS
    for finger, limits in FINGER_ENVELOPES.items():
        assert {n: PARAMETERS[n].safe[finger] for n in limits} == limits  # type: ignore[index]


def test_every_default_has_a_reason_and_a_unit_in_its_name() -> None:
    for p in PARAMETERS.values():
        assert p.default_reason, p.name
        assert p.name == "note" or p.unit, p.name


def test_one_acceleration_default() -> None:
    """A spec's trial, a predictor's missing input and `pianobot model simulate` agree."""
    table = PARAMETERS["acceleration_mps2"].default
    assert table is not None
    assert DEFAULT_INPUTS["acceleration_mps2"] == table == input_default("acceleration_mps2")
    assert press_from({"down_velocity_mps": 0.05, "depth_m": 0.02}).acceleration_mps2 == table
    import pandas as pd

    filled = complete_inputs(pd.DataFrame({"down_velocity_mps": [0.03, 0.05]}))
    assert (filled["acceleration_mps2"] == table).all()
    assert list(filled["up_velocity_mps"]) == [0.03, 0.05]


def test_press_from_fills_defaults_by_name() -> None:
    press = press_from({"depth_m": 0.02, "down_velocity_mps": 0.04, "up_velocity_mps": math.nan})
    assert press == Press(distance_m=0.05, depth_m=0.02, down_velocity_mps=0.04, up_velocity_mps=0.04,
                          acceleration_mps2=0.5, hold_s=0.0)
    assert press_from({"depth_m": 0.02, "down_velocity_mps": 0.04, "up_velocity_mps": 0.3}).up_velocity_mps == 0.3
    with pytest.raises(ValueError, match="depth_m is not given"):
        press_from({"down_velocity_mps": 0.04})
    with pytest.raises(ValueError, match="down_velocity_mps is not given"):
        press_from({"depth_m": 0.02, "up_velocity_mps": 0.1})


def test_trial_from_builds_by_name() -> None:
    trial = trial_from("t", 3, 1, {"down_velocity_mps": 0.04, "depth_m": 0.02, "note": 60.0, "approach_m": 0.01})
    assert trial.note == 60 and isinstance(trial.note, int)
    assert (trial.index, trial.repeat, trial.up_velocity_mps, trial.approach_m) == (3, 1, 0.04, 0.01)
    assert trial.press() == press_from(trial.row())


# Plans as the code before the table drove them (main at dc0b68b): sha256 of plan.csv, first ids.
OLD_PLANS = {
    "grid": ("""name: g
finger: soft
rig: sim
sweep:
  mode: grid
  params:
    vacuum_kpa: [0, -60]
    down_velocity_mps: {start: 0.01, stop: 0.05, num: 3}
    depth_m: [0.02, 0.03]
  repeats: 2
  order: blocked-shuffle
""", "755e705a1325ca43", ["96b0b008b273e3d1", "98276e0b7f9c24d4", "330ad1ecfe4425ad"]),
    "lhs": ("""name: l
finger: rigid
rig: sim
note: 60
sweep:
  mode: lhs
  samples: 7
  seed: 3
  params:
    down_velocity_mps: {low: 0.02, high: 0.4}
    up_velocity_mps: {low: 0.02, high: 0.6}
    note: {low: 50, high: 70}
  fixed: {depth_m: 0.01, hold_s: 0.1}
  order: shuffled
""", "99bd2ddeaec0b2c8", ["c2be9e009fe2d4f3", "86991ec87ca0139c", "321d3395fc7caf1b"]),
}


@pytest.mark.parametrize("name", sorted(OLD_PLANS))
def test_old_specs_plan_as_before(name: str) -> None:
    """Same trial ids and the same plan table, value for value, as before the table drove them."""
    import hashlib

    from pianobot.plan import expand, plan_frame
    from pianobot.spec import parse_spec_text

    text, digest, first_ids = OLD_PLANS[name]
    trials = expand(parse_spec_text(text, name))
    csv = plan_frame(trials).to_csv(index=False).encode()
    assert [t.trial_id for t in trials[:3]] == first_ids
    assert hashlib.sha256(csv).hexdigest()[:16] == digest


def test_a_log_without_an_up_velocity_moves_up_at_the_down_velocity() -> None:
    import numpy as np

    from pianobot.spec.parameters import recorded_or_followed

    columns = {"up_velocity_mps": np.array([0.2, np.nan, 0.0]), "down_velocity_mps": np.array([0.1, 0.03, 0.04])}
    np.testing.assert_array_equal(recorded_or_followed("up_velocity_mps", columns), [0.2, 0.03, 0.04])
    np.testing.assert_array_equal(recorded_or_followed("depth_m", {"depth_m": np.array([np.nan])}), [np.nan])
