"""The hidden effects the truth lab can switch on, each in one or more functional forms.

Every form names the pianobot effect that is the right answer for it (`effect`), that effect's
family, and whether the form is one of the shapes pianobot's discovery candidates are written in
(`equals_candidate`) or a different one. The force laws themselves live in `kernel` (compiled)
and `readout` (the piano); `encode` maps a form's parameters onto the kernel's slots.

Forms (downward positive, x2 key travel, s finger–key compression, v2 key speed):

| effect / form | law | candidate form? |
|---|---|---|
| keybed / linear | F = max(0, k·p + c·v2), p = x2 − depth > 0 | yes |
| keybed / hunt_crossley | F = (k·p + c·v2)·√(p / 1 mm) | yes (exponent 3/2) |
| keybed / power_law | F = F₁·(p / 1 mm)ⁿ·(1 + λ·v2), n ≠ 1, 1.5 | no |
| key_friction / coulomb | stick below F, slide at F | yes |
| key_friction / stribeck | stick below Fs, slide at Fc + (Fs − Fc)·exp(−(v/vs)²) | yes |
| key_friction / lugre | LuGre bristles: σ0·z + σ1·ż + σ2·v, ż = v − σ0·abs(v)·z / g(v) | no |
| key_preload / rest_stop | constant preload W against a rigid rail | yes |
| key_preload / felt_rail | W against a felt rail compressed by δ: smooth break-away | no |
| finger_stiffening / exponential | pad spring k1·(exp(b·s) − 1)/b | yes |
| finger_stiffening / power_law | pad spring k1·s·(1 + (s/s₀)^q), q ≠ 2 | yes (the power form, q fitted) |
| finger_hysteresis / bouc_wen | body spring k0·(α·u + (1 − α)·z), Bouc–Wen z | no (pianobot's is elastoplastic) |
| letoff / gaussian | F·exp(−((x2 − d)/w)²) while descending | yes |
| letoff / trip | smooth rise over w_r to d, sharp fall over w_d, while descending | no |
| adhesion / pull_off | pad holds the key until the pull exceeds F | yes |
| adhesion / cohesive | after separation δ: −F·(δ/δc)·exp(1 − δ/δc) | no |
| arm_lag / first_order, delay | arm = command through 1/(τs + 1), or τ late | yes |
| arm_lag / servo | arm = command through a 2nd-order servo (f, ζ) | no |
| mocap_delay / offset | mocap clock = true clock + δ | yes |
| mocap_delay / drifting | mocap clock = true clock·(1 + r) + δ (a clock-rate error) | no |
| velocity_curve / tanh | 127·tanh(β·u^γ)/tanh(β), u = speed / full scale | yes |
| velocity_curve / rational | 127·u·(1 + κ)/(u + κ), saturating | no |
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from . import kernel as K

# The family of each pianobot effect name (the unit discovery is scored on).
FAMILY_OF: dict[str, str] = {
    "contact": "contact",
    "adhesion": "contact",
    "keybed": "key_stop",
    "letoff": "key_stop",
    "key_preload": "key_action",
    "key_friction": "key_action",
    "finger_stiffening": "finger",
    "stiffness_drift": "finger",
    "finger_hysteresis": "finger",
    "arm_lag": "arm",
    "arm_acceleration": "arm",
    "velocity_curve": "piano",
    "mocap_delay": "mocap",
}


@dataclass(frozen=True)
class FormInfo:
    """One functional form: which pianobot effect answers it, and its parameters (with units)."""

    kind: str  # the truth lab's name of the effect (equals a pianobot name)
    form: str
    effect: str  # pianobot effect name that is the right answer
    equals_candidate: bool
    params: tuple[str, ...]
    where: str  # "plant" (kernel forces), "arm" (servo), "piano" (readout), "mocap" (clock)

    @property
    def family(self) -> str:
        return FAMILY_OF[self.effect]


_FORMS = (
    FormInfo("keybed", "linear", "keybed", True, ("depth_m", "stiffness_npm", "damping_nspm"), "plant"),
    FormInfo("keybed", "hunt_crossley", "keybed", True, ("depth_m", "stiffness_npm", "damping_nspm"), "plant"),
    FormInfo("keybed", "power_law", "keybed", False, ("depth_m", "force_at_1mm_n", "exponent", "damping_spm"), "plant"),
    FormInfo("key_friction", "coulomb", "key_friction", True, ("friction_n",), "plant"),
    FormInfo("key_friction", "stribeck", "key_friction", True, ("friction_n", "static_friction_n", "stribeck_velocity_mps"), "plant"),
    FormInfo("key_friction", "lugre", "key_friction", False, ("friction_n", "static_friction_n", "stribeck_velocity_mps", "bristle_npm", "bristle_damping_nspm", "viscous_nspm"), "plant"),
    FormInfo("key_preload", "rest_stop", "key_preload", True, ("preload_n",), "plant"),
    FormInfo("key_preload", "felt_rail", "key_preload", False, ("preload_n", "felt_compression_m", "felt_damping_spm"), "plant"),
    FormInfo("finger_stiffening", "exponential", "finger_stiffening", True, ("stiffening_per_m",), "plant"),
    FormInfo("finger_stiffening", "power_law", "finger_stiffening", True, ("reference_compression_m", "exponent"), "plant"),
    FormInfo("finger_hysteresis", "bouc_wen", "finger_hysteresis", False, ("yield_m", "post_yield_ratio", "exponent"), "plant"),
    FormInfo("letoff", "gaussian", "letoff", True, ("force_n", "depth_m", "width_m"), "plant"),
    FormInfo("letoff", "trip", "letoff", False, ("force_n", "depth_m", "rise_m", "drop_m"), "plant"),
    FormInfo("adhesion", "pull_off", "adhesion", True, ("pull_off_n",), "plant"),
    FormInfo("adhesion", "cohesive", "adhesion", False, ("peak_n", "range_m"), "plant"),
    FormInfo("arm_lag", "first_order", "arm_lag", True, ("tau_s",), "arm"),
    FormInfo("arm_lag", "delay", "arm_lag", True, ("tau_s",), "arm"),
    FormInfo("arm_lag", "servo", "arm_lag", False, ("freq_hz", "zeta"), "arm"),
    FormInfo("mocap_delay", "offset", "mocap_delay", True, ("delay_s",), "mocap"),
    FormInfo("mocap_delay", "drifting", "mocap_delay", False, ("delay_s", "rate_ppm"), "mocap"),
    FormInfo("velocity_curve", "tanh", "velocity_curve", True, ("exponent", "saturation", "full_scale_mps"), "piano"),
    FormInfo("velocity_curve", "rational", "velocity_curve", False, ("knee", "full_scale_mps"), "piano"),
)  # fmt: skip
FORMS: dict[tuple[str, str], FormInfo] = {(f.kind, f.form): f for f in _FORMS}


@dataclass(frozen=True)
class Effect:
    """One hidden effect: kind, form and parameter values (SI units in the names)."""

    kind: str
    form: str
    params: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        info = FORMS.get((self.kind, self.form))
        if info is None:
            known = sorted(f"{k}/{f}" for k, f in FORMS)
            raise ValueError(f"unknown effect form {self.kind}/{self.form}; known: {known}")
        missing = set(info.params) - set(self.params)
        extra = set(self.params) - set(info.params)
        if missing or extra:
            raise ValueError(
                f"{self.kind}/{self.form} takes {list(info.params)}; "
                f"missing {sorted(missing)}, unknown {sorted(extra)}"
            )

    @property
    def info(self) -> FormInfo:
        return FORMS[(self.kind, self.form)]

    def to_dict(self) -> dict[str, Any]:
        info = self.info
        return {
            "kind": self.kind,
            "form": self.form,
            "effect": info.effect,
            "family": info.family,
            "equals_candidate": info.equals_candidate,
            "params": dict(self.params),
        }


def encode(effect: Effect, p: Any) -> None:
    """Write a plant effect's parameters into the kernel parameter vector `p` (in place)."""
    q = effect.params
    kind, form = effect.kind, effect.form
    if kind == "keybed":
        p[K.BED_X] = q["depth_m"]
        if form == "power_law":
            p[K.BED_FORM] = K.BED_POWER
            p[K.BED_K], p[K.BED_N], p[K.BED_C] = (
                q["force_at_1mm_n"],
                q["exponent"],
                q["damping_spm"],
            )
        else:
            p[K.BED_FORM] = K.BED_LINEAR if form == "linear" else K.BED_HC15
            p[K.BED_K], p[K.BED_C] = q["stiffness_npm"], q["damping_nspm"]
    elif kind == "key_friction":
        p[K.FR_FC] = q["friction_n"]
        p[K.FR_FS] = q.get("static_friction_n", q["friction_n"])
        p[K.FR_VS] = q.get("stribeck_velocity_mps", 1.0)
        if form == "lugre":
            p[K.FR_FORM] = K.FR_LUGRE
            p[K.FR_S0], p[K.FR_S1], p[K.FR_S2] = (
                q["bristle_npm"],
                q["bristle_damping_nspm"],
                q["viscous_nspm"],
            )
        else:
            p[K.FR_FORM] = K.FR_STRIBECK
    elif kind == "key_preload":
        p[K.PRE_W] = q["preload_n"]
        if form == "felt_rail":
            p[K.PRE_FORM] = K.PRE_FELT
            p[K.PRE_DELTA], p[K.PRE_DAMP] = q["felt_compression_m"], q["felt_damping_spm"]
        else:
            p[K.PRE_FORM] = K.PRE_REST_STOP
    elif kind == "finger_stiffening":
        if form == "exponential":
            p[K.STIFF_FORM], p[K.STIFF_B] = K.STIFF_EXP, q["stiffening_per_m"]
        else:
            p[K.STIFF_FORM] = K.STIFF_POWER
            p[K.STIFF_SREF], p[K.STIFF_Q] = q["reference_compression_m"], q["exponent"]
    elif kind == "finger_hysteresis":
        p[K.HYS_ON] = 1.0
        p[K.HYS_UY], p[K.HYS_ALPHA], p[K.HYS_N] = q["yield_m"], q["post_yield_ratio"], q["exponent"]
    elif kind == "letoff":
        p[K.LET_F], p[K.LET_X] = q["force_n"], q["depth_m"]
        if form == "gaussian":
            p[K.LET_FORM], p[K.LET_W] = K.LET_GAUSS, q["width_m"]
        else:
            p[K.LET_FORM], p[K.LET_W], p[K.LET_WD] = K.LET_TRIP, q["rise_m"], q["drop_m"]
    elif kind == "adhesion":
        if form == "pull_off":
            p[K.ADH_FORM], p[K.ADH_F] = K.ADH_PULL_OFF, q["pull_off_n"]
        else:
            p[K.ADH_FORM], p[K.ADH_F], p[K.ADH_RANGE] = K.ADH_COHESIVE, q["peak_n"], q["range_m"]
    else:
        raise ValueError(f"{kind}/{form} is not a plant effect")
