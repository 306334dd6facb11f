"""Motive CSV reader, marker roles and keystroke segmentation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from motive_synth import as_z_up, motive_csv, six_press_take

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


def test_fixture_zzz40_exported_z_up_reads_as_exported(zhang2022: Path, tmp_path: Path) -> None:
    y_up = read_mocap(zhang2022 / "zzz/zzz40.csv")
    z_up_file = as_z_up(zhang2022 / "zzz/zzz40.csv", tmp_path / "zzz40_z_up.csv")
    z_up = read_mocap(z_up_file)
    assert (y_up.up_axis, z_up.up_axis) == ("y", "z") and z_up.roles == y_up.roles
    assert segment_take(z_up).equals(segment_take(y_up))
    # Read as Y-up, the markers' sideways wobble is no keystroke: the error says which axis moves.
    with pytest.raises(InputError, match="along Z: if Z is vertical in this export, give --up-axis z"):
        read_mocap(z_up_file, up_axis="y")


def test_a_y_up_take_whose_arm_also_moves_sideways_stays_y_up(tmp_path: Path) -> None:
    path = motive_csv(tmp_path / "two_keys.csv", duration_s=12.0, starts_s=[1.0, 4.0, 7.0, 10.0],
                      speeds_mps=[0.02, 0.04, 0.02, 0.04], sideways_m=0.05)
    take = read_mocap(path)
    assert take.up_axis == "y" and take.roles["arm"] == "Unlabeled:100"
    assert len(segment_take(take)) == 4


def test_a_missing_frame_time_is_filled_from_its_neighbours(tmp_path: Path) -> None:
    """An export of a working range starts at that range's time, not at 0."""
    path = six_press_take(tmp_path)
    lines = path.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("Frame,"))
    shifted = [line if i <= header or not line else
               ",".join([line.split(",")[0], f"{float(line.split(',')[1]) + 10.0:.6f}", *line.split(",")[2:]])
               for i, line in enumerate(lines)]
    full = tmp_path / "range.csv"
    full.write_text("\n".join(shifted) + "\n")
    blanked = list(shifted)
    for row in (header + 1, header + 1 + 250, len(lines) - 1):  # first frame, inside a press, last frame
        cells = blanked[row].split(",")
        blanked[row] = ",".join([cells[0], "", *cells[2:]])
    gaps = tmp_path / "gaps.csv"
    gaps.write_text("\n".join(blanked) + "\n")
    expected, got = read_mocap(full), read_mocap(gaps)
    assert got.t_s == pytest.approx(expected.t_s, abs=1e-6) and expected.t_s[0] == pytest.approx(10.0)
    assert segment_take(got)["t_start_s"].to_numpy() == pytest.approx(segment_take(expected)["t_start_s"].to_numpy())


def test_a_take_name_with_an_unquoted_comma_still_reads(synthetic_take: Path, tmp_path: Path) -> None:
    text = synthetic_take.read_text()
    assert "Take Name,synthetic," in text
    named = tmp_path / "named.csv"
    named.write_text(text.replace("Take Name,synthetic,", "Take Name,left,right hand,", 1))
    take = read_mocap(named)
    assert take.meta["Take Name"] == "left,right hand" and take.frame_rate_hz == 120.0
    assert len(segment_take(take)) == len(segment_take(read_mocap(synthetic_take)))


@pytest.mark.parametrize(("sep", "decimal"), [(";", "."), (";", ","), ("\t", "."), ("\t", ",")])
def test_an_export_a_spreadsheet_resaved_reads_as_motive_wrote_it(
    synthetic_take: Path, tmp_path: Path, sep: str, decimal: str
) -> None:
    """A take opened and saved again in a spreadsheet of a European locale: ';' (or tabs) between
    fields, decimal commas. It used to be refused as "not a Motive CSV export"."""
    text = synthetic_take.read_text()
    resaved = tmp_path / "resaved.csv"
    resaved.write_text(text.replace(",", sep).replace(".", decimal))
    take, original = read_mocap(resaved), read_mocap(synthetic_take)
    assert take.frame_rate_hz == original.frame_rate_hz and take.roles == original.roles
    np.testing.assert_array_equal(take.markers[["x", "y", "z"]].to_numpy(),
                                  original.markers[["x", "y", "z"]].to_numpy())
    assert take.notes and "re-saved from a spreadsheet" in take.notes[0]
    assert ("decimal commas" in take.notes[0]) == (decimal == ",")
    assert not original.notes


def test_two_markers_of_one_name_or_one_marker_for_two_roles_are_refused(synthetic_take: Path,
                                                                          tmp_path: Path) -> None:
    # The later column of a repeated name used to replace the earlier one silently.
    lines = synthetic_take.read_text().splitlines()
    named = next(i for i, line in enumerate(lines) if "Unlabeled:101" in line)  # the name row
    lines[named] = lines[named].replace("Unlabeled:101", "Unlabeled:100")
    twice = tmp_path / "twice.csv"
    twice.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"two markers are named 'Unlabeled:100' \(columns 3 and 6\)"):
        read_mocap(twice)
    with pytest.raises(InputError, match="given as both the arm and the fingertip"):
        read_mocap(synthetic_take, markers={"arm": "Unlabeled:100", "fingertip": "Unlabeled:100"})


def test_a_frame_written_twice_is_read_once(synthetic_take: Path, tmp_path: Path) -> None:
    lines = synthetic_take.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("Frame,"))
    rows = [header + 1 + k for k in (250, 700, 1100)]  # inside presses and between them
    doubled = [line for i, line in enumerate(lines) for _ in range(2 if i in rows else 1)]
    path = tmp_path / "doubled.csv"
    path.write_text("\n".join(doubled) + "\n")
    with np.errstate(all="raise"):  # a zero time step used to divide speeds into inf and NaN
        take = read_mocap(path)
        strokes = segment_take(take)
    plain = segment_take(read_mocap(synthetic_take))
    assert take.repeated_frames == 3
    assert strokes["arm_speed_mps"].to_numpy() == pytest.approx(plain["arm_speed_mps"].to_numpy())


def test_a_vacuum_given_as_a_magnitude_is_stored_as_the_gauge_pressure(synthetic_take: Path, tmp_path: Path) -> None:
    from pianobot.io.importers import import_mocap
    from pianobot.store import load_run

    # As identify and discover read `--vacuum-kpa 40` (the study's logs store magnitudes).
    run_id = import_mocap(synthetic_take, tmp_path / "data", vacuum_kpa=40.0).run_id
    assert set(load_run(run_id, tmp_path / "data").trials["vacuum_kpa"]) == {-40.0}
    with pytest.raises(InputError, match=r"\[-100, 0\] kPa"):
        import_mocap(synthetic_take, tmp_path / "data", vacuum_kpa=150.0)


def test_a_damaged_export_reads_with_what_was_wrong_said(synthetic_take: Path, tmp_path: Path) -> None:
    lines = synthetic_take.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("Frame,"))
    frames = len(lines) - header - 1
    # Cut short (the header states more frames), a word in a cell, a header rate twice the frames'.
    cut = lines[: header + 1 + frames // 2]
    cut[0] = cut[0].replace("Export Frame Rate,120.000000", "Export Frame Rate,240.000000") + \
        f",Total Exported Frames,{frames}"
    cells = cut[header + 100].split(",")
    cut[header + 100] = ",".join([*cells[:3], "abc", *cells[4:]])
    damaged = tmp_path / "damaged.csv"
    damaged.write_text("\n".join(cut) + "\n")
    take = read_mocap(damaged)
    notes = " | ".join(take.notes)
    assert f"{frames // 2} frames where its header states {frames}: cut short" in notes
    assert "1 cell(s) are not numbers and are read as gaps (first: data row 100, column 4)" in notes
    assert "header states 240 Hz but the Time column steps at 120 Hz" in notes and take.frame_rate_hz == 120.0
    assert read_mocap(synthetic_take).notes == ()  # a clean export says nothing
    from pianobot.io.importers import import_mocap
    from pianobot.store import load_run

    result = import_mocap(damaged, tmp_path / "data")
    assert load_run(result.run_id, tmp_path / "data").meta["import_warnings"] == result.extra["warnings"]
