"""Experiment specs and rig files: strict pydantic models, YAML loading, JSON schemas.

    spec = load_spec("experiments/quickstart.yaml")   # InputError names file + YAML path
    rig = load_rig_for(spec)                          # the rig file it names, or the sim rig
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# The names below load on first use (PEP 562): the pydantic models take a good part of a
# second to import, and `pianobot runs` or the store only need the parameter table.
if TYPE_CHECKING:
    from pianobot.spec.checks import Problem, spec_problems
    from pianobot.spec.experiment import ExperimentSpec, default_value, resolved_spec_dict
    from pianobot.spec.loader import (
        load_rig,
        load_rig_for,
        load_spec,
        parse_spec_text,
        spec_sha256,
        write_rig_calibration,
    )
    from pianobot.spec.parameters import (
        ENVELOPE_PARAMETERS,
        FINGER_ENVELOPES,
        FINGERS,
        KEY_DIP_M,
        PARAMETER_NAMES,
        PARAMETERS,
        Finger,
        Limits,
        Parameter,
    )
    from pianobot.spec.rig import (
        EnvelopeOverrides,
        Faults,
        FingerEnvelope,
        KeyboardConfig,
        MidiConfig,
        MocapConfig,
        MocapMarkers,
        Retry,
        RigSpec,
        Settle,
        Travel,
        UR5Config,
        VacuumConfig,
    )
    from pianobot.spec.schema import write_schemas
    from pianobot.spec.sweep import (
        GridSweep,
        LhsSweep,
        Linspace,
        RandomSweep,
        Range,
        SampledSweep,
        Sweep,
        clean_value,
    )

_SOURCES: dict[str, str] = {
    "Problem": "pianobot.spec.checks",
    "spec_problems": "pianobot.spec.checks",
    "ExperimentSpec": "pianobot.spec.experiment",
    "default_value": "pianobot.spec.experiment",
    "resolved_spec_dict": "pianobot.spec.experiment",
    "load_rig": "pianobot.spec.loader",
    "load_rig_for": "pianobot.spec.loader",
    "load_spec": "pianobot.spec.loader",
    "parse_spec_text": "pianobot.spec.loader",
    "spec_sha256": "pianobot.spec.loader",
    "write_rig_calibration": "pianobot.spec.loader",
    "ENVELOPE_PARAMETERS": "pianobot.spec.parameters",
    "FINGER_ENVELOPES": "pianobot.spec.parameters",
    "FINGERS": "pianobot.spec.parameters",
    "KEY_DIP_M": "pianobot.spec.parameters",
    "PARAMETER_NAMES": "pianobot.spec.parameters",
    "PARAMETERS": "pianobot.spec.parameters",
    "Finger": "pianobot.spec.parameters",
    "Limits": "pianobot.spec.parameters",
    "Parameter": "pianobot.spec.parameters",
    "EnvelopeOverrides": "pianobot.spec.rig",
    "Faults": "pianobot.spec.rig",
    "FingerEnvelope": "pianobot.spec.rig",
    "KeyboardConfig": "pianobot.spec.rig",
    "MidiConfig": "pianobot.spec.rig",
    "MocapConfig": "pianobot.spec.rig",
    "MocapMarkers": "pianobot.spec.rig",
    "Retry": "pianobot.spec.rig",
    "RigSpec": "pianobot.spec.rig",
    "Settle": "pianobot.spec.rig",
    "Travel": "pianobot.spec.rig",
    "UR5Config": "pianobot.spec.rig",
    "VacuumConfig": "pianobot.spec.rig",
    "write_schemas": "pianobot.spec.schema",
    "GridSweep": "pianobot.spec.sweep",
    "LhsSweep": "pianobot.spec.sweep",
    "Linspace": "pianobot.spec.sweep",
    "RandomSweep": "pianobot.spec.sweep",
    "Range": "pianobot.spec.sweep",
    "SampledSweep": "pianobot.spec.sweep",
    "Sweep": "pianobot.spec.sweep",
    "clean_value": "pianobot.spec.sweep",
}


def __getattr__(name: str) -> Any:
    module = _SOURCES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = [
    "ENVELOPE_PARAMETERS",
    "FINGERS",
    "FINGER_ENVELOPES",
    "KEY_DIP_M",
    "PARAMETERS",
    "PARAMETER_NAMES",
    "EnvelopeOverrides",
    "ExperimentSpec",
    "Faults",
    "Finger",
    "FingerEnvelope",
    "GridSweep",
    "KeyboardConfig",
    "LhsSweep",
    "Limits",
    "Linspace",
    "MidiConfig",
    "MocapConfig",
    "MocapMarkers",
    "Parameter",
    "Problem",
    "RandomSweep",
    "Range",
    "Retry",
    "RigSpec",
    "SampledSweep",
    "Settle",
    "Sweep",
    "Travel",
    "UR5Config",
    "VacuumConfig",
    "clean_value",
    "default_value",
    "load_rig",
    "load_rig_for",
    "load_spec",
    "parse_spec_text",
    "resolved_spec_dict",
    "spec_problems",
    "spec_sha256",
    "write_rig_calibration",
    "write_schemas",
]
