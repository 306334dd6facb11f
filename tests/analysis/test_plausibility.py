"""Plausibility findings fire on crafted implausible inputs, and stay quiet on plausible ones."""

from __future__ import annotations

import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_runner import invoke_cli

from pianobot.analysis.plausibility import (
    Interval,
    at_bounds,
    damping_ratios,
    few_keystrokes,
    fit_findings,
    identify_findings,
    local_resonance_hz,
    no_resonance,
    stiffness_slope,
    wide_intervals,
)
from pianobot.physics.msd import MSDParams
from pianobot.store import RunWriter


def test_no_resonance_names_the_overdamping_parameter() -> None:
    study = MSDParams()
    assert no_resonance(study, [0.0, -40.0, -80.0]) == []  # rings at 7–11 Hz
    damped = replace(study, c2_nspm=34.0)  # the key's stop absorbed into viscous damping
    (finding,) = no_resonance(damped, [-40.0, -80.0], damping_ratios=damping_ratios(damped))
    assert finding.check == "no_resonance" and "-80, -40 kPa" in finding.message
    assert "largest at 0 Hz" in finding.message and "weaker than the static response" in finding.message
    local = [float(x) for x in re.findall(r"([\d.]+) Hz at -\d+ kPa", finding.message)]
    assert len(local) == 2 and all(5.0 < hz < 20.0 for hz in local)
    assert "key damping c2 = 34 N·s/m came out 113× the study's value" in finding.cause
    assert "discover" in finding.cause
    dead = replace(study, c1_nspm=20.0, c2_nspm=200.0)
    (finding,) = no_resonance(dead, [-40.0])
    assert "no resonance at all" in finding.message and math.isnan(local_resonance_hz(dead.at(-40.0)))
    assert "excite the resonance" in finding.cause  # no damping ratio given: the generic cause


def test_parameters_at_a_bound_and_the_coupling_cause() -> None:
    inside = Interval("k2_npm", 400.0, "N/m", (350.0, 450.0), bounds=(0.3, 3e5))
    stuck = Interval("c2_nspm", 300.0, "N·s/m", (299.0, 300.0), bounds=(3e-4, 300.0))
    coupling = Interval("k0_npm", 0.0754, "N/m", (0.07, 0.08), bounds=(0.07541, 75410.0))
    assert at_bounds([inside]) == []
    found = {f.subject: f for f in at_bounds([inside, stuck, coupling], finger_separates=False)}
    assert set(found) == {"c2_nspm", "k0_npm"}
    assert "upper limit" in found["c2_nspm"].message and "lower limit" in found["k0_npm"].message
    assert "never separates from the key" in found["k0_npm"].cause
    assert "not separately identifiable" in found["k0_npm"].cause


def test_stiffness_slope_sign_and_distance_from_the_study() -> None:
    study_like = Interval("k1_b_npm_per_kpa", 1.05, "N/m/kPa", (0.8, 1.3))
    assert stiffness_slope(study_like, levels=5) == []
    (wrong,) = stiffness_slope(Interval("k1_b_npm_per_kpa", -0.66, "N/m/kPa", (-0.85, -0.48)), levels=2)
    assert "falls with vacuum" in wrong.message and "+1.19" in wrong.message
    assert "only 2 vacuum levels" in wrong.cause
    (far,) = stiffness_slope(Interval("k1_b_npm_per_kpa", 9.0, "N/m/kPa", (8.0, 10.0)), levels=4)
    assert "7.6× the study's" in far.message
    # Far in value but uncertain enough to include the study's slope: not a finding.
    assert stiffness_slope(Interval("k1_b_npm_per_kpa", 5.0, "N/m/kPa", (0.5, 9.0)), levels=4) == []


def test_intervals_wider_than_the_value() -> None:
    ok = Interval("k2_npm", 400.0, "N/m", (350.0, 450.0))
    wide = Interval("c1_nspm", 0.8, "N·s/m", (0.15, 1.51))
    (finding,) = wide_intervals([ok, wide])
    assert finding.subject == "c1_nspm" and "[0.15, 1.51]" in finding.message


def test_too_few_keystrokes_per_level() -> None:
    assert few_keystrokes({-40.0: 24, -80.0: 5}, 5) == []
    (finding,) = few_keystrokes({-40.0: 24, -80.0: 3, 0.0: 1}, 5)
    assert "3 at -80 kPa" in finding.message and "1 at 0 kPa" in finding.message and "24" not in finding.message


def _trials(rng: np.random.Generator, *, louder_when_faster: bool = True, n: int = 30) -> pd.DataFrame:
    rows = []
    for level in (-40.0, -80.0):
        speeds = rng.uniform(0.01, 0.06, n)
        for v in speeds:
            loud = 400 * v if louder_when_faster else 30 - 400 * v
            rows.append({"status": "ok", "vacuum_kpa": level, "down_velocity_mps": v,
                         "on_velocity": loud + rng.normal(0, 0.5)})
    for _ in range(6):
        rows.append({"status": "silent", "vacuum_kpa": 0.0, "down_velocity_mps": 0.03, "on_velocity": np.nan})
    return pd.DataFrame(rows)


def test_fit_findings_on_crafted_training_data() -> None:
    rng = np.random.default_rng(0)
    good_cv = pd.DataFrame({"model": ["mean", "gp"], "r2": [0.0, 0.95]})
    checks = {f.check for f in fit_findings(_trials(rng), good_cv)}
    assert checks == {"silent_level"}  # the all-silent 0 kPa level only
    bad_cv = pd.DataFrame({"model": ["mean", "gp", "poly"], "r2": [0.0, 0.05, np.nan]})
    found = {f.check: f for f in fit_findings(_trials(rng, louder_when_faster=False, n=6), bad_cv)}
    assert {"no_better_than_mean", "few_keystrokes"} <= set(found)
    assert "R² is 0.05 (gp)" in found["no_better_than_mean"].message
    falling = {f.check for f in fit_findings(_trials(rng, louder_when_faster=False), good_cv)}
    assert "falls_with_speed" in falling


def test_fit_prints_and_stores_the_findings(data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    trials = _trials(rng, n=4).assign(trial_id=lambda f: [f"t{i}" for i in range(len(f))], acceleration_mps2=0.5,
                                      depth_m=0.03, distance_m=0.05, hold_s=0.0)
    writer = RunWriter.create(data_dir, name="thin", kind="import", meta={}, plan=None, fsync=False)
    writer.append(trials)
    writer.finish("completed")
    code, out, err = invoke_cli(["fit", writer.run_id, "--data", str(data_dir), "--model", "poly",
                                 "--folds", "2", "--out-dir", str(tmp_path)], capsys, monkeypatch)
    assert code == 0, err
    warnings = [line for line in err.splitlines() if line.startswith("warning: ")]
    assert any("too few sounded keystrokes per vacuum level" in w and "likely cause" in w for w in warnings)
    stored = json.loads((tmp_path / "predictor-poly.json").read_text())["warnings"]
    assert {w["check"] for w in stored} >= {"few_keystrokes", "silent_level"}
    code, out, _ = invoke_cli(["fit", writer.run_id, "--data", str(data_dir), "--model", "poly", "--folds", "2",
                               "--out-dir", str(tmp_path), "--json"], capsys, monkeypatch)
    assert {w["check"] for w in json.loads(out)["warnings"]} == {w["check"] for w in stored}


def test_identify_findings_give_unbounded_fits_a_plausible_range() -> None:
    study = MSDParams()
    estimates = [Interval("k1_npm@-40kPa", 123.0, "N/m", (110.0, 140.0)),
                 Interval("c0_nspm", 0.0004, "N·s/m", (0.0, math.inf)),  # collapsed to zero
                 Interval("k2_npm", 300.0, "N/m", (20.0, 900.0)),  # wider than its value
                 Interval("c2_over_m2_per_s", 8.8, "1/s", (0.1, 40.0)),  # derived: not checked
                 Interval("k1_b_npm_per_kpa", 1.19, "N/m/kPa", (1.19, 1.19))]
    found = {f.check: f for f in identify_findings(study, estimates, {-40.0: 24})}
    assert set(found) == {"at_bound", "wide_interval"}  # one level: the slope is held, not checked
    assert found["at_bound"].subject == "c0_nspm" and "plausible range" in found["at_bound"].message
    assert "--coupling tied" in found["at_bound"].cause
    assert found["wide_interval"].subject == "k2_npm"
    assert identify_findings(study, estimates[:1], {-40.0: 24}) == []
    falling = [Interval("k1_b_npm_per_kpa", -0.66, "N/m/kPa", (-0.85, -0.48))]
    checks = [f.check for f in identify_findings(study, falling, {-40.0: 12, -80.0: 3})]
    assert checks == ["stiffness_slope", "few_keystrokes"]
    # A fit the fitter itself saw end on a limit (zzz40's m1 = 0.6997 kg against 0.7, c0/c1 =
    # 0.001): flagged even where the plausible range would not catch it (it used to pass unsaid).
    mass = Interval("m1_kg", 0.6997, "kg", (0.01, 0.7), at_limit=True)
    stuck = {f.subject: f for f in identify_findings(study, [mass], {-40.0: 24})}
    assert "limit of the fitter's search range" in stuck["m1_kg"].message
