"""Layouts of keystroke logs: named keys, user-declared columns, YAML layout files, refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pianobot.errors import InputError
from pianobot.io.keystroke_log import read_keystroke_log
from pianobot.io.named_keys import note_number


def write(tmp_path: Path, lines: list[str], name: str = "log.txt") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def named(group: int, order: int, note: str, t_ms: int | None, **extra: object) -> str:
    key = note_number(note) if note in "CDEFGAB" else 60
    midi = [] if t_ms is None else [[[144, key, 40, 0], t_ms], [[128, key, 60, 0], t_ms + 700]]
    record = {
        "group": group,
        "order": order,
        "note": note,
        "move_vel": 0.2,
        "down_vel": 0.3,
        "up_vel": 0.4,
        "distance": 0.02,
        "hold_time": 0.5,
        "move_acc": 1.0,
        "down_acc": 0.8,
        "up_acc": 1.2,
        "press_depth": 0.012,
        **extra,
        "midi": midi,
    }
    return repr(record)


def test_note_names_and_the_octave_convention() -> None:
    assert [note_number(n) for n in "CDEFGAB"] == [60, 62, 64, 65, 67, 69, 71]  # octave 4: middle C
    assert note_number("C", octave=3) == 48 and note_number("c#") == 61 and note_number("Bb3") == 58
    assert note_number("F♯5") == 78 and note_number(57) == 57 and note_number(57.0) == 57
    for bad in ("H", "C##12", True, 3.5, "do"):
        with pytest.raises(ValueError, match="note"):
            note_number(bad)


def test_named_keys_become_columns_and_unknown_keys_are_kept(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        [
            named(0, 0, "F", 1000, operator="yy", take=3),
            named(0, 1, "C", 4000, operator="yy", take=3),
            named(1, 0, "G", None, operator="zz", take=4),
            named(1, 1, "A", 10000, **{"room temp": 21.5}),
        ],
    )
    log = read_keystroke_log(path)
    trials = log.trials
    assert log.layout == "named-keys" and log.finger == "rigid"  # 12 mm presses: the rigid finger
    assert trials["sequence_id"].tolist() == [0, 0, 1, 1] and trials["sequence_order"].tolist() == [
        0,
        1,
        0,
        1,
    ]
    assert trials["note"].tolist() == [65, 60, 67, 69]
    assert trials["status"].tolist() == ["ok", "ok", "silent", "ok"]
    row = trials.iloc[0]
    assert (
        row["down_velocity_mps"],
        row["up_velocity_mps"],
        row["acceleration_mps2"],
        row["up_acceleration_mps2"],
        row["distance_m"],
        row["depth_m"],
        row["hold_s"],
        row["move_velocity_mps"],
        row["move_acceleration_mps2"],
    ) == (0.3, 0.4, 0.8, 1.2, 0.02, 0.012, 0.5, 0.2, 1.0)
    assert (
        trials["operator"].tolist()[:3] == ["yy", "yy", "zz"] and trials["operator"].isna().iloc[3]
    )
    assert trials["take"].tolist()[:3] == [3.0, 3.0, 4.0] and np.isnan(trials["take"].iloc[3])
    assert trials["log_room_temp"].iloc[3] == 21.5  # not a plain name: prefixed
    assert log.columns["room temp"] == "log_room_temp" and log.columns["hold_time"] == "hold_s"
    assert "octave 4" in log.notes and "middle C is C4 = 60" in log.notes


def test_note_octave_is_overridable(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        [
            repr(
                {
                    "note": "A",
                    "down_vel": 0.3,
                    "midi": [[[144, 57, 40, 0], 1000], [[128, 57, 60, 0], 1500]],
                }
            )
        ],
    )
    log = read_keystroke_log(path, note_octave=3)
    assert log.trials["note"].tolist() == [57] and log.trials["status"].tolist() == ["ok"]
    with pytest.raises(InputError, match="octave"):
        read_keystroke_log(path, note_octave=12)


def test_named_line_with_a_bad_note_is_skipped_with_the_reason(tmp_path: Path) -> None:
    path = write(tmp_path, [named(0, 0, "F", 1000), named(0, 1, "H", 4000), named(0, 2, "G", 8000)])
    log = read_keystroke_log(path)
    assert [s.line for s in log.skipped] == [2] and "'H'" in log.skipped[0].reason
    assert log.trials["source_line"].tolist() == [1, 3]


def rigid8(values: list[float], midi: list[tuple[int, int, int, int]]) -> str:
    return repr({"control": values, "midi": [[[s, n, v, 0], t] for s, n, v, t in midi]})


EIGHT = "finger_angle_deg,acceleration_mps2,up_acceleration_mps2,down_velocity_mps,up_velocity_mps,distance_m,hold_s,depth_m"


def test_a_log_with_eight_values_is_refused_naming_the_line_the_count_and_the_layouts(
    tmp_path: Path,
) -> None:
    path = write(
        tmp_path,
        [
            rigid8(
                [0, 1.0, 1.0, 0.2, 0.3, 0.03, 0.5, 0.01], [(144, 60, 50, 900), (128, 60, 70, 1900)]
            )
        ]
        * 3,
    )
    with pytest.raises(InputError) as error:
        read_keystroke_log(path)
    message = str(error.value)
    assert "line 1: 8 control values" in message and "--columns" in message
    for layout in ("soft-2022 (7 values)", "rigid-2022-acc (6 values)", "sweep-2021 (5 values)"):
        assert layout in message


def test_declared_columns(tmp_path: Path) -> None:
    lines = [
        rigid8(
            [0, 1.0, 0.8, 0.2, 0.3, 0.03, 0.5, 0.01],
            [(144, 60, 50, 900 + 4000 * i), (128, 60, 70, 1900 + 4000 * i)],
        )
        for i in range(3)
    ]
    path = write(tmp_path, lines)
    log = read_keystroke_log(path, columns=EIGHT.split(","), finger="rigid")
    row = log.trials.iloc[0]
    assert log.layout == "declared" and log.finger == "rigid"
    assert (
        row["acceleration_mps2"],
        row["up_acceleration_mps2"],
        row["down_velocity_mps"],
        row["up_velocity_mps"],
        row["depth_m"],
    ) == (1.0, 0.8, 0.2, 0.3, 0.01)
    assert (log.trials["status"] == "ok").all()
    kept = read_keystroke_log(
        path,
        columns=[
            "skip",
            "acceleration_mps2",
            "skip",
            "velocity_mps",
            "skip",
            "distance_m",
            "hold_s",
            "trial_number",
        ],
    )
    assert kept.trials["trial_number"].tolist() == [0.01] * 3  # a unit-less name: an extra column
    assert kept.trials["up_velocity_mps"].tolist() == [0.2] * 3
    aliases = read_keystroke_log(
        path, columns="angle,acc,up_acc,down_vel,up_vel,distance,hold_time,press_depth".split(",")
    )
    assert (
        aliases.trials[["hold_s", "depth_m"]].to_numpy().tolist() == [[0.5, 0.01]] * 3
    )  # the old scripts' names


@pytest.mark.parametrize(
    ("columns", "message"),
    [
        (["dwon_velocity_mps"], "did you mean 'down_velocity_mps'"),
        (["depth_mm"], "not a known column"),
        (["hold_s", "hold_s"], "named twice"),
        (["velocity_mps", "down_velocity_mps"], "cannot be combined"),
        (["", "hold_s"], "comma-separated"),
    ],
)
def test_declared_columns_are_validated(tmp_path: Path, columns: list[str], message: str) -> None:
    path = write(tmp_path, [rigid8([0, 1.0], [])])
    with pytest.raises(InputError, match=message) as error:
        read_keystroke_log(path, columns=columns)
    assert error.value.where == "--columns"


def test_layout_file(tmp_path: Path) -> None:
    lines = [
        rigid8([0, 1.0, 0.8, 0.2, 0.3, 0.03, 0.5, 0.01], [(144, 60, 50, 900), (128, 60, 70, 1900)])
    ]
    path = write(tmp_path, lines)
    layout = tmp_path / "eight.yaml"
    layout.write_text(f"name: rigid-8\nfinger: rigid\ncolumns: [{EIGHT.replace(',', ', ')}]\n")
    log = read_keystroke_log(path, layout_file=layout)
    assert (
        log.layout == "rigid-8"
        and log.finger == "rigid"
        and log.trials["depth_m"].tolist() == [0.01]
    )
    layout.write_text("name: x\ncolums: [hold_s]\n")
    with pytest.raises(InputError, match="columns") as error:
        read_keystroke_log(path, layout_file=layout)
    assert str(layout) in str(error.value.where)
    layout.write_text("columns: [hold_s, depht_m]\n")
    with pytest.raises(InputError, match="depht_m") as error:
        read_keystroke_log(path, layout_file=layout)
    assert "columns" in str(error.value.where)
    with pytest.raises(InputError, match="not both"):
        read_keystroke_log(path, columns=["hold_s"], layout_file=layout)
