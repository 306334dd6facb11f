"""Keystroke trajectories on one uniform time grid, ready for vectorised simulation.

Identification drives the model with the measured arm trace x0 and compares the simulated
fingertip x1 and key x2 with the measured ones, for all keystrokes at once. This module turns the
store's long-form samples table into padded (n_keystrokes, n_samples) arrays: the input is held at
its last value past the end of a trace, outputs are NaN there and where frames were dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.errors import InputError

FloatArray = npt.NDArray[np.float64]

#: Output sources in order of preference (a measured trace beats the simulator's truth).
OUTPUT_SOURCES: tuple[str, ...] = ("mocap", "sim-truth")


@dataclass(frozen=True, eq=False)
class KeystrokeBatch:
    """n keystrokes on one grid t_s (T,); x0/x1/x2 of shape (n, T), relative to rest."""

    trial_id: tuple[str, ...]
    vacuum_kpa: FloatArray  # (n,)
    t_s: FloatArray  # (T,)
    x0_m: FloatArray  # input, finite everywhere
    x1_m: FloatArray  # NaN where not measured
    x2_m: FloatArray

    @property
    def n(self) -> int:
        return len(self.trial_id)

    def subset(self, index: npt.ArrayLike) -> KeystrokeBatch:
        """Keystrokes `index` (an int array; repeats allowed, for the bootstrap)."""
        idx = np.asarray(index, dtype=np.intp)
        return KeystrokeBatch(
            tuple(self.trial_id[i] for i in idx),
            self.vacuum_kpa[idx],
            self.t_s,
            self.x0_m[idx],
            self.x1_m[idx],
            self.x2_m[idx],
        )


def _rest(t_s: FloatArray, values: FloatArray) -> float:
    """Rest level: the median before motion start (t < 0) if recorded, else the first sample.

    Times are relative to motion start, so samples at t < 0 are at rest; a trace that starts
    at t = 0 is at rest only at its very first sample.
    """
    finite = np.isfinite(values)
    before = finite & (t_s < 0.0)
    if before.any():
        return float(np.median(values[before]))
    if not finite.any():
        return float("nan")
    return float(values[np.argmax(finite)])


def _on_grid(t: FloatArray, x: FloatArray, grid: FloatArray, *, hold: bool) -> FloatArray:
    good = np.isfinite(x)
    if good.sum() < 2:
        return np.full(grid.shape, np.nan)
    out = np.interp(grid, t[good], x[good])
    if not hold:
        # Outputs: no invention of data beyond the trace or across long dropouts (> 3 frames).
        dt = np.median(np.diff(t))
        outside = (grid < t[good][0]) | (grid > t[good][-1])
        nearest = np.searchsorted(t[good], grid).clip(1, good.sum() - 1)
        gap = t[good][nearest] - t[good][nearest - 1]
        out[outside | (gap > 3.5 * dt)] = np.nan
    return out


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
        trials: `trial_id, vacuum_kpa` (and `status`; failed trials are skipped).
        x0_source: where the arm trace comes from: "arm", "mocap", "sim-truth" or "auto"
            (the arm log if present, else the mocap arm marker, else the simulator's truth).
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
            "the run has no key trajectories (x2_m from mocap or sim-truth); "
            "trajectory identification needs mocap",
            "identify",
        )
    out_source = out_sources[0]
    if x0_source == "auto":
        for candidate in ("arm", out_source, "mocap", "sim-truth"):
            if ((samples["source"] == candidate) & samples["x0_m"].notna()).any():
                x0_source = candidate
                break
    ok = trials
    if "status" in trials:
        ok = trials[trials["status"] != "failed"]
    vac = ok.set_index("trial_id")["vacuum_kpa"].astype(float)

    outs = samples[samples["source"] == out_source]
    ins = samples[(samples["source"] == x0_source) & samples["x0_m"].notna()]
    ids = [tid for tid in outs["trial_id"].unique() if tid in vac.index and tid in set(ins["trial_id"])]
    if not ids:
        raise InputError(
            f"no trial has both an arm trace ({x0_source}) and a key trajectory ({out_source})",
            "identify",
        )
    dt = float(np.median(np.diff(np.sort(outs[outs["trial_id"] == ids[0]]["t_s"].to_numpy()))))
    t_end = float(outs["t_s"].max()) if max_duration_s is None else max_duration_s
    t_start = float(outs["t_s"].min())
    grid: FloatArray = t_start + dt * np.arange(int(np.floor((t_end - t_start) / dt)) + 1, dtype=np.float64)

    by_out = dict(tuple(outs.groupby("trial_id", sort=False)))
    by_in = dict(tuple(ins.groupby("trial_id", sort=False)))
    x0 = np.empty((len(ids), grid.size))
    x1 = np.empty_like(x0)
    x2 = np.empty_like(x0)
    for i, tid in enumerate(ids):
        g_out = by_out[tid].sort_values("t_s")
        g_in = by_in[tid].sort_values("t_s")
        t_in = g_in["t_s"].to_numpy(float)
        a = g_in["x0_m"].to_numpy(float)
        x0[i] = _on_grid(t_in, a - _rest(t_in, a), grid, hold=True)
        t_out = g_out["t_s"].to_numpy(float)
        for target, col in ((x1, "x1_m"), (x2, "x2_m")):
            v = g_out[col].to_numpy(float) if col in g_out else np.full(t_out.shape, np.nan)
            target[i] = _on_grid(t_out, v - _rest(t_out, v), grid, hold=False)
    keep = np.isfinite(x0).all(axis=1)
    if not keep.any():
        raise InputError("no arm trace could be put on a uniform grid", "identify")
    idx = np.flatnonzero(keep)
    return KeystrokeBatch(
        tuple(str(ids[i]) for i in idx), np.asarray(vac.loc[[ids[i] for i in idx]].to_numpy(float), dtype=np.float64),
        grid, x0[idx], x1[idx], x2[idx],
    )
