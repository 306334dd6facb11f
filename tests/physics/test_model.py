"""Keystroke models and their JSON files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pianobot.errors import InputError
from pianobot.physics.effects import Effects
from pianobot.physics.model import KeystrokeModel, load_model, read_model_file, save_model
from pianobot.physics.msd import MSDParams


def test_study_model_is_linear_with_ramp_and_linear_readout() -> None:
    m = KeystrokeModel.study()
    assert m.effects == Effects.none()
    assert m.msd == MSDParams()
    assert m.arm_profile == "ramp"
    assert m.readout_params().curve_exponent == 1.0
    m2 = m.with_effect("arm_acceleration").with_effect("velocity_curve", curve_exponent=3.0)
    assert m2.arm_profile == "trapezoid"
    assert m2.readout_params().curve_exponent == 3.0
    assert m2.without("arm_acceleration").arm_profile == "ramp"
    assert m.effects == Effects.none()  # frozen: copies only


def test_save_and_load_round_trip(tmp_path: Path) -> None:
    m = KeystrokeModel(
        MSDParams(c1_nspm=0.7, k1_table=((-60.0, 140.0),)), Effects.default_world()
    )
    path = save_model(m, tmp_path / "sub" / "m.json", intervals={"c1_nspm": [0.6, 0.8]},
                      provenance={"run": "abc", "score": float("nan")})
    payload = json.loads(path.read_text())
    assert payload["schema"] == "pianobot.model/1"
    assert payload["provenance"]["score"] is None
    assert load_model(path) == m
    f = read_model_file(path)
    assert f.intervals == {"c1_nspm": [0.6, 0.8]}
    assert f.provenance is not None and f.provenance["run"] == "abc"


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ('{"schema": "pianobot.run/1"}', "pianobot.model/1"),
        ('{"schema": "pianobot.model/1", "kind": "dataset"}', "keystroke_model"),
        ("not json", "JSON"),
        ('{"schema": "pianobot.model/1", "model": {"effects": {"wings": {}}}}', "wings"),
        ('{"schema": "pianobot.model/1", "model": {"msd": {"m1_kg": -1}}}', "m1_kg"),
    ],
)
def test_bad_files_raise_input_error_naming_the_file(tmp_path: Path, content: str, match: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(InputError, match=match) as info:
        load_model(path)
    assert info.value.where == str(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found"):
        load_model(tmp_path / "none.json")
