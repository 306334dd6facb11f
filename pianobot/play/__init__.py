"""Playing songs: MIDI file → melody → model-based plan → rig → performance → score.

    result = play_song(Path("experiments/songs/twinkle.mid"), data_dir=Path("data"))
    print(result.score.f1, result.plan.dynamics.describe())

Modules: `warmup` (the calibration on the piano before the song) and `warmup_model` (what it
fits), `tempo` (the user's tempo request and the fastest tempo the finger keeps), `plan` (the
model-based planner), `schedule` (fitting the presses into the song's time), `geometry` (hover,
depth, the two-segment press), `strokes` (a model tabulated for fast inverses), `dynamics`
(loudness mapping), `naive` (the study's demo logic as a baseline), `perform` (execution on the
rig as a run), `adapt` and `corrections` (online correction while playing), `score` (mir_eval,
strict and tempo-relative), `figure` and `report` (piano roll, warm-up fit, the run's HTML
page), `library` (test songs in code), `session` (the whole `play` command).
"""

from __future__ import annotations

from pianobot.play.adapt import OnlineAdapter
from pianobot.play.dynamics import DynamicsMap
from pianobot.play.naive import plan_naive
from pianobot.play.perform import Performance, Performer
from pianobot.play.score import Score, score_performance
from pianobot.play.session import PlayResult, load_song, play_rig, play_song
from pianobot.play.settings import PlaySettings
from pianobot.play.song_plan import SongPlan, plan_model
from pianobot.play.tempo import Feasibility, TempoChoice, TempoRequest
from pianobot.play.warmup import WarmUp

__all__ = [
    "DynamicsMap",
    "Feasibility",
    "OnlineAdapter",
    "Performance",
    "SongPlan",
    "PlayResult",
    "PlaySettings",
    "Score",
    "TempoChoice",
    "TempoRequest",
    "WarmUp",
    "load_song",
    "Performer",
    "plan_model",
    "plan_naive",
    "play_rig",
    "play_song",
    "score_performance",
]
