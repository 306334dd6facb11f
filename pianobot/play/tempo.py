"""Which tempo to play at: the user's request, and the fastest tempo the finger can keep.

A note can be struck in time when the arm, done with the previous note, can start it at its
onset minus its lead (motion start → note-on). With both notes at their fastest stroke within
the loudness tolerance (a faster stroke sounds sooner and frees the arm sooner) and no hold,
consecutive notes p, i need

    onset_i − onset_p ≥ busy_p − lead_p + gap + lead_i               (arm back up, moved over)
    onset_i − onset_p ≥ midi_hold_p + restrike margin + lead_i        (same key: note-off first)

where busy is the press plus the recovery and gap the move to the other key plus a vacuum
change. Slowing the song by a factor s stretches every onset gap by s and nothing else, so the
whole song fits when s ≥ need_i / gap_i for every note: one pass over the notes, and each note's
own limit (`tempo_limit_bpm`) says which notes limit the tempo. A scheduler that starts every
note on time whenever these pairwise conditions hold (`schedule`) makes this limit exact.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from pianobot.errors import InputError

FloatArray = npt.NDArray[np.float64]
TempoMode = Literal["auto", "written", "bpm"]
LIMITING_SHOWN = 3  # limiting notes named in messages


def note_numbers(indices: Iterable[int]) -> str:
    """Notes as a musician counts them, from 1 (`note_index` in files and JSON counts from 0)."""
    return ", ".join(str(int(i) + 1) for i in indices)
FEW_FRACTION = 0.05  # "a few notes" slowing a whole song: at most this share of them (at least one)
MIN_TEMPO_BPM = 1.0
MAX_TEMPO_BPM = 1000.0


@dataclass(frozen=True)
class TempoRequest:
    """What the user asked for: `auto` (fastest feasible, never above the written tempo), the
    written tempo, or a tempo in quarter-note beats per minute. `explicit` is False only for the
    default (no tempo option given)."""

    mode: TempoMode = "auto"
    bpm: float | None = None
    explicit: bool = False

    @classmethod
    def parse(cls, text: str | None) -> TempoRequest:
        """`None` (the default: auto), "auto", "written" or a number of bpm; InputError otherwise."""
        if text is None:
            return cls()
        value = str(text).strip().lower()
        if value in ("auto", "written"):
            return cls(value, None, True)  # type: ignore[arg-type]
        try:
            bpm = float(value)
        except ValueError:
            raise InputError(f"tempo should be auto, written or beats per minute, got {text!r}", "--tempo") from None
        if not (math.isfinite(bpm) and MIN_TEMPO_BPM <= bpm <= MAX_TEMPO_BPM):
            raise InputError(f"tempo should be in [{MIN_TEMPO_BPM:g}, {MAX_TEMPO_BPM:g}] bpm, got {text}", "--tempo")
        return cls("bpm", bpm, True)

    @property
    def allows_skipping(self) -> bool:
        """Only a tempo the user chose may drop notes that cannot be struck in time."""
        return self.mode != "auto"

    def describe(self) -> str:
        return f"{self.bpm:g} bpm" if self.mode == "bpm" else self.mode


@dataclass(frozen=True)
class Feasibility:
    """Per note the fastest tempo at which it can be struck in time; the song's is their minimum."""

    written_bpm: float
    tempo_limit_bpm: FloatArray  # per note (inf for the first note and after a long rest)

    @property
    def fastest_bpm(self) -> float:
        """The fastest tempo at which every note can be struck in time (inf for one note)."""
        return float(np.min(self.tempo_limit_bpm)) if self.tempo_limit_bpm.size else math.inf

    def limiting(self, count: int = LIMITING_SHOWN) -> list[int]:
        """Indices of the notes with the lowest limits (ties in song order), at most `count`."""
        limits = self.tempo_limit_bpm
        if not np.isfinite(limits).any():
            return []
        order = np.lexsort((np.arange(limits.size), np.round(limits, 6)))
        return [int(i) for i in order[:count] if math.isfinite(limits[i])]

    def few_limit(self, fraction: float = FEW_FRACTION) -> tuple[int, float] | None:
        """(j, bpm) when j notes, at most `fraction` of them (at least one), alone hold the song
        below half the tempo `bpm` the other notes allow (capped at the written tempo): a grace
        note or a trill that slows a whole song to a crawl. None otherwise."""
        limits = np.sort(self.tempo_limit_bpm)
        fastest = float(limits[0]) if limits.size else math.inf
        if not math.isfinite(fastest):
            return None
        for j in range(1, max(1, int(fraction * limits.size)) + 1):
            others = min(float(limits[j]) if j < limits.size else math.inf, self.written_bpm)
            if others >= 2 * fastest:
                return j, others
        return None

    def infeasible_at(self, bpm: float) -> int:
        """How many notes cannot be struck in time at `bpm`."""
        return int(np.sum(self.tempo_limit_bpm < bpm * (1 - 1e-9)))


def tempo_limits(written_onset_s: FloatArray, need_s: FloatArray, written_bpm: float) -> Feasibility:
    """Per-note tempo limits from the onset gaps at the written tempo and what each note needs."""
    gaps = np.diff(written_onset_s, prepend=np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(np.isfinite(gaps) & (gaps > 0), need_s / gaps, np.where(np.isfinite(gaps), np.inf, 0.0))
        limit = np.where(ratio > 0, written_bpm / ratio, np.inf)
    limit[0] = np.inf
    return Feasibility(float(written_bpm), np.asarray(limit, dtype=np.float64))


@dataclass(frozen=True)
class TempoChoice:
    """The tempo a plan plays at and why."""

    request: TempoRequest
    written_bpm: float
    feasible_bpm: float  # the model's fastest feasible tempo (inf when unbounded, NaN: no model)
    played_bpm: float
    limiting_notes: tuple[int, ...]
    infeasible_notes: int  # notes that cannot be struck in time at the played tempo
    few: tuple[int, float] | None = None  # `Feasibility.few_limit`: a few notes slow the whole song

    @property
    def scale(self) -> float:
        """Factor on the song's times: written → played (2 = half the written tempo)."""
        return self.written_bpm / self.played_bpm

    def message(self) -> str | None:
        """One line when the played tempo is not the written one, or notes cannot keep up."""
        limiting = note_numbers(self.limiting_notes)
        if self.request.mode == "auto" and self.played_bpm < self.written_bpm * (1 - 1e-9):
            few = ""
            if self.few is not None:
                count, others = self.few
                # Rounded down as the played tempo is: at that tempo only those notes are skipped.
                at = math.floor(others * 10) / 10
                few = (f"; {count} note(s) alone hold it below {at:.4g} bpm, where the other notes can be "
                       f"struck in time: --tempo {at:g} plays there and skips them")
            return (f"the written tempo {self.written_bpm:.4g} bpm is too fast for this finger: playing at "
                    f"{self.played_bpm:.4g} bpm, the fastest at which every note can be struck in time "
                    f"(limited by note(s) {limiting}; --tempo written plays at {self.written_bpm:.4g} bpm "
                    f"and skips what cannot keep up{few})")
        if self.infeasible_notes:
            return (f"at {self.played_bpm:.4g} bpm {self.infeasible_notes} note(s) cannot be struck in time "
                    f"(the fastest feasible tempo is {self.feasible_bpm:.4g} bpm, limited by note(s) {limiting})")
        return None

    def to_dict(self) -> dict[str, Any]:
        return {"request": self.request.describe(), "written_bpm": self.written_bpm,
                "feasible_bpm": _finite(self.feasible_bpm), "played_bpm": self.played_bpm,
                "scale": self.scale, "limiting_notes": list(self.limiting_notes),
                "infeasible_notes": self.infeasible_notes}


def choose_tempo(request: TempoRequest, feasibility: Feasibility | None) -> TempoChoice:
    """The played tempo: auto → the fastest feasible (≤ written); written/bpm → as asked."""
    written = feasibility.written_bpm if feasibility is not None else math.nan
    if feasibility is None:
        raise ValueError("choose_tempo needs a feasibility (use written_only for a planner without a model)")
    fastest = feasibility.fastest_bpm
    if request.mode == "auto":
        # Rounded down to 0.1 bpm: a tempo a musician can read, never above the feasible one.
        played = written if fastest >= written else max(MIN_TEMPO_BPM / 10, math.floor(fastest * 10) / 10)
    elif request.mode == "written":
        played = written
    else:
        assert request.bpm is not None
        played = float(request.bpm)
    return TempoChoice(request, written, fastest, played, tuple(feasibility.limiting()),
                       feasibility.infeasible_at(played), feasibility.few_limit())


def written_only(request: TempoRequest, written_bpm: float) -> TempoChoice:
    """For a planner without a model (naive): auto and written play the written tempo."""
    played = float(request.bpm) if request.mode == "bpm" and request.bpm is not None else float(written_bpm)
    return TempoChoice(request, float(written_bpm), math.nan, played, (), 0)


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None
