"""Motive CSV reader, marker roles and keystroke segmentation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from motive_synth import motive_csv, six_press_take

from pianobot.errors import InputError
from pianobot.io.mocap import read_mocap
from pianobot.io.mocap_segment import segment_take


@pytest.fixture()
def synthetic_take(tmp_path: Path) -> Path:
    return six_press_take(tmp_path)


def test_reader_meta_ghosts_and_roles(synthetic_take: Path) -> None:
    take = read_mocap(synthetic_take)
    assert take.meta["Take Name"] == "synthetic" and take.frame_rate_hz == 120.0
    assert sorted(take.markers["marker"].unique()) == [f"Unlabeled:10{i}" for i in range(4)]
    assert take.coverage["Unlabeled:900"] < 0.05  # ghost dropped by coverage
    assert take.roles == {
        "arm": "Unlabeled:100",
        "fingertip": "Unlabeled:102",
        "key": "Unlabeled:103",
    }
    # dropped frames are absent rows, never zeros
    assert take.markers.groupby("marker").size().max() == take.t_s.size - 3


def test_keystrokes_travel_and_speed(synthetic_take: Path) -> None:
    strokes = segment_take(read_mocap(synthetic_take))
    assert len(strokes) == 6
    assert strokes["arm_travel_m"].to_numpy() == pytest.approx(0.0072, abs=2e-4)
    assert strokes["arm_speed_mps"].to_numpy() == pytest.approx(
        [0.01, 0.02, 0.03, 0.04, 0.05, 0.06], rel=0.05
    )
    assert strokes["key_travel_m"].to_numpy() == pytest.approx(0.0036, abs=2e-4)
    assert strokes["t_start_s"].to_numpy() == pytest.approx(
        [1.0 + 3 * i for i in range(6)], abs=0.03
    )


def test_units_and_labelled_first_cells(tmp_path: Path) -> None:
    path = motive_csv(tmp_path / "mm.csv", duration_s=8.0, starts_s=[1.0, 4.0], speeds_mps=[0.02, 0.04],
                      units="Millimeters", first_cells=True)  # fmt: skip
    take = read_mocap(path)
    strokes = segment_take(take)
    assert len(strokes) == 2
    assert strokes["arm_travel_m"].to_numpy() == pytest.approx(0.0072, abs=2e-4)  # mm -> m


def test_given_roles_are_used_and_checked(synthetic_take: Path) -> None:
    take = read_mocap(synthetic_take, markers={"fingertip": "Unlabeled:101"})
    assert take.roles["fingertip"] == "Unlabeled:101" and take.roles["arm"] == "Unlabeled:100"
    with pytest.raises(InputError, match="not a persistent marker"):
        read_mocap(synthetic_take, markers={"arm": "Unlabeled:900"})
    with pytest.raises(InputError, match="role"):
        read_mocap(synthetic_take, markers={"elbow": "Unlabeled:100"})


@pytest.mark.parametrize(
    "content",
    [b"", b"\x00\x00\x00", b"Frame,Time,X\n1,2,3\n", b"Format Version,1.21\n\nno header here\n"],
)
def test_not_a_take_is_an_input_error(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "bad.csv"
    path.write_bytes(content)
    with pytest.raises(InputError) as error:
        read_mocap(path)
    assert error.value.where == str(path)


def test_fixture_zzz40(zhang2022: Path) -> None:
    take = read_mocap(zhang2022 / "zzz/zzz40.csv")
    assert take.roles == {
        "arm": "Unlabeled:100",
        "fingertip": "Unlabeled:102",
        "key": "Unlabeled:103",
    }
    strokes = segment_take(take)
    assert len(strokes) == 24
    assert strokes["arm_travel_m"].to_numpy() == pytest.approx(0.0072, abs=0.0005)
    speeds = strokes.sort_values("t_start_s")["arm_speed_mps"].to_numpy().reshape(8, 3)
    means = speeds.mean(axis=1)
    assert 0.008 < means[0] < 0.013 and 0.075 < means[-1] < 0.095  # about 10 to 80 mm/s
    assert (np.diff(means) > 0).all()  # 8 groups of 3, each faster than the last
    spread = speeds.max(axis=1) - speeds.min(axis=1)
    assert (spread < 0.6 * np.diff(means).min() + 0.003).all()
    assert ((strokes["key_travel_m"] > 0.003) & (strokes["key_travel_m"] < 0.005)).all()


def test_fixture_p50_has_no_key(zhang2022: Path) -> None:
    take = read_mocap(zhang2022 / "data/soft/soft_no_pp/P50.csv")
    assert set(take.roles) == {"arm", "fingertip"}
    assert len(segment_take(take)) == 3
