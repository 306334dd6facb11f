"""Measured trajectories into the keystroke container: one uniform frame grid, one clock.

Identification drives the model with the measured arm trace x0 and compares the simulated
fingertip x1 and key x2 with the measured ones, for all keystrokes at once. This module turns the
store's long-form samples table into padded (n_keystrokes, n_samples) arrays.

Two details keep the measurements exactly what they were, so that a model that generated the
data can reproduce it to the noise level:

- Outputs are not resampled. Every keystroke's motion-capture frames fall on a uniform clock
  whose phase differs from keystroke to keystroke (the camera runs freely, the arm starts when it
  starts), so each row has its own time offset: row i holds the frames at `t_s + t_offset_s[i]`.
  Interpolating frames onto a shared grid instead would flatten every peak of the key's 10-20 Hz
  ringing (it is sampled only 6-12 times per cycle at 120 Hz), which reads as extra damping.
  Grid points without a frame (dropped, or past the end of the keystroke) are NaN.
- The input is kept at its own rate (the UR controller logs at 125 or 500 Hz) on its own grid
  `input_t_s`, held at its last value past the end of a trace; `x0_m` is that trace at the
  output times, for plots and model-free checks.
- Input and outputs share one clock. The arm log runs on the controller's clock and motion
  capture on its own, which may lag by milliseconds — at 60 mm/s, 5 ms is 0.3 mm, a hundred
  times the mocap noise. When the output instrument also tracked the arm (the mocap arm marker),
  the arm log is shifted onto the mocap clock by the one delay that best overlays the two arm
  traces over all keystrokes (`clock_offset_s`, with its standard error: a delay is a property
  of the set-up, and one keystroke alone pins it only to ~10 µs, which the fingertip's lag
  behind the arm, a few ms, would feel).

Each keystroke also carries its fingertip-key gap at the start (`distance_m`, from the trials'
column of that name; 0 when not recorded: the finger starts on the key, as in the study's takes).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.interpolate import CubicSpline

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.noise import pooled_noise_m
from pianobot.analysis.greybox.stages import rest_level
from pianobot.errors import InputError

FloatArray = npt.NDArray[np.float64]

#: Output sources in order of preference (a measured trace beats the simulator's truth).
OUTPUT_SOURCES: tuple[str, ...] = ("mocap", "sim-truth")


def _phase_s(times: FloatArray, origin_s: float, dt_s: float) -> float:
    """Clock phase in [0, dt) of samples on a uniform clock of period dt (circular mean, so a
    phase near 0 and one near dt agree instead of averaging to dt/2)."""
    angle = 2.0 * math.pi * (times - origin_s) / dt_s
    phase = math.atan2(float(np.mean(np.sin(angle))), float(np.mean(np.cos(angle))))
    return (phase / (2.0 * math.pi) % 1.0) * dt_s


def _frames_on(t: FloatArray, x: FloatArray, times: FloatArray) -> FloatArray:
    """Measured values at `times`; NaN where no finite frame lies within half a frame.

    On the row's own clock phase this picks the frames themselves (no interpolation); a dropped
    frame or a time past the trace is NaN rather than invented.
    """
    good = np.isfinite(x)
    out = np.full(times.shape, np.nan)
    if good.sum() < 2:
        return out
    tg, xg = t[good], x[good]
    half = 0.5 * float(np.median(np.diff(t)))
    j = np.searchsorted(tg, times).clip(1, tg.size - 1)
    nearest = np.minimum(np.abs(times - tg[j - 1]), np.abs(tg[j] - times))
    inside = nearest <= half * (1.0 + 1e-6)
    out[inside] = np.interp(times[inside], tg, xg)
    return out


def _clock_offset_s(traces: list[tuple[FloatArray, FloatArray, FloatArray, FloatArray]],
                    max_offset_s: float = 0.1) -> tuple[float, float]:
    """(τ, its standard error): the delay of the reference clock behind the input's, so that
    x_in(t − τ) best overlays x_ref(t) in every keystroke (input time, input, reference time,
    reference arm trace).

    Least squares with a free constant per keystroke (the instruments' rest levels differ), by a
    1 ms scan over ±`max_offset_s` and a bounded refinement. The error is the regression's: the
    residual σ over the root sum of squared arm speeds. (0, 0) when no trace overlaps.
    """
    from scipy.optimize import minimize_scalar

    pairs = []
    for t_in, x_in, t_ref, x_ref in traces:
        ok_in, good = np.isfinite(x_in), np.isfinite(x_ref)
        if good.sum() >= 10 and ok_in.sum() >= 2 and np.ptp(x_in[ok_in]) > 0:
            pairs.append((t_in[ok_in], x_in[ok_in], t_ref[good], x_ref[good]))
    if not pairs:
        return 0.0, 0.0

    def cost(tau: float) -> float:
        return float(sum(np.sum((d - d.mean()) ** 2) for d in
                         (np.interp(tr - tau, ti, xi) - xr for ti, xi, tr, xr in pairs)))

    scan = np.arange(-max_offset_s, max_offset_s + 5e-4, 1e-3)
    best = float(scan[int(np.argmin([cost(float(tau)) for tau in scan]))])
    tau = float(minimize_scalar(cost, bounds=(best - 1e-3, best + 1e-3), method="bounded",
                                options={"xatol": 1e-8}).x)
    speed2, count = 0.0, 0
    for ti, xi, tr, _ in pairs:
        v = np.interp(tr - tau, ti, np.gradient(xi, ti))
        speed2 += float(np.sum((v - v.mean()) ** 2))
        count += tr.size - 1
    dof = max(count - 1, 1)
    se = math.sqrt(cost(tau) / dof / speed2) if speed2 > 0 else 0.0
    return tau, se


def _arm_on(grid: FloatArray, t: FloatArray, x: FloatArray) -> FloatArray:
    """The arm's samples on another uniform grid (a log's samples fall between the grid's points
    by its clock offset): a cubic spline through them, held at their ends.

    Linear interpolation cuts each accelerating stretch by a chord, up to a·h²/8 (8 µm at
    1 m/s² between 125 Hz samples) with the sign of the acceleration: the arm checks read the
    truth lab's 1.0 m/s² logged arms at 0.987-0.993 with intervals that excluded it."""
    finite = np.isfinite(x)
    if finite.sum() < 4:
        return np.interp(grid, t[finite], x[finite]) if finite.any() else np.full(grid.shape, np.nan)
    tf, xf = t[finite], x[finite]
    out = np.interp(grid, tf, xf)  # held at the ends
    inside = (grid > tf[0]) & (grid < tf[-1])
    out[inside] = CubicSpline(tf, xf)(grid[inside])
    return out


def _uniform_dt(times_by_trial: list[FloatArray]) -> float:
    diffs = np.concatenate([np.diff(t) for t in times_by_trial if t.size > 1])
    diffs = diffs[diffs > 0]
    if diffs.size == 0:
        raise InputError("trajectories need at least two samples per keystroke", "identify")
    return float(np.median(diffs))


#: An arm trace drives the model when at least this share of the keystrokes with a key
#: trajectory have it (a few lost to a dropped stream are left out, as before; a whole run
#: imported without an arm log is not).
ARM_COVERAGE = 0.9


def _arm_source(samples: pd.DataFrame, out_source: str) -> str:
    """The arm trace to drive the model with: the arm log, else the output instrument's arm
    marker, else the simulator's truth; the first that `ARM_COVERAGE` of the keystrokes with a key
    trajectory have (runs imported with and without an arm log, together: the marker all of
    them have), else the one most have."""
    keyed = set(samples.loc[(samples["source"] == out_source) & samples["x2_m"].notna(), "trial_id"])
    coverage = {}
    for candidate in dict.fromkeys(("arm", out_source, "mocap", "sim-truth")):
        has = set(samples.loc[(samples["source"] == candidate) & samples["x0_m"].notna(), "trial_id"])
        coverage[candidate] = len(keyed & has)
        if keyed and coverage[candidate] >= ARM_COVERAGE * len(keyed):
            return candidate
    return max(coverage, key=lambda c: coverage[c]) if any(coverage.values()) else "arm"


def keystroke_batch(
    samples: pd.DataFrame,
    trials: pd.DataFrame,
    *,
    x0_source: str = "auto",
    max_duration_s: float | None = None,
) -> KeystrokeBatch:
    """Build the batch from a run's samples and trials tables.

    Args:
        samples: long form `trial_id, source, t_s, x0_m, x1_m, x2_m`.
        trials: `trial_id, vacuum_kpa`, optionally `distance_m` (missing or NaN: 0) and
            `status` (failed trials are skipped).
        x0_source: where the arm trace comes from: "arm", "mocap", "sim-truth" or "auto"
            (the arm log if present, else the mocap arm marker, else the simulator's truth; the
            first every keystroke has, `_arm_source`).
        max_duration_s: cut every trace after this time (None: the longest trace).

    Raises:
        InputError: when no trial has both an arm trace and a measured key trajectory.
    """
    if samples is None or samples.empty:
        raise InputError("the run has no trajectory samples (record mocap to identify)", "identify")
    has_key = samples["x2_m"].notna() if "x2_m" in samples else pd.Series(False, index=samples.index)
    out_sources = [s for s in OUTPUT_SOURCES if ((samples["source"] == s) & has_key).any()]
    if not out_sources:
        raise InputError(
            "the run has no key trajectories (no key marker in its mocap, no simulated truth): trajectory "
            "identification compares the model with the key's measured motion",
            "identify",
        )
    out_source = out_sources[0]
    if x0_source == "auto":
        x0_source = _arm_source(samples, out_source)
    ok = trials
    if "status" in trials:
        ok = trials[trials["status"] != "failed"]
    ok = ok.drop_duplicates("trial_id", keep="last").set_index("trial_id")
    vac = ok["vacuum_kpa"].astype(float)
    gap = ok["distance_m"].astype(float).fillna(0.0) if "distance_m" in ok else pd.Series(0.0, index=ok.index)

    outs = samples[samples["source"] == out_source]
    ins = samples[(samples["source"] == x0_source) & samples["x0_m"].notna()]
    if max_duration_s is not None:
        outs = outs[outs["t_s"] <= max_duration_s]
    in_ids = set(ins["trial_id"])
    ids = [tid for tid in outs["trial_id"].unique() if tid in vac.index and tid in in_ids]
    if not ids:
        raise InputError(
            f"no trial has both an arm trace ({x0_source}) and a key trajectory ({out_source})",
            "identify",
        )
    by_out = {tid: g.sort_values("t_s") for tid, g in outs.groupby("trial_id", sort=False)}
    by_in = {tid: g.sort_values("t_s") for tid, g in ins.groupby("trial_id", sort=False)}
    t_outs = [by_out[tid]["t_s"].to_numpy(float) for tid in ids]
    t_ins = [by_in[tid]["t_s"].to_numpy(float) for tid in ids]
    # One clock: the arm log shifted onto the output instrument's, where that also saw the arm.
    clock, clock_se = 0.0, 0.0
    if x0_source != out_source and "x0_m" in outs:
        clock, clock_se = _clock_offset_s([(t_ins[i], by_in[tid]["x0_m"].to_numpy(float), t_outs[i],
                                            by_out[tid]["x0_m"].to_numpy(float)) for i, tid in enumerate(ids)])
        t_ins = [t + clock for t in t_ins]

    # Output grid: one frame period, each row on its own clock phase.
    dt = _uniform_dt(t_outs)
    t_start = min(float(t[0]) for t in t_outs)
    t_end = max(float(t[-1]) for t in t_outs)
    grid: FloatArray = t_start + dt * np.arange(int(np.floor((t_end - t_start) / dt + 1e-6)) + 1, dtype=np.float64)
    offsets = np.array([_phase_s(t, t_start, dt) for t in t_outs])
    # Input grid: the input's own rate, from its earliest sample (the arm is at rest before it).
    dt_in = _uniform_dt(t_ins)
    in_start = min(min(float(t[0]) for t in t_ins), t_start)
    in_end = max(max(float(t[-1]) for t in t_ins), t_end + dt)
    in_grid: FloatArray = in_start + dt_in * np.arange(int(np.ceil((in_end - in_start) / dt_in)) + 1, dtype=np.float64)

    n, T = len(ids), grid.size
    x0, x1, x2 = np.empty((n, T)), np.empty((n, T)), np.empty((n, T))
    x0_in = np.empty((n, in_grid.size))
    for i, tid in enumerate(ids):
        a = by_in[tid]["x0_m"].to_numpy(float)
        a = a - rest_level(t_ins[i], a)
        # The arm is a held, continuous input: interpolated, and held at its ends.
        x0_in[i] = _arm_on(in_grid, t_ins[i], a)
        row_t = grid + offsets[i]
        x0[i] = np.interp(row_t, t_ins[i], a)
        g_out = by_out[tid]
        for target, col in ((x1, "x1_m"), (x2, "x2_m")):
            v = g_out[col].to_numpy(float) if col in g_out else np.full(t_outs[i].shape, np.nan)
            target[i] = _frames_on(t_outs[i], v - rest_level(t_outs[i], v), row_t)
    # Noise of the arm trace from its own samples (the held ends would read as noise-free).
    noise_in = pooled_noise_m([by_in[tid]["x0_m"].to_numpy(float) for tid in ids])
    keep = np.isfinite(x0_in).all(axis=1) & np.isfinite(x0).all(axis=1)
    if not keep.any():
        raise InputError("no arm trace could be put on a uniform grid", "identify")
    idx = np.flatnonzero(keep)
    kept = [ids[i] for i in idx]
    return KeystrokeBatch(
        tuple(str(t) for t in kept),
        np.asarray(vac.loc[kept].to_numpy(float), dtype=np.float64),
        grid, x0[idx], x1[idx], x2[idx],
        np.asarray(gap.loc[kept].to_numpy(float), dtype=np.float64),
        offsets[idx], in_grid, x0_in[idx], noise_in, clock, clock_se, arm_source=x0_source,
    )
