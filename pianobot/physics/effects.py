"""The effect vocabulary: named, parameterised augmentations of the study's linear keystroke model.

One vocabulary serves the simulated world (which switches several effects on with realistic
values) and discovery (which fits candidate effects to find what a model is missing). The names
in `EFFECT_NAMES` are stable API. Each effect lists its parameters with a unit, a default, fit
bounds and the value that switches it off; where the physics admits more than one shape (a
Hunt–Crossley vs a linear keybed, Stribeck vs Coulomb friction) the effect has a `form`, so a
world can be structurally richer than the candidate a discoverer fits.

`Effects` is an immutable set of enabled effects with their parameter values and forms.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of an effect: default, fit bounds, and the value that means "off".

    `off` is the value at which this parameter adds nothing of its own (a zero force); None
    when it is a shape, not a size (a depth, a width, a speed scale). An effect with several
    sizes (Stribeck friction: sliding and breakaway force) is on when any of them is away from
    its `off`. `forms` names the forms that use it (empty: all forms).
    """

    name: str
    default: float
    lower: float
    upper: float
    off: float | None
    unit: str
    description: str
    forms: tuple[str, ...] = ()


@dataclass(frozen=True)
class EffectSpec:
    """An effect: what it adds, its parameters, and its forms (the first is the default)."""

    name: str
    description: str
    params: tuple[ParamSpec, ...] = ()
    forms: tuple[str, ...] = ("default",)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def param(self, name: str) -> ParamSpec:
        """The parameter called `name` (ValueError naming the valid ones)."""
        for p in self.params:
            if p.name == name:
                return p
        raise ValueError(
            f"Effect {self.name!r} has no parameter {name!r}; valid: {list(self.param_names)}."
        )


_SPECS: tuple[EffectSpec, ...] = (
    EffectSpec(
        "contact",
        "Unilateral finger-key contact: the finger pushes, never pulls; separation and re-contact.",
    ),
    EffectSpec(
        "keybed",
        "End of key travel: a stiff, damped stop (felt) at depth bed_depth_m.",
        (
            ParamSpec("bed_depth_m", 0.010, 0.0005, 0.015, None, "m", "key travel where the stop begins"),
            ParamSpec("bed_stiffness_npm", 3.0e4, 2.0e3, 2.0e5, 0.0, "N/m", "stop stiffness (at 1 mm for hunt_crossley)"),
            ParamSpec("bed_damping_nspm", 15.0, 0.0, 100.0, None, "N*s/m", "stop damping (at 1 mm for hunt_crossley)"),
        ),
        ("linear", "hunt_crossley"),
    ),
    # A key's return spring presses it up against a rest rail; the finger must overcome that
    # preload before the key moves. On a rigid rail (the default form) nothing moves below it.
    # A felt or cloth rail gives: the key leaves it over a short travel, the rail's push fading
    # as it decompresses (`smooth`: a net −P·tanh(x/w) at key travel x, the rigid rail as w → 0).
    EffectSpec(
        "key_preload",
        "The key rests on a stop with a constant down-weight: it needs a minimum force to move "
        "(default: a rigid stop; smooth: the stop lets go over a short travel, like a felt rail).",
        (
            ParamSpec("preload_n", 0.5, 0.0, 1.5, 0.0, "N", "down-weight the finger must overcome"),
            ParamSpec("preload_width_m", 3e-4, 2e-5, 3e-3, None, "m",
                      "key travel over which the stop lets go", ("smooth",)),
        ),
        ("default", "smooth"),
    ),
    EffectSpec(
        "key_friction",
        "Dry friction in the key action (Coulomb, or Stribeck with a higher breakaway force).",
        (
            ParamSpec("friction_n", 0.12, 0.0, 0.5, 0.0, "N", "kinetic (Coulomb) friction force"),
            ParamSpec("static_friction_n", 0.18, 0.0, 0.8, 0.0, "N", "breakaway force", ("stribeck",)),
            ParamSpec("stribeck_velocity_mps", 0.005, 1e-4, 0.05, None, "m/s", "Stribeck speed", ("stribeck",)),
        ),
        ("coulomb", "stribeck"),
    ),
    EffectSpec(
        "finger_stiffening",
        "Nonlinear finger spring: the contact force grows faster than the compression.",
        (
            ParamSpec("stiffening_per_m", 60.0, 0.0, 1000.0, 0.0, "1/m", "inverse compression scale of the stiffening"),
            ParamSpec("stiffening_exponent", 2.0, 1.0, 4.0, None, "1",
                      "power of the scaled compression in the added stiffness", ("power",)),
        ),
        ("cubic", "exponential", "power"),
    ),
    # The skin sticks on release. The default form holds the key like the finger's spring
    # until the pull reaches the pull-off force, then lets go at once; a soft skin lets go
    # gradually (`cohesive`: its pull grows, peaks and fades to nothing over a separation range).
    EffectSpec(
        "adhesion",
        "The silicone skin sticks to the key on release up to a pull-off force (needs contact; "
        "default: it lets go at once; cohesive: the pull fades over a separation range).",
        (
            ParamSpec("pull_off_force_n", 0.05, 0.0, 0.5, 0.0, "N", "largest pull before the skin lets go"),
            ParamSpec("adhesion_range_m", 1e-3, 1e-4, 5e-3, None, "m",
                      "separation at which the skin's pull is gone", ("cohesive",)),
        ),
        ("default", "cohesive"),
    ),
    EffectSpec(
        "letoff",
        "Escapement: a resisting force bump near the bottom of key travel while descending.",
        (
            ParamSpec("letoff_force_n", 0.3, 0.0, 1.5, 0.0, "N", "peak resisting force"),
            ParamSpec("letoff_depth_m", 0.007, 0.003, 0.010, None, "m", "key travel at the bump"),
            ParamSpec("letoff_width_m", 0.001, 2e-4, 3e-3, None, "m", "half-width of the bump"),
        ),
    ),
    EffectSpec(
        "arm_lag",
        "The arm tracks its commanded profile with a first-order lag or a pure delay.",
        (ParamSpec("arm_lag_s", 0.006, 0.0, 0.05, 0.0, "s", "time constant (first_order) or delay"),),
        ("first_order", "delay"),
    ),
    EffectSpec(
        "arm_acceleration",
        "The arm accelerates and brakes at a finite rate (UR moveL trapezoid), not a constant-speed ramp.",
    ),
    EffectSpec(
        "velocity_curve",
        "The piano's key-speed -> MIDI-velocity map is nonlinear and saturates.",
        (
            ParamSpec("curve_exponent", 2.0, 0.5, 4.0, 1.0, "1", "power of the normalised key speed"),
            ParamSpec("curve_saturation", 1.0, 0.0, 5.0, 0.0, "1", "tanh saturation strength"),
        ),
    ),
    EffectSpec(
        "mocap_delay",
        "The motion-capture clock lags the arm and MIDI clocks by a constant offset.",
        (ParamSpec("mocap_delay_s", 0.005, -0.05, 0.05, 0.0, "s", "mocap time minus true time"),),
    ),
    EffectSpec(
        "stiffness_drift",
        "Finger stiffness at a given vacuum drifts between blocks (re-inflation, particle packing).",
        (ParamSpec("drift_fraction", 0.05, 0.0, 0.3, 0.0, "1", "largest relative change of k0 and k1 per block"),),
    ),
    # The finger's body is a bag of granular medium stiffened by vacuum (jamming). A jammed
    # packing is elastic under small strain, but once the shear stress reaches its frictional
    # (Mohr–Coulomb) limit the grains slide past each other: the packing yields plastically and
    # springs back elastically only from where it yielded, so loading and unloading follow
    # different curves (hysteresis). The simplest element with that behaviour is Jenkins'
    # elastoplastic one: a share of the body spring k0 acts through a slider that slips once its
    # spring is stretched past the yield deflection, the rest stays elastic (so the body never
    # loses all its stiffness, as a jammed bag does not). Rate-independent, like dry friction
    # between grains; one internal state (the slider's spring stretch) per keystroke. A body
    # that yields keeps a permanent set: on the way back up its slider slips the other way, and
    # the next keystroke starts from there, its fingertip hanging higher above the key and with
    # twice the elastic range before it yields again (`yield_set`; keystrokes are simulated
    # apart, so this is the state repeated presses leave, not the one the last press left).
    EffectSpec(
        "finger_hysteresis",
        "The finger body (arm to fingertip, k0) yields past a deflection and springs back elastically "
        "(elastoplastic: a share of k0 in series with a slider): loading and unloading differ.",
        (
            ParamSpec("yield_share", 0.3, 0.0, 0.95, 0.0, "1", "share of the body spring k0 that yields"),
            ParamSpec("yield_m", 0.008, 2e-4, 0.05, None, "m", "body deflection at which that share starts to slip"),
            ParamSpec("yield_set", 1.0, 0.0, 1.0, None, "1",
                      "state a keystroke starts in: 1 a body the presses before yielded (its slider sprung "
                      "back by yield_m, so it keeps a set), 0 a fresh one"),
        ),
        ("elastoplastic",),
    ),
)

EFFECTS: Mapping[str, EffectSpec] = MappingProxyType({s.name: s for s in _SPECS})
EFFECT_NAMES: tuple[str, ...] = tuple(s.name for s in _SPECS)


def effect_spec(name: str) -> EffectSpec:
    """The spec of effect `name` (ValueError naming the valid effects)."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise ValueError(f"Unknown effect {name!r}; valid: {list(EFFECT_NAMES)}.") from None


@dataclass(frozen=True)
class _Enabled:
    form: str
    values: tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class Effects:
    """An immutable set of enabled effects with their parameter values and forms.

    Build with `Effects.none().with_effect("keybed", bed_depth_m=0.011)`; parameters not given
    take their defaults. Iteration order follows `EFFECT_NAMES`.
    """

    _enabled: Mapping[str, _Enabled] = field(default_factory=dict)

    @classmethod
    def none(cls) -> Effects:
        """No effects: the study's linear model."""
        return cls({})

    @classmethod
    def all(cls) -> Effects:
        """Every effect on with its default form and values."""
        out = cls.none()
        for name in EFFECT_NAMES:
            out = out.with_effect(name)
        return out

    @classmethod
    def default_world(cls) -> Effects:
        """The simulated world's effects: all on, with the richer forms where there is a choice.

        All but a yielding finger body (`finger_hysteresis`, a discovery candidate that the
        world does not simulate: its sweeps stay what they were)."""
        return (
            cls.all()
            .without("finger_hysteresis")
            .with_effect("keybed", form="hunt_crossley")
            .with_effect("key_friction", form="stribeck")
            .with_effect("finger_stiffening", form="exponential")
            .with_effect("arm_lag", arm_lag_s=0.004)
            .with_effect("adhesion", pull_off_force_n=0.03)
            .with_effect("stiffness_drift", drift_fraction=0.04)
        )

    def with_effect(self, name: str, *, form: str | None = None, **params: float) -> Effects:
        """A copy with effect `name` on; unknown names, forms or parameters raise ValueError.

        If the effect is already on, unspecified parameters keep their current values.
        """
        spec = effect_spec(name)
        current = self._enabled.get(name)
        values = dict(current.values) if current else {p.name: p.default for p in spec.params}
        for key, value in params.items():
            p = spec.param(key)
            v = float(value)
            if not math.isfinite(v):
                raise ValueError(f"Effect parameter {name}.{key} should be finite, got {value}.")
            values[p.name] = v
        chosen = form if form is not None else (current.form if current else spec.forms[0])
        if chosen not in spec.forms:
            raise ValueError(f"Effect {name!r} has no form {chosen!r}; valid: {list(spec.forms)}.")
        enabled = dict(self._enabled)
        enabled[name] = _Enabled(chosen, tuple((p.name, values[p.name]) for p in spec.params))
        return Effects(MappingProxyType(enabled))

    def without(self, name: str) -> Effects:
        """A copy with effect `name` off (ValueError for an unknown name)."""
        effect_spec(name)
        enabled = {k: v for k, v in self._enabled.items() if k != name}
        return Effects(MappingProxyType(enabled))

    @property
    def names(self) -> tuple[str, ...]:
        """Enabled effects, in `EFFECT_NAMES` order."""
        return tuple(n for n in EFFECT_NAMES if n in self._enabled)

    def __contains__(self, name: object) -> bool:
        return name in self._enabled

    def __len__(self) -> int:
        return len(self._enabled)

    def params(self, name: str) -> dict[str, float]:
        """Parameter values of enabled effect `name` (ValueError if unknown or off)."""
        return dict(self._get(name).values)

    def form(self, name: str) -> str:
        """The form of enabled effect `name`."""
        return self._get(name).form

    def value(self, name: str, param: str, default: float = 0.0, form: str | None = None) -> float:
        """One parameter of an effect, or `default` when the effect is off (or, with `form`, in
        another form: a parameter only that form uses, such as a smooth rest stop's width)."""
        enabled = self._enabled.get(name)
        if enabled is None or (form is not None and enabled.form != form):
            effect_spec(name).param(param)
            return default
        return dict(enabled.values)[effect_spec(name).param(param).name]

    def _get(self, name: str) -> _Enabled:
        effect_spec(name)
        try:
            return self._enabled[name]
        except KeyError:
            raise ValueError(f"Effect {name!r} is not enabled; enabled: {list(self.names)}.") from None

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """`{name: {"form": ..., param: value, ...}}` for the enabled effects (JSON-ready)."""
        out: dict[str, dict[str, Any]] = {}
        for name in self.names:
            enabled = self._enabled[name]
            out[name] = {"form": enabled.form, **dict(enabled.values)}
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Mapping[str, Any] | None]) -> Effects:
        """Inverse of `to_dict` (missing parameters take defaults; unknown keys raise ValueError)."""
        out = cls.none()
        for name, entry in data.items():
            params = dict(entry or {})
            form = params.pop("form", None)
            out = out.with_effect(str(name), form=None if form is None else str(form), **params)
        return out

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Effects):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(tuple((n, self._enabled[n]) for n in self.names))

    def __repr__(self) -> str:
        return f"Effects({self.to_dict()!r})"
