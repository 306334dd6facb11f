"""Closing the loop while playing: online correction of the planner's model, note by note.

After each note the MIDI the piano reported is compared with what was expected, and the
planner's loudness map (on-velocity over down velocity, per vacuum level) and lead map (motion
start → note-on) are corrected in two layers (see `corrections`):

    expected(v) = a + b · model(v)      global: recursive least squares, bounded steps
                + r(v)                  local: kernel regression of what is left, near the
                                        speeds already played at this vacuum level

A different piano (velocity curve) scales and shifts the whole map, which the global layer
learns within a few notes; a stiffer finger also changes the map's shape over down velocity
(where finger and key separate on the way down, the key's speed between the sensors jumps), which
no global gain can undo and which the local layer learns near the notes actually played.

For the next note the adapter forecasts loudness (mean and spread) and lead at candidate down
velocities and plays the stroke whose forecast is closest to the target among those that can
still start on time (certainty equivalence). Charging the spread as well, as the expected
squared error of this one note would, keeps the adapter on speeds it has already played and
it never tries the ones between them; a song comes back to similar loudness many times, so
what one trial teaches pays back (`exploration` sets the spread's weight, 0 by default).
Every update is recorded (`history`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from pianobot.play.corrections import RLS2, LocalCorrection

if TYPE_CHECKING:  # the plan imports nothing from here; annotations only
    from pianobot.play.song_plan import SongPlan

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

FEASIBILITY_GRID = 200  # down velocities checked for an on-time start when adapting
# Observations kept per vacuum level for the local layer: bounds the cost per note (a Cholesky
# of this size) over a long song; with forgetting, older notes weigh little anyway.
LOCAL_WINDOW = 120


@dataclass(frozen=True)
class Observation:
    """One played note as the adapter saw it (silent: played velocity 0, no lead)."""

    update: int  # running number of the observation
    note_index: int
    vacuum_kpa: float
    speed_mps: float
    model_velocity: float  # the uncorrected model at this stroke
    model_lead_s: float
    played_velocity: float
    observed_lead_s: float | None


@dataclass(frozen=True)
class Forecast:
    """The corrected model at candidate down velocities of one vacuum level."""

    speeds_mps: FloatArray
    velocity: FloatArray
    velocity_sd: FloatArray
    lead_s: FloatArray

    def best(self, target_velocity: float, allowed: BoolArray | None = None, spread_weight: float = 1.0) -> int:
        """Index of the allowed speed minimising (mean − target)² + spread_weight · spread².

        With nothing allowed (no stroke can start on time) the shortest-lead stroke.
        """
        cost = (self.velocity - target_velocity) ** 2 + spread_weight * self.velocity_sd**2
        if allowed is not None:
            if not allowed.any():
                return int(np.argmin(self.lead_s))
            cost = np.where(allowed, cost, np.inf)
        return int(np.argmin(cost))


def _velocity_rls() -> RLS2:
    return RLS2.prior(offset_sd=3.0, gain_sd=0.3, max_step=(2.0, 0.15), bounds=((-30.0, 30.0), (0.3, 3.0)),
                      forgetting=0.97)


def _lead_rls() -> RLS2:
    return RLS2.prior(offset_sd=0.05, gain_sd=0.2, max_step=(0.05, 0.1), bounds=((-0.5, 0.5), (0.5, 2.0)),
                      forgetting=0.97)


@dataclass
class OnlineAdapter:
    """The planner's online corrections of loudness and lead, with their history.

    Local length scale: 1 mm/s, 2 % of a soft finger's speed range (0.01–0.06 m/s) and about
    the width of the plateaus between the steps a finger–key separation puts into the loudness
    map. Spreads: a MIDI velocity is an integer (quantisation sd 0.3) from a piano with some
    scatter of its own; a note-on time is stamped to 1 ms with sub-millisecond jitter.
    """

    velocity: RLS2 = field(default_factory=_velocity_rls)
    lead: RLS2 = field(default_factory=_lead_rls)
    velocity_local: LocalCorrection = field(default_factory=lambda: LocalCorrection(
        scales=((0.001, 3.0),), noise_sd=0.5, forgetting=0.98, max_residual=30.0))
    lead_local: LocalCorrection = field(default_factory=lambda: LocalCorrection(
        scales=((0.001, 0.02),), noise_sd=0.002, forgetting=0.98, max_residual=0.2))
    exploration: float = 0.0  # weight of the forecast's spread in a stroke's cost (see `choose`)
    velocity_noise_var: float = 1.0  # for the global layer: quantisation plus the local shape
    lead_noise_var: float = 1e-4  # ~10 ms
    observations: list[Observation] = field(default_factory=list)
    history: list[dict[str, Any]] = field(default_factory=list)

    def forecast(self, vacuum_kpa: float, speeds_mps: npt.ArrayLike, model_velocity: npt.ArrayLike,
                 model_lead_s: npt.ArrayLike) -> Forecast:
        """Corrected loudness (mean, sd) and lead at `speeds_mps` (model values given per speed)."""
        v = np.asarray(speeds_mps, dtype=np.float64)
        m_vel = np.asarray(model_velocity, dtype=np.float64)
        m_lead = np.asarray(model_lead_s, dtype=np.float64)
        seen = self._at_level(vacuum_kpa)
        ages = np.array([len(self.observations) - 1 - o.update for o in seen], dtype=np.float64)
        xs = np.array([o.speed_mps for o in seen], dtype=np.float64)
        r_vel = np.array([o.played_velocity for o in seen]) - self.velocity.predict([o.model_velocity for o in seen])
        vel_mean, vel_sd = self.velocity_local.posterior(xs, r_vel, ages, v)
        timed = np.array([o.observed_lead_s is not None for o in seen], dtype=bool)
        r_lead = (np.array([o.observed_lead_s for o in seen if o.observed_lead_s is not None], dtype=np.float64)
                  - self.lead.predict([o.model_lead_s for o in seen if o.observed_lead_s is not None]))
        lead_mean, _ = self.lead_local.posterior(xs[timed], r_lead, ages[timed], v)
        velocity = np.clip(self.velocity.predict(m_vel) + vel_mean, 0.0, 127.0)
        return Forecast(v, velocity, vel_sd, self.lead.predict(m_lead) + lead_mean)

    def choose(self, forecast: Forecast, target_velocity: float, allowed: BoolArray | None = None) -> int:
        """Index of the forecast's stroke to play for a target loudness (see `Forecast.best`)."""
        return forecast.best(target_velocity, allowed, self.exploration)

    def observe(self, note_index: int, vacuum_kpa: float, speed_mps: float, model_velocity: float,
                model_lead_s: float, played_velocity: float | None, observed_lead_s: float | None,
                *, forecast_velocity: float = float("nan"), forecast_lead_s: float = float("nan")) -> None:
        """Learn from one played note (a silent note counts as on-velocity 0, without a lead).

        `forecast_*` are what the adapter expected for this stroke (recorded in the history).
        """
        y = 0.0 if played_velocity is None else float(played_velocity)
        lead = None if observed_lead_s is None or not np.isfinite(observed_lead_s) else float(observed_lead_s)
        self.velocity.update(float(model_velocity), y, self.velocity_noise_var)
        if lead is not None:
            self.lead.update(float(model_lead_s), lead, self.lead_noise_var)
        self.observations.append(Observation(len(self.observations), int(note_index), float(vacuum_kpa),
                                             float(speed_mps), float(model_velocity), float(model_lead_s), y, lead))
        self.history.append({
            "note_index": int(note_index),
            "vacuum_kpa": float(vacuum_kpa),
            "down_velocity_mps": float(speed_mps),
            "model_velocity": float(model_velocity),
            "predicted_velocity": float(forecast_velocity),
            "played_velocity": played_velocity,
            "model_lead_s": float(model_lead_s),
            "predicted_lead_s": float(forecast_lead_s),
            "observed_lead_s": lead,
            **self.state(),
            "local_points": len(self._at_level(vacuum_kpa)),
        })

    def state(self) -> dict[str, float]:
        """The global layer's parameters (the local layer is the observations themselves)."""
        return {
            "velocity_offset": float(self.velocity.theta[0]),
            "velocity_gain": float(self.velocity.theta[1]),
            "lead_offset_s": float(self.lead.theta[0]),
            "lead_gain": float(self.lead.theta[1]),
        }

    def _at_level(self, vacuum_kpa: float) -> list[Observation]:
        same = [o for o in self.observations if abs(o.vacuum_kpa - float(vacuum_kpa)) < 1e-6]
        return same[-LOCAL_WINDOW:]


def adapted_stroke(adapter: OnlineAdapter, plan: SongPlan, row: Any, earliest_s: float, origin_s: float,
                   following: Any | None) -> tuple[float, float, float, float]:
    """Down velocity, hold, expected on-velocity and lead of a note under the corrected model.

    The stroke is the one with the least expected loudness error among those that can still
    start by `earliest_s` (+ the allowed lateness). The hold is then cut, as the planner does
    (shorten the previous hold before playing a note louder): so the arm is free when the plan
    expects it, and early enough for the stroke the corrected model wants for the following
    note — a model that learned the piano is louder asks for slower strokes, whose longer lead
    needs an earlier start than planned. `row`/`following` are plan rows (attribute access).
    """
    table = plan.tables[float(row.vacuum_kpa)]
    forecast = _forecast(adapter, plan, row)
    onset = origin_s + float(row.onset_s)
    # As the planner does: lateness (up to max_late_s) only where no stroke starts on time.
    on_time = onset - forecast.lead_s >= earliest_s
    if not on_time.any():
        on_time = onset - forecast.lead_s >= earliest_s - plan.settings.max_late_s
    k = adapter.choose(forecast, float(row.target_velocity), on_time)
    speed, lead = float(forecast.speeds_mps[k]), float(forecast.lead_s[k])
    free_by = origin_s + float(row.start_s) + float(row.busy_s)
    if following is not None:
        ahead = _forecast(adapter, plan, following)
        j = adapter.choose(ahead, float(following.target_velocity))
        between = float(following.move_s) if int(following.pitch) != int(row.pitch) else 0.0
        if abs(float(following.vacuum_kpa) - float(row.vacuum_kpa)) > 1e-9:
            between += float(following.vacuum_change_s)
        free_by = min(free_by, origin_s + float(following.onset_s) - float(ahead.lead_s[j]) - between)
    room = free_by - (onset - lead) - table.busy_s(speed, 0.0)
    hold = float(min(float(row.hold_s), max(0.0, room)))
    return speed, hold, float(forecast.velocity[k]), lead


def _forecast(adapter: OnlineAdapter, plan: SongPlan, row: Any) -> Forecast:
    """The adapter's corrected model over a fine grid of down velocities at the row's vacuum."""
    table = plan.tables[float(row.vacuum_kpa)]
    grid = np.linspace(table.speeds_mps[0], table.speeds_mps[-1], FEASIBILITY_GRID)
    return adapter.forecast(float(row.vacuum_kpa), grid, table.predict_velocity(grid), table.lead(grid))
