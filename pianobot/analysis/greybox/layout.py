"""The parameter layout of a grey-box fit: which numbers are free, their bounds, and the model
they make.

One layout serves identification (the base model) and discovery (the base model plus effects):

- **base**: k1 per vacuum level, c1, k2, c2; with free coupling also the arm-fingertip coupling
  as ratios k0/k1 and c0/c1 (one finger on both sides: the tied coupling is ratio 1, so free
  coupling contains it at every vacuum level) and the fingertip mass m1. Only one mass scale is
  unidentifiable (scaling every mass, spring and damper by one factor leaves the trajectories
  unchanged), so m2 stays at the prior's value; m1 relative to m2 is seen through the
  fingertip's own motion and is fitted with the free coupling. Fitted in log space (positive,
  multiplicative intervals) within a factor 1e3 of the prior (m1: 10).
- **readout** (MIDI outcomes): the piano's full-scale speed, trigger (lower sensor) depth and
  release depth.
- **drive** (the commanded drive only): the arm's acceleration where the data do not record it.
- **effects**: the parameters of effects from `physics.effects`, within the vocabulary's bounds,
  in the form the layout names (a candidate may be any form of an effect).

Internally a log parameter is log(value); a linear one is value / (upper − lower), so that one
relative step (the fitter's Jacobian step) means the same for every parameter.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from pianobot.physics.effects import EFFECTS
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams

FloatArray = npt.NDArray[np.float64]

#: Base parameters may move this factor either way from the prior (m1: `MASS_RANGE`).
BASE_RANGE = 1e3
MASS_RANGE = 10.0
#: A fitted value this close to a bound (in internal units) is reported as "on bound".
INTERNAL_BOUND_TOLERANCE = 1e-3
#: The parameter of each effect that measures its size (its "off" value switches it off).
_SIZE_UNITS = {"m": "m", "s": "s", "n": "N", "npm": "N/m", "nspm": "N*s/m", "mps": "m/s", "per_m": "1/m"}


def gauge_kpa(vacuum_kpa: float) -> float:
    """A vacuum level as the negative gauge pressure it is named by (0 stays 0, not -0)."""
    return -abs(float(vacuum_kpa)) + 0.0


def k1_name(vacuum_kpa: float) -> str:
    """Name of the per-level stiffness, e.g. `k1_npm@-40kPa` (`k1_npm@0kPa` without vacuum)."""
    return f"k1_npm@{gauge_kpa(vacuum_kpa):g}kPa"


def k1_law(levels: FloatArray, k1: FloatArray, prior: MSDParams) -> tuple[float, float]:
    """k1 = a + b|p| through the per-level values (one level: keep the prior slope)."""
    if levels.size < 2:
        b = prior.k1_b_npm_per_kpa
        return float(k1[0] - b * levels[0]), float(b)
    b, a = np.polyfit(levels, k1, 1)
    return float(a), float(b)


@dataclass(frozen=True)
class Param:
    """One free number: its start value, bounds, scale, unit, and for effects its "off" value."""

    name: str
    start: float
    lower: float
    upper: float
    log: bool
    unit: str
    off: float | None = None

    @property
    def _span(self) -> float:
        return max(self.upper - self.lower, 1e-300)

    def to_internal(self, value: float) -> float:
        return math.log(value) if self.log else value / self._span

    def from_internal(self, u: float) -> float:
        return math.exp(u) if self.log else u * self._span

    @property
    def bounds(self) -> tuple[float, float]:
        return self.to_internal(self.lower), self.to_internal(self.upper)

    @property
    def group(self) -> str:
        """"base", "readout", "drive" or the effect's name."""
        head = self.name.split(".", 1)[0]
        return head if "." in self.name else "base"


def _unit(name: str) -> str:
    for suffix, unit in sorted(_SIZE_UNITS.items(), key=lambda kv: -len(kv[0])):
        if name.endswith("_" + suffix):
            return unit
    return "1"


@dataclass(frozen=True)
class Layout:
    """The free parameters over a prior model; `model(theta)` is the model they make."""

    prior: KeystrokeModel
    params: tuple[Param, ...]
    levels_kpa: tuple[float, ...]
    forms: Mapping[str, str] = field(default_factory=dict)  # effect -> form fitted
    fixed_drive: Mapping[str, float] = field(default_factory=dict)  # drive values not free here

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.params]

    @property
    def free_coupling(self) -> bool:
        return "k0_over_k1" in self.names

    @property
    def effects(self) -> tuple[str, ...]:
        """Effects whose parameters the layout fits (or switches on), in layout order."""
        return tuple(self.forms)

    def start(self) -> FloatArray:
        return np.array([p.to_internal(p.start) for p in self.params], dtype=np.float64)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        lo = np.array([p.bounds[0] for p in self.params], dtype=np.float64)
        hi = np.array([p.bounds[1] for p in self.params], dtype=np.float64)
        return lo, hi

    def values(self, theta: FloatArray) -> dict[str, float]:
        """Name -> value of the internal vector theta."""
        return {p.name: p.from_internal(float(u)) for p, u in zip(self.params, theta, strict=True)}

    def internal(self, values: Mapping[str, float]) -> FloatArray:
        """Theta of named values (a missing name takes its start)."""
        return np.array([p.to_internal(values.get(p.name, p.start)) for p in self.params], dtype=np.float64)

    def on_bounds(self, theta: FloatArray) -> tuple[str, ...]:
        """Parameters sitting on (within `INTERNAL_BOUND_TOLERANCE` of) a bound."""
        lo, hi = self.bounds()
        near = (theta - lo < INTERNAL_BOUND_TOLERANCE * np.maximum(1.0, np.abs(lo))) | (
            hi - theta < INTERNAL_BOUND_TOLERANCE * np.maximum(1.0, np.abs(hi)))
        return tuple(p.name for p, flag in zip(self.params, near, strict=True) if flag)

    def model(self, theta: FloatArray) -> KeystrokeModel:
        """The model of theta (drive parameters are not part of it: see `drive`)."""
        return apply_values(self.prior, self.values(theta), self.levels_kpa, self.forms)

    def drive(self, theta: FloatArray) -> dict[str, float]:
        """Drive parameters of theta, without their "drive." prefix (fixed ones included)."""
        free = {k.split(".", 1)[1]: v for k, v in self.values(theta).items() if k.startswith("drive.")}
        return {**self.fixed_drive, **free}

    def with_params(self, extra: Sequence[Param], forms: Mapping[str, str] | None = None) -> Layout:
        """A layout with more free parameters (and effect forms)."""
        known = set(self.names)
        added = tuple(p for p in extra if p.name not in known)
        return Layout(self.prior, self.params + added, self.levels_kpa, {**self.forms, **(forms or {})},
                      self.fixed_drive)

    def restricted(self, groups: Sequence[str]) -> Layout:
        """Only the parameters of these groups (or these names) free (the others stay at the
        prior's values)."""
        keep = tuple(p for p in self.params if p.group in groups or p.name in groups)
        return Layout(self.prior, keep, self.levels_kpa, self.forms, self.fixed_drive)

    def rebased(self, model: KeystrokeModel, drive: Mapping[str, float] | None = None) -> Layout:
        """The same free parameters, started from (and with the prior) `model`."""
        current = model_values(model, self.levels_kpa)
        current.update({f"drive.{k}": v for k, v in (drive or {}).items()})
        params = tuple(Param(p.name, _clip(current.get(p.name, p.start), p), p.lower, p.upper, p.log, p.unit, p.off)
                       for p in self.params)
        return Layout(model, params, self.levels_kpa, self.forms, dict(drive or {}))


def _clip(value: float, p: Param) -> float:
    return min(max(value, p.lower), p.upper)


def model_values(model: KeystrokeModel, levels_kpa: Sequence[float]) -> dict[str, float]:
    """Every layout name's value in `model` (base, readout and enabled effects)."""
    msd, piano = model.msd, model.piano
    out = {k1_name(p): msd.k1_npm(-p) for p in levels_kpa}
    mid = msd.at(-levels_kpa[len(levels_kpa) // 2]) if levels_kpa else msd.at(0.0)
    out.update({"c1_nspm": msd.c1_nspm, "k2_npm": msd.k2_npm, "c2_nspm": msd.c2_nspm,
                "k0_over_k1": mid.k0_npm / mid.k1_npm, "c0_over_c1": mid.c0_nspm / max(mid.c1_nspm, 1e-300),
                "m1_kg": msd.m1_kg, "readout.full_scale_speed_mps": piano.full_scale_speed_mps,
                "readout.trigger_depth_m": piano.lower_sensor_m, "readout.release_m": piano.release_m})
    for effect in model.effects.names:
        for name, value in model.effects.params(effect).items():
            out[f"{effect}.{name}"] = value
    return out


def apply_values(prior: KeystrokeModel, values: Mapping[str, float], levels_kpa: Sequence[float],
                 forms: Mapping[str, str] | None = None) -> KeystrokeModel:
    """`prior` with the named values set (base, readout and effect parameters; effects in
    `forms` are switched on in that form)."""
    msd = prior.msd
    names = [k1_name(p) for p in levels_kpa]
    if any(n in values for n in names):
        k1 = np.array([values.get(n, msd.k1_npm(-p)) for n, p in zip(names, levels_kpa, strict=True)])
        a, b = k1_law(np.asarray(levels_kpa, dtype=np.float64), k1, msd)
        msd = msd.replace(k1_a_npm=a, k1_b_npm_per_kpa=b,
                          k1_table=tuple((-p, float(k)) for p, k in zip(levels_kpa, k1, strict=True)))
    msd = msd.replace(**{k: float(values[k]) for k in ("c1_nspm", "k2_npm", "c2_nspm", "k0_over_k1", "c0_over_c1",
                                                         "m1_kg") if k in values})
    if "k0_over_k1" in values or "c0_over_c1" in values:
        msd = msd.replace(k0_npm=None, c0_nspm=None)  # the ratios define the coupling
    piano = prior.piano
    if "readout.trigger_depth_m" in values or "readout.full_scale_speed_mps" in values or "readout.release_m" in values:
        gap = piano.lower_sensor_m - piano.upper_sensor_m
        lower = values.get("readout.trigger_depth_m", piano.lower_sensor_m)
        release = min(values.get("readout.release_m", piano.release_m), 0.95 * lower)
        piano = piano.replace(upper_sensor_m=max(lower - gap, 0.3 * lower), lower_sensor_m=lower, release_m=release,
                              full_scale_speed_mps=values.get("readout.full_scale_speed_mps", piano.full_scale_speed_mps))
    effects = prior.effects
    per_effect: dict[str, dict[str, float]] = {name: {} for name in (forms or {})}
    for name, value in values.items():
        head, _, param = name.partition(".")
        if param and head in EFFECTS:
            per_effect.setdefault(head, {})[param] = value
    for effect, params in per_effect.items():
        effects = effects.with_effect(effect, form=(forms or {}).get(effect), **params)
    return prior.replace(msd=msd, piano=piano, effects=effects)


def base_params(prior: KeystrokeModel, levels_kpa: Sequence[float], *, free_coupling: bool,
                trajectories: bool = True) -> list[Param]:
    """The base model's free parameters (see the module docstring).

    Without trajectories (MIDI only) damping cannot be told from stiffness: c1, c2 stay at the
    prior's values and only the stiffnesses are free.
    """
    values = model_values(prior, levels_kpa)
    names = [k1_name(p) for p in levels_kpa] + ["k2_npm"]
    if trajectories:
        names = [k1_name(p) for p in levels_kpa] + ["c1_nspm", "k2_npm", "c2_nspm"]
        if free_coupling:
            names += ["k0_over_k1", "c0_over_c1", "m1_kg"]
    out = []
    for name in names:
        v = values[name]
        span = MASS_RANGE if name == "m1_kg" else BASE_RANGE
        unit = "kg" if name == "m1_kg" else "1" if name.endswith("_over_k1") or name.endswith("_over_c1") else _unit(name.split("@")[0])
        out.append(Param(name, v, v / span, v * span, True, unit))
    return out


def readout_params(prior: KeystrokeModel, max_travel_m: float = 0.012) -> list[Param]:
    """The piano readout's free parameters: full-scale speed, trigger and release depth."""
    piano = prior.piano
    trigger = min(max(piano.lower_sensor_m, 0.6e-3), 0.9 * max_travel_m)
    return [
        Param("readout.full_scale_speed_mps", piano.full_scale_speed_mps, piano.full_scale_speed_mps / 30.0,
              piano.full_scale_speed_mps * 30.0, True, "m/s"),
        Param("readout.trigger_depth_m", trigger, 0.5e-3, max_travel_m, False, "m"),
        Param("readout.release_m", min(piano.release_m, 0.9 * trigger), 0.1e-3, max_travel_m, False, "m"),
    ]


# Where the fit of an unrecorded acceleration starts. Not a default (the parameter table's 0.5
# m/s² is what a spec's trial gets when unset): a starting guess between the study's levels
# (0.1-1 m/s²) and a UR moveL's own default (1.2 m/s²), which the fit moves within 0.02-10 m/s².
UNRECORDED_ACCELERATION_START_MPS2 = 1.0


def drive_params(start_mps2: float = UNRECORDED_ACCELERATION_START_MPS2) -> list[Param]:
    """The commanded drive's acceleration, when the data do not record it."""
    return [Param("drive.acceleration_mps2", start_mps2, 0.02, 10.0, True, "m/s^2")]


def effect_params(effect: str, form: str | None = None, start: Mapping[str, float] | None = None) -> list[Param]:
    """Free parameters of one effect in one form, within the vocabulary's bounds."""
    spec = EFFECTS[effect]
    chosen = form or spec.forms[0]
    out = []
    for p in spec.params:
        if p.forms and chosen not in p.forms:
            continue
        wide = p.lower > 0 and p.upper / p.lower > 20  # scale-like: fit in log space
        value = (start or {}).get(p.name, p.default)
        value = min(max(value, p.lower if p.lower > 0 or not wide else 1e-12), p.upper)
        out.append(Param(f"{effect}.{p.name}", value, p.lower, p.upper, wide, p.unit, p.off))
    return out


def base_layout(prior: KeystrokeModel, levels_kpa: Sequence[float], *, free_coupling: bool = False,
                trajectories: bool = True, readout: bool = False, fit_acceleration: bool = False,
                max_travel_m: float = 0.012) -> Layout:
    """The base model's layout over `prior` (see the module docstring)."""
    levels = tuple(sorted(abs(float(p)) for p in levels_kpa))
    params = base_params(prior, levels, free_coupling=free_coupling, trajectories=trajectories)
    if readout:
        params += readout_params(prior, max_travel_m)
    if fit_acceleration:
        params += drive_params()
    return Layout(prior, tuple(params), levels, {})
