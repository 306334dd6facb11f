"""The model side of discovery: predictions at the measured samples, residuals, synthetic data.

Predictions come from the physics simulator (`simulate_presses`) on a 1 ms grid, read at each
keystroke's own mocap times (shifted by the model's mocap delay) and through a rounding-free
copy of the piano's readout, so that fits see smooth functions of the parameters.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.signal import savgol_filter

from pianobot.analysis.discover.data import Keystroke, Prediction, phase_labels
from pianobot.analysis.discover.localise import estimate_sigma, position_residuals
from pianobot.analysis.discover.sparse import KeyState, Proposal, propose_terms
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
# Noise floors of MIDI outcomes: velocities are integers (σ = 1/√12 ≈ 0.29) and note-on times
# carry 1 ms quantisation plus scan jitter; the floors are rounded up so as not to overweight.
MIDI_VELOCITY_SIGMA = 0.5
MIDI_TIME_SIGMA_S = 1e-3


@dataclass(frozen=True)
class Weights:
    """Noise levels that turn residuals into χ² terms."""

    sigma_m: float
    velocity: float = MIDI_VELOCITY_SIGMA
    time_s: float = MIDI_TIME_SIGMA_S


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
