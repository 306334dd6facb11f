"""The experiment spec: which finger, which rig, which sweep, which streams to record."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import Field, PrivateAttr, field_validator

from pianobot.spec.parameters import PARAMETERS, Finger
from pianobot.spec.sweep import GridSweep, Linspace, StrictModel, Sweep, clean_value

Stream = Literal["midi", "arm", "mocap"]
ApproachMode = Literal["as-specified", "fast"]
SLUG_PATTERN = r"^[a-z0-9][a-z0-9_-]*$"
SIM_RIG = "sim"

# Keys of a resolved sweep, in reading order (pydantic would list the shared base fields first).
_SWEEP_KEY_ORDER = ("mode", "samples", "sequences", "length", "seed", "params", "fixed", "repeats", "order", "block_by")


class ExperimentSpec(StrictModel):
    """One experiment: a sweep of keystrokes with one finger on one rig."""

    name: str = Field(
        min_length=1,
        max_length=80,
        pattern=SLUG_PATTERN,
        description="Slug naming the experiment (lowercase letters, digits, - and _).",
    )
    description: str | None = Field(None, description="Free text: what the experiment is for.")
    rig: str = Field(
        SIM_RIG,
        min_length=1,
        description="`sim` (the default simulated rig) or a rig file, relative to this spec.",
    )
    finger: Finger = Field(description="soft (vacuum-stiffened) or rigid; selects the envelope.")
    note: int = Field(57, ge=21, le=108, description="MIDI note pressed unless the sweep sets it.")
    sweep: Sweep = Field(description="The parameters to vary and how.")
    approach: ApproachMode = Field(
        "as-specified",
        description="as-specified: each press is the spec's two moves (the run-up at the contact "
        "speed). fast: the arm covers the run-up at travel speed and finishes the press in exactly "
        "the spec's state at contact, and returns at travel speed after lift-off (rig `approach:`).",
    )
    record: list[Stream] = Field(
        default_factory=lambda: list[Stream](["midi", "arm"]),
        min_length=1,
        description="Streams to record: midi, arm (TCP trace), mocap.",
    )
    _source: Path | None = PrivateAttr(default=None)

    @field_validator("rig")
    @classmethod
    def _rig_reference(cls, value: str) -> str:
        if value != SIM_RIG and not value.endswith((".yaml", ".yml")):
            raise ValueError(f"must be 'sim' or a rig file ending in .yaml, got {value!r}")
        return value

    @field_validator("record")
    @classmethod
    def _unique_streams(cls, value: list[Stream]) -> list[Stream]:
        if len(set(value)) != len(value):
            raise ValueError(f"lists a stream twice: {value}")
        return value

    @property
    def source_path(self) -> Path | None:
        """The file this spec was loaded from (None when built in code)."""
        return self._source

    def with_source(self, path: Path) -> ExperimentSpec:
        """This spec, remembering the file it came from (rig paths resolve relative to it)."""
        copy = self.model_copy()
        copy._source = path
        return copy

    def rig_path(self) -> Path | None:
        """The rig file this spec names, resolved relative to the spec file; None for `sim`."""
        if self.rig == SIM_RIG:
            return None
        path = Path(self.rig)
        if not path.is_absolute() and self._source is not None:
            path = self._source.parent / path
        return path


def default_value(name: str, spec: ExperimentSpec) -> float | None:
    """The value a parameter takes when the sweep neither varies nor fixes it.

    None for the parameters a sweep must give (down velocity, depth) and for the up velocity,
    which follows the down velocity of each trial.
    """
    if name == "note":
        return float(spec.note)
    return PARAMETERS[name].default


def resolved_spec_dict(spec: ExperimentSpec) -> dict[str, Any]:
    """The spec as plain JSON-able data, with grid spacings expanded and defaults filled in.

    It validates again as the same experiment (resolving is idempotent), and it is what the
    trial ids are hashed from, so `{start: 0.01, stop: 0.08, num: 15}` and the 15 listed levels
    give the same ids. The free-text `description` is left out: it does not change what runs.
    """
    # The default approach is left out, so trial ids of specs written before it existed stay.
    exclude = {"description"} | ({"approach"} if spec.approach == "as-specified" else set())
    data = spec.model_dump(mode="json", exclude=exclude)
    sweep = spec.sweep
    resolved = data["sweep"]
    if isinstance(sweep, GridSweep):
        resolved["params"] = {
            name: value.values() if isinstance(value, Linspace) else [clean_value(v) for v in value]
            for name, value in sweep.params.items()
        }
    swept = set(sweep.params.names())
    fixed = {name: clean_value(v) for name, v in sweep.fixed.items()}
    for name in PARAMETERS:
        if name in swept or name in fixed or name == "note":
            continue
        default = default_value(name, spec)
        if default is not None:
            fixed[name] = clean_value(default)
    if "note" in fixed:
        fixed["note"] = int(fixed["note"])
    resolved["fixed"] = fixed
    data["sweep"] = {k: resolved[k] for k in _SWEEP_KEY_ORDER if k in resolved}
    return data
