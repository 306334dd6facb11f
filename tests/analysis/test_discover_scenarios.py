"""A reduced own-world scenario suite (12-keystroke takes): the full one with hit rates is
benchmarks/bench_discover.py, and the independent suite (tests/truth) is the acceptance test.

Each dataset is stored as a run (500 Hz arm log, 120 Hz mocap with noise and dropped frames,
MIDI) and loaded through the one loader, so every test here is one full discovery run.
"""

from __future__ import annotations

from pathlib import Path

import own_world as ow
import pytest

from pianobot.analysis.discover.candidates import family_of
from pianobot.analysis.discover.loop import discover
from pianobot.analysis.discover.result import DiscoveryResult


def _run(scenario: ow.Scenario, data_dir: Path, n_speeds: int = 4) -> DiscoveryResult:
    return discover(ow.generate(ow.reduced(scenario, n_speeds), data_dir))


def test_hidden_key_effect_is_named_and_the_gap_shrinks(data_dir: Path) -> None:
    result = _run(ow.hidden_effect("key_friction", "weak", seed=7), data_dir)
    assert [family_of(e) for e in result.accepted_effects] == ["key_action"]
    first = result.accepted[0]
    assert first.ratio >= 3.0 and first.delta_ic > 10
    assert "mm" in result.decision_line and "explained" in result.verdict


def test_clean_control_and_a_wrong_base_parameter_accept_nothing(data_dir: Path) -> None:
    for scenario in (ow.control("clean", seed=31), ow.control("k2-off", seed=40)):
        result = _run(scenario, data_dir)
        assert result.accepted_effects == (), scenario.name
        assert "no missing effect found" in result.verdict
        # The arm is measured: its trapezoid is a measured property, never a discovery.
        assert "arm_acceleration" in result.measured_effects


def test_a_richer_form_is_caught_by_its_family(data_dir: Path) -> None:
    result = _run(ow.structural("keybed", seed=21), data_dir)
    assert family_of(result.accepted_effects[0]) == "key_stop"
    assert result.accepted[0].ratio >= 3.0 or "unexplained" in result.verdict


def test_a_sticking_pad_is_found_past_lift_off_and_a_finger_that_just_leaves_is_measured(data_dir: Path) -> None:
    """The finger leaves the key at every release: that contact is unilateral is measured on the
    release (not discovered), and a pad sticking up to 0.15 N is named there with its force."""
    sticky = _run(ow.release("adhesion", seed=43), data_dir)
    assert sticky.accepted_effects == ("adhesion",)
    assert sticky.accepted[0].params["adhesion.pull_off_force_n"] == pytest.approx(0.15, rel=0.2)
    assert sticky.iterations[-1].window == "release"
    clean = _run(ow.release("contact", seed=44), data_dir)
    assert clean.accepted_effects == () and "contact" in clean.measured_effects
    assert "contact" in clean.final_model.effects
    # The model written (--model-out) is the one the tables show: nothing was accepted before
    # lift-off, so its base is the base fit, not the release's refit of it (m1 went to its limit).
    assert clean.final_model.msd == clean.base_model.msd
    for result in (sticky, clean):  # the press-window gaps are what the summary reports
        assert result.gap_after is result.press_iterations[-1].gap_before


def test_arm_lag_and_mocap_clock_are_judged_against_the_measurements(data_dir: Path) -> None:
    lag = _run(ow.hidden_effect("arm_lag", "strong", seed=11), data_dir)
    assert "arm_lag" in lag.measured_effects and "arm_lag" not in lag.accepted_effects
    found = next(f for f in lag.findings if f.effect == "arm_lag")
    assert found.value == pytest.approx(0.010, abs=0.003)
    clock = _run(ow.hidden_effect("mocap_delay", "strong", seed=12), data_dir)
    assert "mocap_delay" in clock.measured_effects and not clock.accepted_effects


def test_midi_only_names_the_trapezoid_cap(data_dir: Path) -> None:
    result = _run(ow.midi_only("arm_acceleration", seed=50), data_dir, n_speeds=4)
    assert result.mode == "midi"
    assert result.accepted_effects and result.accepted_effects[0] == "arm_acceleration"
    first = result.accepted[0]
    assert first.ratio >= 3.0
