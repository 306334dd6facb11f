"""Loading runs for discovery: stored scenario runs round-trip; missing press parameters are derived."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import own_world as sc
import pandas as pd
import pytest

from pianobot.analysis.discover.load import (
    DEFAULT_ACCELERATION_MPS2,
    load_keystrokes,
    resolve_model,
)
from pianobot.errors import InputError
from pianobot.physics.model import KeystrokeModel
from pianobot.store import RunWriter


def test_stored_run_round_trips(data_dir: Path) -> None:
    keystrokes = sc.generate(sc.reduced(sc.control("clean", seed=1), n_speeds=2))
    run_id = sc.write_run(keystrokes, data_dir)
    loaded = load_keystrokes([run_id], data_dir)
    assert len(loaded) == len(keystrokes)
    for a, b in zip(keystrokes, loaded, strict=True):
        assert a.press == b.press and a.vacuum_kpa == b.vacuum_kpa and a.sounded == b.sounded
        np.testing.assert_allclose(a.x_m, b.x_m, atol=1e-12)
        assert a.on_velocity == b.on_velocity


def _take(data_dir: Path, vacuum: float | None) -> str:
    trials = pd.DataFrame(
        {
            "trial_id": ["a", "b"],
            "index": [0, 1],
            "attempt": [1, 1],
            "status": ["ok", "ok"],
            "vacuum_kpa": [vacuum, vacuum],
            "down_velocity_mps": [0.01, 0.02],
            "arm_travel_m": [0.007, 0.007],
        }
    )
    t = np.arange(-0.1, 1.0, 1 / 120)
    samples = pd.concat(
        pd.DataFrame(
            {
                "trial_id": tid,
                "source": "mocap",
                "t_s": t,
                "x0_m": 0.5 + 0 * t,
                "x1_m": 0.4 + 0 * t,
                "x2_m": 0.3 + 0 * t,
            }
        )
        for tid in ("a", "b")
    )
    writer = RunWriter.create(data_dir, name="take", kind="import", meta={}, plan=None)
    writer.append(trials, samples)
    writer.finish("completed")
    return writer.run_id


def test_imported_take_derives_press_and_states_assumptions(data_dir: Path) -> None:
    run_id = _take(data_dir, None)
    with pytest.raises(InputError, match="--vacuum-kpa"):
        load_keystrokes([run_id], data_dir)
    notes: set[str] = set()
    loaded = load_keystrokes([run_id], data_dir, vacuum_kpa=-40.0, notes=notes)
    assert [k.vacuum_kpa for k in loaded] == [-40.0, -40.0]
    press = loaded[0].press
    assert press.distance_m == 0.0 and press.depth_m == pytest.approx(0.007)
    assert press.acceleration_mps2 == DEFAULT_ACCELERATION_MPS2
    assert loaded[0].sounded is None  # no MIDI recorded at all
    assert np.nanmax(np.abs(loaded[0].x_m)) < 1e-12  # absolute heights referenced to rest
    assert any("acceleration" in n for n in notes)


def test_resolve_model(tmp_path: Path) -> None:
    assert resolve_model("study") == KeystrokeModel.study()
    with pytest.raises(InputError):
        resolve_model(str(tmp_path / "missing.json"))
