"""Which parameters discovery fits: base scale factors, candidate effects, starting points.

Base parameters are fitted as scale factors in log space (k1 as one factor on its whole vacuum
law, so the published vacuum dependence is kept); effect parameters use the vocabulary's bounds
with the simplest form of each effect (linear keybed, Coulomb friction, cubic stiffening,
first-order lag): a world may use a richer form, and discovery must still name the family.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pianobot.analysis.discover.data import Keystroke
from pianobot.analysis.discover.fit import FitResult, ParamSpec
from pianobot.analysis.discover.sparse import Proposal
from pianobot.physics.effects import EFFECT_NAMES, EFFECTS
from pianobot.physics.model import KeystrokeModel

_BASE_RANGE = 3.0  # base parameters may move by this factor either way
# Effects whose simplest form discovery fits (a world may use the richer one).
_CANDIDATE_FORM = {"keybed": "linear", "key_friction": "coulomb", "finger_stiffening": "cubic"}


def base_specs(model: KeystrokeModel, keystrokes: Sequence[Keystroke]) -> list[ParamSpec]:
    """Free base parameters: finger stiffness and damping, key spring and damping, MIDI gain."""
    specs = [
        ParamSpec("base.k1_scale", 1.0, 1 / _BASE_RANGE, _BASE_RANGE, log=True),
        ParamSpec("base.c1_scale", 1.0, 1 / _BASE_RANGE, _BASE_RANGE, log=True),
        ParamSpec("base.k2_scale", 1.0, 1 / _BASE_RANGE, _BASE_RANGE, log=True),
        ParamSpec("base.c2_scale", 1.0, 1 / _BASE_RANGE, _BASE_RANGE, log=True),
    ]
    if not any(k.has_motion for k in keystrokes):
        # MIDI alone cannot separate damping from stiffness: keep the published damping.
        specs = [s for s in specs if s.name in ("base.k1_scale", "base.k2_scale")]
    if any(k.sounded for k in keystrokes):
        specs.append(
            ParamSpec("base.full_scale_scale", 1.0, 1 / _BASE_RANGE, _BASE_RANGE, log=True)
        )
    return specs


def candidate_form(effect: str) -> str | None:
    """The form discovery fits for an effect (None: the effect's default)."""
    return _CANDIDATE_FORM.get(effect)


def with_effect(model: KeystrokeModel, effect: str) -> KeystrokeModel:
    """The model with a candidate effect on at its defaults (adhesion brings contact along)."""
    out = model
    if effect == "adhesion" and "contact" not in model.effects:
        out = out.with_effect("contact")
    return out.with_effect(effect, form=candidate_form(effect))


def effect_specs(model: KeystrokeModel, effect: str) -> list[ParamSpec]:
    """Free parameters of an enabled effect, for its form, within the vocabulary's bounds."""
    spec = EFFECTS[effect]
    form = model.effects.form(effect)
    current = model.effects.params(effect)
    out = []
    for p in spec.params:
        if p.forms and form not in p.forms:
            continue
        wide = p.lower > 0 and p.upper / p.lower > 20  # scale-like: fit in log space
        start = min(max(current[p.name], p.lower), p.upper)
        out.append(ParamSpec(f"{effect}.{p.name}", start, p.lower, p.upper, p.off, log=wide))
    return out


def start_points(
    model: KeystrokeModel, effect: str, keystrokes: Sequence[Keystroke]
) -> list[dict[str, float]]:
    """Starting values worth trying for an effect's fit (one simulation each, best one kept).

    The effect's magnitude (the parameter with an "off" value) is started across its range: a
    stick/slip or stick/release switch makes the error jump, and a local fit from one start can
    stall on the wrong step. An end stop or escapement the key never reaches has no gradient,
    so their depths are also started across the key travel actually measured (or across their
    bounds without mocap), in combination with the magnitudes.
    """
    specs = effect_specs(model, effect)
    by_name = {s.name: s for s in specs}
    magnitudes: list[dict[str, float]] = [{}]
    magnitude = next((s for s in specs if s.off is not None), None)
    if magnitude is not None:
        lo = magnitude.to_internal(max(magnitude.lower, 1e-9))
        hi = magnitude.to_internal(magnitude.upper)
        for fraction in (0.1, 0.3, 0.6, 0.9):
            value = magnitude.from_internal(lo + fraction * (hi - lo))
            if value != magnitude.off:
                magnitudes.append({magnitude.name: value})
    travel = [
        float(np.nanmax(k.x_m[2]))
        for k in keystrokes
        if k.has_motion and np.isfinite(k.x_m[2]).any()
    ]
    for name in (f"{effect}.bed_depth_m", f"{effect}.letoff_depth_m"):
        spec = by_name.get(name)
        if spec is None:
            continue
        if travel:
            top = float(np.quantile(travel, 0.9))
            depths = [f * top for f in (0.5, 0.7, 0.85, 0.95)]
        else:
            depths = list(np.linspace(spec.lower, spec.upper, 5)[1:-1])
        return [
            {name: min(max(d, spec.lower), spec.upper), **m} for d in depths for m in magnitudes[:4]
        ]
    return magnitudes


def off_values(names: Sequence[str]) -> tuple[float, ...]:
    """The "off" value of each `effect.param` name (NaN where none exists)."""
    out = []
    for name in names:
        effect, param = name.split(".", 1)
        off = EFFECTS[effect].param(param).off
        out.append(float("nan") if off is None else off)
    return tuple(out)


def apply_values(model: KeystrokeModel, values: dict[str, float]) -> KeystrokeModel:
    """The model with base scale factors and effect parameters set from `values`."""
    msd, piano = model.msd, model.piano
    if values:
        k1 = values.get("base.k1_scale", 1.0)
        c1 = values.get("base.c1_scale", 1.0)
        msd = msd.replace(
            k1_a_npm=msd.k1_a_npm * k1,
            k1_b_npm_per_kpa=msd.k1_b_npm_per_kpa * k1,
            k1_table=tuple((p, k * k1) for p, k in msd.k1_table),
            k0_npm=None if msd.k0_npm is None else msd.k0_npm * k1,
            c1_nspm=msd.c1_nspm * c1,
            c0_nspm=None if msd.c0_nspm is None else msd.c0_nspm * c1,
            k2_npm=msd.k2_npm * values.get("base.k2_scale", 1.0),
            c2_nspm=msd.c2_nspm * values.get("base.c2_scale", 1.0),
        )
        piano = piano.replace(
            full_scale_speed_mps=piano.full_scale_speed_mps
            * values.get("base.full_scale_scale", 1.0)
        )
    out = model.replace(msd=msd, piano=piano)
    per_effect: dict[str, dict[str, float]] = {}
    for name, value in values.items():
        head, param = name.split(".", 1)
        if head != "base":
            per_effect.setdefault(head, {})[param] = value
    for effect, params in per_effect.items():
        out = out.replace(effects=out.effects.with_effect(effect, form=None, **params))
    return out


def candidate_effects(
    model: KeystrokeModel, keystrokes: Sequence[Keystroke], proposals: Sequence[Proposal] = ()
) -> list[str]:
    """Effects of the vocabulary not yet in the model that these data can reveal.

    Sparse proposals come first (they are fitted the same way, only earlier). mocap_delay needs
    motion capture, velocity_curve needs MIDI; stiffness_drift changes nothing a single model
    predicts (its drift is random per block), so it cannot be fitted by simulation error.
    """
    has_motion = any(k.has_motion for k in keystrokes)
    has_midi = any(k.sounded for k in keystrokes)
    out = []
    for effect in EFFECT_NAMES:
        if effect in model.effects or effect == "stiffness_drift":
            continue
        if effect == "mocap_delay" and not has_motion:
            continue
        if effect == "velocity_curve" and not has_midi:
            continue
        out.append(effect)
    first = [p.family for p in proposals if p.family in out]
    ordered = list(dict.fromkeys([f for f in first if f is not None] + out))
    return ordered


def format_value(name: str, value: float, fit: FitResult, key: str) -> str:
    """`value ± half-width` in a readable unit (mm for metres, ms for seconds)."""
    i = fit.names.index(key)
    half = 0.5 * (fit.upper_ci[i] - fit.lower_ci[i])
    scale, unit = 1.0, ""
    if name.endswith("_per_m"):
        unit = " 1/m"
    elif name.endswith("_m"):
        scale, unit = 1e3, " mm"
    elif name.endswith("_s"):
        scale, unit = 1e3, " ms"
    elif name.endswith("_n"):
        unit = " N"
    return f"{value * scale:.3g} ± {half * scale:.2g}{unit}"


def model_to_dict(model: KeystrokeModel) -> dict[str, Any]:
    """The model's JSON form."""
    return model.to_dict()
