"""The scenario suite: every hidden-effect form at a strong and a weak strength, and clean controls.

Mocap takes come in three schedules, used across effects *and* controls so that the schedule
never gives the answer away: `shallow` (the study's zzz takes: finger resting on the key, about
8 mm of arm travel), `deep` (pressed until the key of the linear chain would sit 11 mm down, past a
≈ 10 mm key dip: needed to see a key stop or a let-off), and `hover` (the finger starts 5 mm above
the key, so it leaves the key on every release: needed to see adhesion). MIDI-only sessions are the
study's soft-finger grid (3 accelerations × 15 speeds × 3 depths, 5 cm hover, hold 0).

Base sets and vacuum levels rotate through the scenarios; each scenario has its own seed.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from typing import Any

import numpy as np

from .base import BASE_SETS
from .forms import Effect
from .readout import Piano
from .scenario import Scenario, TakeSchedule

SHALLOW = TakeSchedule()
DEEP = TakeSchedule(key_target_m=0.011)
HOVER = TakeSchedule(depth_m=0.008, distance_m=0.005)
SCHEDULES = {"shallow": SHALLOW, "deep": DEEP, "hover": HOVER}
BASES = tuple(BASE_SETS)


def _e(kind: str, form: str, **params: float) -> Effect:
    return Effect(kind, form, params)


# (truth kind, form, schedule, {strength: params}) of the mocap effects.
MOCAP_EFFECTS: tuple[tuple[str, str, str, dict[str, Effect]], ...] = (
    ("keybed", "hunt_crossley", "deep", {
        "strong": _e("keybed", "hunt_crossley", depth_m=0.0095, stiffness_npm=4e4, damping_nspm=30.0),
        "weak": _e("keybed", "hunt_crossley", depth_m=0.0102, stiffness_npm=1.5e4, damping_nspm=10.0),
    }),
    ("keybed", "power_law", "deep", {
        "strong": _e("keybed", "power_law", depth_m=0.009, force_at_1mm_n=25.0, exponent=2.5, damping_spm=1.5),
        "weak": _e("keybed", "power_law", depth_m=0.0102, force_at_1mm_n=8.0, exponent=2.2, damping_spm=0.5),
    }),
    ("letoff", "gaussian", "deep", {
        "strong": _e("letoff", "gaussian", force_n=0.4, depth_m=0.007, width_m=0.0008),
        "weak": _e("letoff", "gaussian", force_n=0.15, depth_m=0.0075, width_m=0.0008),
    }),
    ("letoff", "trip", "deep", {
        "strong": _e("letoff", "trip", force_n=0.45, depth_m=0.0075, rise_m=0.0015, drop_m=0.0003),
        "weak": _e("letoff", "trip", force_n=0.18, depth_m=0.007, rise_m=0.0015, drop_m=0.0003),
    }),
    ("key_friction", "stribeck", "shallow", {
        "strong": _e("key_friction", "stribeck", friction_n=0.12, static_friction_n=0.2, stribeck_velocity_mps=0.004),
        "weak": _e("key_friction", "stribeck", friction_n=0.04, static_friction_n=0.06, stribeck_velocity_mps=0.004),
    }),
    ("key_friction", "lugre", "deep", {
        "strong": _e("key_friction", "lugre", friction_n=0.12, static_friction_n=0.2, stribeck_velocity_mps=0.004,
                     bristle_npm=2e4, bristle_damping_nspm=15.0, viscous_nspm=0.1),
        "weak": _e("key_friction", "lugre", friction_n=0.04, static_friction_n=0.06, stribeck_velocity_mps=0.004,
                   bristle_npm=2e4, bristle_damping_nspm=15.0, viscous_nspm=0.03),
    }),
    ("key_preload", "rest_stop", "deep", {
        "strong": _e("key_preload", "rest_stop", preload_n=0.4),
        "weak": _e("key_preload", "rest_stop", preload_n=0.12),
    }),
    ("key_preload", "felt_rail", "shallow", {
        "strong": _e("key_preload", "felt_rail", preload_n=0.3, felt_compression_m=0.00035, felt_damping_spm=2.0),
        "weak": _e("key_preload", "felt_rail", preload_n=0.1, felt_compression_m=0.0002, felt_damping_spm=2.0),
    }),
    ("finger_stiffening", "exponential", "deep", {
        "strong": _e("finger_stiffening", "exponential", stiffening_per_m=45.0),
        "weak": _e("finger_stiffening", "exponential", stiffening_per_m=15.0),
    }),
    ("finger_stiffening", "power_law", "shallow", {
        "strong": _e("finger_stiffening", "power_law", reference_compression_m=0.0025, exponent=3.0),
        "weak": _e("finger_stiffening", "power_law", reference_compression_m=0.0045, exponent=3.0),
    }),
    ("finger_hysteresis", "bouc_wen", "deep", {
        "strong": _e("finger_hysteresis", "bouc_wen", yield_m=0.008, post_yield_ratio=0.6, exponent=1.5),
        "weak": _e("finger_hysteresis", "bouc_wen", yield_m=0.015, post_yield_ratio=0.8, exponent=1.5),
    }),
    ("adhesion", "pull_off", "hover", {
        "strong": _e("adhesion", "pull_off", pull_off_n=0.2),
        "weak": _e("adhesion", "pull_off", pull_off_n=0.08),
    }),
    ("adhesion", "cohesive", "hover", {
        "strong": _e("adhesion", "cohesive", peak_n=0.15, range_m=0.0004),
        "weak": _e("adhesion", "cohesive", peak_n=0.08, range_m=0.0003),
    }),
    ("arm_lag", "first_order", "shallow", {
        "strong": _e("arm_lag", "first_order", tau_s=0.025),
        "weak": _e("arm_lag", "first_order", tau_s=0.008),
    }),
    ("mocap_delay", "offset", "deep", {
        "strong": _e("mocap_delay", "offset", delay_s=0.02),
        "weak": _e("mocap_delay", "offset", delay_s=0.006),
    }),
    ("mocap_delay", "drifting", "shallow", {
        "strong": _e("mocap_delay", "drifting", delay_s=0.005, rate_ppm=300.0),
        "weak": _e("mocap_delay", "drifting", delay_s=0.0, rate_ppm=100.0),
    }),
    ("arm_lag", "servo", "deep", {
        "strong": _e("arm_lag", "servo", freq_hz=6.0, zeta=0.5),
        "weak": _e("arm_lag", "servo", freq_hz=10.0, zeta=0.6),
    }),
)  # fmt: skip

# (truth kind, form, {strength: effect}) of the MIDI-only effects.
MIDI_EFFECTS: tuple[tuple[str, str, dict[str, Effect]], ...] = (
    ("velocity_curve", "tanh", {
        "strong": _e("velocity_curve", "tanh", exponent=1.8, saturation=1.0, full_scale_mps=0.05),
        "weak": _e("velocity_curve", "tanh", exponent=1.3, saturation=0.5, full_scale_mps=0.065),
    }),
    ("velocity_curve", "rational", {
        "strong": _e("velocity_curve", "rational", knee=0.08, full_scale_mps=0.5),
        "weak": _e("velocity_curve", "rational", knee=0.2, full_scale_mps=0.35),
    }),
    ("key_preload", "rest_stop", {
        "strong": _e("key_preload", "rest_stop", preload_n=0.35),
        "weak": _e("key_preload", "rest_stop", preload_n=0.12),
    }),
    ("key_preload", "felt_rail", {
        "strong": _e("key_preload", "felt_rail", preload_n=0.35, felt_compression_m=0.0004, felt_damping_spm=2.0),
        "weak": _e("key_preload", "felt_rail", preload_n=0.12, felt_compression_m=0.00025, felt_damping_spm=2.0),
    }),
    ("finger_stiffening", "exponential", {
        "strong": _e("finger_stiffening", "exponential", stiffening_per_m=60.0),
        "weak": _e("finger_stiffening", "exponential", stiffening_per_m=25.0),
    }),
    ("finger_stiffening", "power_law", {
        "strong": _e("finger_stiffening", "power_law", reference_compression_m=0.012, exponent=2.5),
        "weak": _e("finger_stiffening", "power_law", reference_compression_m=0.02, exponent=2.5),
    }),
)  # fmt: skip


def piano_for(base: str, vacuum_kpa: float) -> Piano:
    """The session's piano: its lower (note-on) contact sits just past where a 20 mm press of
    the linear chain leaves the key, so 20 mm presses sound only when the key overshoots (as in
    the study, where they sounded only when fast); the other contacts scale with it."""
    k = BASE_SETS[base].at(vacuum_kpa)
    static = 0.02 / (k["k2_npm"] * (1 / k["k0_npm"] + 1 / k["k1_npm"] + 1 / k["k2_npm"]))
    lower = static + LOWER_CONTACT_MARGIN_M
    return Piano(upper_m=0.35 * lower, lower_m=lower, release_m=0.6 * lower)


LOWER_CONTACT_MARGIN_M = 7e-5
MOCAP_VACUA = (-40.0, -60.0)
MIDI_VACUA = (-40.0, -60.0, -80.0)
CONTROL_SEEDS_PER_BASE = {"mocap": 3, "midi": 2}


def _seed(*parts: object) -> int:
    """A stable seed per scenario name (Python's hash() is salted per process)."""
    text = "/".join(str(p) for p in parts)
    value = 0
    for ch in text.encode():
        value = (value * 131 + ch) % 2_147_483_629
    return value


def effect_scenarios() -> list[Scenario]:
    """Every effect form at a strong and a weak strength, mocap and MIDI-only."""
    out: list[Scenario] = []
    i = 0
    for kind, form, schedule, by_strength in MOCAP_EFFECTS:
        for strength, effect in by_strength.items():
            name = f"mocap-{kind}-{form}-{strength}"
            out.append(Scenario(
                name, "mocap", BASES[i % len(BASES)], MOCAP_VACUA[i % len(MOCAP_VACUA)],
                _seed(name), strength, effect, take=SCHEDULES[schedule],
                description=f"{schedule} take, hidden {kind} ({form}, {strength})",
            ))  # fmt: skip
            i += 1
    for kind, form, by_strength in MIDI_EFFECTS:
        for strength, effect in by_strength.items():
            name = f"midi-{kind}-{form}-{strength}"
            base, vacuum = BASES[i % len(BASES)], MIDI_VACUA[i % len(MIDI_VACUA)]
            out.append(Scenario(
                name, "midi", base, vacuum, _seed(name), strength, effect,
                piano=piano_for(base, vacuum),
                description=f"MIDI-only grid, hidden {kind} ({form}, {strength})",
            ))  # fmt: skip
            i += 1
    return out


def control_scenarios() -> list[Scenario]:
    """Clean sessions: several seeds on every base set, every schedule, both kinds."""
    out: list[Scenario] = []
    schedules = ("shallow", "deep", "hover")
    for b, base in enumerate(BASES):
        for j in range(CONTROL_SEEDS_PER_BASE["mocap"]):
            schedule = schedules[(b + j) % len(schedules)]
            name = f"mocap-clean-{base}-{schedule}-{j}"
            out.append(Scenario(
                name, "mocap", base, MOCAP_VACUA[(b + j) % len(MOCAP_VACUA)], _seed(name),
                take=SCHEDULES[schedule], description=f"{schedule} take, no hidden effect",
            ))  # fmt: skip
        for j in range(CONTROL_SEEDS_PER_BASE["midi"]):
            name = f"midi-clean-{base}-{j}"
            vacuum = MIDI_VACUA[(b + j) % len(MIDI_VACUA)]
            out.append(Scenario(
                name, "midi", base, vacuum, _seed(name), piano=piano_for(base, vacuum),
                description="MIDI-only grid, no hidden effect",
            ))  # fmt: skip
    return out


def full_suite() -> list[Scenario]:
    """Effects first, then controls (names are unique)."""
    return effect_scenarios() + control_scenarios()


SMALL = (
    "mocap-clean-light-finger-shallow-0",
    "midi-clean-light-finger-0",
    "mocap-keybed-power_law-strong",
    "mocap-key_preload-felt_rail-strong",
)


def small_suite() -> list[Scenario]:
    """A quick subset for tests: a clean take, a clean log, two form-differs effects."""
    by_name = {s.name: s for s in full_suite()}
    return [by_name[n] for n in SMALL]


FEW_SPEEDS = {"speeds_mps": (0.015, 0.03, 0.045, 0.06, 0.075), "repeats": 2}  # 10 keystrokes
FAST_SPEEDS = {"speeds_mps": (0.02, 0.04, 0.06, 0.08, 0.1, 0.12), "repeats": 3}
SMALL_GRID = {"accelerations_mps2": (0.25, 0.75), "speeds_mps": tuple(float(v) for v in np.linspace(0.015, 0.075, 10)),
              "depths_m": (0.025, 0.035)}  # 40 keystrokes
OTHER_GRID = {"accelerations_mps2": (0.2, 0.6, 1.2), "speeds_mps": tuple(float(v) for v in np.linspace(0.015, 0.1, 15)),
              "depths_m": (0.025, 0.035, 0.045)}  # 135 keystrokes at other levels

#: Sessions recorded otherwise than the suite's: (what, suite scenario, changes). Changes set the
#: frame rate (OptiTrack's 100 and 240 Hz), the take's schedule (`take`: 10 keystrokes, faster
#: presses, hovering, the finger resting on the key), a MIDI-only grid (`grid`: 40 keystrokes,
#: other accelerations, speeds and depths), the piano (`piano`: its full-scale speed), the lab
#: (`base`, `vacuum_kpa`: the hidden effect on another finger and key) or the effect's parameters (`effect`: a stop a resting finger reaches
#: within a millimetre; friction that holds the key down after the first press, for good; a rest
#: stop that a resting finger barely overcomes, so the key moves only at the bottom of a press, or
#: a fraction of a millimetre on a stiff key). Each
#: variant gets a seed of its own.
VARIANTS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("clean-240hz", "mocap-clean-light-finger-shallow-0", {"frame_rate_hz": 240.0}),
    ("clean-100hz", "mocap-clean-light-finger-shallow-0", {"frame_rate_hz": 100.0}),
    ("clean-10-keystrokes", "mocap-clean-light-finger-shallow-0", {"take": FEW_SPEEDS}),
    ("clean-deep-240hz", "mocap-clean-stiff-key-deep-0", {"frame_rate_hz": 240.0}),
    ("clean-hover-fast-100hz", "mocap-clean-stiff-key-deep-0",
     {"frame_rate_hz": 100.0, "take": {**FAST_SPEEDS, "distance_m": 0.005, "key_target_m": None}}),
    ("preload-felt_rail-weak-240hz", "mocap-key_preload-felt_rail-weak", {"frame_rate_hz": 240.0}),
    ("friction-stribeck-strong-100hz", "mocap-key_friction-stribeck-strong", {"frame_rate_hz": 100.0}),
    ("letoff-gaussian-strong-10-keystrokes", "mocap-letoff-gaussian-strong", {"take": FEW_SPEEDS}),
    ("stiffening-exponential-weak-240hz-10-keystrokes", "mocap-finger_stiffening-exponential-weak",
     {"frame_rate_hz": 240.0, "take": FEW_SPEEDS}),
    ("keybed-power_law-strong-fast", "mocap-keybed-power_law-strong", {"take": FAST_SPEEDS}),
    ("friction-stribeck-strong-stiff-key", "mocap-key_friction-stribeck-strong", {"base": "stiff-key", "vacuum_kpa": -60.0}),
    ("keybed-hunt_crossley-strong-resting", "mocap-keybed-hunt_crossley-strong",
     {"take": {"key_target_m": None, "depth_m": SHALLOW.depth_m}, "effect": {"depth_m": 0.0008}}),
    ("friction-stribeck-stuck-light-key", "mocap-key_friction-stribeck-strong",
     {"base": "light-key", "effect": {"friction_n": 0.25, "static_friction_n": 0.3, "stribeck_velocity_mps": 0.01}}),
    ("preload-rest_stop-strong-resting", "mocap-key_preload-rest_stop-strong", {"take": asdict(SHALLOW)}),
    ("preload-rest_stop-strong-resting-stiff-key", "mocap-key_preload-rest_stop-strong",
     {"take": asdict(SHALLOW), "base": "stiff-key"}),
    # A hover above a key a preload holds: the pad compresses by the preload's share before the
    # key moves, so a hover read from the take reads long by far more than on a free key.
    ("preload-felt_rail-weak-hover", "mocap-key_preload-felt_rail-weak", {"take": asdict(HOVER)}),
    # A preload only the 40 mm presses overcome: the split's fixed position held out exactly those.
    ("midi-preload-rest_stop-only-deepest-sound", "midi-key_preload-rest_stop-weak", {"effect": {"preload_n": 0.8}}),
    ("midi-clean-40-keystrokes", "midi-clean-light-finger-0", {"grid": SMALL_GRID}),
    ("midi-clean-other-grid", "midi-clean-stiff-key-1", {"grid": OTHER_GRID}),
    ("midi-velocity_curve-tanh-strong-40-keystrokes", "midi-velocity_curve-tanh-strong", {"grid": SMALL_GRID}),
    ("midi-velocity_curve-rational-strong-other-grid", "midi-velocity_curve-rational-strong", {"grid": OTHER_GRID}),
    # A soft piano (or a soft velocity map): many notes sound at 1-3, the softest it sends.
    ("midi-clean-soft-piano", "midi-clean-light-key-0", {"piano": {"full_scale_mps": 0.6}}),
    ("midi-velocity_curve-tanh-strong-soft-piano", "midi-velocity_curve-tanh-strong", {"effect": {"full_scale_mps": 0.1}}),
)


def variant_suite() -> list[Scenario]:
    """Suite sessions recorded otherwise (`VARIANTS`), named `variant-<what>`; the hidden effect
    is the suite scenario's, and so are the base set and vacuum unless the variant changes them."""
    by_name = {s.name: s for s in full_suite()}
    out = []
    for what, source, changes in VARIANTS:
        s = by_name[source]
        name = f"variant-{what}"
        if "effect" in changes and s.effect is not None:
            s = replace(s, effect=replace(s.effect, params={**s.effect.params, **changes["effect"]}))
        out.append(replace(s, name=name, seed=_seed(name), description=f"{s.description}; recorded as {what}",
                           take=replace(s.take, **changes.get("take", {})),
                           grid=replace(s.grid, **changes.get("grid", {})),
                           frame_rate_hz=changes.get("frame_rate_hz", s.frame_rate_hz),
                           base=changes.get("base", s.base), vacuum_kpa=changes.get("vacuum_kpa", s.vacuum_kpa),
                           piano=replace(s.piano, **changes["piano"]) if "piano" in changes else s.piano))
    return out


#: Marker noise of `noisy_suite`'s capture: a few times the study's zzz40 (8 µm), as markers seen
#: by few cameras or a coarser calibration give.
NOISY_CAPTURE_M = 30e-6


def noisy_suite(noise_m: float = NOISY_CAPTURE_M) -> list[Scenario]:
    """The suite's takes recorded by a noisier capture (`noise_m` of marker noise instead of
    3 µm), named `<take>-noise<µm>um`; same seeds, effects and bases."""
    return [replace(s, name=f"{s.name}-noise{1e6 * noise_m:g}um",
                    description=f"{s.description}; {1e6 * noise_m:g} um of marker noise",
                    observation=replace(s.observation, noise_m=noise_m))
            for s in full_suite() if s.kind == "mocap"]


def scenario(name: str) -> Scenario:
    """One scenario of the full suite or the variants by name (KeyError naming the known ones)."""
    by_name = {s.name: s for s in full_suite() + variant_suite() + noisy_suite()}
    if name not in by_name:
        raise KeyError(f"unknown scenario {name!r}; known: {sorted(by_name)}")
    return by_name[name]


def with_seed(s: Scenario, seed: int) -> Scenario:
    """The same scenario with another seed (and the seed in its name)."""
    return replace(s, seed=seed, name=f"{s.name}-seed{seed}")
