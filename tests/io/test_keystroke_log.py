"""Keystroke-log reader: layouts, sessions, malformed lines, events assigned by timestamp."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

from pianobot.errors import InputError
from pianobot.io.keystroke_events import KIND_OFF, KIND_ON, group_presses
from pianobot.io.keystroke_layouts import round_grid
from pianobot.io.keystroke_log import read_keystroke_log

SOFT = "data/soft/ctrl_midi"


def write(tmp_path: Path, lines: list[str], name: str = "log.txt") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def rec(control: list[float], midi: list[tuple[int, int, int, int]]) -> str:
    events = [[[s, n, v, 0], t] for s, n, v, t in midi]
    return repr({"control": control, "midi": events})


def test_soft_layout_units_and_rounding(tmp_path: Path) -> None:
    path = write(tmp_path, [
        rec([60, 45, 0.5, 0.045000000000000005, 0.04, 0.05, 0], [(144, 57, 3, 1000), (128, 57, 9, 2300)]),
        rec([60, 45, 0.5, 0.05, 0.04, 0.05, 0], []),
    ])  # fmt: skip
    log = read_keystroke_log(path)
    assert log.layout == "soft-2022" and log.finger == "soft"
    first = log.trials.iloc[0]
    assert first["vacuum_kpa"] == -60.0  # stored positive, gauge is negative
    assert first["down_velocity_mps"] == 0.045 == first["up_velocity_mps"]
    assert first["status"] == "ok" and first["on_velocity"] == 3 and first["off_velocity"] == 9
    assert first["midi_hold_s"] == pytest.approx(1.3)
    assert log.trials.iloc[1]["status"] == "silent"
    assert round_grid(0.30000000000000004) == 0.3
    assert round_grid(0.2885714285714286) == pytest.approx(0.2885714285714286, rel=1e-11)


def test_rigid_code_and_auto_detection(tmp_path: Path) -> None:
    seven = write(
        tmp_path, [rec([10000, 0, 0.1, 0.01, 0.02, 0.05, 0], [(144, 57, 2, 10), (128, 57, 9, 900)])]
    )
    log = read_keystroke_log(seven)
    assert log.layout == "rigid-2022" and log.finger == "rigid"
    assert np.isnan(log.trials.iloc[0]["vacuum_kpa"])
    acc = write(tmp_path, [rec([0, 4.01, 3.61, 0.774, 0.035, 1], [])], "acc.txt")
    log = read_keystroke_log(acc, layout="rigid-2022")
    assert log.layout == "rigid-2022-acc"
    row = log.trials.iloc[0]
    assert (row["acceleration_mps2"], row["up_acceleration_mps2"], row["distance_m"]) == (
        4.01,
        3.61,
        0.035,
    )
    pre = write(
        tmp_path, [rec([0, 0.2, 0.04, 0.1, h, 1], []) for h in (0.0, 0.5, 1.5, 2.0)], "pre.txt"
    )
    assert read_keystroke_log(pre).layout == "rigid-2022-pretest"


def test_header_sets_acceleration_and_starts_a_session(tmp_path: Path) -> None:
    path = write(tmp_path, [
        repr({"start_position_l": [0.1] * 6, "acc": 0.5}),
        rec([0, 0.31, 0.07, 0.1361, 1], [(144, 60, 36, 3000), (128, 60, 76, 4500)]),
        repr({"start_position_l": [0.1] * 6, "acc": 1}),
        rec([0, 0.31, 0.07, 0.1361, 1], [(144, 60, 30, 2000), (128, 60, 70, 3100)]),
    ])  # fmt: skip
    log = read_keystroke_log(path)
    assert log.layout == "sweep-2021"
    assert log.trials["acceleration_mps2"].tolist() == [0.5, 1.0]
    assert log.trials["session"].tolist() == [0, 1]
    assert log.header["acc"] == 0.5 and len(log.headers) == 2
    assert np.isnan(log.trials["depth_m"]).all()  # not logged by this layout: never guessed


def test_malformed_lines_are_reported_and_the_rest_imported(tmp_path: Path) -> None:
    good = rec([60, 45, 0.5, 0.05, 0.04, 0.05, 0], [])
    path = write(
        tmp_path, [good, good[1:], "[1, 2]", good + good, "{'control': ['a'], 'midi': []}", good]
    )
    log = read_keystroke_log(path)
    assert [s.line for s in log.skipped] == [2, 3, 4, 5]
    assert len(log.trials) == 2 and log.trials["source_line"].tolist() == [1, 6]


def test_what_other_scripts_write_reads_as_the_plain_log(tmp_path: Path) -> None:
    lines = [rec([60, 45, 0.5, 0.01 * (i + 1), 0.04, 0.05, 0], [(144, 57, 5 + i, 1000 + 900 * i), (128, 57, 9, 1400 + 900 * i)])
             for i in range(6)]
    plain = read_keystroke_log(write(tmp_path, lines))
    utf16 = tmp_path / "utf16.txt"
    utf16.write_text("\n".join(lines) + "\n", encoding="utf-16")  # PowerShell 5's `>` redirect
    whole_floats = [re.sub(r"\], (\d+)\]", r"], \1.0]", line) for line in lines]
    assert "1000.0]" in whole_floats[0] and "1400.0]" in whole_floats[0]
    extra_keys = [line[:-1] + ", 'time': 12.5}" for line in lines]
    for other, name in ((read_keystroke_log(utf16), "utf16"),
                        (read_keystroke_log(write(tmp_path, whole_floats, "floats.txt")), "floats"),
                        (read_keystroke_log(write(tmp_path, extra_keys, "extra.txt")), "extra")):
        assert not other.skipped, name
        columns = ["on_velocity", "midi_hold_s", "down_velocity_mps", "depth_m", "status"]
        assert other.trials[columns].equals(plain.trials[columns]), name
    assert read_keystroke_log(write(tmp_path, extra_keys, "extra.txt")).notes == (
        "keys besides control and midi ignored: time (6 lines)")


def test_a_log_most_of_whose_lines_fail_is_not_imported_in_part(tmp_path: Path) -> None:
    silent = rec([60, 45, 0.5, 0.01, 0.04, 0.05, 0], [])
    in_seconds = rec([60, 45, 0.5, 0.02, 0.04, 0.05, 0], [])[:-3] + "[[[144, 57, 5, 0], 1.25]]}"
    with pytest.raises(InputError, match=r"2 of 3 keystroke lines fail alike \(line 2: MIDI event 0 holds a non-integer"):
        read_keystroke_log(write(tmp_path, [silent, in_seconds, in_seconds]))
    assert len(read_keystroke_log(write(tmp_path, [silent, silent, in_seconds], "ok.txt")).trials) == 2


def test_double_notes_and_spills_assigned_by_timestamp(tmp_path: Path) -> None:
    # Keystroke 1 makes on,on,off,off; read(2) leaves its offs for line 2, whose own press
    # spills into line 3, and so on: every line prints the previous keystroke's events.
    lines = [
        rec([0, 0.2, 0.04, 0.1, 1, 1], [(144, 60, 90, 1000), (144, 60, 40, 1050)]),
        rec([0, 0.2, 0.04, 0.1, 1, 1], [(128, 60, 100, 2400), (128, 60, 100, 2401)]),
        rec([0, 0.2, 0.04, 0.1, 1, 1], [(144, 60, 91, 5000), (144, 60, 41, 5050)]),
        rec([0, 0.2, 0.04, 0.1, 1, 1], [(128, 60, 101, 6400), (128, 60, 101, 6401)]),
    ]
    log = read_keystroke_log(write(tmp_path, lines))
    ok = log.trials[log.trials["status"] == "ok"]
    assert ok["n_note_on"].tolist() == [2, 2]
    assert ok["midi_hold_s"].round(3).tolist() == [1.401, 1.401]
    assert log.midi.groupby("index").size().tolist() == [4, 4]


def test_a_note_on_after_the_release_is_a_new_keystroke_however_soon() -> None:
    """Repeated notes (sequences, a late release) can follow a note-off within 100 ms: a new
    press. A second note-on while the key is held (double strike) and a surplus note-off stay."""
    t_ms = np.array([0, 40, 900, 1000, 1100, 1900, 1950, 1960], dtype=np.int64)
    kind = np.array([KIND_ON, KIND_ON, KIND_OFF, KIND_OFF, KIND_ON, KIND_OFF, KIND_OFF, KIND_ON])
    note = np.full(t_ms.size, 60, dtype=np.int64)
    assert group_presses(t_ms, kind.astype(np.int64), note).tolist() == [0, 0, 0, 0, 1, 1, 1, 2]


def test_timestamp_restart_starts_a_new_clock(tmp_path: Path) -> None:
    path = write(tmp_path, [
        rec([60, 45, 0.5, 0.05, 0.04, 0.05, 0], [(144, 57, 3, 9000), (128, 57, 9, 10000)]),
        rec([60, 45, 0.5, 0.05, 0.04, 0.05, 0], [(144, 57, 3, 500), (128, 57, 9, 1600)]),
    ])  # fmt: skip
    log = read_keystroke_log(path)
    assert log.n_sessions == 2
    assert log.trials["status"].tolist() == ["ok", "ok"]


@pytest.mark.parametrize(
    "content", [b"", b"\x00\x01\x02binary", b"hello world\nnot a log\n", b"\xff\xfe\xfa"]
)
def test_not_a_log_is_an_input_error_naming_the_file(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "bad.txt"
    path.write_bytes(content)
    with pytest.raises(InputError) as error:
        read_keystroke_log(path)
    assert error.value.where == str(path)


def test_unknown_layout_is_an_input_error(tmp_path: Path) -> None:
    path = write(tmp_path, [rec([60, 45, 0.5, 0.05, 0.04, 0.05, 0], [])])
    with pytest.raises(InputError, match="layout"):
        read_keystroke_log(path, layout="piano-1999")


def _file_note_ons(path: Path) -> int:
    count = 0
    for line in path.read_text().splitlines():
        try:
            value = ast.literal_eval(line)
        except (ValueError, SyntaxError):
            continue
        if isinstance(value, dict) and "midi" in value:
            count += sum(
                1 for (status, _, velocity, _), _ in value["midi"] if status == 144 and velocity > 0
            )
    return count


def test_fixture_soft_60_angle_45(zhang2022: Path) -> None:
    log = read_keystroke_log(zhang2022 / SOFT / "soft_60_angle_45.txt")
    trials = log.trials
    assert log.layout == "soft-2022" and len(trials) == 135
    counts = trials["status"].value_counts().to_dict()
    assert counts == {"ok": 103, "silent": 32}
    assert set(trials.loc[trials["status"] == "ok", "note"]) == {57}
    assert set(trials["vacuum_kpa"]) == {-60.0} and set(trials["finger_angle_deg"]) == {45.0}
    grid = trials[["acceleration_mps2", "down_velocity_mps", "depth_m"]].drop_duplicates()
    assert len(grid) == 135  # 3 acc x 15 vel x 3 depth, repr noise rounded away
    assert set(trials["acceleration_mps2"]) == {0.1, 0.5, 1.0}
    assert set(trials["depth_m"]) == {0.02, 0.03, 0.04}


def test_fixture_soft_0_is_all_silent(zhang2022: Path) -> None:
    log = read_keystroke_log(zhang2022 / SOFT / "soft_0_angle_20.txt")
    assert len(log.trials) == 135 and (log.trials["status"] == "silent").all()


def test_fixture_rigid_changing_acc_by_timestamp(zhang2022: Path) -> None:
    """Every keystroke makes 4-6 events (double strikes, two note-offs); read(2) leaves the rest
    for later lines, so the backlog grows to the end of the log. Assigned by timestamp."""
    path = zhang2022 / "data/rigid/rigid_data_angle_0_changing_acc.txt"
    log = read_keystroke_log(path)
    ons = log.midi[log.midi["type"] == "note_on"]
    assert len(ons) == _file_note_ons(path)  # none lost
    assert int(log.trials["n_note_on"].sum()) == len(ons)  # none assigned twice
    assert not ons.duplicated(["t_s", "velocity", "source_line"]).any()
    # each keystroke's events lie in its own time window: windows never overlap
    spans = log.midi.groupby("index")["t_s"].agg(["min", "max"]).sort_index()
    assert (spans["min"].to_numpy()[1:] > spans["max"].to_numpy()[:-1]).all()
    # the slow release (up acceleration 0.01) is seen exactly on those keystrokes
    ok = log.trials[log.trials["status"] == "ok"]
    slow = ok["up_acceleration_mps2"] == 0.01
    assert slow.any() and (ok.loc[slow, "midi_hold_s"] > 2.0).all()
    assert (ok.loc[~slow, "midi_hold_s"] < 1.5).all()
    # the first 64 keystrokes sounded (63 moved off the line that printed them); the log ends
    # before the last 51 keystrokes' events were read
    counts = log.trials["assignment"].value_counts().to_dict()
    assert counts == {"own line": 1, "moved": 63, "unread": 51}
    moved = log.trials[log.trials["assignment"] == "moved"]
    assert moved["assignment_evidence"].str.contains("backlog from line").all()
    assert (moved["moved_from_line"] > moved["source_line"]).all()


def test_fixture_seq_data(zhang2022: Path) -> None:
    """The sequential rigid log: named keys, 99 sequences, note letters of octave 4."""
    log = read_keystroke_log(zhang2022 / "experiments/rigid/data/seq_data.txt")
    trials = log.trials
    assert len(trials) == 1151 and log.layout == "named-keys" and log.finger == "rigid"
    assert trials["sequence_id"].nunique() == 99
    assert trials.groupby("sequence_id").size().max() == 12
    assert trials["note"].between(60, 71).all()
    # the 8 lines that printed nothing are silent
    empty = trials["read_line"].isna() & (trials["assignment"] == "silent")
    lines = (zhang2022 / "experiments/rigid/data/seq_data.txt").read_text().splitlines()
    printed_nothing = {n for n, line in enumerate(lines, start=1) if line.endswith("'midi': []}")}
    assert len(printed_nothing) == 8
    assert printed_nothing <= set(trials.loc[trials["status"] == "silent", "source_line"])
    # every sounded keystroke got a press of its own key
    ons = log.midi[log.midi["type"] == "note_on"].groupby("index")["note"].first()
    ok = trials[trials["status"] == "ok"]
    assert (ok["index"].map(ons) == ok["note"]).all()
    # the other silent lines printed the previous keystroke's note: their own key never sounded
    assert int(empty.sum()) >= 8 and (trials["status"] == "silent").sum() == 14
    assert (trials["status"] == "ok").sum() == 1135 and trials["assignment"].eq("unread").sum() == 2
    # three presses belong to keystrokes the log never wrote (groups cut short by a connection drop)
    unassigned = log.assignment["unassigned_presses"]
    assert [p["line"] for p in unassigned] == [468, 974, 1092]
    assert {"move_velocity_mps", "move_acceleration_mps2", "up_acceleration_mps2"} <= set(trials)
    assert log.columns["group"] == "sequence_id" and log.columns["press_depth"] == "depth_m"


@pytest.mark.parametrize(
    ("name", "lines", "sounded", "silent", "moved", "unknown"),
    [
        ("data/soft/ctrl_midi/soft_0_angle_20.txt", 135, 0, 135, 0, 0),
        ("data/soft/ctrl_midi/soft_60_angle_45.txt", 135, 103, 32, 0, 0),
        ("data/soft/ctrl_midi/soft_80_angle_20.txt", 135, 92, 43, 0, 0),
        ("data/rigid/rigid__angle_0.txt", 100, 98, 2, 0, 0),
        ("data/rigid/rigid_pre_test_changing_hold_time.txt", 21, 21, 0, 0, 0),
        ("data/soft/soft_0_data_angle_90_smaller_interval.txt", 257, 257, 0, 0, 0),
    ],
)
def test_fixture_counts(zhang2022: Path, name: str, lines: int, sounded: int, silent: int, moved: int,
                        unknown: int) -> None:  # fmt: skip
    """Logs whose lines each hold their own keystroke's events: nothing moves."""
    trials = read_keystroke_log(zhang2022 / name).trials
    status = trials["status"].value_counts()
    assert len(trials) == lines
    assert (status.get("ok", 0), status.get("silent", 0), status.get("failed", 0)) == (sounded, silent, unknown)
    assert (trials["assignment"] == "moved").sum() == moved


def test_fixture_rigid_restart_is_two_sessions(zhang2022: Path) -> None:
    log = read_keystroke_log(zhang2022 / "data/rigid/rigid__angle_0.txt")
    assert log.layout == "rigid-2022" and log.finger == "rigid" and log.n_sessions == 2


def test_fixture_malformed_lines(zhang2022: Path) -> None:
    path = zhang2022 / "data/soft/soft_0_data_angle_90_smaller_interval.txt"
    log = read_keystroke_log(path)
    assert [s.line for s in log.skipped] == [8, 232]
    records = sum(1 for line in path.read_text().splitlines() if "'control'" in line)
    assert len(log.trials) == records - 2
    assert (log.trials["status"] == "ok").all()
    assert log.n_sessions == 3  # two headers, and a restart without one after the cut line 232
