"""Experiment specs and rig files: strict pydantic models, YAML loading, JSON schemas.

    spec = load_spec("experiments/quickstart.yaml")   # InputError names file + YAML path
    rig = load_rig_for(spec)                          # the rig file it names, or the sim rig
"""

from __future__ import annotations

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
