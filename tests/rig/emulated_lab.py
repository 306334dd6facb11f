"""A lab rig file and a spec pointing at an emulated UR controller (tests/hardware_emulator).

The emulated arm starts hovering above the reference key (B3, MIDI 59) whose surface is at
z = 0.15 m in the base frame; the emulated piano sounds the white keys along +x; the
emulated SMC ITV2090 regulator sits on analog output 0 with its 1-5 V monitor on input 0.
"""

from __future__ import annotations

import itertools
import math
import os
from pathlib import Path
from typing import Any

import yaml
from hardware_emulator import PianoConfig

from pianobot.spec.rig import RigSpec, UR5Config

REFERENCE_POSE = (-0.5, -0.1, 0.15, 0.0, math.pi, 0.0)
HOVER_POSE = (-0.5, -0.1, 0.17, 0.0, math.pi, 0.0)  # where the emulated arm starts
SMC_ITV2090 = {"output_channel": 0, "signal": "voltage", "signal_span": [0.0, 10.0],
               "kpa_span": [0.0, -80.0]}
SMC_MONITOR = {"input_channel": 0, "signal": "voltage", "signal_span": [1.0, 5.0]}
_pianos = itertools.count()


def ur5_section(host: str, **overrides: Any) -> dict[str, Any]:
    section: dict[str, Any] = {
        "host": host,
        "connect_timeout_s": 2.0,
        "workspace_min_m": [-0.75, -0.35, 0.05],
        "workspace_max_m": [-0.30, 0.10, 0.30],
        "reference_pose": list(REFERENCE_POSE),
        "reference_note": 59,
        "calibrated_utc": "2026-01-01T00:00:00Z",
        "safe_lift_m": 0.01,
    }
    section.update(overrides)
    return section


def ur5_config(host: str, **overrides: Any) -> UR5Config:
    return UR5Config.model_validate(ur5_section(host, **overrides))


def piano(jack: bool = True) -> PianoConfig:
    """The emulated piano; with `jack`, it plays on a JACK port named after it."""
    name = f"urpiano{os.getpid()}x{next(_pianos)}" if jack else None
    return PianoConfig(reference_x_m=REFERENCE_POSE[0], surface_z_m=REFERENCE_POSE[2],
                       reference_note=59, jack_client_name=name)


def lab_rig(host: str, piano_config: PianoConfig | None = None, **sections: Any) -> dict[str, Any]:
    """A rig file (as a dict) for the emulator at `host`; `sections` replace top-level keys."""
    port = piano_config.jack_client_name if piano_config and piano_config.jack_client_name else "ES8"
    rig: dict[str, Any] = {
        "kind": "ur5",
        "ur5": ur5_section(host),
        "vacuum": {"mode": "ur-analog", "regulator": SMC_ITV2090, "monitor": SMC_MONITOR,
                   "settle_timeout_s": 10.0, "tolerance_kpa": 2.0},
        "midi": {"api": "JACK", "port": port},
        "settle_s": {"after_vacuum_change_s": 0.2, "between_presses_s": 0.1},
        "travel": {"velocity_mps": 0.25, "acceleration_mps2": 2.0, "lift_m": 0.01},
        "retry": {"max_attempts": 3, "backoff_s": 0.6, "backoff_factor": 1.0},
        # Fast approaches keep 0.1 s of the spec's motion before contact (a rigid finger here).
        "approach": {"velocity_mps": 0.25, "acceleration_mps2": 2.0, "settle_s": 0.1},
    }
    rig.update(sections)
    return rig


def write_lab(folder: Path, host: str, piano_config: PianoConfig | None = None,
              **sections: Any) -> Path:
    path = folder / "emulated-lab.yaml"
    rig = lab_rig(host, piano_config, **sections)
    RigSpec.model_validate(rig)  # fail here, not inside the sweep
    path.write_text(yaml.safe_dump(rig, sort_keys=False))
    return path


def write_spec(folder: Path, rig_path: Path, *, vacuum_kpa: tuple[float, ...] = (0.0, -40.0),
               down_velocity_mps: tuple[float, ...] = (0.03, 0.05), repeats: int = 1,
               distance_m: float = 0.005, approach: str = "as-specified") -> Path:
    """A small soft-finger grid on the reference key (4 trials by default)."""
    spec = {
        "name": "emulated-lab",
        "rig": str(rig_path),
        "finger": "soft",
        "note": 59,
        "approach": approach,
        "sweep": {
            "mode": "grid",
            "params": {"vacuum_kpa": list(vacuum_kpa),
                       "down_velocity_mps": list(down_velocity_mps)},
            "fixed": {"acceleration_mps2": 1.0, "depth_m": 0.02, "distance_m": distance_m,
                      "hold_s": 0.05, "up_velocity_mps": 0.1},
            "repeats": repeats,
            "order": "as-listed",
        },
        "record": ["midi", "arm"],
    }
    path = folder / "spec.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path
