"""Effects judged directly against a measurement, never inferred from the key's motion.

When the arm is measured it drives the model, so the key cannot tell anything about the arm;
instead the arm trace itself is compared with the commanded press:

- `arm_acceleration`: is the measured down move a constant-speed ramp (the study's input) or a
  trapezoid? One acceleration for every keystroke (the command's), each keystroke's speed,
  travel and start free; the ramp is the limit a → ∞. Judged by the information criterion.
- `arm_lag`: when the commanded timing is known (an arm log on the run clock, t = 0 at the
  commanded motion start, or a lab script's schedule matched to the keystrokes), how late the
  measured arm follows it; an imported Motive take alone defines t = 0 from the arm marker
  itself, so there a lag cannot be seen. A servo that feeds the commanded speed forward tracks
  a ramp without lag and misses the command only where its acceleration changes: when the start
  shows no lag, the trace is fitted as the command through a second-order servo (`_servo`).
- `mocap_delay`: the motion-capture clock offset against the arm log, estimated when the batch
  was built from the arm marker seen by both (`trajectories._clock_offset_s`); with the arm
  timed only by its marker and the commands known, a clock *rate* error: the marker's lag
  behind the commands growing along the run (`_clock_drift`). A constant offset of that clock
  reads exactly like a late arm and is reported with `arm_lag`.
- `velocity_curve`: with the key tracked and MIDI recorded, the piano's key-speed → velocity
  map is fitted against the measured key speed at the trigger depth (`identify.readout`): a
  power law or a saturating curve against the straight line through the origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.optimize import least_squares, minimize_scalar
from scipy.signal import bilinear, lfilter

from pianobot.analysis.discover.arm_moves import DownMoves, fit_moves, ramp_and_duration_s
from pianobot.analysis.greybox.keystrokes import COMMAND_FIELDS, KeystrokeBatch
from pianobot.analysis.greybox.noise import (
    VELOCITY_QUANTUM_SIGMA,
    autocorrelation_time,
    noise_sigma_m,
)
from pianobot.analysis.identify.readout import fit_readout

FloatArray = npt.NDArray[np.float64]

#: ΔIC a measured effect needs (strong evidence, as for candidates).
MARGIN = 10.0
#: Accelerations scanned for the arm's trapezoid (m/s²).
_ACCELERATIONS = np.geomspace(0.03, 30.0, 41)
#: A lag or clock offset below this is not worth a model effect.
_MIN_DELAY_S = 1e-3


@dataclass(frozen=True)
class MeasuredCheck:
    """One measured check: what was measured, its value, the evidence, and whether it holds."""

    effect: str
    value: float  # the effect's size (m/s², s)
    ci95: tuple[float, float]
    delta_ic: float  # evidence against the effect being absent (ΔIC or value/se-based)
    accepted: bool
    text: str
    params: dict[str, float]  # the effect's parameters, for the model

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.effect, "value": self.value, "ci95": list(self.ci95), "delta_ic": self.delta_ic,
                "accepted": self.accepted, "text": self.text, "params": self.params}


def _down_moves(batch: KeystrokeBatch) -> list[tuple[int, FloatArray, FloatArray]]:
    """Each keystroke's measured arm from rest to its deepest point (time on the arm's clock),
    with the keystroke's row."""
    t = batch.input_t_s - batch.clock_offset_s
    out = []
    for i, x in enumerate(batch.input_x0_m):
        bottom = int(np.argmax(x))
        travel = float(x[bottom])
        if travel <= 0:
            continue
        start = np.flatnonzero(x[:bottom] < 0.02 * travel)
        first = int(start[-1]) if start.size else 0
        lo = max(first - max(int(0.05 / max(t[1] - t[0], 1e-6)), 5), 0)
        out.append((i, t[lo : bottom + 1], x[lo : bottom + 1]))
    return out


def _ic(rss: float, n: int, n_eff: float, noise: float, k: int) -> float:
    """Information criterion of a fit with residual sum of squares `rss` over `n` samples
    (`n_eff` independent ones: the residual is autocorrelated), never below the noise."""
    return n_eff * math.log(max(rss / n, noise**2, 1e-300)) + k * math.log(n_eff)


def _refine(padded: DownMoves, k: int, n: int, n_eff: float) -> tuple[float, tuple[float, float]]:
    """Best acceleration and 95 % interval, refined between the scanned neighbours of grid point
    `k`: the moves' residual minimised over log a (bounded Brent), the interval from the
    curvature of −2 log L = n_eff·log(RSS/n) at ±`_CURVATURE_STEP` in log a (where it rises by
    3.84, χ²₁).

    A parabola through the best grid point and its neighbours (17 % apart) read the truth lab's
    1.0 m/s² arms at 0.970-0.986 with intervals that excluded it; refined, 0.988-0.9995."""
    if k == 0 or k == len(_ACCELERATIONS) - 1:
        a = float(_ACCELERATIONS[k])
        return a, (a, a)

    def m2ll(u: float) -> float:
        return n_eff * math.log(max(fit_moves(padded, math.exp(u)).rss / n, 1e-300))

    u = np.log(_ACCELERATIONS)
    found = minimize_scalar(m2ll, bounds=(float(u[k - 1]), float(u[k + 1])), method="bounded",
                            options={"xatol": 1e-4})
    centre, h = float(found.x), _CURVATURE_STEP
    c2 = (m2ll(centre + h) + m2ll(centre - h) - 2.0 * float(found.fun)) / (2.0 * h * h)
    if not c2 > 0:
        return math.exp(centre), (math.exp(centre), math.exp(centre))
    half = math.sqrt(3.84 / c2)
    return math.exp(centre), (math.exp(centre - half), math.exp(centre + half))


#: Where the curvature of the acceleration's likelihood is read (in log a: ±1 %).
_CURVATURE_STEP = 0.01


def arm_checks(batch: KeystrokeBatch) -> list[MeasuredCheck]:
    """`arm_acceleration` and `arm_lag` against the measured arm trace (empty without one)."""
    if not batch.arm_measured:
        return []
    found = _down_moves(batch)
    moves = [(t, x) for _, t, x in found]
    rows = np.array([i for i, _, _ in found], dtype=np.intp)
    if len(moves) < 3:
        return []
    # The commanded start is known for a run's own arm log (t = 0) or from a schedule.
    command = batch.command_start_s
    timed = bool(np.isfinite(command[rows]).all()) if rows.size else False
    padded = DownMoves.of(moves)
    fits = [fit_moves(padded, a) for a in [math.inf, *_ACCELERATIONS]]
    rss = [fit.rss for fit in fits]
    n = sum(t.size for t, _ in moves)
    noise = noise_sigma_m(np.concatenate([x for _, x in moves]))
    best = int(np.argmin(rss[1:])) + 1
    residual = np.concatenate(padded.residuals(fits[best].residual))
    tau = autocorrelation_time(residual[None, :])
    n_eff = n / tau

    def ic(value: float, k: int) -> float:
        return _ic(value, n, n_eff, noise, k)

    a_best, ci = _refine(padded, best - 1, n, n_eff)
    delta = ic(rss[0], 0) - min(ic(r, 1) for r in rss[1:])
    recorded = batch.acceleration_mps2[np.isfinite(batch.acceleration_mps2)]
    said = f" (commanded {np.median(recorded):.3g} m/s²)" if recorded.size else ""
    accepted = delta > MARGIN
    text = (f"the measured arm accelerates at {a_best:.3g} m/s² [{ci[0]:.3g}, {ci[1]:.3g}]{said}: a trapezoid, not a "
            f"ramp (ΔIC {delta:.0f})" if accepted else f"the measured arm is as well described by a constant-speed ramp "
                                                         f"(ΔIC {delta:.1f} for a trapezoid)")
    out = [MeasuredCheck("arm_acceleration", a_best, ci, delta, accepted, text, {})]
    if timed:
        # Against the command's own profile: its acceleration where recorded (a lag would read
        # as a gentler acceleration if that were free), started where the command started.
        a_cmd = float(np.median(recorded)) if recorded.size else a_best
        commanded = command[rows]
        starts = fit_moves(padded, a_cmd).starts - commanded
        drift = _clock_drift(batch, rows, starts) if batch.arm_source == "mocap" else None
        if drift is not None and drift.accepted:
            out.append(drift.check)
            commanded = commanded + (starts - drift.starts)  # the commands on the drifting clock
            starts = drift.starts  # the lag at each run's start, the clock's drift taken out
        lag = float(np.median(starts))
        se = float(1.2533 * np.std(starts, ddof=1) / math.sqrt(starts.size)) if starts.size > 1 else math.inf
        z = lag / se if se > 0 else math.inf
        lagging = lag > _MIN_DELAY_S and z > 3.0
        text = f"the measured arm starts {_ms(lag)} ± {_ms(1.96 * se)} ms after the commanded start"
        if drift is not None and drift.accepted:
            text += " at the start of the run (the clock's drift taken out)"
        # The marker is timed by the mocap clock, the command by the arm's: a constant offset
        # between the two clocks reads exactly like an arm that is late.
        either = (" (or the motion-capture clock runs that much behind the arm's: with the arm timed only by the "
                  "marker the two look the same; an arm log tells them apart)") if batch.arm_source == "mocap" else ""
        if lagging:
            text += either
        else:
            text += " (no lag worth modelling)"
        servo = None if lagging else _servo(moves, commanded, a_cmd, noise)
        if servo is not None and servo.delta_ic > MARGIN and servo.freq_hz < _SERVO_AT_BOUND * _SERVO_HZ[-1]:
            lagging = True
            text = (f"the measured arm follows its command through a servo of {servo.freq_hz:.3g} Hz, damping ratio "
                    f"{servo.zeta:.2g} (ΔIC {servo.delta_ic:.0f} against following it exactly): it starts "
                    f"{_ms(lag)} ms after the commanded start, follows a ramp {_ms(servo.ramp_lag_s)} ms late and "
                    f"misses the command by up to {1e3 * servo.peak_error_m:.2f} mm where the command changes its "
                    "acceleration" + (either if servo.ramp_lag_s > _MIN_DELAY_S else ""))
        out.append(MeasuredCheck("arm_lag", lag, (lag - 1.96 * se, lag + 1.96 * se), z * z, lagging, text,
                                 {"arm_lag_s": lag}))
    return out


@dataclass(frozen=True)
class _Servo:
    freq_hz: float
    zeta: float
    delta_ic: float  # evidence for the servo against exact tracking
    peak_error_m: float  # the largest gap between the command and the servo's response
    ramp_lag_s: float  # how late it follows a constant-speed ramp: 2ζ(1 − κ)/ωn


#: The finer time step the command is filtered on (the arm trace is interpolated from it).
_SERVO_DT_S = 1e-3
#: Natural frequencies of the coarse grid the servo fit starts from (its bounds are the ends), Hz.
_SERVO_HZ = (0.5, 2.0, 5.0, 12.0, 30.0, 60.0)
#: A servo fitted this close to the fastest frequency tried is not claimed: it cannot be told from
#: following the command exactly (its "off" value lies at that bound), and what it absorbs is
#: something else. Seen: an independent generator's exact trapezoid, logged at 125 Hz and put on
#: the input grid by linear interpolation (whose chords that was), fitted as a 60 Hz servo of
#: damping ratio 3 "0.59 ms late" (ΔIC 470), both at their bounds.
_SERVO_AT_BOUND = 0.95
#: An arm that follows its command this close (mean square, in units of the noise's) has no servo
#: worth fitting.
_SERVO_SKIP = 2.0


def _servo_filter(wn: float, zeta: float, feed: float) -> tuple[FloatArray, FloatArray]:
    """The servo ẍ = ωn²·(xc − x) + 2ζωn·(κ·ẋc − ẋ) as a digital filter on the command's grid
    (Tustin): κ = 1 feeds the commanded speed forward (a ramp is tracked without lag), κ = 0 is
    a plain second-order lag. Worked out once per parameter set (it is the same for every move)."""
    num, den = bilinear([2.0 * zeta * wn * feed, wn * wn], [1.0, 2.0 * zeta * wn, wn * wn], fs=1.0 / _SERVO_DT_S)
    return np.asarray(num, dtype=np.float64), np.asarray(den, dtype=np.float64)


@dataclass(frozen=True)
class _CommandResidual:
    """The measured moves against their commands, every move at once, less each move's straight
    line in time (the whole capture volume drifts slowly, tens of µm over a long move; a servo
    shows at the command's corners).

    A trapezoid from rest is four steps of acceleration (+a at 0, −a where cruising starts and
    where braking starts, +a at the end), so the command, or the servo's response to it, is four
    shifted copies of the response to x = ½t² (linear, time-invariant). That response is ½t²
    exactly without a servo; through one, ½t² plus the servo's error, filtered once per
    parameter set on a 1 ms grid and read at each sample's shifted times."""

    a: float
    t: FloatArray  # (m, Lt): sample times from the commanded start, padded
    x: FloatArray  # (m, Lt): measured, padded
    real: npt.NDArray[np.bool_]  # (m, Lt): a sample, not padding
    trend: FloatArray  # (m, Lt, 2): [1, t] on the samples, 0 on padding
    trend_pinv: FloatArray  # (m, 2, Lt)
    grid: FloatArray  # (Lc,): where the servo's error is worked out (0 up to past the last sample)

    @classmethod
    def of(cls, moves: list[tuple[FloatArray, FloatArray]], a: float) -> _CommandResidual:
        """`moves`: each move's sample times from its commanded start, and its positions."""
        m, length = len(moves), max(tt.size for tt, _ in moves)
        steps = int(math.ceil(max(float(tt[-1]) for tt, _ in moves) / _SERVO_DT_S)) + 2
        tt_pad, x_pad = np.zeros((m, length)), np.zeros((m, length))
        real = np.zeros((m, length), dtype=bool)
        trend, trend_pinv = np.zeros((m, length, 2)), np.zeros((m, 2, length))
        for k, (tt, x) in enumerate(moves):
            n = tt.size
            tt_pad[k, :n], x_pad[k, :n], real[k, :n] = tt, x, True
            trend[k, :n] = np.column_stack([np.ones_like(tt), tt])
            trend_pinv[k, :, :n] = np.linalg.pinv(trend[k, :n])
        return cls(a, tt_pad, x_pad, real, trend, trend_pinv, np.arange(steps, dtype=np.float64) * _SERVO_DT_S)

    def __call__(self, p: FloatArray, filtered: bool) -> FloatArray:
        """The residual of moves (travel, speed) pairs `p[:2m]`, through the servo
        (log ωn/2π, log ζ, κ = `p[-3:]`) when `filtered`, each move's samples in turn."""
        m, a = self.x.shape[0], self.a
        ta, total = ramp_and_duration_s(p[0 : 2 * m : 2, None], p[1 : 2 * m : 2, None], a)
        error = None
        if filtered:
            half_t2 = 0.5 * self.grid**2
            servo = _servo_filter(2.0 * math.pi * math.exp(p[-3]), math.exp(p[-2]), p[-1])
            error = lfilter(*servo, half_t2) - half_t2

        def response(tau: FloatArray) -> FloatArray:
            late = np.maximum(tau, 0.0)
            out = 0.5 * late * late
            return out if error is None else out + np.interp(tau, self.grid, error, left=0.0)

        command = a * (response(self.t) - response(self.t - ta) - response(self.t - (total - ta))
                       + response(self.t - total))
        r = np.where(self.real, command - self.x, 0.0)
        r = r - np.einsum("mlj,mj->ml", self.trend, np.einsum("mjl,ml->mj", self.trend_pinv, r))
        return np.asarray(r[self.real], dtype=np.float64)


def _servo(moves: list[tuple[FloatArray, FloatArray]], commanded: FloatArray, a: float, noise: float) -> _Servo | None:
    """Does the measured arm follow its command (each move a trapezoid at the commanded
    acceleration from its commanded start, `commanded`, its travel and speed free) exactly, or
    through a second-order servo (natural frequency, damping ratio and speed feed-forward shared
    by all moves)? None when the moves are too few or the fit fails."""
    if len(moves) < 3 or not (math.isfinite(a) and a > 0):
        return None
    timed = [(np.asarray(t - c, dtype=np.float64), x) for (t, x), c in zip(moves, commanded, strict=True)]
    if min(float(tt[-1]) for tt, _ in timed) <= 0.0:
        return None  # a move that ended before its command: no command to follow
    residual = _CommandResidual.of(timed, a)

    d0 = np.array([float(np.max(x)) for _, x in timed])
    p0 = np.column_stack([d0, np.full(d0.size, 0.05)]).ravel()
    lo = np.column_stack([0.5 * d0, np.full(d0.size, 1e-3)]).ravel()
    hi = np.column_stack([1.5 * d0, np.full(d0.size, 5.0)]).ravel()
    for k, (tt, x) in enumerate(timed):  # the speed from the move's middle
        mid = np.flatnonzero((x > 0.2 * d0[k]) & (x < 0.8 * d0[k]))
        if mid.size > 1 and tt[mid[-1]] > tt[mid[0]]:
            p0[2 * k + 1] = float(np.clip((x[mid[-1]] - x[mid[0]]) / (tt[mid[-1]] - tt[mid[0]]), 2e-3, 4.0))
    n_moves = d0.size
    sparsity = np.zeros((sum(tt.size for tt, _ in timed), 2 * n_moves + 3), dtype=np.int8)
    row = 0
    for k, (tt, _) in enumerate(timed):
        sparsity[row : row + tt.size, 2 * k : 2 * k + 2] = 1
        row += tt.size
    sparsity[:, -3:] = 1
    try:
        exact = least_squares(lambda p: residual(p, False), p0, bounds=(lo, hi), x_scale="jac",
                              jac_sparsity=sparsity[:, :-3], max_nfev=100)
        if 2.0 * exact.cost / exact.fun.size < _SERVO_SKIP * noise**2:
            return None  # the command is followed to the noise: nothing for a servo to explain
        # One refinement from the best of a coarse grid, the moves held at their exact fit.
        q_lo = np.concatenate([lo, [math.log(_SERVO_HZ[0]), math.log(0.1), 0.0]])
        q_hi = np.concatenate([hi, [math.log(_SERVO_HZ[-1]), math.log(3.0), 1.0]])
        coarse = [np.concatenate([exact.x, [math.log(f), math.log(z), k]])
                  for f in _SERVO_HZ for z in (0.3, 0.7, 1.5) for k in (0.0, 1.0)]
        q0 = min(coarse, key=lambda q: float(np.sum(residual(q, True) ** 2)))
        best = least_squares(lambda q: residual(q, True), np.clip(q0, q_lo + 1e-9, q_hi - 1e-9),
                             bounds=(q_lo, q_hi), x_scale="jac", jac_sparsity=sparsity, max_nfev=60)
    except (ValueError, np.linalg.LinAlgError):
        return None
    n = int(exact.fun.size)
    n_eff = float(n / autocorrelation_time(exact.fun[None, :]))
    k_moves = 2 * n_moves
    delta = (_ic(2.0 * float(exact.cost), n, n_eff, noise, k_moves)
             - _ic(2.0 * float(best.cost), n, n_eff, noise, k_moves + 3))
    gap = residual(best.x, True) - residual(best.x, False)
    freq, zeta, feed = math.exp(best.x[-3]), math.exp(best.x[-2]), float(best.x[-1])
    return _Servo(freq, zeta, delta, float(np.max(np.abs(gap))), 2.0 * zeta * (1.0 - feed) / (2.0 * math.pi * freq))


@dataclass(frozen=True)
class _Drift:
    check: MeasuredCheck
    starts: FloatArray  # the arm's start against the command with the drift taken out

    @property
    def accepted(self) -> bool:
        return self.check.accepted


#: A clock-rate error is named when the lag it builds up over the run is this many standard errors
#: from none (stricter than a lag's 3: the start estimates carry speed-dependent biases).
_DRIFT_Z = 4.0


def _clock_drift(batch: KeystrokeBatch, rows: npt.NDArray[np.intp], starts: FloatArray) -> _Drift | None:
    """`mocap_delay` as a clock running at another rate: the marker's start against the lab
    script's command growing along the run (an arm's lag does not grow with the time a run has
    been going; a clock whose rate is off by r falls r·t behind after t).

    The rate is shared; each run (trial ids are `run/trial`) and each commanded press that was
    repeated has an offset of its own, which takes up how a trapezoid fit's start estimate
    depends on the press (a slow move's start is read late) even when the lab ran its speeds in
    order. None without the keystrokes' times on the run's clock or without repeated presses."""
    times = batch.motion_start_s[rows]
    if not (np.isfinite(times).all() and np.isfinite(starts).all()) or rows.size < 6:
        return None
    runs = batch.run_ids[rows]
    press = np.column_stack([getattr(batch, name)[rows] for name in (*COMMAND_FIELDS, "distance_m")])
    keys = [f"{run}|" + "|".join(f"{v:.4g}" for v in row) for run, row in zip(runs, press, strict=True)]
    groups = sorted(set(keys))
    if len(groups) > rows.size - 4:
        return None  # too few repeats to tell a drift from the presses' own offsets
    design = np.column_stack([np.array([k == g for k in keys], dtype=np.float64) for g in groups]
                             + [times - times.mean()])
    run_names, run_of = np.unique(runs, return_inverse=True)
    first = np.array([times[run_of == r].min() for r in range(run_names.size)])[run_of]  # each run's start
    spans = [float(np.ptp(times[run_of == r])) for r in range(run_names.size)]
    if max(spans) <= 0:
        return None
    # Each press weighted by how well its starts repeat (a slow move's start scatters by ms, a
    # fast one's by µs), never above the typical press's weight.
    member = design[:, : len(groups)].astype(bool)
    spread = np.array([np.var(starts[m], ddof=1) if m.sum() > 1 else np.nan for m in member.T])
    typical = float(np.nanmedian(spread)) if np.isfinite(spread).any() else 0.0
    variance = np.fmax(np.where(np.isfinite(spread), spread, np.inf), max(typical, 1e-12))
    root_w = 1.0 / np.sqrt(member @ variance)
    wx, wy = design * root_w[:, None], starts * root_w
    coef, *_ = np.linalg.lstsq(wx, wy, rcond=None)
    residual = wy - wx @ coef
    sigma2 = float(residual @ residual) / (rows.size - design.shape[1])  # an outlier widens it: no false alarm
    cov = sigma2 * np.linalg.pinv(wx.T @ wx)
    j = len(groups)
    rate, se = float(coef[j]), math.sqrt(max(float(cov[j, j]), 0.0))
    span = max(spans)
    z = abs(rate) / se if se > 0 else math.inf
    built = rate * span
    accepted = abs(built) > _MIN_DELAY_S and z > _DRIFT_Z
    offset = float(np.clip(rate * np.median(times - first), -0.05, 0.05))
    text = (f"the arm marker falls behind the commanded starts by {1e6 * rate:.0f} ± {1.96e6 * se:.0f} ppm of the "
            f"run's time ({_ms(built)} ms over {span:.0f} s): the motion-capture clock runs at another rate than "
            "the lab script's (a clock error: an arm's lag does not grow along a run)")
    check = MeasuredCheck("mocap_delay", built, (built - 1.96 * se * span, built + 1.96 * se * span), z * z,
                          accepted, text, {"mocap_delay_s": offset})
    return _Drift(check, starts - rate * (times - first))


def _ms(seconds: float) -> str:
    """A delay in ms to two significant decimals, never "-0.0" (a lag of -0.00002 s is none)."""
    value = round(1e3 * seconds, 2)
    return f"{value + 0.0:.2f}"


def _half_width_ms(se_s: float) -> str:
    """A 95 % half-width in ms, to two decimals, or to one significant digit when smaller (an arm
    log times the marker to microseconds: "± 0.00" would read as no uncertainty at all)."""
    half = 1.96e3 * se_s
    return f"{half:.2f}" if half >= 0.005 or half == 0.0 or not math.isfinite(half) else f"{half:.1g}"


def clock_check(batch: KeystrokeBatch) -> MeasuredCheck | None:
    """`mocap_delay` from the clock offset between the arm log and the arm marker (None when the
    batch's arm trace is the marker itself: then one clock serves both)."""
    if batch.arm_source != "arm" or not batch.has_motion:
        return None
    tau, se = batch.clock_offset_s, batch.clock_offset_se_s
    z = abs(tau) / se if se > 0 else (math.inf if tau else 0.0)
    accepted = abs(tau) > _MIN_DELAY_S and z > 3.0
    return MeasuredCheck("mocap_delay", tau, (tau - 1.96 * se, tau + 1.96 * se), z * z, accepted,
                   f"motion capture runs {1e3 * tau:.2f} ± {_half_width_ms(se)} ms behind the arm log "
                   f"(measured on the arm marker{'' if accepted else '; too small to model'})",
                   {"mocap_delay_s": tau})


def readout_check(batch: KeystrokeBatch) -> MeasuredCheck | None:
    """`velocity_curve` against the measured key speed at the trigger depth (None without both a
    tracked key and MIDI, or with too few sounded keystrokes)."""
    if not (batch.has_motion and batch.has_midi):
        return None
    trials = pd.DataFrame({"trial_id": list(batch.trial_id), "on_velocity": batch.on_velocity})
    fit = fit_readout(batch, trials)
    if fit is None:
        return None
    n = fit.n_trials
    # The straight line through the origin (γ = 1) at its best full scale, against the power law.
    rmse_power, rmse_line = fit.rmse_velocity, fit.linear_rmse_velocity
    if not math.isfinite(rmse_line):
        return None
    floor = VELOCITY_QUANTUM_SIGMA**2
    delta = n * (math.log(max(rmse_line**2, floor)) - math.log(max(rmse_power**2, floor))) - math.log(n)
    accepted = delta > MARGIN and abs(fit.curve_exponent - 1.0) > 0.05
    text = (f"measured key speed → MIDI velocity follows a power {fit.curve_exponent:.2f} (RMSE {rmse_power:.2f} "
            f"against {rmse_line:.2f} MIDI for a straight line; ΔIC {delta:.0f})")
    return MeasuredCheck("velocity_curve", fit.curve_exponent, (math.nan, math.nan), delta, accepted, text,
                   {"curve_exponent": min(max(fit.curve_exponent, 0.5), 4.0), "curve_saturation": 0.0})
