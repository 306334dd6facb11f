"""Stitching the pieces of a marker's track that Motive split after an occlusion.

Motive gives a marker a new ID when it reappears after being hidden, so one physical marker can
come as `Unlabeled:103` for 40 % of the take, `Unlabeled:512` for the next 30 % and
`Unlabeled:618` for the rest. Each piece alone looks like a ghost. Two pieces are the same
marker when they do not overlap in time and the later one starts where the earlier one, carried
on at its last velocity, would be (within `JOIN_TOL_M` plus `JOIN_SPEED_MPS` per second of gap).
Pieces are joined greedily in time order, each to the chain it continues best; a piece that two
chains continue about equally well is joined to neither and the ambiguity is reported.

Ghosts (short tracks of reflections) are stitched the same way; they stay ghosts because even
joined they cover few frames, and their position is far from the real markers'.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

JOIN_TOL_M = 0.003  # position mismatch allowed at a join (marker noise, reconstruction jitter)
JOIN_SPEED_MPS = 0.03  # ... plus this much per second of gap (an unseen change of speed)
MAX_GAP_S = 2.0  # pieces further apart in time are not joined
EDGE_FRAMES = 5  # frames averaged at each end of a piece (noise)
AMBIGUOUS_RATIO = 2.0  # the best chain must fit this many times better than the next


@dataclass(frozen=True)
class Track:
    """One marker's positions (metres) on the frames where it was seen."""

    name: str
    frames: IntArray
    xyz: FloatArray  # (len(frames), 3)


@dataclass(frozen=True)
class Join:
    """One join: `piece` continues the chain named `chain` after `gap_s` with `mismatch_m`."""

    chain: str
    piece: str
    gap_s: float
    mismatch_m: float

    def to_dict(self) -> dict[str, object]:
        return {
            "chain": self.chain,
            "piece": self.piece,
            "gap_s": round(self.gap_s, 4),
            "mismatch_mm": round(self.mismatch_m * 1000, 3),
        }


@dataclass
class Stitched:
    """The chains (a track per physical marker), the pieces of each, the joins and doubts."""

    chains: list[Track]
    pieces: dict[str, list[str]]
    joins: list[Join] = field(default_factory=list)
    ambiguous: list[tuple[str, str, str]] = field(
        default_factory=list
    )  # (piece, chain, other chain)

    def chain_of(self, name: str) -> str | None:
        """The chain a marker name (any of its pieces) belongs to."""
        for chain, pieces in self.pieces.items():
            if name in pieces:
                return chain
        return None


def stitch(tracks: list[Track], t_s: FloatArray) -> Stitched:
    """Join the pieces of split tracks (module docstring). `t_s`: time of every frame."""
    order = sorted(tracks, key=lambda tr: int(tr.frames[0]) if tr.frames.size else 0)
    chains: list[list[Track]] = []
    joins: list[Join] = []
    ambiguous: list[tuple[str, str, str]] = []
    for track in order:
        if not track.frames.size:
            continue
        scores = []
        for c, chain in enumerate(chains):
            score = _continuation(chain[-1], track, t_s)
            if score is not None:
                scores.append((score[0], c, score[1], score[2]))
        scores.sort()
        if scores and (
            len(scores) == 1 or scores[1][0] > AMBIGUOUS_RATIO * max(scores[0][0], 1e-9)
        ):
            _, c, gap, mismatch = scores[0]
            joins.append(Join(chains[c][0].name, track.name, gap, mismatch))
            chains[c].append(track)
            continue
        if len(scores) > 1:
            ambiguous.append(
                (track.name, chains[scores[0][1]][0].name, chains[scores[1][1]][0].name)
            )
        chains.append([track])
    merged = [
        Track(
            chain[0].name,
            np.concatenate([p.frames for p in chain]),
            np.concatenate([p.xyz for p in chain]),
        )
        for chain in chains
    ]
    return Stitched(
        merged, {chain[0].name: [p.name for p in chain] for chain in chains}, joins, ambiguous
    )


def _continuation(last: Track, piece: Track, t_s: FloatArray) -> tuple[float, float, float] | None:
    """(misfit relative to the tolerance, gap, mismatch) when `piece` can continue `last`."""
    end, begin = int(last.frames[-1]), int(piece.frames[0])
    if begin <= end:
        return None  # they overlap in time: two markers
    gap_s = float(t_s[begin] - t_s[end])
    if gap_s > MAX_GAP_S:
        return None
    tail, head = last.xyz[-EDGE_FRAMES:], piece.xyz[:EDGE_FRAMES]
    tail_t, head_t = t_s[last.frames[-EDGE_FRAMES:]], t_s[piece.frames[:EDGE_FRAMES]]
    velocity = _velocity(tail_t, tail)
    predicted = tail[-1] + velocity * (float(np.median(head_t)) - float(tail_t[-1]))
    mismatch = float(np.linalg.norm(np.median(head, axis=0) - predicted))
    tolerance = JOIN_TOL_M + JOIN_SPEED_MPS * gap_s
    if not mismatch <= tolerance:
        return None
    return mismatch / tolerance, gap_s, mismatch


def _velocity(t: FloatArray, xyz: FloatArray) -> FloatArray:
    if t.size < 2 or not t[-1] > t[0]:
        return np.zeros(3)
    slope = np.polyfit(t - t[0], xyz, 1)[0]
    return np.asarray(slope, dtype=np.float64) if np.all(np.isfinite(slope)) else np.zeros(3)


__all__ = ["Join", "Stitched", "Track", "stitch"]
