"""A reduced, seeded scenario suite: the full one with hit rates is benchmarks/bench_discover.py.

Each dataset is 12 world-generated keystrokes (4 speeds × 3 vacua) with 120 Hz mocap noise,
dropped frames and MIDI quantisation, so every test here is one full discovery run.
"""

from __future__ import annotations

import own_world as sc
import pytest

from pianobot.analysis.discover.decide import family_of
from pianobot.analysis.discover.loop import discover
from pianobot.analysis.discover.result import DiscoveryResult


def _run(scenario: sc.Scenario) -> DiscoveryResult:
    small = sc.reduced(scenario)
    return discover(sc.generate(small), small.start)


def _shrink(result: DiscoveryResult) -> float:
    first, last = result.iterations[0], result.iterations[-1]
    after = (last.after or last.before).gap.primary
    return first.before.gap.primary / max(after, 1e-12)


@pytest.mark.parametrize(
    ("effect", "strength"),
    [("key_friction", "weak"), ("arm_lag", "strong"), ("mocap_delay", "weak")],
)
def test_hidden_effect_is_named_and_the_gap_shrinks(effect: str, strength: str) -> None:
    result = _run(sc.hidden_effect(effect, strength, seed=7))
    assert family_of(effect) in {family_of(e) for e in result.accepted_effects}
    assert _shrink(result) >= 5.0
    assert result.iterations[0].to_dict()["accepted_effect"] in result.accepted_effects


def test_clean_control_accepts_nothing() -> None:
    result = _run(sc.control("clean", seed=31))
    assert result.accepted_effects == ()
    assert result.iterations[0].accepted is None
    assert "no missing effect found" in result.verdict


def test_base_parameter_error_is_not_mistaken_for_an_effect() -> None:
    result = _run(sc.control("k2-off", seed=40))
    assert result.accepted_effects == ()


def test_structural_mismatch_names_the_family_or_says_unexplained() -> None:
    result = _run(sc.structural("keybed", seed=21))
    assert "keybed" in result.accepted_effects
    assert _shrink(result) >= 3.0 or "unexplained" in result.verdict


def test_midi_only_names_arm_acceleration() -> None:
    result = _run(sc.midi_only(seed=50))
    first = result.iterations[0]
    assert first.accepted is not None and first.accepted.effect == "arm_acceleration"
    assert first.after is not None
    assert first.after.gap.on_velocity < first.before.gap.on_velocity
    assert first.before.gap.primary_name == "on_velocity"
