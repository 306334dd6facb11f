"""Discovery's building blocks on synthetic arrays: noise, STLSQ, fitter, decision, localisation."""

from __future__ import annotations

import numpy as np
import pytest

from pianobot.analysis.discover.data import (
    PHASES,
    Keystroke,
    Prediction,
    phase_labels,
    stratified_split,
)
from pianobot.analysis.discover.decide import Candidate, DecisionRule, choose, family_of
from pianobot.analysis.discover.fit import ParamSpec, fit
from pianobot.analysis.discover.localise import gap, localise
from pianobot.analysis.discover.noise import lag1_autocorrelation, noise_sigma, systematic_rms
from pianobot.analysis.discover.sparse import KeyState, propose_terms, proposed_families, stlsq
from pianobot.physics.trajectory import Press


def test_noise_sigma_ignores_a_smooth_misfit() -> None:
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 2.0, 240)
    smooth = 1e-3 * np.sin(2 * np.pi * 1.5 * t)  # a 1 mm systematic misfit
    noisy = smooth + rng.normal(0.0, 5e-6, t.size)
    noisy[50:53] = np.nan  # dropped frames break the difference runs, not the estimate
    sigma = noise_sigma([noisy])
    assert sigma == pytest.approx(5e-6, rel=0.25)
    assert systematic_rms(noisy, sigma) == pytest.approx(np.sqrt(0.5) * 1e-3, rel=0.02)


def test_lag1_separates_white_noise_from_misfit() -> None:
    rng = np.random.default_rng(1)
    assert abs(lag1_autocorrelation(rng.normal(size=500))) < 0.15
    assert lag1_autocorrelation(np.sin(np.linspace(0, 3, 500))) > 0.9


def test_stlsq_recovers_sparse_coefficients() -> None:
    rng = np.random.default_rng(2)
    theta = rng.normal(size=(400, 6))
    truth = np.array([0.0, 2.0, 0.0, 0.0, -0.5, 0.0])
    xi = stlsq(theta, theta @ truth + rng.normal(0, 0.01, 400), threshold=0.05)
    assert np.flatnonzero(xi).tolist() == [1, 4]
    assert xi[1] == pytest.approx(2.0, abs=0.01)


def test_sparse_terms_point_at_a_keybed_hinge() -> None:
    t = np.linspace(0.0, 1.0, 600)
    x2 = 0.011 * np.sin(np.pi * t) ** 2
    v2 = np.gradient(x2, t)
    state = KeyState(x2, v2, 0.002 + 0.0 * x2, 0.3 + 0.0 * x2, (v2 > 0).astype(float))
    force = -3.0e4 * np.maximum(0.0, x2 - 0.009)
    families = proposed_families(propose_terms(state, force, key_dip_m=0.010))
    assert families[0] == "keybed"


def test_fit_recovers_parameter_and_interval_excludes_off() -> None:
    rng = np.random.default_rng(3)
    x = np.linspace(0, 1, 200)
    y = 0.3 * x**2 + rng.normal(0, 0.01, x.size)
    specs = [ParamSpec("a", 0.1, 0.0, 1.0, off=0.0), ParamSpec("b", 1.0, 0.1, 10.0, log=True)]
    result = fit(specs, lambda p: (y - p["a"] * x ** (2 * p["b"] / 2)) / 0.01)
    assert result.value("a") == pytest.approx(0.3, abs=0.02)
    assert result.excludes("a", 0.0)
    assert result.chi2 / result.n == pytest.approx(1.0, abs=0.3)


def _candidate(effect: str, dbic: float, after: float, n: int = 1, ci: float = 0.1) -> Candidate:
    from pianobot.analysis.discover.fit import FitResult

    names = tuple(f"p{i}" for i in range(n))
    fr = FitResult(names, (1.0,) * n, (1.0 - ci,) * n, (1.0 + ci,) * n, 100.0, 1000, 0.0, True)
    return Candidate(effect, fr, names, (0.0,) * n, dbic, 1.0, after)


def test_choose_applies_every_condition_and_prefers_simpler() -> None:
    rule = DecisionRule(bic_margin=10.0, min_gap_reduction=0.2, nested_tolerance=10.0)
    accepted, judged = choose(
        [
            _candidate("keybed", 500.0, 0.1, n=3),
            _candidate("key_preload", 495.0, 0.12, n=1),
            _candidate("letoff", 800.0, 0.95),  # big ΔBIC but no held-out gain
            _candidate("adhesion", 600.0, 0.1, ci=2.0),  # interval includes off
        ],
        rule,
        threshold=rule.threshold([3.0]),
    )
    assert accepted is not None and accepted.effect == "key_preload"
    status = {c.effect: c.status for c in judged}
    assert status["letoff"] == "rejected" and status["adhesion"] == "rejected"
    none, _ = choose([_candidate("keybed", 5.0, 0.1)], rule, threshold=10.0)
    assert none is None
    assert family_of("letoff") == family_of("keybed")


def test_bootstrap_raises_the_threshold() -> None:
    rule = DecisionRule(bic_margin=10.0, bootstrap_factor=2.0)
    assert rule.threshold([]) == 10.0
    assert rule.threshold([30.0, float("nan")]) == 60.0


def _synthetic(n: int, misfit_m: float, seed: int) -> tuple[list[Keystroke], list[Prediction]]:
    rng = np.random.default_rng(seed)
    ks, ps = [], []
    t = np.arange(0.0, 1.0, 1 / 120)
    for i in range(n):
        speed = 0.01 + 0.005 * i
        x0 = 0.02 * np.sin(np.pi * t) ** 2
        x2 = np.clip(x0 - 0.01, 0, None)
        comp = x0 - 0.01
        pred = np.vstack([x0, x0, x2])
        meas = pred + rng.normal(0, 5e-6, pred.shape)
        meas[2] += misfit_m * (x2 > 0.005)
        press = Press(0.01, 0.01, speed, speed, 1.0)
        ks.append(Keystroke(f"k{i}", press, -40.0 * (i % 2), t, meas, 40.0, 0.5, 0.7, True))
        phase = phase_labels(t, x0, comp)
        ps.append(
            Prediction(pred, np.gradient(x2, t), comp, comp * 100, phase, 38.0, 0.5, 0.7, True)
        )
    return ks, ps


def test_localise_finds_the_phase_and_the_gap() -> None:
    ks, ps = _synthetic(8, 2e-4, 4)
    loc = localise(ks, ps)
    assert loc.gap.sigma_m == pytest.approx(5e-6, rel=0.3)
    assert loc.gap.position_m > 5e-5
    assert loc.gap.on_velocity == pytest.approx(np.sqrt(4 - 1 / 12), rel=1e-6)
    assert "press" in loc.worst_phases() or "hold" in loc.worst_phases()
    assert "approach" not in loc.worst_phases()
    clean = gap(*_synthetic(8, 0.0, 5))
    assert clean.position_m < 3e-6


def test_phase_labels_cover_a_press() -> None:
    t = np.linspace(0, 1, 121)
    x0 = 0.02 * np.sin(np.pi * t) ** 2
    labels = phase_labels(t, x0, x0 - 0.01)
    names = {PHASES[i] for i in labels}
    assert {"approach", "press", "release", "return"} <= names


def test_stratified_split_spans_speeds_and_vacua() -> None:
    ks, _ = _synthetic(24, 0.0, 6)
    train, held = stratified_split(ks, 0.33, seed=0)
    assert len(set(train) | set(held)) == 24 and not set(train) & set(held)
    assert {ks[i].vacuum_kpa for i in held} == {0.0, -40.0}
    assert 6 <= len(held) <= 10


def test_a_switch_without_parameters_can_be_accepted() -> None:
    rule = DecisionRule()
    switch = _candidate("arm_acceleration", 500.0, 0.1, n=0)
    accepted, _ = choose([switch], rule, threshold=10.0)
    assert accepted is not None and accepted.effect == "arm_acceleration"


def test_decision_values_are_shown_in_readable_units() -> None:
    from pianobot.analysis.discover.fit import FitResult
    from pianobot.analysis.discover.params import format_value

    fr = FitResult(
        ("a.bed_depth_m", "a.stiffening_per_m"),
        (0.0095, 60.0),
        (0.0094, 50.0),
        (0.0096, 70.0),
        1.0,
        10,
        0.0,
        True,
    )
    assert format_value("bed_depth_m", 0.0095, fr, "a.bed_depth_m") == "9.5 ± 0.1 mm"
    assert format_value("stiffening_per_m", 60.0, fr, "a.stiffening_per_m").endswith("1/m")
