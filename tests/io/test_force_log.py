"""Force-capture reader: truncated edges, junk lines, bursts, rate alignment."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pianobot.errors import InputError
from pianobot.io.force_log import ForceCalibration, align_to_note_ons, read_force_log
from pianobot.io.keystroke_log import read_keystroke_log


def capture(readings: list[int], head: str = "ing = 0", tail: str = "Analog rea") -> str:
    body = "\r\n".join(f"Analog reading = {r}" for r in readings)
    return f"{head}\r\n{body}\r\n{tail}"


def presses(n: int, rest: int = 60, width: int = 40, peak: int = 30) -> list[int]:
    shape = (peak * np.sin(np.linspace(0, np.pi, width))).round().astype(int).tolist()
    out = [0] * rest
    for _ in range(n):
        out += shape + [0] * rest
    return out


def test_bursts_peaks_and_calibration(tmp_path: Path) -> None:
    path = tmp_path / "force.txt"
    readings = presses(5)
    readings[100] = 3  # a one-sample spike is not a press
    path.write_text(capture(readings))
    log = read_force_log(path, ForceCalibration(gain_n=0.05, offset_n=0.1, rate_hz=50.0))
    assert log.truncated_lines == (1, len(readings) + 2) and log.skipped == ()
    assert len(log.samples) == len(readings)
    assert log.samples["t_s"].iloc[-1] == pytest.approx((len(readings) - 1) / 50.0)
    assert len(log.bursts) == 5
    assert log.bursts["peak_force_n"].tolist() == pytest.approx([30 * 0.05 + 0.1] * 5, abs=0.06)
    assert np.diff(log.bursts["start_s"]).tolist() == pytest.approx(
        [(40 + 60) / 50.0] * 4, abs=0.05
    )


def test_a_dip_inside_a_press_does_not_split_it(tmp_path: Path) -> None:
    readings = [0] * 50 + [20] * 30 + [0] + [20] * 30 + [0] * 50
    path = tmp_path / "dip.txt"
    path.write_text(capture(readings))
    assert len(read_force_log(path).bursts) == 1


def test_junk_lines_are_reported(tmp_path: Path) -> None:
    path = tmp_path / "junk.txt"
    text = capture(presses(2)).replace(
        "Analog reading = 0\r\n", "Analog reading = 0\r\nGARBAGE\r\n", 1
    )
    path.write_text(text)
    log = read_force_log(path)
    assert [s.line for s in log.skipped] == [3]
    assert len(log.bursts) == 2


@pytest.mark.parametrize("content", [b"", b"\x00\x00", b"just text\nmore text\n"])
def test_not_a_capture_is_an_input_error(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "bad.txt"
    path.write_bytes(content)
    with pytest.raises(InputError) as error:
        read_force_log(path)
    assert error.value.where == str(path)


def test_rate_is_recovered_from_note_ons() -> None:
    rng = np.random.default_rng(3)
    true_rate, offset = 47.8, 12.0
    index = np.cumsum(rng.integers(150, 300, size=40)).astype(float)
    notes = offset + index / true_rate + rng.normal(0.5, 0.05, size=40)  # note-on after onset
    sounded = notes[rng.random(40) > 0.25]  # some presses stay silent
    fit = align_to_note_ons(index, sounded, nominal_rate_hz=46.0)
    assert fit is not None and fit.n_matched == sounded.size
    assert fit.rate_hz == pytest.approx(true_rate, rel=2e-3)


def test_fixture_one_burst_per_keystroke(zhang2022: Path) -> None:
    force = read_force_log(zhang2022 / "data/soft/force/P60A45.txt")
    log = read_keystroke_log(zhang2022 / "data/soft/ctrl_midi/soft_60_angle_45.txt")
    # one burst per pressed keystroke: every keystroke of the sweep pressed the sensor
    assert len(force.bursts) == len(log.trials) == 135
    ons = log.trials["t_on_s"].dropna()
    fit = align_to_note_ons(force.bursts["start_index"], ons)
    assert fit is not None and fit.n_matched == len(ons)  # every sounded keystroke has its burst
    assert fit.rate_hz == pytest.approx(47.8, rel=0.01)


def test_fixture_no_piano_presses_parse(zhang2022: Path) -> None:
    folder = zhang2022 / "data/soft/Soft finger no piano"
    peaks = {}
    for path in sorted(folder.glob("*.txt")):
        log = read_force_log(path)
        assert len(log.bursts) == 3, path.name
        peaks[int(path.stem)] = float(log.bursts["peak_force_n"].mean())
    levels = sorted(peaks)
    assert peaks[levels[-1]] > 1.5 * peaks[levels[0]]  # a stiffer finger pushes harder
