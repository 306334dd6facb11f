"""A keystroke model = MSD parameters + effects + piano readout, and its JSON model files.

Identification, discovery and `play` exchange models through these files:

    {"schema": "pianobot.model/1", "kind": "keystroke_model",
     "model": {"msd": {...}, "effects": {...}, "piano": {...}},
     "intervals": {...} | null, "provenance": {...} | null}
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pianobot.atomic_files import write_text_atomic
from pianobot.errors import InputError
from pianobot.output import check_output_path
from pianobot.physics.effects import Effects
from pianobot.physics.msd import MSDParams
from pianobot.physics.piano import PianoParams
from pianobot.physics.trajectory import ProfileKind

MODEL_SCHEMA = "pianobot.model/1"
MODEL_KIND = "keystroke_model"


@dataclass(frozen=True)
class KeystrokeModel:
    """The whole forward model of a keystroke: arm → finger → key → MIDI.

    `piano` holds the sensor geometry and the full-scale speed; its curve shape is used only
    when the `velocity_curve` effect is on (see `readout_params`), so a model without that
    effect reads velocity linearly, as the study did.
    """

    msd: MSDParams = field(default_factory=MSDParams)
    effects: Effects = field(default_factory=Effects.none)
    piano: PianoParams = field(default_factory=PianoParams)

    @classmethod
    def study(cls) -> KeystrokeModel:
        """The study's linear model: published parameters, no effects (ramp input, linear readout)."""
        return cls(MSDParams(), Effects.none(), PianoParams())

    def with_effect(self, name: str, *, form: str | None = None, **params: float) -> KeystrokeModel:
        """A copy with one effect on (see `Effects.with_effect`)."""
        return dataclasses.replace(self, effects=self.effects.with_effect(name, form=form, **params))

    def without(self, name: str) -> KeystrokeModel:
        """A copy with one effect off."""
        return dataclasses.replace(self, effects=self.effects.without(name))

    def replace(self, **changes: Any) -> KeystrokeModel:
        """A copy with `msd`, `effects` or `piano` replaced."""
        return dataclasses.replace(self, **changes)

    @property
    def arm_profile(self) -> ProfileKind:
        """"trapezoid" when `arm_acceleration` is on, else the study's constant-speed "ramp"."""
        return "trapezoid" if "arm_acceleration" in self.effects else "ramp"

    @property
    def mocap_delay_s(self) -> float:
        """How far mocap time lags the true time under this model (0 without `mocap_delay`)."""
        return self.effects.value("mocap_delay", "mocap_delay_s", 0.0)

    def readout_params(self) -> PianoParams:
        """The piano readout this model predicts with: linear unless `velocity_curve` is on."""
        if "velocity_curve" in self.effects:
            p = self.effects.params("velocity_curve")
            return self.piano.replace(
                curve_exponent=p["curve_exponent"], curve_saturation=p["curve_saturation"]
            )
        return self.piano.replace(curve_exponent=1.0, curve_saturation=0.0)

    def to_dict(self) -> dict[str, Any]:
        return {
            "msd": self.msd.to_dict(),
            "effects": self.effects.to_dict(),
            "piano": self.piano.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> KeystrokeModel:
        """Inverse of `to_dict` (ValueError for unknown keys or effects)."""
        unknown = sorted(set(data) - {"msd", "effects", "piano"})
        if unknown:
            raise ValueError(f"unknown model section(s) {unknown}; known: ['effects', 'msd', 'piano'].")
        return cls(
            MSDParams.from_dict(data.get("msd") or {}),
            Effects.from_dict(data.get("effects") or {}),
            PianoParams.from_dict(data.get("piano") or {}),
        )


@dataclass(frozen=True)
class ModelFile:
    """What a model file holds besides the model: confidence intervals and provenance."""

    model: KeystrokeModel
    intervals: dict[str, Any] | None = None
    provenance: dict[str, Any] | None = None


def save_model(
    model: KeystrokeModel,
    path: str | Path,
    *,
    intervals: Mapping[str, Any] | None = None,
    provenance: Mapping[str, Any] | None = None,
) -> Path:
    """Write a model file (JSON, schema `pianobot.model/1`) atomically; returns the path.

    Through `pianobot.atomic_files`: a temp file beside `path`, fsync'd and renamed over it, so a
    crash or a full disk leaves the old model file whole (or none), never half a new one.
    """
    target = Path(path)
    payload = {
        "schema": MODEL_SCHEMA,
        "kind": MODEL_KIND,
        "model": model.to_dict(),
        "intervals": _finite(dict(intervals)) if intervals is not None else None,
        "provenance": _finite(dict(provenance)) if provenance is not None else None,
    }
    # Checked first (a folder, a read-only place: one line), then written atomically.
    check_output_path(target, "--out")
    target.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(target, json.dumps(payload, indent=2, default=str) + "\n")
    return target


def read_model_file(path: str | Path) -> ModelFile:
    """Read a model file with its intervals and provenance.

    Raises InputError naming the file when it is missing, not JSON, of another schema or
    kind, or holds an invalid model.
    """
    source = Path(path)
    where = str(source)
    try:
        payload = json.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("model file not found", where) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON model file ({exc})", where) from None
    if not isinstance(payload, dict):
        raise InputError(f"expected a JSON object with schema {MODEL_SCHEMA!r}", where)
    schema = payload.get("schema")
    if schema != MODEL_SCHEMA:
        raise InputError(f"expected schema {MODEL_SCHEMA!r}, got {schema!r}", where)
    kind = payload.get("kind", MODEL_KIND)
    if kind != MODEL_KIND:
        raise InputError(f"expected kind {MODEL_KIND!r}, got {kind!r}", where)
    raw = payload.get("model") or {}
    problem = _non_finite(raw, "model")
    if problem is not None:
        raise InputError(f"invalid model: {problem}", where)
    try:
        model = KeystrokeModel.from_dict(raw) if isinstance(raw, dict) else None
    except (TypeError, ValueError, AttributeError, KeyError, IndexError, OverflowError) as exc:
        # A hand-edited or damaged file: any shape the parameter classes do not expect.
        raise InputError(f"invalid model: {' '.join(str(exc).split())[:200]}", where) from None
    if model is None:
        raise InputError(f"invalid model: expected an object, got {type(raw).__name__}", where)
    intervals, provenance = payload.get("intervals"), payload.get("provenance")
    return ModelFile(model, intervals if isinstance(intervals, dict) else None,
                     provenance if isinstance(provenance, dict) else None)


def _non_finite(value: Any, path: str) -> str | None:
    """Where a model holds a number that is not one (NaN, ±inf, true/false), if anywhere."""
    if isinstance(value, bool):
        return f"{path} is {str(value).lower()}, not a number"
    if isinstance(value, float) and not math.isfinite(value):
        return f"{path} is {value}, not a finite number"
    if isinstance(value, dict):
        for key, item in value.items():
            found = _non_finite(item, f"{path}.{key}")
            if found:
                return found
    if isinstance(value, list):
        for i, item in enumerate(value):
            found = _non_finite(item, f"{path}[{i}]")
            if found:
                return found
    return None


def load_model(path: str | Path) -> KeystrokeModel:
    """Read the model of a model file (see `read_model_file` for the errors)."""
    return read_model_file(path).model


def _finite(value: Any) -> Any:
    """JSON has no NaN/inf: store them as null so every reader can parse the file."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if hasattr(value, "item") and callable(value.item):
        return _finite(value.item())
    return value
