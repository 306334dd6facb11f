"""The warm-up: a few keystrokes on the song's keys before the song, like a pianist on a new piano.

The model a planner starts with (the published physics model, or a file) was made on another
piano, finger or day; what `play` must get right — when a stroke sounds after motion start
(the lead) and how loud — depends on exactly those. So before the song the rig plays a short
calibration with the stroke geometry and at the vacuum levels the song will use:

- first a survey: a few down velocities spread over the finger's whole range (the slowest
  considered to the envelope's fastest), which finds where strokes fall silent and where the
  loudness stops growing; then the rest of the keystrokes spread over that useful range, so the
  fit sees the loudness range from the quiet edge to the loudest;
- on the song's keys in turn (a neighbouring key while the last one returns), every other
  stroke with a held note, so the hold map is learned too.

The note-on delay (lead), loudness, note-off and silence maps are then fitted to these
keystrokes with the project's learned predictors (`warmup_model`: `pianobot fit`'s model kinds,
the one with the smallest error on held-out strokes), and the song is planned with that fit. The warm-up keystrokes are stored in the play run (phase
`warmup`) and summarised in its report.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from pianobot.plan import Trial, lab_time
from pianobot.play.geometry import StrokeGeometry, stroke_trial
from pianobot.play.settings import PlaySettings
from pianobot.play.warmup_model import WarmUpPredictor
from pianobot.spec import RigSpec

SURVEY_MIN = 4  # keystrokes per level of the first pass, at least
WARMUP_SETTLE_S = 0.1  # after each warm-up stroke: the note-off arrives, the key comes to rest


def warmup_trial_id(song_key: str, index: int) -> str:
    """A stable id per (song, warm-up stroke)."""
    return hashlib.sha256(f"{song_key}|warmup|{index}".encode()).hexdigest()[:16]


def survey_size(strokes_per_level: int) -> int:
    """Keystrokes per level of the first pass (the survey); the rest map the useful range."""
    return min(strokes_per_level, max(SURVEY_MIN, round(strokes_per_level / 3)))


def design_warmup(pitches: Sequence[int], geometry: StrokeGeometry, levels_kpa: Sequence[float],
                  settings: PlaySettings, rig: RigSpec, *, strokes_per_level: int, song_key: str,
                  survey: pd.DataFrame | None = None, start: int | None = None) -> list[Trial]:
    """One pass of the warm-up keystrokes, level by level (the regulator settles once per level).

    Without `survey`: the first pass, `survey_size` down velocities spread geometrically over
    [`min_down_velocity_mps`, the envelope's fastest] (loudness grows like a power of the speed
    and the lead like its inverse, so equal ratios see equal changes). With the first pass's
    trials rows as `survey`: the rest of the strokes, geometrically over the speeds where the
    loudness changed (`useful_speeds`). Each stroke is on one of the song's keys in turn (the
    most frequent first); every other one holds the key. `start`: the first keystroke's index
    (default: after the survey, or 0), for a first pass at more levels after an earlier one.
    """
    if strokes_per_level <= 0:
        return []
    cap = rig.envelope_for(settings.finger)["down_velocity_mps"].high
    slowest = min(settings.min_down_velocity_mps, cap)
    first = survey_size(strokes_per_level)
    counts: dict[int, int] = {}
    for p in pitches:
        counts[int(p)] = counts.get(int(p), 0) + 1
    keys = sorted(counts, key=lambda p: (-counts[p], p)) or [60]
    if start is None:
        start = 0 if survey is None else len(survey)
    trials: list[Trial] = []
    for level in levels_kpa:
        if survey is None:
            speeds = np.geomspace(slowest, cap, first)
        else:
            lo, hi = useful_speeds(survey[np.isclose(survey["vacuum_kpa"], level)], slowest, cap)
            speeds = np.geomspace(lo, hi, strokes_per_level - first) if strokes_per_level > first else np.zeros(0)
        for j, speed in enumerate(speeds):
            index = start + len(trials)
            hold = settings.warmup_hold_s if (j + (survey is not None)) % 2 else 0.0
            trials.append(stroke_trial(warmup_trial_id(song_key, index), index, keys[index % len(keys)], level,
                                       geometry.press(float(speed), hold)))
    return trials


def useful_speeds(survey: pd.DataFrame, slowest_mps: float, cap_mps: float) -> tuple[float, float]:
    """The down velocities worth mapping, from a survey: where the loudness still changes.

    From the fastest stroke that is silent or no louder than the quietest heard (slower ones
    sound the same, later) to the slowest that is as loud as the loudest heard (faster ones are
    no louder; the planner uses them only to save time, where the survey's strokes teach the
    fit enough). The whole range when the survey heard nothing or one loudness.
    """
    speeds = survey["down_velocity_mps"].to_numpy(float)
    velocity = survey["on_velocity"].to_numpy(float)
    heard = np.isfinite(velocity)
    if heard.sum() < 2 or np.ptp(velocity[heard]) < 1.0:
        return slowest_mps, cap_mps
    quiet, loud = float(np.min(velocity[heard])), float(np.max(velocity[heard]))
    low = speeds[~heard | (velocity <= quiet + 0.5)]
    high = speeds[heard & (velocity >= loud - 0.5)]
    lo = float(np.max(low)) if low.size else slowest_mps
    hi = float(np.min(high)) if high.size else cap_mps
    return (lo, hi) if hi > lo * 1.05 else (slowest_mps, cap_mps)


def warmup_lab_time_s(survey: Sequence[Trial], rig: RigSpec, strokes_per_level: int) -> float:
    """The warm-up's lab time before it runs: the survey's presses, key changes, vacuum settling
    and pauses, scaled to the whole warm-up (the second pass's speeds are not known yet)."""
    if not survey:
        return 0.0
    estimate = lab_time(survey, rig)
    per_stroke = (estimate.presses_s + estimate.travel_s) / len(survey) + WARMUP_SETTLE_S
    levels = len({t.vacuum_kpa for t in survey})
    return estimate.vacuum_s + per_stroke * strokes_per_level * levels


class WarmUpFailed(RuntimeError):
    """The warm-up heard too little to learn the piano from (the run is kept, status failed)."""


@dataclass(frozen=True)
class WarmUp:
    """The warm-up as played and the model fitted to it."""

    trials: pd.DataFrame  # one row per warm-up keystroke (the run's trials rows, phase warmup)
    predictor: WarmUpPredictor
    geometry: StrokeGeometry
    levels_kpa: tuple[float, ...]  # levels where the warm-up heard notes
    lab_time_s: float  # first motion → last keystroke back up, on the rig clock
    speed_ranges_mps: dict[float, tuple[float, float]]  # per level: the down velocities mapped

    def summary(self) -> dict[str, Any]:
        """What the warm-up played and how well the fit explains it (in-sample)."""
        t = self.trials
        sounded = t[t["status"] == "ok"]
        fitted = self.predictor.predict(sounded) if len(sounded) else pd.DataFrame()
        out: dict[str, Any] = {
            "strokes": int(len(t)),
            "sounded": int(len(sounded)),
            "silent": int((t["status"] == "silent").sum()),
            "failed": int((t["status"] == "failed").sum()),
            "levels_kpa": list(self.levels_kpa),
            "geometry": self.geometry.to_dict(),
            "down_velocity_mps": [float(t["down_velocity_mps"].min()), float(t["down_velocity_mps"].max())],
            "mapped_mps": {f"{k:g}": list(v) for k, v in self.speed_ranges_mps.items()},
            "lab_time_s": self.lab_time_s,
            "fit": {row["kind"]: {"velocity_mae_held_out": row["velocity_mae"],
                                  "lead_rmse_ms_held_out": 1e3 * row["lead_rmse_s"],
                                  "used_for": [n for n in ("loudness", "lead") if row[n]]}
                    for row in self.predictor.cv_.to_dict(orient="records")},
        }
        if len(sounded):
            out["on_velocity"] = [float(sounded["on_velocity"].min()), float(sounded["on_velocity"].max())]
            out["lead_s"] = [float(sounded["t_on_s"].min()), float(sounded["t_on_s"].max())]
            cv = self.predictor.cv_
            out["velocity_mae_held_out"] = float(cv.loc[cv["loudness"], "velocity_mae"].iloc[0])
            out["lead_rmse_ms_held_out"] = 1e3 * float(cv.loc[cv["lead"], "lead_rmse_s"].iloc[0])
            out["fit_velocity_rmse"] = _rmse(fitted["on_velocity"], sounded["on_velocity"])
        return out


def fit_warmup(trials: pd.DataFrame, geometry: StrokeGeometry, *, lab_time_s: float, seed: int = 0,
               survey: int = 0) -> WarmUp:
    """Fit the lead, loudness, hold and silence maps to the warm-up keystrokes.

    The first `survey` rows per level are the survey; the speeds of the rest (the second pass)
    are the range the planner may use at that level (where the fit has seen enough).

    Raises:
        WarmUpFailed: the warm-up heard too few notes to learn from (the piano does not sound,
            MIDI is not connected, or the finger cannot reach the key).
    """
    played = trials[trials["status"].isin(["ok", "silent"])]
    sounded = played[played["status"] == "ok"]
    levels = tuple(sorted({float(v) for v in sounded["vacuum_kpa"]
                           if (sounded["vacuum_kpa"] == v).sum() >= 3}))
    if len(sounded) < 3 or not levels:
        raise WarmUpFailed(
            f"the warm-up heard {len(sounded)} note(s) from {len(trials)} keystroke(s): too few to learn "
            "this piano (is the MIDI input connected, does the finger reach the key?)"
        )
    predictor = WarmUpPredictor.fit(played, seed)
    ranges = {}
    for level in levels:
        at = trials[np.isclose(trials["vacuum_kpa"], level)]
        mapped = at.iloc[survey:] if len(at) > survey else at
        ranges[level] = (float(mapped["down_velocity_mps"].min()), float(mapped["down_velocity_mps"].max()))
    return WarmUp(trials.reset_index(drop=True), predictor, geometry, levels, float(lab_time_s), ranges)


def _rmse(a: pd.Series, b: pd.Series) -> float:
    err = a.to_numpy(float) - b.to_numpy(float)
    err = err[np.isfinite(err)]
    return float(np.sqrt(np.mean(err**2))) if err.size else math.nan
