"""Playing songs: MIDI file → melody → model-based plan → rig → performance → score.

    result = play_song(Path("experiments/songs/twinkle.mid"), data_dir=Path("data"))
    print(result.score.f1, result.plan.dynamics.describe())

Modules: `plan` (the model-based planner), `naive` (the study's demo logic as a baseline),
`strokes` (a model tabulated for fast inverses), `dynamics` (loudness mapping), `perform`
(execution on the rig as a run), `adapt` and `corrections` (online correction while playing),
`score` (mir_eval), `figure` (piano roll), `library` (test songs in code), `session` (the whole
`play` command).
"""

from __future__ import annotations

from pianobot.play.adapt import OnlineAdapter
from pianobot.play.dynamics import DynamicsMap
from pianobot.play.naive import plan_naive
from pianobot.play.perform import Performance, perform
from pianobot.play.plan import Plan, plan_model
from pianobot.play.score import Score, score_performance
from pianobot.play.session import PlayResult, load_song, play_rig, play_song
from pianobot.play.settings import PlaySettings

__all__ = [
    "DynamicsMap",
    "OnlineAdapter",
    "Performance",
    "Plan",
    "PlayResult",
    "PlaySettings",
    "Score",
    "load_song",
    "perform",
    "plan_model",
    "plan_naive",
    "play_rig",
    "play_song",
    "score_performance",
]
