"""Seeded discovery scenarios with known truth: hidden effects, structural mismatch, controls.

Each scenario builds a simulated world (`physics.world.World`) whose true model is the scenario's
*truth*, observes 24 keystrokes the way the lab does (120 Hz mocap with µm noise and dropped
frames; the piano's two-sensor readout with 1 ms timestamps, jitter and integer velocities),
and says what discovery
should find when it starts from the *start* model. Tests run a reduced suite, the benchmark the
full one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from pianobot.analysis.discover.data import Keystroke
from pianobot.analysis.discover.decide import family_of
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.trajectory import Press
from pianobot.physics.world import MocapConfig, World, WorldConfig
from pianobot.store import RunWriter

MOCAP_NOISE_M = 5e-6
DROP_FRACTION = 0.01


@dataclass(frozen=True)
class Scenario:
    """A dataset recipe and the answer discovery should give."""

    name: str
    kind: str  # hidden | structural | control | midi | multi
    truth: KeystrokeModel
    start: KeystrokeModel
    expected: tuple[str, ...]  # effects that should be named (empty: none)
    seed: int = 0
    noise_m: float = MOCAP_NOISE_M
    mocap: bool = True
    acceleration_mps2: float = 1.0
    n_speeds: int = 8  # keystrokes = n_speeds × 3 vacuum levels (tests use fewer)

    @property
    def expected_families(self) -> tuple[str | None, ...]:
        """Families of the expected effects."""
        return tuple(family_of(e) for e in self.expected)


def presses(acceleration_mps2: float = 1.0, n_speeds: int = 8) -> list[tuple[Press, float]]:
    """n_speeds × 3 vacuum levels (24 by default), 40 mm depth from 3 mm above the key."""
    out = []
    for speed in np.linspace(0.02, 0.08, n_speeds):
        for vacuum in (-20.0, -40.0, -60.0):
            out.append((Press(0.003, 0.040, float(speed), float(speed), acceleration_mps2), vacuum))
    return out


def world_of(scenario: Scenario) -> World:
    """The simulated world whose true model is the scenario's truth."""
    truth = scenario.truth
    config = WorldConfig(
        msd=truth.msd.to_dict(),
        effects=truth.effects.to_dict(),
        piano={k: v for k, v in truth.piano.to_dict().items() if k != "jitter_s"},
        mocap=MocapConfig(noise_m=scenario.noise_m, drop_prob=DROP_FRACTION),
    )
    return World(config, seed=scenario.seed)


def generate(scenario: Scenario) -> list[Keystroke]:
    """Simulate and observe the scenario's dataset with the simulated world (seeded)."""
    plan = presses(scenario.acceleration_mps2, scenario.n_speeds)
    world = world_of(scenario)
    keys = [f"{scenario.name}/{j:02d}" for j in range(len(plan))]
    observed = world.keystrokes([p for p, _ in plan], np.array([v for _, v in plan]), keys=keys)
    out = []
    for key, (press, vacuum), w in zip(keys, plan, observed, strict=True):
        on = [e for e in w.midi if e.type == "note_on"]
        off = [e for e in w.midi if e.type == "note_off"]
        t_s, x = np.empty(0), np.empty((3, 0))
        if scenario.mocap:
            t_s = w.mocap_t_s - w.t0_s
            x = np.vstack([w.mocap_x0_m, w.mocap_x1_m, w.mocap_x2_m])
        out.append(
            Keystroke(
                key_id=key,
                press=press,
                vacuum_kpa=vacuum,
                t_s=t_s,
                x_m=x,
                on_velocity=float(on[0].velocity) if on else float("nan"),
                t_on_s=on[0].t_s - w.t0_s if on else float("nan"),
                t_off_s=off[0].t_s - w.t0_s if off else float("nan"),
                sounded=bool(on),
            )
        )
    return out


# A soft finger moves the key slowly: a full scale of 50 mm/s puts these presses at MIDI
# velocities of about 10–60 (the piano's default full scale would leave them all near 1).
FULL_SCALE_SPEED_MPS = 0.05


def _study() -> KeystrokeModel:
    study = KeystrokeModel.study()
    return study.replace(piano=study.piano.replace(full_scale_speed_mps=FULL_SCALE_SPEED_MPS))


def _trapezoid() -> KeystrokeModel:
    return _study().with_effect("arm_acceleration")


# (effect, strong parameters, weak parameters); the start model is the trapezoid-driven study
# model, so every difference in the data is the one hidden effect.
HIDDEN: tuple[tuple[str, dict[str, float], dict[str, float]], ...] = (
    ("keybed", {"bed_depth_m": 0.0060}, {"bed_depth_m": 0.0075, "bed_stiffness_npm": 1.0e4}),
    ("key_preload", {"preload_n": 0.5}, {"preload_n": 0.15}),
    ("key_friction", {"friction_n": 0.2}, {"friction_n": 0.06}),
    ("finger_stiffening", {"stiffening_per_m": 80.0}, {"stiffening_per_m": 35.0}),
    (
        "letoff",
        {"letoff_force_n": 0.5, "letoff_depth_m": 0.005},
        {"letoff_force_n": 0.2, "letoff_depth_m": 0.005},
    ),
    ("arm_lag", {"arm_lag_s": 0.010}, {"arm_lag_s": 0.004}),
    ("mocap_delay", {"mocap_delay_s": 0.010}, {"mocap_delay_s": 0.004}),
    (
        "velocity_curve",
        {"curve_exponent": 2.0, "curve_saturation": 1.0},
        {"curve_exponent": 1.4, "curve_saturation": 0.0},
    ),
    ("contact", {}, {}),
    ("adhesion", {"pull_off_force_n": 0.3}, {"pull_off_force_n": 0.1}),
)


def hidden_effect(effect: str, strength: str, seed: int = 0) -> Scenario:
    """One hidden effect at "strong" or "weak" magnitude on top of the start model."""
    for name, strong, weak in HIDDEN:
        if name == effect:
            params = strong if strength == "strong" else weak
            start = _trapezoid()
            truth = start
            if effect == "adhesion":
                truth = truth.with_effect("contact")
                start = start.with_effect("contact")  # adhesion is tested given contact
            truth = truth.replace(effects=truth.effects.with_effect(effect, form=None, **params))
            return Scenario(f"{effect}-{strength}", "hidden", truth, start, (effect,), seed)
    raise ValueError(f"no hidden-effect scenario for {effect!r}; known: {[h[0] for h in HIDDEN]}")


def structural(effect: str, seed: int = 0) -> Scenario:
    """The world uses a richer form than the candidate discovery fits."""
    forms = {
        "keybed": ("hunt_crossley", {"bed_depth_m": 0.0060}),
        "key_friction": ("stribeck", {"friction_n": 0.12, "static_friction_n": 0.25}),
        "finger_stiffening": ("exponential", {"stiffening_per_m": 80.0}),
    }
    form, params = forms[effect]
    start = _trapezoid()
    truth = start.with_effect(effect, form=form, **params)
    return Scenario(f"{effect}-{form}", "structural", truth, start, (effect,), seed)


def control(kind: str, seed: int) -> Scenario:
    """No hidden effect: clean, a base parameter 30 % off, or doubled noise."""
    start = _trapezoid()
    truth, noise = start, MOCAP_NOISE_M
    if kind == "k2-off":
        truth = start.replace(msd=start.msd.replace(k2_npm=start.msd.k2_npm * 1.3))
    elif kind == "c1-off":
        truth = start.replace(msd=start.msd.replace(c1_nspm=start.msd.c1_nspm * 0.7))
    elif kind == "noise-x2":
        noise = 2 * MOCAP_NOISE_M
    elif kind != "clean":
        raise ValueError(f"control kind should be clean, k2-off, c1-off or noise-x2, got {kind!r}")
    return Scenario(f"control-{kind}-{seed}", "control", truth, start, (), seed, noise)


def midi_only(seed: int = 0) -> Scenario:
    """MIDI logs only, slow acceleration: the study's ramp model misses the arm's trapezoid."""
    return Scenario(
        "midi-arm_acceleration",
        "midi",
        _trapezoid(),
        _study(),
        ("arm_acceleration",),
        seed,
        mocap=False,
        acceleration_mps2=0.1,
    )


def several(seed: int = 0) -> Scenario:
    """Several effects at once: keybed, key friction and a mocap clock offset."""
    start = _trapezoid()
    truth = (
        start.with_effect("keybed", bed_depth_m=0.006)
        .with_effect("key_friction", friction_n=0.15)
        .with_effect("mocap_delay", mocap_delay_s=0.008)
    )
    return Scenario(
        "several", "multi", truth, start, ("keybed", "key_friction", "mocap_delay"), seed
    )


def default_world(seed: int = 0) -> Scenario:
    """The simulated world's default physics (every effect, richer forms) from the study model."""
    truth = WorldConfig().build_model()
    start = _study().replace(piano=truth.piano)
    expected = tuple(n for n in truth.effects.names if n != "stiffness_drift")
    return Scenario("default-world", "multi", truth, start, expected, seed)


def full_suite() -> list[Scenario]:
    """Every scenario of the benchmark."""
    suite = [
        hidden_effect(e, s, seed=i)
        for i, (e, _, _) in enumerate(HIDDEN)
        for s in ("strong", "weak")
    ]
    suite += [
        structural(e, seed=20 + i)
        for i, e in enumerate(("keybed", "key_friction", "finger_stiffening"))
    ]
    suite += [control("clean", seed) for seed in range(30, 35)]
    suite += [control("k2-off", 40), control("c1-off", 41), control("noise-x2", 42)]
    suite += [midi_only(50), several(60), default_world(70)]
    return suite


def reduced(scenario: Scenario, n_speeds: int = 4) -> Scenario:
    """The same scenario with fewer keystrokes (for fast tests)."""
    return replace(scenario, n_speeds=n_speeds)


def named(scenarios: Sequence[Scenario], name: str) -> Scenario:
    """The scenario called `name`."""
    for s in scenarios:
        if s.name == name:
            return s
    raise KeyError(name)


def write_run(
    keystrokes: Sequence[Keystroke], data_dir: Path, name: str = "discover-scenario"
) -> str:
    """Store scenario keystrokes as an imported run (trials, mocap samples); returns the run id."""
    trials, samples = [], []
    for index, k in enumerate(keystrokes):
        trial_id = f"t{index:03d}"
        p = k.press
        trials.append(
            {
                "trial_id": trial_id,
                "index": index,
                "attempt": 1,
                "status": "ok" if k.sounded else "silent",
                "note": 57,
                "vacuum_kpa": k.vacuum_kpa,
                "down_velocity_mps": p.down_velocity_mps,
                "up_velocity_mps": p.up_velocity_mps,
                "acceleration_mps2": p.acceleration_mps2,
                "depth_m": p.depth_m,
                "distance_m": p.distance_m,
                "hold_s": p.hold_s,
                "t_start_s": 10.0 * index,
                "on_velocity": k.on_velocity,
                "t_on_s": k.t_on_s,
                "t_off_s": k.t_off_s,
                "n_note_on": int(bool(k.sounded)),
            }
        )
        if k.t_s.size:
            samples.append(
                pd.DataFrame(
                    {
                        "trial_id": trial_id,
                        "source": "mocap",
                        "t_s": k.t_s,
                        "x0_m": k.x_m[0],
                        "x1_m": k.x_m[1],
                        "x2_m": k.x_m[2],
                    }
                )
            )
    writer = RunWriter.create(
        data_dir, name=name, kind="import", meta={"source": "discover scenario"}, plan=None
    )
    writer.append(pd.DataFrame(trials), pd.concat(samples) if samples else None)
    writer.finish("completed")
    return writer.run_id
