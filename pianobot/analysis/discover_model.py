"""The model side of discovery: which parameters are free, predictions, residuals, synthetic data.

Base parameters are fitted as scale factors in log space (k1 as one factor on its whole vacuum
law, so the published vacuum dependence is kept); effect parameters use the vocabulary's bounds
with the simplest form of each effect (linear keybed, Coulomb friction, cubic stiffening,
first-order lag): a world may use a richer form, and discovery must still name the family.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.signal import savgol_filter

from pianobot.analysis.discover_data import Keystroke, Prediction, phase_labels
from pianobot.analysis.discover_fit import FitResult, ParamSpec
from pianobot.analysis.discover_localise import estimate_sigma, position_residuals
from pianobot.analysis.sparse_terms import KeyState, Proposal, propose_terms
from pianobot.physics.effects import EFFECT_NAMES, EFFECTS
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.piano import PianoParams
from pianobot.physics.simulate import simulate_presses

FloatArray = npt.NDArray[np.float64]
_EMPTY = np.empty(0)
_EMPTY3 = np.empty((3, 0))

SIM_RATE_HZ = 1000.0  # output grid of the simulator; mocap samples are interpolated from it
SIM_STEP_S = 2e-4  # the simulator's largest internal step: fits call it thousands of times
_GROUPS = 3  # batches of similar press length per prediction
_TAIL_S = 0.4  # simulate this long past the arm's return: the key rings after release
_BASE_RANGE = 3.0  # base parameters may move by this factor either way
# Noise floors of MIDI outcomes: velocities are integers (σ = 1/√12 ≈ 0.29) and note-on times
# carry 1 ms quantisation plus scan jitter; the floors are rounded up so as not to overweight.
MIDI_VELOCITY_SIGMA = 0.5
MIDI_TIME_SIGMA_S = 1e-3
# Effects whose simplest form discovery fits (a world may use the richer one).
_CANDIDATE_FORM = {"keybed": "linear", "key_friction": "coulomb", "finger_stiffening": "cubic"}


@dataclass(frozen=True)
class Weights:
    """Noise levels that turn residuals into χ² terms."""

    sigma_m: float
    velocity: float = MIDI_VELOCITY_SIGMA
    time_s: float = MIDI_TIME_SIGMA_S


# ---- parameters --------------------------------------------------------------------------


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
    if name.endswith("_m"):
        scale, unit = 1e3, " mm"
    elif name.endswith("_s"):
        scale, unit = 1e3, " ms"
    elif name.endswith("_n"):
        unit = " N"
    return f"{value * scale:.3g} ± {half * scale:.2g}{unit}"


def model_to_dict(model: KeystrokeModel) -> dict[str, Any]:
    """The model's JSON form."""
    return model.to_dict()


# ---- predictions -------------------------------------------------------------------------


def _continuous_velocity(speed_mps: float, piano: PianoParams) -> float:
    """The piano's velocity curve before rounding, so fits see a smooth function of speed."""
    u = max(speed_mps, 0.0) / piano.full_scale_speed_mps
    g = u**piano.curve_exponent
    if piano.curve_saturation > 0.0:
        g = math.tanh(piano.curve_saturation * g) / math.tanh(piano.curve_saturation)
    return float(min(max(127.0 * g, 1.0), 127.0))


def _crossing(
    t: FloatArray, x: FloatArray, level: float, start: int, down: bool
) -> tuple[float, int]:
    seg = x[start:]
    hit = (
        (seg[:-1] < level) & (seg[1:] >= level) if down else (seg[:-1] > level) & (seg[1:] <= level)
    )
    idx = np.flatnonzero(hit)
    if idx.size == 0:
        return float("nan"), -1
    k = start + int(idx[0]) + 1
    frac = (level - x[k - 1]) / (x[k] - x[k - 1])
    return float(t[k - 1] + frac * (t[k] - t[k - 1])), k


def readout(
    t_s: FloatArray, x2_m: FloatArray, piano: PianoParams
) -> tuple[bool, float, float, float]:
    """(sounded, on velocity, t_on, t_off) of one simulated key trace, without rounding."""
    t_up, k_up = _crossing(t_s, x2_m, piano.upper_sensor_m, 0, True)
    if k_up < 0:
        return False, float("nan"), float("nan"), float("nan")
    t_low, k_low = _crossing(t_s, x2_m, piano.lower_sensor_m, k_up - 1, True)
    if k_low < 0:
        return False, float("nan"), float("nan"), float("nan")
    speed = (piano.lower_sensor_m - piano.upper_sensor_m) / max(t_low - t_up, 1e-6)
    t_off, _ = _crossing(t_s, x2_m, piano.release_m, k_low, False)
    return True, _continuous_velocity(speed, piano), t_low, t_off


def predict(
    model: KeystrokeModel, keystrokes: Sequence[Keystroke], *, states: bool = True
) -> list[Prediction]:
    """Simulate every keystroke's press and read the model at its mocap sample times.

    With `states=False` only positions and MIDI are filled (what a fit needs, and faster).
    Keystrokes are simulated in groups of similar length: the simulator runs a batch to the
    end of its longest press, so one slow press would otherwise lengthen every fast one.
    """
    if not keystrokes:
        return []
    durations = np.array([_duration(k) for k in keystrokes]) + _TAIL_S
    order = np.argsort(durations)
    out: list[Prediction | None] = [None] * len(keystrokes)
    for group in np.array_split(order, min(_GROUPS, len(keystrokes))):
        if group.size == 0:
            continue
        members = [keystrokes[i] for i in group]
        for i, p in zip(
            group,
            _predict_batch(model, members, float(durations[group].max()), states),
            strict=True,
        ):
            out[int(i)] = p
    return [p for p in out if p is not None]


def _predict_batch(
    model: KeystrokeModel, keystrokes: Sequence[Keystroke], t_end_s: float, states: bool
) -> list[Prediction]:
    presses = [k.press for k in keystrokes]
    vacuum = np.array([k.vacuum_kpa for k in keystrokes])
    batch = simulate_presses(
        presses, vacuum, model, out_dt_s=1.0 / SIM_RATE_HZ, duration_s=t_end_s, step_s=SIM_STEP_S
    )
    t_grid = batch.t_s
    piano = model.readout_params()
    delay = model.mocap_delay_s
    distance = np.array([k.press.distance_m for k in keystrokes])
    out = []
    for j, k in enumerate(keystrokes):
        x0, x1, x2 = batch.x0_m[j], batch.x1_m[j], batch.x2_m[j]
        comp_grid = x1 - x2 - distance[j]
        sounded, vel, t_on, t_off = readout(t_grid, x2, piano)
        # A mocap sample stamped t shows the world at t − delay.
        t_true = k.t_s - delay
        xs = (
            np.vstack([np.interp(t_true, t_grid, s) for s in (x0, x1, x2)])
            if k.t_s.size
            else _EMPTY3
        )
        if states:
            comp = np.interp(t_true, t_grid, comp_grid)
            v2 = np.interp(t_true, t_grid, batch.v2_mps[j])
            force = np.interp(t_true, t_grid, batch.contact_force_n[j])
            phase = phase_labels(k.t_s, xs[0], comp)
        else:
            comp = v2 = force = _EMPTY
            phase = np.zeros(0, dtype=np.int64)
        out.append(
            Prediction(
                x_m=xs,
                v2_mps=v2,
                compression_m=comp,
                contact_force_n=force,
                phase=phase,
                on_velocity=vel,
                t_on_s=t_on,
                t_off_s=t_off,
                sounded=sounded,
            )
        )
    return out


def _duration(k: Keystroke) -> float:
    from pianobot.physics.trajectory import press_duration_s

    measured = float(k.t_s[-1]) if k.t_s.size else 0.0
    return max(press_duration_s(k.press, "trapezoid"), press_duration_s(k.press, "ramp"), measured)


# ---- residuals ---------------------------------------------------------------------------


def residual_vector(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction], weights: Weights
) -> FloatArray:
    """Every residual divided by its noise level: positions, then MIDI outcomes.

    A keystroke the piano sounded but the model keeps silent (or the reverse) costs its whole
    velocity, so the fit is pulled toward getting sound and silence right.
    """
    parts: list[FloatArray] = []
    sigma = max(weights.sigma_m, 1e-7)
    for k, p in zip(keystrokes, predictions, strict=True):
        if k.t_s.size:
            r = (k.x_m - p.x_m).ravel()
            parts.append(r[np.isfinite(r)] / sigma)
    midi: list[float] = []
    for k, p in zip(keystrokes, predictions, strict=True):
        if k.sounded is None:
            continue
        # Two terms per keystroke whatever happens, so the residual keeps its length.
        dv, dt = 0.0, 0.0
        if k.sounded and p.sounded:
            dv = (k.on_velocity - p.on_velocity) / weights.velocity
            if np.isfinite(k.t_on_s) and np.isfinite(p.t_on_s):
                dt = (k.t_on_s - p.t_on_s) / weights.time_s
        elif k.sounded:
            dv = k.on_velocity / weights.velocity
        elif p.sounded:
            dv = p.on_velocity / weights.velocity
        midi.extend((dv, dt))
    parts.append(np.asarray(midi, dtype=np.float64))
    return np.concatenate(parts) if parts else np.empty(0)


def estimate_weights(keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction]) -> Weights:
    """Noise levels from the data (position) and the stated MIDI floors."""
    sigma = estimate_sigma(position_residuals(keystrokes, predictions))
    return Weights(sigma_m=sigma if np.isfinite(sigma) and sigma > 0 else 1e-5)


def synthesise(
    keystrokes: Sequence[Keystroke],
    predictions: Sequence[Prediction],
    weights: Weights,
    rng: np.random.Generator,
) -> list[Keystroke]:
    """Measurements a model would produce: its prediction + white noise, integer velocities."""
    out = []
    for k, p in zip(keystrokes, predictions, strict=True):
        x = p.x_m + rng.normal(0.0, weights.sigma_m, p.x_m.shape)
        x[~np.isfinite(k.x_m)] = np.nan  # same dropped frames as the real data
        sounded = None if k.sounded is None else p.sounded
        vel = float(np.clip(np.rint(p.on_velocity), 1, 127)) if p.sounded else float("nan")
        t_on = p.t_on_s + rng.normal(0.0, 0.3 * weights.time_s) if p.sounded else float("nan")
        t_off = p.t_off_s if p.sounded else float("nan")
        out.append(Keystroke(k.key_id, k.press, k.vacuum_kpa, k.t_s, x, vel, t_on, t_off, sounded))
    return out


# ---- sparse proposals --------------------------------------------------------------------


def _second_derivative(t: FloatArray, x: FloatArray) -> FloatArray:
    ok = np.isfinite(x)
    if ok.sum() < 11:
        return np.full_like(x, np.nan)
    filled = np.interp(t, t[ok], x[ok])
    dt = float(np.median(np.diff(t)))
    acc = savgol_filter(filled, 9, 3, deriv=2, delta=dt)
    acc[~ok] = np.nan
    return np.asarray(acc, dtype=np.float64)


def sparse_proposals(
    model: KeystrokeModel, keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction]
) -> tuple[Proposal, ...]:
    """STLSQ on the key force the model lacks, m2·(ẍ2 measured − ẍ2 predicted)."""
    rows = [(k, p) for k, p in zip(keystrokes, predictions, strict=True) if k.has_motion]
    if not rows:
        return ()
    m2 = model.msd.m2_kg
    force, x2, v2, comp, fc, down = [], [], [], [], [], []
    for k, p in rows:
        force.append(
            m2 * (_second_derivative(k.t_s, k.x_m[2]) - _second_derivative(k.t_s, p.x_m[2]))
        )
        x2.append(p.x_m[2])
        v2.append(p.v2_mps)
        comp.append(p.compression_m)
        fc.append(p.contact_force_n)
        down.append((np.gradient(p.x_m[0], k.t_s) > 0).astype(np.float64))
    state = KeyState(*(np.concatenate(a) for a in (x2, v2, comp, fc, down)))
    return propose_terms(state, np.concatenate(force))
