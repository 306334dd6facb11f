"""The effect vocabulary: stable names, sane parameter specs, an immutable set."""

from __future__ import annotations

import pytest

from pianobot.physics.effects import EFFECT_NAMES, EFFECTS, Effects

DESIGN_NAMES = (
    "contact", "keybed", "key_preload", "key_friction", "finger_stiffening", "adhesion",
    "letoff", "arm_lag", "arm_acceleration", "velocity_curve", "mocap_delay", "stiffness_drift",
    "finger_hysteresis",
)


def test_names_are_the_stable_vocabulary() -> None:
    assert EFFECT_NAMES == DESIGN_NAMES
    assert set(EFFECTS) == set(DESIGN_NAMES)


@pytest.mark.parametrize("name", DESIGN_NAMES)
def test_parameter_specs_are_consistent(name: str) -> None:
    spec = EFFECTS[name]
    assert spec.forms, name
    for p in spec.params:
        assert p.lower <= p.default <= p.upper, p
        assert p.unit and p.description
        if p.off is not None:  # "off" may sit outside the fit bounds (a stiffness of 0)
            assert p.off != p.default, p
        assert set(p.forms) <= set(spec.forms)


def test_parameter_names_are_unique_across_effects() -> None:
    names = [p.name for s in EFFECTS.values() for p in s.params]
    assert len(names) == len(set(names))


def test_with_effect_defaults_overrides_and_immutability() -> None:
    base = Effects.none()
    e = base.with_effect("keybed", bed_depth_m=0.011)
    assert base.names == () and e.names == ("keybed",)
    assert e.params("keybed")["bed_depth_m"] == 0.011
    assert e.params("keybed")["bed_stiffness_npm"] == EFFECTS["keybed"].param("bed_stiffness_npm").default
    assert e.form("keybed") == "linear"
    e2 = e.with_effect("keybed", form="hunt_crossley")
    assert e2.params("keybed")["bed_depth_m"] == 0.011  # kept when re-enabled
    assert e2.form("keybed") == "hunt_crossley"
    assert e2.without("keybed") == Effects.none()


def test_unknown_names_raise_naming_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="keybed"):
        Effects.none().with_effect("keybeds")
    with pytest.raises(ValueError, match="bed_depth_m"):
        Effects.none().with_effect("keybed", depth=0.01)
    with pytest.raises(ValueError, match="hunt_crossley"):
        Effects.none().with_effect("keybed", form="cubic")
    with pytest.raises(ValueError, match="not enabled"):
        Effects.none().params("keybed")


def test_round_trip_and_order() -> None:
    e = Effects.default_world()
    assert len(e.names) >= 5
    assert list(e.names) == [n for n in EFFECT_NAMES if n in e]
    assert Effects.from_dict(e.to_dict()) == e
    assert hash(Effects.from_dict(e.to_dict())) == hash(e)
    assert Effects.from_dict({"contact": None}).names == ("contact",)
    assert e.value("keybed", "bed_depth_m") == e.params("keybed")["bed_depth_m"]
    assert Effects.none().value("keybed", "bed_depth_m", 1.0) == 1.0


def test_a_form_only_parameter_reads_as_its_default_in_another_form() -> None:
    """`value(..., form=)`: a smooth rest stop's width is read only from a smooth stop (the rigid
    stop holds the parameter too, at its default, but does not use it)."""
    rigid = Effects.none().with_effect("key_preload", preload_n=0.4)
    smooth = Effects.none().with_effect("key_preload", form="smooth", preload_n=0.4, preload_width_m=5e-4)
    assert rigid.value("key_preload", "preload_width_m", 0.0, form="smooth") == 0.0
    assert smooth.value("key_preload", "preload_width_m", 0.0, form="smooth") == 5e-4
    assert Effects.none().value("adhesion", "adhesion_range_m", 0.0, form="cohesive") == 0.0
    with pytest.raises(ValueError):
        rigid.value("key_preload", "no_such_parameter", 0.0, form="smooth")
