"""Line parsing (the fast json path gives what ast.literal_eval gives), timing predictions, progress."""

from __future__ import annotations

import ast
import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.io.keystroke_import import import_keystroke_log
from pianobot.io.keystroke_timing import line_timing, move_duration_s, time_at_m
from pianobot.io.log_lines import literal
from pianobot.progress import Task

scalars = st.one_of(
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(alphabet="abcdefgh #_-", max_size=8),
    st.booleans(),
    st.none(),
)
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4), max_leaves=12)
records = st.dictionaries(st.text(alphabet="abcdefghij_", min_size=1, max_size=8), values, max_size=6)


@settings(max_examples=100, deadline=None)
@given(records)
def test_fast_path_gives_what_literal_eval_gives(record: dict[str, object]) -> None:
    text = repr(record)
    assert literal(text) == ast.literal_eval(text)


def test_nan_and_inf_are_accepted_and_nothing_is_evaluated() -> None:
    value = literal("{'control': [nan, inf, 1], 'midi': []}")
    assert math.isnan(value["control"][0]) and value["control"][1] == math.inf
    for bad in ("{'a': __import__('os')}", "{'a': 1 + 1}", "{'a': f(x)}"):
        with pytest.raises(ValueError):
            literal(bad)


def test_numpy_reprs_python2_longs_and_whole_floats_read_as_their_values() -> None:
    plain = literal("{'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': [[[144, 57, 1, 0], 468620]]}")
    written = ("{'control': [np.float64(60.0), numpy.int64(45), np.float64(0.5), np.float32(0.03), 0.04, 0.05, 0],"
               " 'midi': [[[144, 57, 1, 0], 468620L]]}")
    value = literal(written)
    assert value == plain and type(value["midi"][0][1]) is int and type(value["control"][1]) is int
    assert math.isnan(literal("{'control': [np.float64(nan)]}")["control"][0])
    assert literal("{'control': [np.float64(-0.5)]}")["control"] == [-0.5]
    for bad in ("{'a': np.float64(os.system('x'))}", "{'a': np.array([1, 2])}", "{'a': np.float64(1, 2)}",
                "{'a': 'x'L}"):
        with pytest.raises(ValueError, match="call or a name|syntax|malformed"):
            literal(bad)


def stepped_move(distance: float, speed: float, accel: float, step: float = 1e-5) -> tuple[float, list[float]]:
    """Duration and positions of a move by stepping accelerate / cruise / brake."""
    x = v = 0.0
    xs = [0.0]
    while x < distance - 1e-12:
        if v * v / (2 * accel) >= distance - x:
            v = max(v - accel * step, 1e-6)
        else:
            v = min(v + accel * step, speed)
        x = min(x + v * step, distance)
        xs.append(x)
    return (len(xs) - 1) * step, xs


@pytest.mark.parametrize(("d", "v", "a"), [(0.02, 0.01, 0.1), (0.035, 0.774, 4.01), (0.035, 0.774, 0.01), (0.02, 0.5, 1.0)])
def test_move_times_match_a_stepped_robot(d: float, v: float, a: float) -> None:
    duration, xs = stepped_move(d, v, a)
    assert float(move_duration_s(np.array([d]), np.array([v]), np.array([a]))[0]) == pytest.approx(duration, rel=1e-2)
    half = next(i for i, x in enumerate(xs) if x >= d / 3) * 1e-5
    assert float(time_at_m(np.array([d / 3]), np.array([d]), np.array([v]), np.array([a]))[0]) == pytest.approx(half, rel=1e-2)


def test_line_timing_window_and_unknown_lines() -> None:
    params = {
        "distance_m": np.array([0.05, 0.05, np.nan]),
        "depth_m": np.array([0.03, np.nan, 0.02]),
        "down_velocity_mps": np.array([0.02, 0.02, np.nan]),
        "acceleration_mps2": np.array([0.5, np.nan, 0.5]),
        "hold_s": np.array([1.0, 0.0, 0.0]),
    }
    timing = line_timing(params)
    assert list(timing.known) == [True, True, False]
    # down 0.08 m and up 0.08 m at 0.02 m/s (a = 0.5), hold 1 s
    down = 0.08 / 0.02 + 0.02 / 0.5
    assert timing.motion_s[0] == pytest.approx(2 * down + 1.0)
    assert 0.05 / 0.02 < timing.on_early_s[0] < timing.on_late_s[0] < down + 0.2  # after contact, by the bottom
    assert timing.motion_s[1] == pytest.approx(2 * 0.05 / 0.02)  # no depth, a ramp: the shortest possible
    assert timing.motion_s[2] == 0.0


class RecordingProgress:
    def __init__(self) -> None:
        self.tasks: list[str] = []
        self.steps = 0.0

    @contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[Task]:
        self.tasks.append(description)
        outer = self

        class _Task:
            def advance(self, steps: float = 1, *, note: str | None = None) -> None:
                outer.steps += steps

            def update(self, *, completed: float | None = None, total: float | None = None,
                       note: str | None = None) -> None:  # fmt: skip
                return None

        yield _Task()


def test_import_reports_progress(tmp_path: Path, data_dir: Path) -> None:
    path = tmp_path / "log.txt"
    line = "{'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': []}"
    path.write_text("\n".join([line] * 50) + "\n")
    progress = RecordingProgress()
    result = import_keystroke_log(path, data_dir, progress=progress)
    assert result.trials == 50 and result.run_dir.endswith(result.run_id)
    assert progress.tasks == ["reading log lines", "assigning MIDI events to keystrokes", "writing the run"]
    assert progress.steps == 50
