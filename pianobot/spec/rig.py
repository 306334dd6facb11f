"""Rig files: which rig runs a spec (simulated or the UR5 lab) and how it is set up.

A rig file holds everything about the lab that is not the experiment: the simulated world and
its injected faults, retry policy, settle pauses, explicit widening of a finger's safety
envelope, and for the real rig the arm, vacuum regulator, MIDI port, mocap markers and keyboard
geometry. `load_rig("sim")` is the default simulated rig.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, Strict, ValidationError, field_validator, model_validator

from pianobot.spec.messages import error_message, format_path
from pianobot.spec.parameters import FINGER_ENVELOPES, PARAMETERS, Finger, Limits
from pianobot.spec.sweep import Number, Pair, StrictModel

WORLD_PRESETS: tuple[str, ...] = ("default", "linear")
# YAML lists, each item a strict finite number (see `sweep.StrictModel`).
Vector3 = Annotated[tuple[Number, Number, Number], Strict(False)]
Pose6 = Annotated[tuple[Number, Number, Number, Number, Number, Number], Strict(False)]
# Keys of `world:` whose value is a name, not a number.
_WORLD_TEXT_KEYS = ("preset", "form")


class Faults(StrictModel):
    """Faults the simulated rig injects, to exercise retries and safety stops."""

    drop_connection_every_n_presses: int | None = Field(
        None, ge=1, description="Drop the arm connection on every n-th press (null: never)."
    )
    protective_stop_at_trial: int | None = Field(
        None, ge=0, description="Raise a protective stop when the trial with this index starts."
    )
    midi_loss_prob: float = Field(
        0.0, ge=0.0, le=1.0, description="Probability that a MIDI event is lost."
    )
    mocap_drop_prob: float = Field(
        0.0, ge=0.0, le=1.0, description="Probability that a mocap frame is dropped."
    )


class Retry(StrictModel):
    """Retries of a trial after a transient fault (a dropped connection)."""

    max_attempts: int = Field(3, ge=1, le=100, description="Attempts per trial, the first included.")
    backoff_s: float = Field(1.0, ge=0.0, le=600.0, description="Wait before the first retry.")
    backoff_factor: float = Field(
        2.0, ge=1.0, le=10.0, description="Each further retry waits this many times longer."
    )


class Settle(StrictModel):
    """Pauses that let the rig come to rest; they dominate the lab time of a sweep."""

    after_vacuum_change_s: float = Field(
        5.0, ge=0.0, le=600.0,
        description="Wait after the vacuum level changes (the regulator and the particle "
        "jamming settle in seconds).",
    )
    between_presses_s: float = Field(
        0.5, ge=0.0, le=60.0,
        description="Wait between two presses, so the key and the finger are at rest (the "
        "study's script slept 0.5 s around each press).",
    )


class Travel(StrictModel):
    """How the arm moves between keys (used by lab-time estimates)."""

    velocity_mps: float = Field(0.1, gt=0.0, le=1.0, description="moveL speed between keys.")
    acceleration_mps2: float = Field(
        0.5, gt=0.0, le=5.0, description="moveL acceleration between keys."
    )
    lift_m: float = Field(
        0.05, ge=0.0, le=0.3, description="Lift above the hover height before moving sideways."
    )


class Approach(StrictModel):
    """Two-segment presses (a spec with `approach: fast`): the fast moves and what they keep.

    The arm covers the run-up at travel speed, stops, and finishes the press with the spec's own
    move so that it meets the key in exactly the spec's kinematic state; after lift-off it goes
    back up at travel speed. See `pianobot.physics.approach` for the conditions.
    """

    velocity_mps: float = Field(
        0.25, gt=0.0, le=1.0, description="moveL speed of the fast approach and retract."
    )
    acceleration_mps2: float = Field(
        1.0, gt=0.0, le=5.0, description="moveL acceleration of the fast approach and retract."
    )
    clearance_m: float = Field(
        0.005, ge=0.001, le=0.05,
        description="Fingertip height above the key where a fast move must end (approach) or "
        "may begin (retract); it must exceed the finger's sway when the arm stops.",
    )
    settle_s: float = Field(
        1.5, ge=0.0, le=10.0,
        description="The arm moves exactly as the spec's single move for this long before "
        "contact, so the finger's ringing from the stop has died out (the published soft "
        "finger rings down with a 0.28 s time constant: 1.5 s leaves 0.5 %).",
    )


class FingerEnvelope(StrictModel):
    """Explicit per-parameter [low, high] ranges that replace a finger's built-in envelope."""

    vacuum_kpa: Pair | None = Field(None, description="[low, high] kPa gauge.")
    down_velocity_mps: Pair | None = Field(None, description="[low, high] m/s.")
    up_velocity_mps: Pair | None = Field(None, description="[low, high] m/s.")
    acceleration_mps2: Pair | None = Field(None, description="[low, high] m/s².")
    depth_m: Pair | None = Field(None, description="[low, high] m.")
    distance_m: Pair | None = Field(None, description="[low, high] m.")
    hold_s: Pair | None = Field(None, description="[low, high] s.")

    @model_validator(mode="after")
    def _ordered_and_physical(self) -> FingerEnvelope:
        for name, limits in self.ranges().items():
            low, high = limits
            if high < low:
                raise ValueError(f"{name}: high ({high}) must be >= low ({low})")
            p = PARAMETERS[name]
            if low < p.minimum or high > p.maximum:
                raise ValueError(
                    f"{name}: [{low}, {high}] leaves the physical bounds {p.bounds_text()}"
                )
        return self

    def ranges(self) -> dict[str, tuple[float, float]]:
        """The parameters this envelope sets, with their [low, high]."""
        return {
            name: value
            for name in type(self).model_fields
            if (value := getattr(self, name)) is not None
        }


class EnvelopeOverrides(StrictModel):
    """Per finger, ranges that replace the built-in safety envelope (normally to widen it)."""

    soft: FingerEnvelope | None = Field(None, description="Ranges for the soft finger.")
    rigid: FingerEnvelope | None = Field(None, description="Ranges for the rigid finger.")


class UR5Config(StrictModel):
    """The UR5 arm, reached over RTDE."""

    host: str = Field(min_length=1, description="IP address or host name of the UR controller.")
    frequency_hz: float | None = Field(
        None, gt=0.0, le=500.0,
        description="RTDE rate; null (the default) takes it from the controller version like "
        "ur_rtde does: 125 Hz on a CB3, 500 Hz on an e-Series. A rate above the controller's "
        "loop rate is lowered to it, with a warning.",
    )
    connect_timeout_s: float = Field(2.0, gt=0.0, le=120.0, description="Connection timeout.")
    workspace_min_m: Vector3 = Field(
        description="Lower corner [x, y, z] of the box the TCP must stay in (base frame)."
    )
    workspace_max_m: Vector3 = Field(
        description="Upper corner [x, y, z] of the box the TCP must stay in (base frame)."
    )
    reference_pose: Pose6 | None = Field(
        None,
        description="TCP pose [x, y, z, rx, ry, rz] (m, rad, base frame) with the fingertip "
        "resting on the reference key; null until `pianobot rig calibrate` writes it.",
    )
    reference_note: int = Field(59, ge=21, le=108, description="MIDI note of the reference key.")
    keyboard_axis: Vector3 = Field(
        (1.0, 0.0, 0.0),
        description="Horizontal unit vector [x, y, z] in the base frame pointing from bass to "
        "treble along the keyboard; key poses are the reference pose shifted along it.",
    )
    calibrated_utc: str | None = Field(
        None, description="When the reference pose was calibrated (ISO 8601, UTC)."
    )
    safe_lift_m: float = Field(
        0.05, ge=0.0, le=0.3, description="Height above the hover pose the arm retracts to."
    )
    warn_speed_slider_below: float = Field(
        1.0, gt=0.0, le=1.0,
        description="Warn before any motion when the teach pendant's speed slider "
        "(target_speed_fraction) is below this: every move then runs slower than commanded.",
    )

    @model_validator(mode="before")
    @classmethod
    def _renamed(cls, data: Any) -> Any:
        if isinstance(data, dict) and "max_speed_scaling_warning" in data:
            raise ValueError(
                "max_speed_scaling_warning was renamed warn_speed_slider_below (it is about the "
                "pendant's speed slider, target_speed_fraction)"
            )
        return data

    @model_validator(mode="after")
    def _box(self) -> UR5Config:
        if any(lo >= hi for lo, hi in zip(self.workspace_min_m, self.workspace_max_m, strict=True)):
            raise ValueError("workspace_min_m must be below workspace_max_m on every axis")
        return self


Signal = Literal["voltage", "current"]
# What a UR standard analog output drives over its ratio 0..1, per domain (V or mA).
UR_ANALOG_SPAN: dict[str, tuple[float, float]] = {"voltage": (0.0, 10.0), "current": (4.0, 20.0)}
SIGNAL_UNIT = {"voltage": "V", "current": "mA"}


def _check_span(signal: str, span: tuple[float, float], what: str) -> None:
    lo, hi = UR_ANALOG_SPAN[signal]
    unit = SIGNAL_UNIT[signal]
    if span[0] == span[1]:
        raise ValueError(f"{what} must have two different ends, got [{span[0]:g}, {span[1]:g}]")
    if min(span) < lo - 1e-9 or max(span) > hi + 1e-9:
        raise ValueError(
            f"{what} [{span[0]:g}, {span[1]:g}] {unit} leaves the UR's {signal} range "
            f"[{lo:g}, {hi:g}] {unit}"
        )


class RegulatorCommand(StrictModel):
    """How the UR's analog output commands the regulator (its set-point input)."""

    output_channel: int = Field(0, ge=0, le=1, description="UR standard analog output 0 or 1.")
    signal: Signal = Field(
        description="The regulator's command input: voltage (0-10 V, 0-5 V) or current "
        "(4-20 mA). pianobot puts the UR output in that domain (ur_rtde's "
        "setAnalogOutputVoltage / setAnalogOutputCurrent)."
    )
    signal_span: Pair = Field(
        description="The input signal's two ends in V or mA, e.g. [0, 10] V or [4, 20] mA."
    )
    kpa_span: Pair = Field(
        description="The pressure (kPa gauge) at the two ends of signal_span, from the "
        "regulator's data sheet, e.g. [0, -80] for an SMC ITV2090."
    )

    @model_validator(mode="after")
    def _spans(self) -> RegulatorCommand:
        _check_span(self.signal, self.signal_span, "signal_span")
        if self.kpa_span[0] == self.kpa_span[1]:
            raise ValueError("kpa_span must have two different ends")
        if max(self.kpa_span) > 0:
            raise ValueError(f"kpa_span must be <= 0 kPa (gauge vacuum), got {list(self.kpa_span)}")
        return self


class RegulatorMonitor(StrictModel):
    """The regulator's pressure monitor output, wired to a UR analog input."""

    input_channel: int = Field(0, ge=0, le=1, description="UR standard analog input 0 or 1.")
    signal: Signal = Field(
        "voltage", description="Domain of the monitor output; the UR input must be set to the "
        "same domain on the teach pendant."
    )
    signal_span: Pair = Field(
        description="The monitor's two ends in V or mA, e.g. [1, 5] V on an SMC ITV."
    )
    kpa_span: Pair | None = Field(
        None, description="Pressure at the two ends of signal_span (null: the command's)."
    )

    @model_validator(mode="after")
    def _spans(self) -> RegulatorMonitor:
        _check_span(self.signal, self.signal_span, "monitor signal_span")
        return self


class VacuumConfig(StrictModel):
    """The vacuum regulator that stiffens the soft finger."""

    mode: Literal["sim", "manual", "ur-analog"] = Field(
        "sim",
        description="sim: commanded = measured; manual: the operator sets the regulator when "
        "asked; ur-analog: the UR's analog output drives the regulator.",
    )
    regulator: RegulatorCommand | None = Field(
        None, description="The regulator's command signal and span (needed for ur-analog)."
    )
    monitor: RegulatorMonitor | None = Field(
        None, description="The regulator's pressure monitor on a UR analog input (null: none; "
        "then the settle pause covers the regulator)."
    )
    settle_timeout_s: float = Field(
        20.0, gt=0.0, le=600.0, description="Give up if the level has not settled by then."
    )
    tolerance_kpa: float = Field(2.0, gt=0.0, le=50.0, description="Settled when within this.")

    @model_validator(mode="before")
    @classmethod
    def _replaced(cls, data: Any) -> Any:
        old = [k for k in ("kpa_at_ratio_0", "kpa_at_ratio_1", "output_channel", "input_channel")
               if isinstance(data, dict) and k in data]
        if old:
            raise ValueError(
                f"{', '.join(old)} replaced by `regulator:` (output_channel, signal, signal_span, "
                "kpa_span) and `monitor:` (input_channel, signal, signal_span): declare the "
                "regulator's signal and span, e.g. signal: voltage, signal_span: [0, 10], "
                "kpa_span: [0, -80] for an SMC ITV2090"
            )
        return data

    @model_validator(mode="after")
    def _regulator_for_ur_analog(self) -> VacuumConfig:
        if self.mode == "ur-analog" and self.regulator is None:
            raise ValueError(
                "vacuum mode ur-analog needs a `regulator:` section with its signal (voltage | "
                "current), signal_span and kpa_span: pianobot assumes no span, a wrong one puts "
                "every vacuum level off"
            )
        return self


class MidiConfig(StrictModel):
    """The piano's MIDI output, as seen by this computer."""

    api: Literal["ALSA", "JACK", "auto"] = Field("auto", description="rtmidi backend.")
    port: str = Field(min_length=1, description="Substring or regex of the input port's name.")
    note: int | None = Field(
        None, ge=21, le=108, description="Only accept this note (null: the trial's note)."
    )


class MocapMarkers(StrictModel):
    """Names of the Motive markers that track the arm, the fingertip and the key."""

    arm: str = Field(description="Marker on the UR5 end effector.")
    fingertip: str = Field(description="Marker on the fingertip.")
    key: str = Field(description="Marker on the key surface.")


class MocapConfig(StrictModel):
    """OptiTrack motion capture."""

    markers: MocapMarkers | None = Field(None, description="Marker names (null: no mocap).")


class KeyboardConfig(StrictModel):
    """Keyboard geometry: where each key is relative to the reference key."""

    white_key_pitch_m: float = Field(
        0.0235, gt=0.0, le=0.05, description="Centre-to-centre distance of white keys."
    )
    offsets_m: dict[int, float] = Field(
        default_factory=dict,
        description="Measured lateral corrections per MIDI note, in metres.",
    )

    @field_validator("offsets_m")
    @classmethod
    def _notes(cls, value: dict[int, float]) -> dict[int, float]:
        bad = [n for n in value if not 21 <= n <= 108]
        if bad:
            raise ValueError(f"notes must be in [21, 108], got {bad[0]}")
        return value


class RigSpec(StrictModel):
    """A rig file: the simulated rig or the UR5 lab, with faults, pauses and envelope."""

    kind: Literal["sim", "ur5"] = Field("sim", description="sim: the simulated world; ur5: the lab.")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Seed of the simulated world (noise, faults).")
    realtime: bool = Field(
        False, description="Run the sim at wall-clock speed (default: a virtual clock)."
    )
    world: dict[str, Any] = Field(
        default_factory=dict,
        description="Simulated world configuration passed to the physics World; "
        "`preset: default | linear` picks a preset, other keys override it.",
    )
    faults: Faults = Field(default_factory=Faults, description="Faults the sim injects.")
    retry: Retry = Field(default_factory=Retry, description="Retry policy for transient faults.")
    envelope: EnvelopeOverrides = Field(
        default_factory=EnvelopeOverrides,
        description="Explicit per-finger ranges that widen (or narrow) the safety envelope.",
    )
    settle_s: Settle = Field(default_factory=Settle, description="Settle pauses.")
    travel: Travel = Field(default_factory=Travel, description="Moves between keys.")
    approach: Approach = Field(
        default_factory=Approach, description="Fast approach and retract (specs with approach: fast)."
    )
    ur5: UR5Config | None = Field(None, description="The arm (kind ur5 only).")
    vacuum: VacuumConfig = Field(default_factory=VacuumConfig, description="Vacuum regulator.")
    midi: MidiConfig | None = Field(None, description="MIDI input (required for kind ur5).")
    mocap: MocapConfig = Field(default_factory=MocapConfig, description="Motion capture.")
    keyboard: KeyboardConfig = Field(
        default_factory=KeyboardConfig, description="Keyboard geometry."
    )

    @field_validator("world")
    @classmethod
    def _world(cls, value: dict[str, Any]) -> dict[str, Any]:
        preset = value.get("preset", "default")
        if preset not in WORLD_PRESETS:
            raise ValueError(f"preset must be one of {', '.join(WORLD_PRESETS)}, got {preset!r}")
        overrides = {k: v for k, v in value.items() if k != "preset"}
        _refuse_non_numbers(overrides, ())
        if overrides:
            # Imported only when needed: the physics world pulls in the simulator.
            from pianobot.physics.world import WorldConfig

            try:
                # Building the model also checks the MSD parameter and effect names.
                WorldConfig.model_validate(overrides, strict=True).build_model()
            except ValidationError as exc:
                path, message = error_message(exc.errors()[0], list(WorldConfig.model_fields))
                raise ValueError(f"{format_path(path)}: {message}") from None
            except (TypeError, ValueError) as exc:
                raise ValueError(" ".join(str(exc).split())) from None
        return value

    @model_validator(mode="after")
    def _sections_match_kind(self) -> RigSpec:
        if self.kind == "ur5" and (self.ur5 is None or self.midi is None):
            raise ValueError("a ur5 rig needs both a `ur5:` and a `midi:` section")
        if self.kind == "sim" and self.ur5 is not None:
            raise ValueError("the `ur5:` section is only for kind: ur5")
        return self

    def envelope_for(self, finger: Finger, source: str = "the rig file") -> dict[str, Limits]:
        """The finger's safety envelope with this rig's explicit overrides applied."""
        limits = dict(FINGER_ENVELOPES[finger])
        overrides: FingerEnvelope | None = getattr(self.envelope, finger)
        if overrides is not None:
            for name, (low, high) in overrides.ranges().items():
                limits[name] = Limits(low, high, source=f"set by {source}")
        return limits

    @property
    def lift_m(self) -> float:
        """Lift before a sideways move: the arm's safe lift on the UR5, else `travel.lift_m`."""
        return self.ur5.safe_lift_m if self.ur5 is not None else self.travel.lift_m


def _refuse_non_numbers(value: Any, path: tuple[str | int, ...]) -> None:
    """In `world:`, every setting is a finite number (or a name where a name is meant).

    The physics world takes plain dicts of parameters and would turn `true` into 1.0.
    """
    if isinstance(value, dict):
        for key, item in value.items():
            _refuse_non_numbers(item, (*path, str(key)))
        return
    if isinstance(value, list | tuple):
        for i, item in enumerate(value):
            _refuse_non_numbers(item, (*path, i))
        return
    name = next((p for p in reversed(path) if isinstance(p, str)), "")
    if value is None or (isinstance(value, str) and name in _WORLD_TEXT_KEYS):
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{format_path(path)}: must be a number, got {value!r}")
    if isinstance(value, float) and value != value or value in (float("inf"), float("-inf")):
        raise ValueError(f"{format_path(path)}: must be a finite number, got {value!r}")
