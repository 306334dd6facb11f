"""The `sweep:` section of an experiment spec: grid, random, Latin-hypercube and sequence sweeps.

A sweep names the parameters it varies (`params`), those it holds (`fixed`), how often each
point is repeated and in which order the trials run. Parameter names are the trials table's
columns (see `parameters.PARAMETERS`); any other name is an unknown key.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    PrivateAttr,
    SerializerFunctionWrapHandler,
    Strict,
    Tag,
    create_model,
    model_serializer,
    model_validator,
)

from pianobot.spec.parameters import PARAMETER_NAMES, PARAMETERS, Parameter, defaults_text

# Numbers in trial values are cleaned to this many decimals: linspace and YAML give
# 0.045000000000000005 where the experimenter meant 0.045.
VALUE_DECIMALS = 12

if TYPE_CHECKING:
    ParameterName = str
else:  # the names of the parameter table, as a Literal pydantic checks and shows in the schema
    ParameterName = Literal[PARAMETER_NAMES]
Order = Literal["as-listed", "shuffled", "blocked-shuffle"]


class StrictModel(BaseModel):
    """Base of every spec model: unknown keys are errors, values are immutable and strict.

    Strict: `true` is not a number and `"1.0"` is not 1.0 (no coercion from bool or text), a
    whole number is not written `2.0`, and NaN or infinity is never a valid setting.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


# A YAML list where a fixed-length tuple is expected: the list itself is accepted (lax), each
# item is still a strict, finite number.
Number = Annotated[float, Strict()]
Pair = Annotated[tuple[Number, Number], Strict(False)]


def clean_value(value: float) -> float:
    """A parameter value without float repr noise (and without a negative zero)."""
    return float(round(float(value), VALUE_DECIMALS)) + 0.0


class Linspace(StrictModel):
    """`num` evenly spaced grid levels from `start` to `stop`, both included."""

    start: float = Field(description="First level, in the parameter's unit.")
    stop: float = Field(description="Last level, in the parameter's unit.")
    num: int = Field(ge=1, le=10_000, description="Number of levels (1 gives only `start`).")

    def values(self) -> list[float]:
        """The levels, cleaned of float repr noise."""
        return [clean_value(v) for v in np.linspace(self.start, self.stop, self.num)]


class Range(StrictModel):
    """A closed interval to sample from uniformly."""

    low: float = Field(description="Lower end, in the parameter's unit.")
    high: float = Field(description="Upper end, in the parameter's unit.")

    @model_validator(mode="after")
    def _ordered(self) -> Range:
        if self.high < self.low:
            raise ValueError(f"high ({self.high}) must be >= low ({self.low})")
        return self


def _item_type(p: Parameter) -> Any:
    """The type of one value of `p`, with its physical bounds (shown in the JSON schema)."""
    base: Any = int if p.integer else float
    if p.exclusive_minimum:
        return Annotated[base, Field(gt=p.minimum, le=p.maximum)]
    return Annotated[base, Field(ge=p.minimum, le=p.maximum)]


def _shape(value: Any, *, mapping: str, sequence: str) -> str:
    """Tag of a value that may be written as a mapping or a list (or is a parsed mapping)."""
    return mapping if isinstance(value, dict | BaseModel) else sequence


def _grid_type(p: Parameter) -> Any:
    values: Any = Annotated[list[_item_type(p)], Field(min_length=1)]  # type: ignore[misc]
    if p.integer:  # MIDI notes are listed, never spaced
        return values
    return Annotated[
        Annotated[values, Tag("values")] | Annotated[Linspace, Tag("linspace")],
        Discriminator(lambda v: _shape(v, mapping="linspace", sequence="values")),
    ]


def _sampled_type(p: Parameter) -> Any:
    choices: Any = Annotated[list[_item_type(p)], Field(min_length=1)]  # type: ignore[misc]
    return Annotated[
        Annotated[choices, Tag("choices")] | Annotated[Range, Tag("range")],
        Discriminator(lambda v: _shape(v, mapping="range", sequence="choices")),
    ]


class ParameterSet(StrictModel):
    """Base of the per-parameter mappings; remembers the order the YAML listed them in.

    The order matters: a grid nests its first parameter outermost, so `as-listed` runs
    exactly as written (the study nested vacuum, then acceleration, speed and depth).
    """

    _order: tuple[str, ...] = PrivateAttr(default=())
    # In params (not in fixed) a bare number is a one-level list: `hold_s: 0` means `[0]`.
    number_is_list: ClassVar[bool] = True

    @model_validator(mode="wrap")
    @classmethod
    def _remember_order(cls, data: Any, handler: Any) -> Any:
        if isinstance(data, dict) and cls.number_is_list:
            data = {k: [v] if _is_number(v) else v for k, v in data.items()}
        model = handler(data)
        if isinstance(data, dict):
            model._order = tuple(k for k in data if k in PARAMETERS and data[k] is not None)
        return model

    @model_serializer(mode="wrap")
    def _dump_in_order(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        # Only the parameters given, in YAML order: the dump reads like the spec it came from.
        dumped: dict[str, Any] = handler(self)
        keys = [k for k in self._order if k in dumped]
        keys += [k for k in dumped if k not in keys]
        return {k: dumped[k] for k in keys if dumped[k] is not None}

    def items(self) -> list[tuple[str, Any]]:
        """(name, value) of every parameter given, in the order the YAML listed them."""
        given = [n for n in PARAMETER_NAMES if getattr(self, n) is not None]
        ordered = [n for n in self._order if n in given]
        ordered += [n for n in given if n not in ordered]
        return [(n, getattr(self, n)) for n in ordered]

    def names(self) -> list[str]:
        """Names of the parameters given, in YAML order."""
        return [n for n, _ in self.items()]


class HeldParameterSet(ParameterSet):
    """A mapping of single values (a number stays a number)."""

    number_is_list: ClassVar[bool] = False


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _parameter_model(name: str, kind: str, doc: str) -> type[ParameterSet]:
    """Build a mapping model with one optional field per parameter."""
    fields: dict[str, Any] = {}
    for p in PARAMETERS.values():
        if kind == "grid":
            typ, how = _grid_type(p), "a list of levels" + ("" if p.integer else " or {start, stop, num}")
        elif kind == "sampled":
            typ, how = _sampled_type(p), "a {low, high} range or a list of choices"
        else:
            typ, how = _item_type(p), "one value"
        unit = f" [{p.unit}]" if p.unit else ""
        fields[p.name] = (typ | None, Field(None, description=f"{p.description}{unit} As {how}."))
    base: type[ParameterSet] = HeldParameterSet if kind == "fixed" else ParameterSet
    model: type[ParameterSet] = create_model(name, __base__=base, __doc__=doc, **fields)
    return model


if TYPE_CHECKING:  # the models are built from the parameter table; type checkers see the base
    GridParams = ParameterSet
    SampledParams = ParameterSet
    FixedParams = ParameterSet
else:
    GridParams = _parameter_model(
        "GridParams", "grid", "Grid levels per parameter; the grid is their full Cartesian product."
    )
    SampledParams = _parameter_model(
        "SampledParams", "sampled", "Per parameter a {low, high} range or a list of choices."
    )
    FixedParams = _parameter_model(
        "FixedParams", "fixed", "Parameters held at one value for every trial (override defaults)."
    )


class SweepBase(StrictModel):
    """What every sweep mode shares: held parameters, repeats, trial order, seed."""

    fixed: FixedParams = Field(
        default_factory=FixedParams,
        description=f"Parameters held constant. Unset ones take their defaults: {defaults_text()}.",
    )
    repeats: int = Field(1, ge=1, le=1000, description="How many times each point is pressed.")
    order: Order = Field(
        "as-listed",
        description="Trial order. as-listed: grid order (first parameter outermost), each point's "
        "repeats back to back; shuffled: all trials in a seeded random order; blocked-shuffle: "
        "trials grouped in blocks of equal slow settings (block_by, e.g. vacuum, which takes "
        "seconds to settle), blocks in listed order, shuffled inside each block.",
    )
    block_by: list[ParameterName] = Field(
        default_factory=lambda: list[ParameterName](["vacuum_kpa"]),
        description="Slow parameters that define the blocks of order: blocked-shuffle.",
    )
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Seed of the sampling and of the shuffles.")


class GridSweep(SweepBase):
    """Every combination of the listed levels."""

    mode: Literal["grid"] = Field(description="Full Cartesian grid of the levels in params.")
    params: GridParams = Field(
        default_factory=GridParams,
        description="Levels per parameter: a list, or {start, stop, num} evenly spaced.",
    )


class SampledSweep(SweepBase):
    """Shared fields of the random and Latin-hypercube sweeps."""

    samples: int = Field(ge=1, le=1_000_000, description="Number of sampled points.")
    params: SampledParams = Field(
        default_factory=SampledParams,
        description="Per parameter a {low, high} range (uniform) or a list of choices.",
    )


class RandomSweep(SampledSweep):
    """Independent uniform samples."""

    mode: Literal["random"] = Field(description="Independent uniform random samples.")


class LhsSweep(SampledSweep):
    """A Latin hypercube: each parameter's range is cut into `samples` strata, each used once."""

    mode: Literal["lhs"] = Field(description="Latin-hypercube samples (scipy.stats.qmc).")


class SequenceSweep(SweepBase):
    """Random note sequences, as the study collected its sequence data: `sequences` runs of
    `length` strokes played back to back, every parameter of `params` (the note too) drawn
    uniformly per stroke. Each trial carries its `sequence_id` and `sequence_order`, which is
    what `pianobot fit --model sequence` learns the context from."""

    mode: Literal["sequence"] = Field(description="Random sequences of strokes, parameters drawn per stroke.")
    sequences: int = Field(ge=1, le=100_000, description="Number of sequences.")
    length: int = Field(ge=1, le=1000, description="Strokes per sequence (the study's: 12).")
    params: SampledParams = Field(
        default_factory=SampledParams,
        description="Per parameter a {low, high} range (uniform) or a list of choices, drawn per stroke.",
    )

    @model_validator(mode="after")
    def _played_in_order(self) -> SequenceSweep:
        # A sequence is the strokes in the order drawn: shuffling or repeating would break it.
        if self.order != "as-listed":
            raise ValueError(f"a sequence sweep plays its strokes in order: order must be as-listed, got {self.order!r}")
        if self.repeats != 1:
            raise ValueError(f"a sequence sweep draws every stroke anew: repeats must be 1, got {self.repeats}")
        if self.sequences * self.length > 1_000_000:
            raise ValueError(f"{self.sequences} sequences of {self.length} strokes exceed 1,000,000 strokes")
        return self

    @property
    def samples(self) -> int:
        """Strokes in all (each one a sampled point)."""
        return self.sequences * self.length


Sweep = Annotated[GridSweep | RandomSweep | LhsSweep | SequenceSweep, Field(discriminator="mode")]
SWEEP_MODES: tuple[str, ...] = ("grid", "random", "lhs", "sequence")
