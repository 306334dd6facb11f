"""Discovery scenarios made by pianobot's own simulated world (the second, own-world suite).

This suite shares the simulator with the code under test, so it is not evidence on its own (an
inverse crime): the acceptance figures come from the independent generators in tests/truth/.
It checks the plumbing the independent suite cannot reach cheaply: every effect of the
vocabulary, arm-side effects seen in an arm log, the mocap clock, MIDI-only logs.

Each scenario builds a `physics.world.World` whose true model is the scenario's truth, observes
the keystrokes the lab's way (500 Hz arm log, 120 Hz mocap with µm noise and dropped frames, the
piano's two-sensor readout with 1 ms timestamps), stores them as a run and names what discovery
should find. Tests run reduced scenarios; benchmarks/bench_discover.py runs the full list.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from pianobot.analysis.discover.candidates import family_of
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.load import load_keystrokes
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.trajectory import Press
from pianobot.physics.world import MocapObservation, World, WorldConfig
from pianobot.store import RunWriter

MOCAP_NOISE_M = 5e-6
DROP_FRACTION = 0.01
# A soft finger moves the key slowly: a full scale of 50 mm/s puts these presses at MIDI
# velocities of about 10-60 (the piano's default full scale would leave them all near 1).
FULL_SCALE_SPEED_MPS = 0.05


@dataclass(frozen=True)
class Scenario:
    """A dataset recipe and the answer discovery should give."""

    name: str
    kind: str  # hidden | measured | structural | control | midi | multi
    truth: KeystrokeModel
    expected: tuple[str, ...]  # effects that should be named (empty: none)
    seed: int = 0
    noise_m: float = MOCAP_NOISE_M
    mocap: bool = True
    accelerations_mps2: tuple[float, ...] = (1.0,)
    n_speeds: int = 8  # keystrokes = n_speeds × 3 vacuum levels × accelerations

    @property
    def expected_families(self) -> tuple[str | None, ...]:
        return tuple(family_of(e) for e in self.expected)


def presses(scenario: Scenario) -> list[tuple[Press, float]]:
    """n_speeds × 3 vacuum levels × accelerations, 40 mm deep from 3 mm above the key."""
    out = []
    for accel in scenario.accelerations_mps2:
        for speed in np.linspace(0.02, 0.08, scenario.n_speeds):
            for vacuum in (-20.0, -40.0, -60.0):
                out.append((Press(0.003, 0.040, float(speed), float(speed), accel), vacuum))
    return out


def _study() -> KeystrokeModel:
    study = KeystrokeModel.study()
    return study.replace(piano=study.piano.replace(full_scale_speed_mps=FULL_SCALE_SPEED_MPS))


def _trapezoid() -> KeystrokeModel:
    return _study().with_effect("arm_acceleration")


def world_of(scenario: Scenario) -> World:
    truth = scenario.truth
    config = WorldConfig(msd=truth.msd.to_dict(), effects=truth.effects.to_dict(),
                         piano={k: v for k, v in truth.piano.to_dict().items() if k != "jitter_s"},
                         mocap=MocapObservation(noise_m=scenario.noise_m, drop_prob=DROP_FRACTION))
    return World(config, seed=scenario.seed)


def write_run(scenario: Scenario, data_dir: Path) -> str:
    """Simulate, observe and store the scenario as a run (trials, arm log, mocap); its id."""
    plan = presses(scenario)
    world = world_of(scenario)
    keys = [f"t{j:03d}" for j in range(len(plan))]
    observed = world.keystrokes([p for p, _ in plan], np.array([v for _, v in plan]), keys=keys,
                                t0_s=10.0 * np.arange(len(plan)))
    trials, samples = [], []
    for index, (key, (p, vacuum), w) in enumerate(zip(keys, plan, observed, strict=True)):
        on = [e for e in w.midi if e.type == "note_on"]
        off = [e for e in w.midi if e.type == "note_off"]
        trials.append({
            "trial_id": key, "index": index, "attempt": 1, "status": "ok" if on else "silent", "note": 57,
            "vacuum_kpa": vacuum, "down_velocity_mps": p.down_velocity_mps, "up_velocity_mps": p.up_velocity_mps,
            "acceleration_mps2": p.acceleration_mps2, "depth_m": p.depth_m, "distance_m": p.distance_m,
            "hold_s": p.hold_s, "t_start_s": w.t0_s,
            "on_velocity": float(on[0].velocity) if on else np.nan,
            "t_on_s": on[0].t_s - w.t0_s if on else np.nan, "t_off_s": off[0].t_s - w.t0_s if off else np.nan,
            "midi_hold_s": off[0].t_s - on[0].t_s if on and off else np.nan, "n_note_on": len(on)})
        if scenario.mocap:
            samples.append(pd.DataFrame({"trial_id": key, "source": "arm", "t_s": w.arm_t_s - w.t0_s,
                                         "x0_m": w.arm_x0_m, "x1_m": np.nan, "x2_m": np.nan}))
            samples.append(pd.DataFrame({"trial_id": key, "source": "mocap", "t_s": w.mocap_t_s - w.t0_s,
                                         "x0_m": w.mocap_x0_m, "x1_m": w.mocap_x1_m, "x2_m": w.mocap_x2_m}))
    writer = RunWriter.create(data_dir, name=scenario.name, kind="import", meta={"source": "own-world scenario"},
                              plan=None, fsync=False)
    writer.append(pd.DataFrame(trials), pd.concat(samples, ignore_index=True) if samples else None)
    writer.finish("completed")
    return writer.run_id


def generate(scenario: Scenario, data_dir: Path) -> KeystrokeBatch:
    """The scenario's keystrokes, through the store and the one loader."""
    run_id = write_run(scenario, data_dir)
    return load_keystrokes([run_id], data_dir).batch


# (effect, form, strong parameters, weak parameters): one hidden key-side effect each.
HIDDEN: tuple[tuple[str, str | None, dict[str, float], dict[str, float]], ...] = (
    ("keybed", None, {"bed_depth_m": 0.0060}, {"bed_depth_m": 0.0075, "bed_stiffness_npm": 1.0e4}),
    ("key_preload", None, {"preload_n": 0.5}, {"preload_n": 0.15}),
    ("key_friction", None, {"friction_n": 0.2}, {"friction_n": 0.06}),
    ("finger_stiffening", None, {"stiffening_per_m": 80.0}, {"stiffening_per_m": 35.0}),
    ("letoff", None, {"letoff_force_n": 0.5, "letoff_depth_m": 0.005}, {"letoff_force_n": 0.2, "letoff_depth_m": 0.005}),
)
#: Effects seen against the measurements themselves (arm log, arm marker, key speed + MIDI).
MEASURED: tuple[tuple[str, dict[str, float], dict[str, float]], ...] = (
    ("arm_lag", {"arm_lag_s": 0.010}, {"arm_lag_s": 0.004}),
    ("mocap_delay", {"mocap_delay_s": 0.010}, {"mocap_delay_s": 0.004}),
    ("velocity_curve", {"curve_exponent": 2.0, "curve_saturation": 1.0}, {"curve_exponent": 1.4, "curve_saturation": 0.0}),
)


def hidden_effect(effect: str, strength: str, seed: int = 0) -> Scenario:
    """One hidden effect at "strong" or "weak" magnitude (key-side or measured)."""
    for name, form, strong, weak in HIDDEN:
        if name == effect:
            truth = _trapezoid().with_effect(effect, form=form, **(strong if strength == "strong" else weak))
            return Scenario(f"{effect}-{strength}", "hidden", truth, (effect,), seed)
    for name, strong, weak in MEASURED:
        if name == effect:
            truth = _trapezoid().with_effect(effect, **(strong if strength == "strong" else weak))
            return Scenario(f"{effect}-{strength}", "measured", truth, (effect,), seed)
    raise ValueError(f"no hidden-effect scenario for {effect!r}")


def structural(effect: str, seed: int = 0) -> Scenario:
    """The world uses the richer form of an effect."""
    forms = {"keybed": ("hunt_crossley", {"bed_depth_m": 0.0060}),
             "key_friction": ("stribeck", {"friction_n": 0.12, "static_friction_n": 0.25}),
             "finger_stiffening": ("exponential", {"stiffening_per_m": 80.0})}
    form, params = forms[effect]
    return Scenario(f"{effect}-{form}", "structural", _trapezoid().with_effect(effect, form=form, **params),
                    (effect,), seed)


def control(kind: str, seed: int) -> Scenario:
    """No hidden effect: clean, a base parameter 30 % off, or doubled noise."""
    truth, noise = _trapezoid(), MOCAP_NOISE_M
    if kind == "k2-off":
        truth = truth.replace(msd=truth.msd.replace(k2_npm=truth.msd.k2_npm * 1.3))
    elif kind == "c1-off":
        truth = truth.replace(msd=truth.msd.replace(c1_nspm=truth.msd.c1_nspm * 0.7))
    elif kind == "noise-x2":
        noise = 2 * MOCAP_NOISE_M
    elif kind != "clean":
        raise ValueError(f"control kind should be clean, k2-off, c1-off or noise-x2, got {kind!r}")
    return Scenario(f"control-{kind}-{seed}", "control", truth, (), seed, noise)


def release(kind: str, seed: int) -> Scenario:
    """The finger leaves the key at every release (unilateral contact: measured, not hidden);
    with kind "adhesion" its pad also sticks to the key up to 0.15 N."""
    truth = _trapezoid().with_effect("contact")
    if kind == "adhesion":
        return Scenario("adhesion-strong", "hidden", truth.with_effect("adhesion", pull_off_force_n=0.15),
                        ("adhesion",), seed)
    if kind != "contact":
        raise ValueError(f"release kind should be contact or adhesion, got {kind!r}")
    return Scenario(f"control-contact-{seed}", "control", truth, (), seed)


def midi_only(effect: str = "arm_acceleration", seed: int = 0) -> Scenario:
    """MIDI logs only: the study's ramp model misses the trapezoid at low acceleration, or the
    piano's velocity map is not a straight line."""
    truth = _trapezoid()
    if effect == "velocity_curve":
        truth = truth.with_effect("velocity_curve", curve_exponent=2.0, curve_saturation=1.0)
    return Scenario(f"midi-{effect}", "midi", truth, (effect,), seed, mocap=False,
                    accelerations_mps2=(0.1, 0.5, 1.0), n_speeds=6)


def midi_control(seed: int = 0) -> Scenario:
    """MIDI logs only, nothing the study's model lacks except the trapezoid it is told about."""
    return Scenario(f"midi-control-{seed}", "control", _study(), (), seed, mocap=False,
                    accelerations_mps2=(0.1, 0.5, 1.0), n_speeds=6)


def several(seed: int = 0) -> Scenario:
    """Several key-side effects at once: an end stop and friction."""
    truth = _trapezoid().with_effect("keybed", bed_depth_m=0.006).with_effect("key_friction", friction_n=0.15)
    return Scenario("several", "multi", truth, ("keybed", "key_friction"), seed)


def full_suite() -> list[Scenario]:
    """Every scenario of the benchmark's own-world table."""
    suite = [hidden_effect(e, s, seed=i) for i, (e, _, _, _) in enumerate(HIDDEN) for s in ("strong", "weak")]
    suite += [hidden_effect(e, s, seed=10 + i) for i, (e, _, _) in enumerate(MEASURED) for s in ("strong", "weak")]
    suite += [structural(e, seed=20 + i) for i, e in enumerate(("keybed", "key_friction", "finger_stiffening"))]
    suite += [control("clean", seed) for seed in range(30, 35)]
    suite += [control("k2-off", 40), control("c1-off", 41), control("noise-x2", 42)]
    suite += [release("adhesion", 43), release("contact", 44)]
    suite += [midi_only("arm_acceleration", 50), midi_only("velocity_curve", 51), midi_control(52), several(60)]
    return suite


def reduced(scenario: Scenario, n_speeds: int = 4) -> Scenario:
    """The same scenario with fewer keystrokes (for fast tests)."""
    return replace(scenario, n_speeds=n_speeds)


def named(scenarios: Sequence[Scenario], name: str) -> Scenario:
    for s in scenarios:
        if s.name == name:
            return s
    raise KeyError(name)
