"""Generated-truth tests: logs written by an independent lab simulation, assignment checked exactly.

`log_truth` steps the robot, the key and the MIDI FIFO itself (no pianobot code), writes the log
the study's script would have written, and keeps which stroke made each event. The importer must
put every printed event on the stroke that made it, call silent only silent strokes, and never
call a stroke whose events were never read silent or ok.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from log_truth import Scenario, TruthLog, check_assignment, make_log, undecided

from pianobot.io.keystroke_log import KeystrokeLog, read_keystroke_log

SETTINGS = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
seeds = st.integers(0, 2**31 - 1)
lengths = st.integers(30, 70)


def imported(truth: TruthLog) -> KeystrokeLog:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "log.txt"
        path.write_text(truth.text)
        return read_keystroke_log(path)


def assert_exact(scenario: Scenario, allow_undecided: float = 0.0) -> KeystrokeLog:
    truth = make_log(scenario)
    log = imported(truth)
    assert check_assignment(truth, log.trials, log.midi) == [], scenario
    assert undecided(log.trials) <= allow_undecided * scenario.n, scenario
    return log


@SETTINGS
@given(seed=seeds, n=lengths, p=st.floats(0.03, 0.25))
def test_sparse_sounding(seed: int, n: int, p: float) -> None:
    log = assert_exact(Scenario(n=n, layout="soft", sound=p, seed=seed))
    assert log.assignment["moved"] == 0  # nothing backlogs: every event stays where it was printed


@SETTINGS
@given(
    seed=seeds,
    n=lengths,
    p=st.floats(0.85, 1.0),
    layout=st.sampled_from(["soft", "rigid-acc", "named"]),
)
def test_dense_sounding(seed: int, n: int, p: float, layout: str) -> None:
    log = assert_exact(Scenario(n=n, layout=layout, sound=p, seed=seed))
    assert log.assignment["moved"] == 0


@SETTINGS
@given(seed=seeds, n=lengths)
def test_only_fast_strokes_late_in_the_file_sound(seed: int, n: int) -> None:
    log = assert_exact(Scenario(n=n, layout="soft", sound="fast-late", seed=seed))
    assert log.assignment["moved"] == 0


@SETTINGS
@given(
    seed=seeds,
    n=lengths,
    p=st.floats(0.5, 0.95),
    strikes=st.floats(0.05, 0.4),
    layout=st.sampled_from(["soft", "rigid-acc", "named"]),
    late=st.sampled_from([0.0, 0.2]),
)
# A late release followed 102 ms later by the next stroke's note-on on the same key: once
# grouped as one keystroke by a "bounce" rule, which moved the next stroke's events.
@example(seed=1624, n=30, p=0.5, strikes=0.25, layout="rigid-acc", late=0.2)
def test_backlog_of_one_or_two_events(
    seed: int, n: int, p: float, strikes: float, layout: str, late: float
) -> None:
    """Double strikes (on, on, off, off) and late releases leave 1-2 events for later reads."""
    assert_exact(
        Scenario(n=n, layout=layout, sound=p, double_strike=strikes, late_release=late, seed=seed)
    )


@SETTINGS
@given(seed=seeds, layout=st.sampled_from(["soft", "rigid-acc"]))
def test_every_stroke_double_struck_backlog_grows_to_the_end(seed: int, layout: str) -> None:
    """The changing-acc pattern: every stroke makes 4 events, the backlog grows by one line per
    two strokes, and the log ends with half its strokes unread."""
    log = assert_exact(Scenario(n=60, layout=layout, sound=1.0, double_strike=1.0, seed=seed))
    assert log.assignment["unread"] >= 20


@SETTINGS
@given(
    seed=seeds,
    n=st.integers(50, 90),
    cut=st.data(),
    header=st.booleans(),
    strikes=st.sampled_from([0.0, 0.3]),
)
def test_restarted_timestamps(
    seed: int, n: int, cut: st.DataObject, header: bool, strikes: float
) -> None:
    """The script restarts (the MIDI clock starts again, unread events are lost)."""
    first = cut.draw(st.integers(10, n // 2))
    second = cut.draw(st.integers(first + 5, n - 5))
    log = assert_exact(
        Scenario(
            n=n,
            layout="soft",
            sound=0.8,
            double_strike=strikes,
            restarts=(first, second),
            header_on_restart=header,
            seed=seed,
        )
    )
    assert log.n_sessions == 3


@SETTINGS
@given(seed=seeds, n=lengths)
def test_double_strikes_in_sequences_with_notes(seed: int, n: int) -> None:
    """Named-key logs: the line's key is evidence too."""
    assert_exact(Scenario(n=n, layout="named", sound=0.95, double_strike=0.3, seed=seed))


@SETTINGS
@given(seed=seeds, late=st.sampled_from([0.0, 0.2]))
def test_unlogged_pauses(seed: int, late: float) -> None:
    """Pauses of 5-40 s the log does not record: a gap that long is a pause, not silent strokes."""
    assert_exact(Scenario(n=70, layout="soft", sound=0.7, late_release=late, pause=0.03, seed=seed))


@pytest.mark.parametrize("seed", range(4))
def test_pauses_inside_a_backlog_with_notes(seed: int) -> None:
    """In a backlog a pause can last as long as a few strokes; the line's key still decides.
    (Without notes, in a log whose lines repeat with a period, such a pause can make two lines
    fit a press equally: see benchmarks/bench_import.py for how often.)"""
    assert_exact(
        Scenario(n=80, layout="named", sound=0.95, double_strike=0.2, pause=0.03, seed=seed),
        allow_undecided=0.05,
    )
