"""`pianobot model bode | simulate`: output, JSON keys, plots, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_runner import invoke_cli

from pianobot.physics.model import KeystrokeModel, save_model


def _run(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    return invoke_cli(list(args), capsys, monkeypatch)


def test_bode_json_and_plot(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    png = tmp_path / "bode.png"
    code, out, _ = _run(monkeypatch, capsys, "model", "bode", "--vacuum-kpa", "-60", "--json", "--plot", str(png))
    assert code == 0
    payload = json.loads(out)
    assert abs(payload["peak_hz"] - 9.1) < 0.1
    assert payload["vacuum_kpa"] == -60 and payload["peak_gain"] > 1
    assert png.stat().st_size > 1000
    code, out, _ = _run(monkeypatch, capsys, "model", "bode", "--vacuum-kpa", "-60")
    assert code == 0 and "9.10 Hz" in out


def test_bode_reads_a_model_file(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    stiff = KeystrokeModel.study()
    stiff = stiff.replace(msd=stiff.msd.replace(k2_npm=600.0))
    path = save_model(stiff, tmp_path / "m.json")
    code, out, _ = _run(monkeypatch, capsys, "model", "bode", "--vacuum-kpa", "-60", "--model", str(path), "--json")
    assert code == 0 and json.loads(out)["peak_hz"] > 9.3
    bad = tmp_path / "bad.json"
    bad.write_text('{"schema": "other/1"}')
    code, _, err = _run(monkeypatch, capsys, "model", "bode", "--model", str(bad))
    assert code == 2 and err.startswith("error:") and "bad.json" in err and err.count("\n") == 1


def test_simulate_prints_midi_outcome_and_plots(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    png = tmp_path / "ks.png"
    code, out, _ = _run(monkeypatch, capsys, "model", "simulate", "--vacuum-kpa", "-60", "--down-velocity-mps", "0.07",
                        "--depth-m", "0.03", "--plot", str(png), "--json")
    assert code == 0 and png.stat().st_size > 1000
    payload = json.loads(out)
    assert payload["silent"] is False and 1 <= payload["on_velocity"] <= 127
    assert [e["type"] for e in payload["midi"]] == ["note_on", "note_off"]
    code, out, _ = _run(monkeypatch, capsys, "model", "simulate", "--vacuum-kpa", "0", "--depth-m", "0.02",
                        "--world", "default", "--json")
    assert code == 0 and json.loads(out)["silent"] is True
    code, out, _ = _run(monkeypatch, capsys, "model", "simulate", "--world", "linear")
    assert code == 0 and "note-on velocity (MIDI)" in out


@pytest.mark.parametrize(
    ("args", "where"),
    [
        (["--vacuum-kpa", "-150"], "--vacuum-kpa"),  # 20 reads as -20 kPa, as in every command
        (["--world", "mars"], "--world"),
        (["--down-velocity-mps", "-0.1"], "press"),
    ],
)
def test_simulate_bad_input_is_one_line_exit_2(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                               args: list[str], where: str) -> None:
    code, _, err = _run(monkeypatch, capsys, "model", "simulate", *args)
    assert code == 2 and err.startswith(f"error: {where}") and err.count("\n") == 1
