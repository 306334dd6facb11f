"""Which effects discovery tries, in which forms, from which starting points.

A candidate is the base model plus one effect of `physics.effects` in one of its forms. Every
form the vocabulary has is a candidate of its own, so a family is tried in shapes that bracket
what a real mechanism may be: an end stop as a linear spring-damper and as a Hunt–Crossley
(force ∝ indentation^1.5) contact, friction as Coulomb and as Stribeck (breakaway above the
sliding force), a stiffening finger as exponential and as a power of the compression whose
exponent is fitted (the cubic form is its exponent 2), a finger body that yields as an
elastoplastic (Jenkins) element. A stop of another power, a LuGre friction or a smoothly yielding
(Bouc–Wen) finger sits between or near these, and the family is named by the form that explains
it best.

What the data can judge decides the list:

- with the arm measured, the model is driven by the arm trace: arm-side effects (`arm_lag`,
  `arm_acceleration`) are judged against that trace (`measured.py`), never inferred from the
  key; the mocap clock offset is measured against the arm log, and the piano's velocity map
  against the measured key speed;
- with MIDI only, everything acts through the outcomes, arm-side and readout effects included;
- `stiffness_drift` changes nothing a single model predicts (its drift is random per block);
- a yielding finger body (`finger_hysteresis`) is tried only where the fingertip and the arm are
  tracked: its deflection is what it acts on, and with MIDI only it is a softer finger on the
  way down and a later release, which the stiffnesses and readout already trade against;
- a rest stop that lets go smoothly (`key_preload/smooth`) and a skin whose pull fades over a
  separation range (`adhesion/cohesive`) likewise only with trajectories (`TRACKED_ONLY`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pianobot.analysis.greybox.forward import largest_compression_m, largest_deflection_m
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.layout import Layout, Param, effect_params
from pianobot.physics.effects import EFFECT_NAMES, EFFECTS
from pianobot.physics.model import KeystrokeModel

#: Effects that act on the finger or the key (judged through the trajectories or the outcomes).
KEY_SIDE: tuple[str, ...] = ("contact", "keybed", "key_preload", "key_friction", "finger_stiffening",
                             "adhesion", "letoff", "finger_hysteresis")
#: Effects on the arm's motion: judged against a measured arm trace when there is one.
ARM_SIDE: tuple[str, ...] = ("arm_lag", "arm_acceleration")

# Effects that are alternative explanations of the same observation; naming any member counts
# as naming the family (e.g. a trapezoid input and a lagging arm both delay the key).
FAMILIES: dict[str, str] = {
    "contact": "contact", "adhesion": "contact", "keybed": "key_stop", "letoff": "key_stop",
    "key_preload": "key_action", "key_friction": "key_action", "finger_stiffening": "finger",
    "stiffness_drift": "finger", "finger_hysteresis": "finger", "arm_lag": "arm", "arm_acceleration": "arm", "velocity_curve": "piano",
    "mocap_delay": "mocap",
}


#: A stiffening finger's scale β is kept to β·δ ≤ this at the largest compression δ the data show
#: (5 mm assumed with MIDI only, where this keeps the former bound of 300 /m): there an
#: exponential finger is e^1.5 ≈ 4.5 times its linear stiffness, a cubic one 7.75 times. Stiffer
#: still would be an end stop, and a model that stiff needs an integration step too small to fit
#: in reasonable time. (At 2, a MIDI log with a velocity curve also accepted an exponential finger.)
STIFFENING_REACH = 1.5

#: A yielding finger body's yield deflection is bounded by the largest body deflection the data
#: show (a body that never yields is the linear one: the size would have nothing to act on) and
#: started at this fraction of it; `start_points` tries `YIELD_FRACTIONS` of it as well.
YIELD_START = 0.5
YIELD_FRACTIONS = (0.25, 0.5, 0.8)

#: Where no key travel is measured (MIDI only), an end stop's depth is started across a piano
#: key's dip, from here to its upper bound: the part of its bounds below is for stops a tracked
#: key shows within a shallower travel (a finger resting on a stiff key moves it a millimetre).
UNTRACKED_STOP_FROM_M = 0.005

#: Forms that another form of the same effect holds as a special case are not tried on their own:
#: the power form at exponent 2 is the cubic (its fits start there).
SUBSUMED: frozenset[tuple[str, str]] = frozenset({("finger_stiffening", "cubic")})


#: Forms tried only where the key is tracked: with MIDI only, a preload is already a shift of the
#: sensor depths (docs/architecture.md), and how its stop lets go acts only in the short
#: transient before break-away, which no outcome shows apart (tried there, it took an
#: independent 135-keystroke log 1.42x the time, with the same findings).
#: Likewise a skin that lets go gradually (`adhesion/cohesive`): with MIDI only, adhesion shows
#: as a later note-off, which the pull-off skin already gives; how the pull fades with
#: separation shows in no outcome apart.
TRACKED_ONLY: frozenset[tuple[str, str]] = frozenset({("key_preload", "smooth"), ("adhesion", "cohesive")})


def family_of(effect: str | None) -> str | None:
    """The family an effect belongs to (itself when unlisted)."""
    return None if effect is None else FAMILIES.get(effect, effect)


@dataclass(frozen=True)
class CandidateSpec:
    """One effect in one form."""

    effect: str
    form: str

    @property
    def label(self) -> str:
        """`effect`, or `effect/form` when the effect has several forms and this is not the
        one called "default" (a form added beside an effect's original shape)."""
        plain = len(EFFECTS[self.effect].forms) == 1 or self.form == "default"
        return self.effect if plain else f"{self.effect}/{self.form}"

    @property
    def family(self) -> str | None:
        return family_of(self.effect)


def candidates(model: KeystrokeModel, batch: KeystrokeBatch) -> list[CandidateSpec]:
    """Every (effect, form) the model lacks that these data can judge (module docstring)."""
    trajectories = batch.has_motion
    out = []
    for effect in EFFECT_NAMES:
        if effect in model.effects or effect in ("stiffness_drift", "mocap_delay"):
            continue
        if trajectories and (effect in ARM_SIDE or effect == "velocity_curve"):
            continue  # judged against the measurement itself (measured.py)
        if not trajectories and effect == "velocity_curve" and not batch.has_midi:
            continue
        if effect == "adhesion" and "contact" not in model.effects:
            continue  # a pull-off force needs a contact that can open; contact comes first
        if effect == "finger_hysteresis" and not trajectories:
            continue  # the body's deflection is not seen (module docstring)
        out += [CandidateSpec(effect, form) for form in EFFECTS[effect].forms
                if (effect, form) not in SUBSUMED and (trajectories or (effect, form) not in TRACKED_ONLY)]
    return out


def candidate_params(spec: CandidateSpec, batch: KeystrokeBatch) -> list[Param]:
    """The effect's free parameters; depths start inside the key travel the data show, a
    stiffening finger's scale stays within `STIFFENING_REACH` of the largest compression, and a
    yielding body's yield within the largest deflection (`YIELD_START` of it to start)."""
    start: dict[str, float] = {}
    travel = _travel_m(batch)
    if travel is not None:
        start = {"bed_depth_m": 0.85 * travel, "letoff_depth_m": 0.7 * travel}
    params = effect_params(spec.effect, spec.form, start)
    reach = STIFFENING_REACH / largest_compression_m(batch)
    params = [dataclasses.replace(p, upper=min(p.upper, reach), start=min(p.start, reach))
              if p.name == "finger_stiffening.stiffening_per_m" else p for p in params]
    deflection = largest_deflection_m(batch)
    if deflection is None:
        return params
    return [dataclasses.replace(p, upper=max(min(p.upper, deflection), p.lower),
                                start=min(max(YIELD_START * deflection, p.lower), p.upper))
            if p.name == "finger_hysteresis.yield_m" else p for p in params]


def _travel_m(batch: KeystrokeBatch) -> float | None:
    """A high quantile of the measured key travel (None without trajectories)."""
    if not batch.has_motion:
        return None
    peaks = np.nanmax(np.where(np.isfinite(batch.x2_m), batch.x2_m, -np.inf), axis=1)
    peaks = peaks[np.isfinite(peaks) & (peaks > 0)]
    return float(np.quantile(peaks, 0.9)) if peaks.size else None


def start_points(layout: Layout, spec: CandidateSpec, batch: KeystrokeBatch) -> list[dict[str, float]]:
    """Starting values of the effect's parameters worth trying (each costs one simulation).

    The effect's size (the parameter with an "off" value) is started across its range: a
    stick/slip or stick/release switch makes the error jump, and a local fit from one start can
    stall on the wrong step. An end stop or escapement the key never reaches has no gradient,
    so their depths are also started across the key travel actually measured (or across their
    bounds without trajectories).
    """
    params = [p for p in layout.params if p.group == spec.effect]
    size = next((p for p in params if p.off is not None), None)
    sizes: list[dict[str, float]] = [{}]
    if size is not None:
        lo, hi = size.to_internal(max(size.lower, 1e-9)), size.to_internal(size.upper)
        for fraction in (0.05, 0.2, 0.45, 0.8):
            value = size.from_internal(lo + fraction * (hi - lo))
            if value != size.off:
                sizes.append({size.name: value, **_scaled_siblings(params, size, value)})
        sizes.append(_near_off(params))
    yield_m = next((p for p in params if p.name == "finger_hysteresis.yield_m"), None)
    if yield_m is not None:
        # Where the body yields decides whether a keystroke's deflection reaches it at all: a
        # yield above every deflection has no gradient, like a stop the key never reaches.
        return [{yield_m.name: min(max(f * yield_m.upper, yield_m.lower), yield_m.upper), **s}
                for f in YIELD_FRACTIONS for s in sizes]
    depth = next((p for p in params if p.name.endswith(("bed_depth_m", "letoff_depth_m"))), None)
    if depth is None:
        return sizes
    travel = _travel_m(batch)
    depths = ([f * travel for f in (0.5, 0.7, 0.85, 0.97)] if travel is not None
              else list(np.linspace(UNTRACKED_STOP_FROM_M if depth.name.endswith("bed_depth_m") else depth.lower,
                                    depth.upper, 6)[1:-1]))
    return [{depth.name: min(max(d, depth.lower), depth.upper), **s} for d in depths for s in sizes]


def _near_off(params: Sequence[Param]) -> dict[str, float]:
    """A start next to the current model: each switchable parameter a tenth of the way from
    "off" to its default. Every other start puts the size's siblings at their defaults, which
    may be far from the current model (a velocity curve's tanh saturation at 1 bends the whole
    map): a local fit from there can end worse than the model without the effect. Not at "off"
    itself: a shape parameter may have no gradient there (the saturation of a tanh curve)."""
    out = {}
    for p in params:
        if p.off is None:
            continue
        off = min(max(float(p.off), p.lower), p.upper)
        out[p.name] = min(max(off + 0.1 * ((p.start if p.start != off else p.upper) - off), p.lower), p.upper)
    return out


def _scaled_siblings(params: Sequence[Param], size: Param, value: float) -> dict[str, float]:
    """The effect's other parameters in the size's unit, scaled with it so that the start keeps
    the default's shape: a Stribeck breakaway started above a small sliding force, not at a
    default that grips the key so hard it never moves (a stuck key gives a fit no gradient)."""
    if size.start <= 0 or size.unit == "1":
        return {}
    ratio = value / size.start
    return {p.name: min(max(p.start * ratio, p.lower), p.upper)
            for p in params if p is not size and p.unit == size.unit}


def size_params(layout: Layout, effect: str) -> list[Param]:
    """The parameters of `effect` with an "off" value (what its confidence interval is judged on)."""
    return [p for p in layout.params if p.group == effect and p.off is not None]


def describe(specs: Sequence[CandidateSpec]) -> str:
    """A short list for progress notes."""
    return ", ".join(s.label for s in specs)
