"""The simulated lab: true keystroke physics plus what the instruments would report.

`World(config, seed)` holds a true `KeystrokeModel` (by default richer than the study's model:
unilateral contact, keybed, preload, friction, stiffening, let-off, ... see
`Effects.default_world`) and observation models: the arm's controller-rate TCP trace, 120 Hz
motion capture with µm noise, dropped frames and a clock offset, and the digital piano's MIDI.

Every keystroke is a pure function of (config, seed, press, vacuum, note, key): its noise comes
from an RNG seeded by (seed, key), and stiffness drift is a hash of (seed, block), so a resumed
run reproduces an uninterrupted one exactly.

A sweep knows its next keystrokes in advance: `prefetch` simulates their true trajectories in
one vectorised batch (sorted by length, so short keystrokes do not run to the longest one's
horizon), and `keystroke` then only observes. The simulator gives a keystroke the same samples
alone and in any batch, so prefetching never changes a result.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from pianobot.physics._observe_kernel import interp, settled
from pianobot.physics.effects import Effects
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams
from pianobot.physics.piano import PianoEvent, PianoParams, key_events
from pianobot.physics.simulate import BATCH_LANES, SimBatch, output_count, simulate_presses
from pianobot.physics.trajectory import Press, press_duration_s

FloatArray = npt.NDArray[np.float64]

# A keystroke is at rest once arm and key stay this close to their rest positions.
REST_TOL_M = 2e-5

# The default world's piano (PianoParams' defaults: sensors at 1.8 and 3.8 mm of the 10 mm dip)
# with a velocity curve that maps the soft finger's key speeds between the sensors (a few mm/s
# to a few cm/s) onto the velocities the real Kawai reported for it: 1-2 for slow presses,
# 10-20 for fast ones, up to ~60 for the fastest approaches.
DEFAULT_CURVE: dict[str, float] = {"curve_exponent": 2.0, "curve_saturation": 1.0}


class MocapObservation(BaseModel):
    """Motion capture observation model."""

    model_config = ConfigDict(extra="forbid")

    rate_hz: float = Field(120.0, gt=0, description="frame rate")
    noise_m: float = Field(3e-6, ge=0, description="position noise (standard deviation)")
    drop_prob: float = Field(0.002, ge=0, le=1, description="probability a frame is lost")
    clock_offset_s: float = Field(0.0, description="mocap clock minus true time")


class WorldConfig(BaseModel):
    """Everything that defines a simulated world (YAML-able; unknown keys are refused)."""

    model_config = ConfigDict(extra="forbid")

    msd: dict[str, Any] = Field(default_factory=dict, description="MSDParams overrides")
    effects: dict[str, dict[str, Any] | None] | None = Field(
        None, description="effect -> {form, params}; null = the default world's effects"
    )
    piano: dict[str, float] = Field(default_factory=dict, description="PianoParams overrides")
    mocap: MocapObservation = Field(default_factory=MocapObservation)
    arm_rate_hz: Literal[125, 500] = Field(500, description="UR controller (RTDE) rate")
    arm_noise_m: float = Field(1e-6, ge=0, description="TCP position noise")
    midi_jitter_s: float = Field(5e-4, ge=0, description="MIDI timestamp jitter (uniform)")
    vacuum_tau_s: float = Field(1.5, gt=0, description="vacuum regulator time constant")
    vacuum_tolerance_kpa: float = Field(0.5, gt=0, description="settled when this close")
    step_s: float = Field(2e-4, gt=0, le=2e-4, description="internal integration step")
    out_dt_s: float = Field(1e-3, gt=0, description="truth sample interval")
    settle_s: float = Field(0.4, ge=0, description="simulated time after the arm is back up")

    def build_model(self) -> KeystrokeModel:
        """The true keystroke model this config describes."""
        effects = Effects.default_world() if self.effects is None else Effects.from_dict(self.effects)
        piano = PianoParams.from_dict({**DEFAULT_CURVE, **self.piano})
        piano = piano.replace(jitter_s=self.midi_jitter_s)
        return KeystrokeModel(MSDParams.from_dict(self.msd), effects, piano)


@dataclass(frozen=True)
class WorldKeystroke:
    """One simulated keystroke as truth and as the instruments saw it (absolute times)."""

    t0_s: float
    duration_s: float
    truth_t_s: FloatArray
    truth_x0_m: FloatArray
    truth_x1_m: FloatArray
    truth_x2_m: FloatArray
    arm_t_s: FloatArray
    arm_x0_m: FloatArray
    mocap_t_s: FloatArray
    mocap_x0_m: FloatArray
    mocap_x1_m: FloatArray
    mocap_x2_m: FloatArray
    midi: tuple[PianoEvent, ...]
    key_speed_at_trigger_mps: float
    max_key_travel_m: float
    rel_t_s: FloatArray | None = None  # the truth samples' times from motion start (exact grid)

    @property
    def silent(self) -> bool:
        return not any(e.type == "note_on" for e in self.midi)

    @property
    def on_velocity(self) -> int | None:
        """Velocity of the first note-on, None if silent."""
        for e in self.midi:
            if e.type == "note_on":
                return e.velocity
        return None


def _seed_of(text: str) -> int:
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "big")


class World:
    """A simulated lab with a known true model and noisy instruments."""

    def __init__(self, config: WorldConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else WorldConfig()
        self.seed = int(seed)
        self.model = self.config.build_model()
        self._readout = self.model.readout_params()
        self._mocap_offset_s = self.config.mocap.clock_offset_s + self.model.mocap_delay_s
        self._truth: dict[tuple[Press, float, str], _Truth] = {}  # prefetched keystrokes
        self._uses: dict[tuple[Press, float, str], int] = {}  # how often each will be asked for

    @classmethod
    def default(cls, seed: int = 0) -> World:
        """Several effects on with realistic values (see `Effects.default_world`)."""
        return cls(WorldConfig(), seed)

    @classmethod
    def linear(cls, seed: int = 0) -> World:
        """Only the study's linear model (ramp arm, linear readout) plus observation noise."""
        return cls(WorldConfig(effects={}), seed)

    def describe(self) -> dict[str, Any]:
        return {"seed": self.seed, "config": self.config.model_dump(), "model": self.model.to_dict()}

    def vacuum_settle_s(self, from_kpa: float, to_kpa: float) -> float:
        """Time for the regulator (first order) to get within tolerance of a new level."""
        step = abs(float(to_kpa) - float(from_kpa))
        tol = self.config.vacuum_tolerance_kpa
        if step <= tol:
            return 0.0
        return self.config.vacuum_tau_s * math.log(step / tol)

    def _block_key(self, vacuum_kpa: float, block: str | None) -> str:
        return f"{self.seed}|{block if block is not None else f'{float(vacuum_kpa):g}'}"

    def simulate(
        self, presses: Sequence[Press], vacuum_kpa: npt.ArrayLike, blocks: Sequence[str | None] | None = None
    ) -> SimBatch:
        """True trajectories of many presses at once (no observation noise)."""
        p = np.broadcast_to(np.asarray(vacuum_kpa, dtype=np.float64), (len(presses),))
        bl = list(blocks) if blocks is not None else [None] * len(presses)
        keys = [self._block_key(float(v), b) for v, b in zip(p, bl, strict=True)]
        cfg = self.config
        dur = max((self._horizon_s(pr) for pr in presses), default=cfg.settle_s)
        return simulate_presses(presses, p, self.model, out_dt_s=cfg.out_dt_s, duration_s=dur,
                                step_s=cfg.step_s, block_keys=keys)

    def _horizon_s(self, press: Press) -> float:
        """How long a keystroke is simulated when it is alone: the press plus settling time.

        In a batch every keystroke runs to the longest one's horizon; observations are cut at
        the keystroke's own horizon so that a keystroke never depends on its companions.
        """
        return press_duration_s(press, "trapezoid") + self.config.settle_s

    def prefetch(
        self, presses: Sequence[Press], vacuum_kpa: npt.ArrayLike,
        blocks: Sequence[str | None] | None = None, *, lanes: int = BATCH_LANES,
    ) -> None:
        """Simulate the true trajectories of keystrokes about to be asked for, in batches.

        The next `keystroke` of each (press, vacuum, block) takes its truth from here instead
        of simulating it alone (bit for bit the same samples). Earlier prefetched keystrokes
        that were never asked for are dropped, so memory holds one block at most.
        """
        p = np.broadcast_to(np.asarray(vacuum_kpa, dtype=np.float64), (len(presses),))
        bl = list(blocks) if blocks is not None else [None] * len(presses)
        wanted: dict[tuple[Press, float, str], str | None] = {}
        uses: dict[tuple[Press, float, str], int] = {}
        for press, vacuum, block in zip(presses, p.tolist(), bl, strict=True):
            k = (press, vacuum, self._block_key(vacuum, block))
            wanted[k] = block
            uses[k] = uses.get(k, 0) + 1  # the same keystroke twice (e.g. repeats): same truth
        self._uses = uses
        truth = {k: v for k, v in self._truth.items() if k in wanted}
        todo = sorted((k for k in wanted if k not in truth), key=lambda k: self._horizon_s(k[0]))
        for start in range(0, len(todo), lanes):  # similar lengths share a batch
            chunk = todo[start : start + lanes]
            batch = self.simulate([k[0] for k in chunk], [k[1] for k in chunk],
                                  [wanted[k] for k in chunk])
            for j, k in enumerate(chunk):
                # Views into the batch: it lives until its last keystroke is taken (one block).
                own = output_count(self._horizon_s(k[0]), self.config.out_dt_s)
                truth[k] = _Truth(batch.t_s[:own], batch.x0_m[j, :own], batch.x1_m[j, :own],
                                  batch.x2_m[j, :own], batch.v2_mps[j, :own])
        self._truth = truth

    def prefetched(self) -> dict[Any, Any]:
        """The truths the last `prefetch` holds and no keystroke has taken yet, for `adopt`."""
        return dict(self._truth)

    def adopt(self, truths: Mapping[Any, Any]) -> None:
        """Truths an equal world prefetched (`prefetched`): the next `prefetch` keeps those it
        wants instead of simulating them again (the same samples: a truth depends only on its
        keystroke, the model and the seed, which its key holds)."""
        self._truth.update(truths)

    def keystroke(
        self,
        press: Press,
        vacuum_kpa: float,
        *,
        note: int = 57,
        t0_s: float = 0.0,
        key: str = "",
        block: str | None = None,
    ) -> WorldKeystroke:
        """One keystroke from motion start to rest, as truth and as observed.

        `key` seeds the observation noise (use the trial id); `block` labels the stiffness-drift
        block (default: the vacuum level, i.e. one drift per level and world).
        """
        return self._observe(self._take(press, vacuum_kpa, block), press, note, t0_s, key)

    def settled_truth(
        self, press: Press, vacuum_kpa: float, *, block: str | None = None
    ) -> SettledTruth:
        """The true trajectory `keystroke` would observe (from motion start until the arm is
        back and the key at rest), without the observation: no noise, no MIDI."""
        truth = self._take(press, vacuum_kpa, block)
        duration, keep, _, _ = settled(truth.t_s, truth.x1_m, truth.x2_m, truth.v2_mps,
                                       press_duration_s(press, self.model.arm_profile), REST_TOL_M,
                                       self._readout.lower_sensor_m)
        return SettledTruth(float(duration), truth.t_s[:keep], truth.x0_m[:keep], truth.x2_m[:keep])

    def _take(self, press: Press, vacuum_kpa: float, block: str | None) -> _Truth:
        """A keystroke's truth: prefetched (once per time it was prefetched for) or simulated."""
        k = (press, float(vacuum_kpa), self._block_key(vacuum_kpa, block))
        cached = self._truth.get(k)
        if cached is not None:
            self._uses[k] = left = self._uses.get(k, 1) - 1
            if left <= 0:
                del self._truth[k]
            return cached
        batch = self.simulate([press], vacuum_kpa, [block])
        own = output_count(self._horizon_s(press), self.config.out_dt_s)
        return _Truth(batch.t_s[:own], batch.x0_m[0, :own], batch.x1_m[0, :own],
                      batch.x2_m[0, :own], batch.v2_mps[0, :own])

    def keystrokes(
        self,
        presses: Sequence[Press],
        vacuum_kpa: npt.ArrayLike,
        *,
        note: int = 57,
        t0_s: npt.ArrayLike = 0.0,
        keys: Sequence[str] | None = None,
        blocks: Sequence[str | None] | None = None,
    ) -> list[WorldKeystroke]:
        """Many keystrokes in one batch (the same results as calling `keystroke` for each)."""
        n = len(presses)
        batch = self.simulate(presses, vacuum_kpa, blocks)
        t0 = np.broadcast_to(np.asarray(t0_s, dtype=np.float64), (n,))
        ks = list(keys) if keys is not None else [""] * n
        out = []
        for j in range(n):
            own = output_count(self._horizon_s(presses[j]), self.config.out_dt_s)
            truth = _Truth(batch.t_s[:own], batch.x0_m[j, :own], batch.x1_m[j, :own],
                           batch.x2_m[j, :own], batch.v2_mps[j, :own])
            out.append(self._observe(truth, presses[j], note, float(t0[j]), ks[j]))
        return out

    def _observe(
        self, truth: _Truth, press: Press, note: int, t0_s: float, key: str
    ) -> WorldKeystroke:
        cfg = self.config
        rng = np.random.default_rng([self.seed, _seed_of(key)])
        t_end = press_duration_s(press, self.model.arm_profile)
        # Rest time (arm back up, key within REST_TOL_M of rest for good), the samples up to it, the key speed where it first passes
        # the lower sensor and its deepest point, in one compiled pass over the truth.
        duration, keep, speed, deepest = settled(
            truth.t_s, truth.x1_m, truth.x2_m, truth.v2_mps, t_end, REST_TOL_M,
            self._readout.lower_sensor_m,
        )
        # The samples up to `duration` (t_s is increasing): views, not copies.
        t = truth.t_s[:keep]
        x0, x1, x2 = truth.x0_m[:keep], truth.x1_m[:keep], truth.x2_m[:keep]

        # Read on the run clock, so timestamps fall on its 1 ms MIDI ticks.
        t_run = t0_s + t
        midi, _ = key_events(t_run, x2, self._readout, note=note, rng=rng)

        t_arm = np.arange(0.0, duration + 1e-9, 1.0 / cfg.arm_rate_hz)
        arm = interp(t_arm, t, x0) + rng.normal(0.0, cfg.arm_noise_m, t_arm.size)

        # Mocap frames fall at true times τ; the mocap clock stamps them τ + offset.
        frame = 1.0 / cfg.mocap.rate_hz
        tau = np.arange(rng.uniform(0.0, frame), duration, frame)
        lost = rng.random(tau.size) < cfg.mocap.drop_prob
        mocap = []
        for x in (x0, x1, x2):
            m = interp(tau, t, x) + rng.normal(0.0, cfg.mocap.noise_m, tau.size)
            m[lost] = np.nan  # a lost frame loses every marker at once
            mocap.append(m)
        return WorldKeystroke(
            t0_s=t0_s,
            duration_s=float(duration),
            truth_t_s=t_run,
            # Views: the prefetched batch they belong to lives one block (its truth), no longer.
            truth_x0_m=x0,
            truth_x1_m=x1,
            truth_x2_m=x2,
            arm_t_s=t0_s + t_arm,
            arm_x0_m=arm,
            mocap_t_s=t0_s + tau + self._mocap_offset_s,
            mocap_x0_m=mocap[0],
            mocap_x1_m=mocap[1],
            mocap_x2_m=mocap[2],
            midi=tuple(midi),
            key_speed_at_trigger_mps=speed,
            max_key_travel_m=deepest,
            rel_t_s=t,
        )


@dataclass(frozen=True)
class SettledTruth:
    """A keystroke's true arm and key positions until it is at rest (times from motion start)."""

    duration_s: float
    rel_t_s: FloatArray
    truth_x0_m: FloatArray
    truth_x2_m: FloatArray


@dataclass(frozen=True)
class _Truth:
    """One keystroke's true samples up to its own horizon (time from motion start)."""

    t_s: FloatArray
    x0_m: FloatArray
    x1_m: FloatArray
    x2_m: FloatArray
    v2_mps: FloatArray

