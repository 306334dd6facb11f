"""Simulate a scenario and write what the lab records, plus truth.json with the answer.

Folder of a mocap scenario: `take.csv` (Motive export), `presses.csv` (what the lab's script
commanded: motion starts on the arm's clock — the take's, unless the hidden effect is a mocap
clock error — speeds, acceleration, depth, hover distance, hold), `arm.csv` (the UR arm log,
ur_rtde's file recording at 125 Hz on the arm's clock, started with the take), `truth.json`.
Folder of a MIDI-only scenario: `soft_<|p|>_angle_<deg>.txt` (ctrl_midi log), `truth.json`.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import kernel as K
from .arm import PressCommand
from .arm_log import RATE_HZ as ARM_LOG_RATE_HZ
from .arm_log import write_arm_log
from .base import BASE_SETS
from .ctrl_log import Stroke, assemble, simulate_stroke, write_log
from .forms import FAMILY_OF
from .motive import build_take, write_take
from .plant import STEP_S, Plant, Trajectory
from .scenario import Scenario

SCHEMA = "pianobot-truth/1"
ALWAYS = ("contact", "arm_acceleration")  # physics every scenario has (not hidden effects)


@dataclass(frozen=True)
class Materialised:
    """Where a scenario was written and what its answer is."""

    scenario: Scenario
    folder: Path
    files: dict[str, Path]  # "take", "presses" (mocap) or "log" (midi), and "truth"
    truth: dict[str, Any]

    @property
    def data_file(self) -> Path:
        return self.files["take"] if "take" in self.files else self.files["log"]


def _streams(seed: int) -> list[np.random.Generator]:
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)]


def _plant(scenario: Scenario, distance_m: float) -> Plant:
    return Plant(BASE_SETS[scenario.base], scenario.vacuum_kpa, distance_m,
                 scenario.plant_effects(), scenario.servo())  # fmt: skip


def _commanded(scenario: Scenario) -> tuple[list[PressCommand], list[Any], float]:
    """The take's commanded presses, their moves and the take's end (s)."""
    rng_schedule = _streams(scenario.seed)[0]
    take = scenario.take
    base = BASE_SETS[scenario.base]
    acc = take.acceleration_mps2 or base.take_acceleration_mps2
    depth = take.depth_m
    if take.key_target_m is not None:
        # Statics of the linear chain: the same force through body, pad and key spring.
        k = base.at(scenario.vacuum_kpa)
        depth = (
            take.key_target_m * k["k2_npm"] * (1 / k["k0_npm"] + 1 / k["k1_npm"] + 1 / k["k2_npm"])
        )
    presses = take.presses(acc, depth, rng_schedule)
    moves = [m for press in presses for m in press.moves()]
    return presses, moves, presses[-1].t_end_s + take.tail_s


def simulate_take(scenario: Scenario) -> tuple[list[PressCommand], Trajectory]:
    """The commanded presses and the true trajectories at the frame times (k/rate s)."""
    presses, moves, t_end = _commanded(scenario)
    plant = _plant(scenario, scenario.take.distance_m)
    delay_s, rate_ppm = scenario.mocap_clock()
    rate = scenario.frame_rate_hz
    if delay_s == 0.0 and rate_ppm == 0.0:
        return presses, plant.simulate(moves, t_end, record_every=int(round(1.0 / (rate * STEP_S))))
    # The mocap clock runs off the arm's: frame k (k/rate s on the mocap clock) shows the state at
    # true time (k/rate − δ)/(1 + r). Recorded finely, then interpolated at those times.
    fine = plant.simulate(moves, t_end + abs(delay_s) + 1.0, record_every=40)
    n = int(round(t_end * rate)) + 1
    t_mocap = np.arange(n) / rate
    t_true = (t_mocap - delay_s) / (1.0 + rate_ppm * 1e-6)
    frames = resample(fine, np.clip(t_true, 0.0, None))
    frames.data[:, K.OUT_T] = t_mocap  # the record is labelled by the mocap clock
    return presses, frames


def simulate_arm_log(scenario: Scenario) -> Trajectory:
    """The true trajectories on the arm's clock at the controller's 125 Hz (the arm log's rows)."""
    _, moves, t_end = _commanded(scenario)
    every = int(round(1.0 / (ARM_LOG_RATE_HZ * STEP_S)))  # 384 steps = 8 ms
    return _plant(scenario, scenario.take.distance_m).simulate(moves, t_end, record_every=every)


def resample(traj: Trajectory, t_s: npt.NDArray[np.float64]) -> Trajectory:
    """The trajectory at other times: cubic Hermite for positions (with their speeds), linear for
    the rest. Accurate to nanometres from a 0.83 ms record."""
    t = traj.t_s
    i = np.clip(np.searchsorted(t, t_s, side="right") - 1, 0, t.size - 2)
    h = t[i + 1] - t[i]
    w = (t_s - t[i]) / h
    out = traj.data[i] * (1.0 - w)[:, None] + traj.data[i + 1] * w[:, None]
    h00, h10 = 2 * w**3 - 3 * w**2 + 1, w**3 - 2 * w**2 + w
    h01, h11 = -2 * w**3 + 3 * w**2, w**3 - w**2
    for x, v in (("x0_m", "v0_mps"), ("x1_m", "v1_mps"), ("x2_m", "v2_mps")):
        cx, cv = K.OUT_NAMES.index(x), K.OUT_NAMES.index(v)
        d = traj.data
        out[:, cx] = (h00 * d[i, cx] + h10 * h * d[i, cv] + h01 * d[i + 1, cx]
                      + h11 * h * d[i + 1, cv])  # fmt: skip
    out[:, K.OUT_T] = t_s
    return Trajectory(out, traj.events, traj.unresolved, traj.long_steps)


def simulate_grid(scenario: Scenario) -> list[Stroke]:
    """Every keystroke of a MIDI-only session, simulated from rest."""
    plant = _plant(scenario, scenario.grid.distance_m)
    piano = scenario.piano_used()
    return [simulate_stroke(plant, press, piano) for press in scenario.grid.presses()]


def materialise(scenario: Scenario, out_dir: Path | str) -> Materialised:
    """Write the scenario into `out_dir/<name>/` and return the paths and the truth."""
    folder = Path(out_dir) / scenario.name
    folder.mkdir(parents=True, exist_ok=True)
    if scenario.kind == "mocap":
        files, extra = _write_mocap(scenario, folder)
    else:
        files, extra = _write_midi(scenario, folder)
    truth = truth_dict(scenario) | extra
    truth["files"] = {k: v.name for k, v in files.items()}
    path = folder / "truth.json"
    path.write_text(json.dumps(_clean(truth), indent=1, sort_keys=False) + "\n", encoding="utf-8")
    files["truth"] = path
    return Materialised(scenario, folder, files, truth)


def truth_dict(scenario: Scenario) -> dict[str, Any]:
    """The answer and everything a scorer needs (without the simulated outcomes)."""
    e = scenario.effect
    base = BASE_SETS[scenario.base]
    family = "none" if e is None else e.info.family
    return {
        "schema": SCHEMA,
        "scenario": scenario.name,
        "kind": scenario.kind,
        "description": scenario.description,
        "family": family,
        "effect": None if e is None else e.info.effect,
        "accepted_effects": sorted(n for n, f in FAMILY_OF.items() if f == family),  # [] if clean
        "truth_kind": None if e is None else e.kind,
        "form": None if e is None else e.form,
        "form_equals_candidate": None if e is None else e.info.equals_candidate,
        "strength": scenario.strength,
        "effect_params": {} if e is None else dict(e.params),
        "seed": scenario.seed,
        "vacuum_kpa": scenario.vacuum_kpa,
        "base_set": base.name,
        "base": base.at(scenario.vacuum_kpa),
        "base_definition": base.to_dict(),
        "always_present": list(ALWAYS),
        "arm": scenario.servo().to_dict(),
        "integrator": {"method": "RK4 with event location", "step_s": STEP_S},
    }


def _write_mocap(scenario: Scenario, folder: Path) -> tuple[dict[str, Path], dict[str, Any]]:
    presses, traj = simulate_take(scenario)
    rng_obs = _streams(scenario.seed)[1]
    take = build_take(scenario.name, traj["x0_m"], traj["x1_m"], traj["x2_m"],
                      scenario.observation, rng_obs, scenario.frame_rate_hz)  # fmt: skip
    take_path = folder / "take.csv"
    write_take(take_path, take)
    presses_path = folder / "presses.csv"
    with presses_path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(presses[0].to_dict()))
        writer.writeheader()
        writer.writerows(p.to_dict() for p in presses)
    arm = simulate_arm_log(scenario)
    arm_path = folder / "arm.csv"
    boot_s = 1800.0 + float(_streams(scenario.seed)[3].uniform(0.0, 3600.0))
    write_arm_log(arm_path, arm.t_s, arm["x0_m"], arm["x_cmd_m"], _streams(scenario.seed)[3], boot_s)
    x2 = traj["x2_m"]
    extra: dict[str, Any] = {
        "presses": [p.to_dict() for p in presses],
        "clock": f"motion starts are on the arm's clock; frame k is at k/{scenario.frame_rate_hz:g} s on the mocap "
        "clock, which equals the arm's unless the hidden effect is mocap_delay",
        "mocap_clock": {
            "delay_s": scenario.mocap_clock()[0],
            "rate_ppm": scenario.mocap_clock()[1],
        },
        "mocap": {
            "frame_rate_hz": scenario.frame_rate_hz,
            "roles": take.roles,
            "observation": scenario.observation.to_dict(),
            "frames": int(x2.size),
        },
        "outcome": {
            "max_key_travel_m": float(np.max(x2)),
            "max_fingertip_travel_m": float(np.max(traj["x1_m"])),
            "max_arm_travel_m": float(np.max(traj["x0_m"])),
            "events_located": traj.events,
            "unresolved_steps": traj.unresolved,
        },
        "arm_log": {"rate_hz": ARM_LOG_RATE_HZ, "first_timestamp_s": boot_s,
                    "clock": "the arm's; its first row is at the take's first frame on the arm's clock"},
        "import": {
            "command": f"pianobot import mocap take.csv --vacuum-kpa {scenario.vacuum_kpa:g}",
            "with_arm_log": f"pianobot import mocap take.csv --arm-log arm.csv --vacuum-kpa {scenario.vacuum_kpa:g}",
        },
    }
    if scenario.effect is not None:
        _, off = simulate_take(scenario.without_effect())
        extra["effect_size"] = _trajectory_change(traj, off)
    return {"take": take_path, "presses": presses_path, "arm_log": arm_path}, extra


def _trajectory_change(on: Trajectory, off: Trajectory) -> dict[str, float]:
    """How much the hidden effect moves each signal (RMS and max over the frames both takes
    have, metres: a mocap clock effect can move the last frame past the take's end)."""
    out = {}
    for name, key in (("key", "x2_m"), ("fingertip", "x1_m"), ("arm", "x0_m")):
        n = min(on[key].size, off[key].size)
        d = on[key][:n] - off[key][:n]
        out[f"{name}_rms_m"] = float(np.sqrt(np.mean(d**2)))
        out[f"{name}_max_m"] = float(np.max(np.abs(d)))
    return out


def _write_midi(scenario: Scenario, folder: Path) -> tuple[dict[str, Path], dict[str, Any]]:
    strokes = simulate_grid(scenario)
    piano = scenario.piano_used()
    rng_midi = _streams(scenario.seed)[2]
    grid = scenario.grid
    session = assemble(strokes, scenario.vacuum_kpa, grid.angle_deg, piano, rng_midi,
                       grid.first_start_s, grid.pause_s, grid.pause_sd_s)  # fmt: skip
    name = f"soft_{abs(scenario.vacuum_kpa):g}_angle_{grid.angle_deg:g}.txt"
    path = folder / name
    write_log(path, session)
    rows = [_stroke_row(s, t0) for s, t0 in zip(strokes, session.starts_s, strict=True)]
    extra: dict[str, Any] = {
        "presses": [
            {**s.press.to_dict(), "t_start_s": t0, "t_end_s": t0 + s.press.t_end_s}
            for s, t0 in zip(strokes, session.starts_s, strict=True)
        ],
        "clock": "motion starts are on the MIDI clock (s since MIDI init; the log has ms)",
        "piano": piano.to_dict(),
        "strokes": rows,
        "outcome": {
            "sounded": sum(r["on_velocity"] is not None for r in rows),
            "silent": sum(r["on_velocity"] is None for r in rows),
            "max_key_travel_m": max(s.max_key_travel_m for s in strokes),
            "events_located": sum(s.events_located for s in strokes),
            "unresolved_steps": sum(s.unresolved for s in strokes),
        },
        "import": {"command": f"pianobot import keystroke-log {name}"},
    }
    if scenario.effect is not None:
        off = simulate_grid(scenario.without_effect())
        extra["effect_size"] = _sound_change(rows, [_stroke_row(s, 0.0) for s in off])
    return {"log": path}, extra


def _stroke_row(stroke: Stroke, t0: float) -> dict[str, Any]:
    ons = [e for e in stroke.events if e.kind == "note_on"]
    offs = [e for e in stroke.events if e.kind == "note_off"]
    on = ons[0] if ons else None
    off = offs[0] if offs else None
    return {
        "on_velocity": None if on is None else on.velocity,
        "transit_speed_mps": None if on is None else on.speed_mps,
        "t_on_s": None if on is None else on.t_s,  # after motion start, before clock jitter
        "hold_s": None if on is None or off is None else off.t_s - on.t_s,
        "n_note_on": len(ons),
        "max_key_travel_m": stroke.max_key_travel_m,
        "contact_speed_mps": stroke.contact_speed_mps,
    }


def _sound_change(on: list[dict[str, Any]], off: list[dict[str, Any]]) -> dict[str, float]:
    """How much the hidden effect changes what the piano reports."""
    both = [(a, b) for a, b in zip(on, off, strict=True)
            if a["on_velocity"] is not None and b["on_velocity"] is not None]  # fmt: skip
    dv = np.array([a["on_velocity"] - b["on_velocity"] for a, b in both], dtype=float)
    dh = np.array([a["hold_s"] - b["hold_s"] for a, b in both
                   if a["hold_s"] is not None and b["hold_s"] is not None], dtype=float)  # fmt: skip
    flips = sum(
        (a["on_velocity"] is None) != (b["on_velocity"] is None)
        for a, b in zip(on, off, strict=True)
    )
    return {
        "on_velocity_rms": float(np.sqrt(np.mean(dv**2))) if dv.size else math.nan,
        "on_velocity_max": float(np.max(np.abs(dv))) if dv.size else math.nan,
        "hold_rms_s": float(np.sqrt(np.mean(dh**2))) if dh.size else math.nan,
        "hold_max_s": float(np.max(np.abs(dh))) if dh.size else math.nan,
        "silent_sounded_flips": int(flips),
    }


def _clean(value: Any) -> Any:
    """JSON-safe: NaN/inf → None, numpy scalars → Python."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
