"""Synthetic runs for the analysis tests: the linear model with known parameters plus noise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pianobot.physics.linear import simulate_linear
from pianobot.physics.msd import MSDParams
from pianobot.physics.trajectory import Press, sample_presses
from pianobot.store import RunWriter

DT_S = 1.0 / 120.0


def linear_keystrokes(truth: MSDParams, *, seed: int, levels_kpa: tuple[float, ...] = (0.0, -40.0, -80.0),
                      speeds_mps: tuple[float, ...] = (0.01, 0.03, 0.05), noise_m: float = 5e-6,
                      duration_s: float = 1.2) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(trials, samples) of keystrokes through the linear model, mocap-like noise on x1, x2."""
    rng = np.random.default_rng(seed)
    t = np.arange(-0.2, duration_s, DT_S)  # mocap starts before the motion (rest level)
    trials, samples = [], []
    for p in levels_kpa:
        for v in speeds_mps:
            tid = f"p{-p:g}-v{v:g}"
            press = Press(0.0, 0.008, v, v, 1.0, 0.1)
            x0, _ = sample_presses([press], t)
            x1, x2 = simulate_linear(truth.at(p), t, x0[0])
            trials.append({"trial_id": tid, "status": "ok", "vacuum_kpa": p, "down_velocity_mps": v,
                           "up_velocity_mps": v, "acceleration_mps2": 1.0, "depth_m": 0.008,
                           "distance_m": 0.0, "hold_s": 0.1})
            samples.append(pd.DataFrame({
                "trial_id": tid, "source": "mocap", "t_s": t, "x0_m": x0[0] + rng.normal(0, noise_m, t.size),
                "x1_m": x1 + rng.normal(0, noise_m, t.size), "x2_m": x2 + rng.normal(0, noise_m, t.size),
            }))
    return pd.DataFrame(trials), pd.concat(samples, ignore_index=True)


def sounded_trials(seed: int, n_repeats: int = 2) -> pd.DataFrame:
    """Trials with a smooth on-velocity law of vacuum and speed, silent when slow and soft."""
    rng = np.random.default_rng(seed)
    rows = []
    for p in (0.0, -40.0, -80.0):
        for v in np.linspace(0.01, 0.08, 8):
            for depth in (0.02, 0.03):
                for r in range(n_repeats):
                    loud = 300.0 * v * (1 + abs(p) / 80.0) + 20 * (depth - 0.02) / 0.01
                    silent = loud < 6.0
                    rows.append({
                        "trial_id": f"{p}-{v:.3f}-{depth}-{r}", "status": "silent" if silent else "ok",
                        "vacuum_kpa": p, "down_velocity_mps": v, "up_velocity_mps": v, "acceleration_mps2": 0.5,
                        "depth_m": depth, "distance_m": 0.05, "hold_s": 0.0,
                        "on_velocity": np.nan if silent else loud + rng.normal(0, 0.5),
                        "midi_hold_s": np.nan if silent else 0.05 / v, "t_on_s": np.nan if silent else 0.06 / v,
                    })
    return pd.DataFrame(rows)


def write_run(data_dir: Path, trials: pd.DataFrame, samples: pd.DataFrame | None, name: str = "synthetic") -> str:
    """Store the tables as a completed run; returns its id."""
    writer = RunWriter.create(data_dir, name=name, kind="import", meta={"seed": 0}, plan=None, fsync=False)
    writer.append(trials, samples=samples)
    writer.finish("completed")
    return writer.run_id


def linear_sweep(data_dir: Path, *, seed: int, levels_kpa: tuple[float, ...] = (-20.0, -60.0),
                 speeds_mps: tuple[float, ...] = (0.03, 0.06), depths_m: tuple[float, ...] = (0.025, 0.03),
                 distance_m: float = 0.05, repeats: int = 2, truth: MSDParams | None = None,
                 effects: tuple[str, ...] = (), hold_s: float = 0.0, mocap_lag_s: float = 0.0) -> str:
    """A sweep of the simulated world's linear preset (the study's model + observation noise)
    through the real runner: rig file, spec file, `run_sweep`, stored run. Returns the run id.

    The fingertip starts `distance_m` above the key, as in every sweep of the lab. `truth`
    replaces the world's published parameters; `effects` switches effects on (default values),
    e.g. ("contact",) for a finger that lets go of the key instead of the study's bilateral spring;
    `mocap_lag_s` sets the motion capture clock behind the arm's.
    """
    from pianobot.run import run_sweep

    folder = data_dir.parent / f"linear-sweep-{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    msd = "" if truth is None else ", msd: {" + ", ".join(
        f"{k}: {v}" for k, v in truth.to_dict().items() if v is not None and k != "k1_table") + "}"
    extra = "" if not effects else ", effects: {" + ", ".join(f"{name}: {{}}" for name in effects) + "}"
    extra += f", mocap: {{clock_offset_s: {mocap_lag_s}}}" if mocap_lag_s else ""
    (folder / "rig.yaml").write_text(f"kind: sim\nseed: {seed}\nworld: {{preset: linear{msd}{extra}}}\n")
    (folder / "spec.yaml").write_text(
        "name: linear-sweep\nrig: rig.yaml\nfinger: soft\nnote: 57\n"
        "sweep:\n  mode: grid\n"
        f"  params: {{vacuum_kpa: {list(levels_kpa)}, down_velocity_mps: {list(speeds_mps)}, depth_m: {list(depths_m)}}}\n"
        f"  fixed: {{distance_m: {distance_m}, acceleration_mps2: 1.0, hold_s: {hold_s}}}\n"
        f"  repeats: {repeats}\n"
        "record: [midi, arm, mocap]\n"
    )
    return run_sweep(folder / "spec.yaml", data_dir=data_dir, progress=False).run_id
