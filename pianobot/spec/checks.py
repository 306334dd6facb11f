"""Checks of a parsed spec that pydantic cannot do alone, each naming the YAML path.

Every value the sweep can produce is checked against the finger's safety envelope (as the
rig file widens it) where the experimenter wrote it: a list item, the ends of a
`{start, stop, num}` spacing or of a `{low, high}` range, a fixed value. A grid's levels all
lie between its ends, so checking the ends covers every level.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from pianobot.spec.experiment import ExperimentSpec, default_value
from pianobot.spec.messages import Location
from pianobot.spec.parameters import (
    ENVELOPE_PARAMETERS,
    PARAMETERS,
    REQUIRED_PARAMETERS,
    Limits,
    format_value,
)
from pianobot.spec.rig import RigSpec
from pianobot.spec.sweep import GridSweep, Linspace, Range, clean_value

REQUIRED = REQUIRED_PARAMETERS
# Parameter → the parameters that take its value when not set (down velocity → up velocity).
_FOLLOWERS: dict[str, tuple[str, ...]] = {
    name: tuple(q.name for q in PARAMETERS.values() if q.follows == name) for name in PARAMETERS
}


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a spec: where (YAML path) and what."""

    path: Location
    message: str


def spec_problems(spec: ExperimentSpec, rig: RigSpec, rig_label: str = "the rig file") -> list[Problem]:
    """Everything wrong with a parsed spec on `rig`, in the order the YAML reads."""
    problems = _structure_problems(spec)
    envelope = rig.envelope_for(spec.finger, rig_label)
    for name, path, value in _written_values(spec):
        problem = _value_problem(spec, envelope, name, value, path)
        for follower in _FOLLOWERS.get(name, ()):
            if problem is None and not _given(spec, follower):
                # Without an up velocity the arm also moves up at this speed.
                problem = _value_problem(spec, envelope, follower, value, path)
                if problem is not None:
                    problem = Problem(path, problem.message + f" (it is also the "
                                      f"{PARAMETERS[follower].label.removeprefix('arm ')}, "
                                      f"since {follower} is not set)")
        if problem is not None:
            problems.append(problem)
    for name in ENVELOPE_PARAMETERS:
        default = default_value(name, spec)
        if _given(spec, name) or default is None:
            continue
        limits = envelope[name]
        if not limits.contains(default):
            problems.append(
                Problem(
                    ("sweep", "fixed"),
                    f"{name} defaults to {format_value(default)} {PARAMETERS[name].unit}, outside "
                    f"{_range_text(spec, name, limits)}; set it in sweep.fixed",
                )
            )
    return problems


def _given(spec: ExperimentSpec, name: str) -> bool:
    return name in spec.sweep.params.names() or name in spec.sweep.fixed.names()


def _structure_problems(spec: ExperimentSpec) -> list[Problem]:
    sweep = spec.sweep
    problems: list[Problem] = []
    swept = sweep.params.names()
    for name in sweep.fixed.names():
        if name in swept:
            problems.append(
                Problem(("sweep", "fixed", name), "is also varied in sweep.params; give it in one place")
            )
    for name in REQUIRED:
        if not _given(spec, name):
            problems.append(
                Problem(("sweep", "params"), f"{name} is not set: give it in sweep.params or sweep.fixed")
            )
    if isinstance(sweep, GridSweep):
        for name, value in sweep.params.items():
            if isinstance(value, Linspace):
                if value.num > 1 and value.start == value.stop:
                    problems.append(
                        Problem(("sweep", "params", name, "stop"),
                                f"equals start, so the {value.num} levels coincide; use num: 1")
                    )
                continue
            seen: set[float] = set()
            for i, level in enumerate(value):
                key = clean_value(level)
                if key in seen:
                    problems.append(
                        Problem(("sweep", "params", name, i),
                                f"repeats the level {format_value(level)}; use repeats: to press "
                                "a point more than once")
                    )
                seen.add(key)
    return problems


def _written_values(spec: ExperimentSpec) -> Iterator[tuple[str, Location, float]]:
    """(parameter, YAML path, value) of every number the sweep was written with."""
    sweep = spec.sweep
    for name, value in sweep.params.items():
        base: Location = ("sweep", "params", name)
        if isinstance(value, Linspace):
            yield name, (*base, "start"), value.start
            yield name, (*base, "stop"), value.stop
        elif isinstance(value, Range):
            yield name, (*base, "low"), value.low
            yield name, (*base, "high"), value.high
        else:
            for i, level in enumerate(value):
                yield name, (*base, i), float(level)
    for name, value in sweep.fixed.items():
        yield name, ("sweep", "fixed", name), float(value)


def _range_text(spec: ExperimentSpec, name: str, limits: Limits) -> str:
    source = f" ({limits.source})" if limits.source else ""
    return f"{limits.text(PARAMETERS[name].unit)} for the {spec.finger} finger{source}"


def _value_problem(
    spec: ExperimentSpec, envelope: dict[str, Limits], name: str, value: float, path: Location
) -> Problem | None:
    p = PARAMETERS[name]
    shown = format_value(value)
    if not p.within_bounds(value):
        return Problem(path, p.bounds_message(value))
    limits = envelope.get(name)
    if limits is None or limits.contains(value):
        return None
    if limits.low == limits.high:
        return Problem(
            path,
            f"must be {format_value(limits.low)} {p.unit} for the {spec.finger} finger "
            f"(it has no {name.rsplit('_', 1)[0]} setting), got {shown}",
        )
    return Problem(path, f"must be in {_range_text(spec, name, limits)}, got {shown}")
