"""Test songs built in code from note lists: what `experiments/songs/make_songs.py` writes.

Each song is a list of (pitch, beats, velocity) with a tempo; `to_notes` puts it on a seconds
axis. Notes are detached: each sounds for `articulation` of its beat length, the rest of the
beat is silence (a single finger needs that gap to release the key and strike the next one).

Songs are in the usual notation by default (`beat=1`: one syllable per quarter note, half notes
at phrase ends). `beat=ROBOT_BEAT` gives robot notation, one syllable per whole note: one soft
finger inside its proven envelope needs 0.7 s (loudest) to 1.6 s (quietest) from motion start
until the arm is back up, plus 0.37–0.53 s to change key, so at ♩ = 90 it keeps every note and
its whole dynamic range only in robot notation; in the usual notation the planner plays faster
(louder) strokes and skips and reports the notes it has no time for.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from pianobot.io.midifile import Note

G3 = 55
C4, D4, E4, F4, G4, A4, B4, C5 = 60, 62, 64, 65, 67, 69, 71, 72
D5, E5, F5, G5 = 74, 76, 77, 79
ROBOT_BEAT = 4.0  # quarter notes per syllable in robot notation (a whole note)
PP, FF = 33, 112  # MIDI velocities of pianissimo and fortissimo (the usual convention)


@dataclass(frozen=True)
class SongSpec:
    """A melody as (pitch, beats, velocity) triples with a tempo in quarter-note beats/min."""

    name: str
    tempo_bpm: float
    notes: tuple[tuple[int, float, int], ...]
    articulation: float = 0.9  # fraction of each note's beats that sounds

    def to_notes(self) -> list[Note]:
        """The melody on a seconds axis (onsets at the beat grid)."""
        beat_s = 60.0 / self.tempo_bpm
        out, t_beats = [], 0.0
        for pitch, beats, velocity in self.notes:
            onset = t_beats * beat_s
            out.append(Note(pitch, onset, onset + beats * beat_s * self.articulation, velocity))
            t_beats += beats
        return out


def _phrase(pitches: Sequence[int], beats: Sequence[float], velocities: Sequence[int]) -> list[tuple[int, float, int]]:
    return list(zip(pitches, beats, velocities, strict=True))


def _ramp(start: int, stop: int, n: int) -> list[int]:
    """n velocities from start to stop (a crescendo or diminuendo)."""
    if n == 1:
        return [start]
    return [round(start + (stop - start) * i / (n - 1)) for i in range(n)]


def scale_crescendo(tempo_bpm: float = 90.0, beat: float = 1.0) -> SongSpec:
    """C major up and down (15 notes), one crescendo from pp to ff."""
    up = [C4, D4, E4, F4, G4, A4, B4, C5]
    pitches = up + up[-2::-1]
    beats = [beat] * (len(pitches) - 1) + [2.0 * beat]
    return SongSpec("scale_crescendo", tempo_bpm, tuple(_phrase(pitches, beats, _ramp(25, 115, len(pitches)))))


_TWINKLE_A = [C4, C4, G4, G4, A4, A4, G4, F4, F4, E4, E4, D4, D4, C4]
_TWINKLE_B = [G4, G4, F4, F4, E4, E4, D4]
_PHRASE_BEATS = [1.0] * 6 + [2.0]


def twinkle(tempo_bpm: float = 90.0, beat: float = 1.0) -> SongSpec:
    """Twinkle Twinkle Little Star (42 notes, A B B A) with phrase dynamics.

    `beat` is how many quarter notes one syllable lasts (1: the usual notation, the default;
    `ROBOT_BEAT`: robot notation, see the module doc).
    """
    beats = [b * beat for b in _PHRASE_BEATS * 2]
    half = [b * beat for b in _PHRASE_BEATS]
    notes = (
        _phrase(_TWINKLE_A, beats, [72, 72, 84, 84, 92, 92, 84] + _ramp(70, 58, 7))
        + _phrase(_TWINKLE_B, half, _ramp(50, 66, 7))
        + _phrase(_TWINKLE_B, half, _ramp(66, 88, 7))
        + _phrase(_TWINKLE_A, beats, [96, 96, 104, 104, 110, 110, 100] + _ramp(90, 40, 7))
    )
    return SongSpec("twinkle", tempo_bpm, tuple(notes))


def mary(tempo_bpm: float = 90.0, beat: float = 1.0) -> SongSpec:
    """Mary Had a Little Lamb (26 notes): soft verse, louder answer, fading close."""
    pitches = [E4, D4, C4, D4, E4, E4, E4, D4, D4, D4, E4, G4, G4,
               E4, D4, C4, D4, E4, E4, E4, E4, D4, D4, E4, D4, C4]
    beats = [1, 1, 1, 1, 1, 1, 2, 1, 1, 2, 1, 1, 2,
             1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 4]
    velocities = _ramp(45, 60, 7) + [64, 64, 64, 90, 100, 100] + _ramp(80, 60, 9) + _ramp(55, 30, 4)
    return SongSpec("mary", tempo_bpm, tuple(_phrase(pitches, [b * beat for b in beats], velocities)))


def etude(n_notes: int = 60, tempo_bpm: float = 90.0, beat: float = 2.0, seed_pitch: int = C4) -> SongSpec:
    """A long exercise for adaptation: a stepwise C-major walk in phrases of uneven length.

    Each phrase is one crescendo or diminuendo over its own range (a musician's phrasing, not a
    cycle arranged so every third of the piece asks for the same loudness): the first third
    swells from mp, the middle reaches ff and pp, the last third fades out and rises once more.
    """
    steps = [0, 2, 4, 5, 7, 5, 4, 2]
    ramps = [(45, 95, 8), (95, 55, 8), (60, 115, 6), (110, 35, 10), (40, 80, 8), (85, 120, 8), (115, 30, 12)]
    velocities = [v for start, stop, n in ramps for v in _ramp(start, stop, n)]
    while len(velocities) < n_notes:  # longer pieces repeat the phrasing
        velocities += velocities
    notes = [(seed_pitch + steps[i % len(steps)], beat, velocities[i]) for i in range(n_notes)]
    return SongSpec(f"etude{n_notes}", tempo_bpm, tuple(notes))


def ode(tempo_bpm: float = 100.0) -> SongSpec:
    """Ode to Joy (Beethoven, 17 + 15 notes), crescendo pp → ff and back, an octave-leap close.

    Each half ends with its dotted rhythm (dotted quarter, eighth); the coda leaps C4 → C5.
    """
    first = [E4, E4, F4, G4, G4, F4, E4, D4, C4, C4, D4, E4, E4, D4, D4]
    second = [E4, E4, F4, G4, G4, F4, E4, D4, C4, C4, D4, E4, D4, C4, C4]
    beats = [1.0] * 12 + [1.5, 0.5, 2.0]
    notes = (_phrase(first, beats, _ramp(PP, 90, 15)) + _phrase(second, beats, _ramp(FF, 45, 15))
             + _phrase([C4, C5], [1.0, 2.0], [PP, 40]))
    return SongSpec("ode", tempo_bpm, tuple(notes))


def frere(tempo_bpm: float = 110.0) -> SongSpec:
    """Frère Jacques (30 notes) rising from pp to ff, dotted "morning bells", an octave leap C4 → C5."""
    pitches = [C4, D4, E4, C4, C4, D4, E4, C4, E4, F4, G4, E4, F4, G4,
               G4, A4, G4, F4, E4, C4, G4, A4, G4, F4, E4, C4, C5, G4, C4, C4]
    beats = [1.0] * 10 + [2.0, 1.0, 1.0, 2.0] + [1.5, 0.5, 1.0, 1.0, 1.0, 1.0] * 2 + [1.0, 1.0, 1.0, 2.0]
    return SongSpec("frere", tempo_bpm, tuple(_phrase(pitches, beats, _ramp(PP, FF, len(pitches)))))


def arpeggio(tempo_bpm: float = 80.0) -> SongSpec:
    """A broken-chord study (24 notes): dotted halves and quarters, octave leaps C4–C5 and
    G4–G5, repeated notes; pp swelling to ff in the middle and back to pp."""
    pitches = [C4, C5, E4, G4, G4, C5, G4, G5, D5, B4, B4, G4,
               A4, E5, C5, A4, A4, F4, F4, F5, D5, C5, C4, C4]
    beats = [3.0, 1.0, 1.0, 1.0, 1.0, 1.0] * 4
    velocities = _ramp(PP, FF, 12) + _ramp(FF, PP, 12)
    return SongSpec("arpeggio", tempo_bpm, tuple(_phrase(pitches, beats, velocities)))


def march(tempo_bpm: float = 120.0) -> SongSpec:
    """A march (24 notes) of dotted figures: a loud call, its soft echo an octave higher, a loud
    close; repeated notes throughout."""
    call = [G4, G4, C5, C5, E5, D5, C5, G4]
    beats = [1.5, 0.5, 1.0, 1.0, 1.5, 0.5, 2.0, 2.0]
    echo = [G5, G5, C5, C5, E5, D5, C5, C5]
    close = [G4, G4, C5, E5, G5, E5, C5, C4]
    notes = (_phrase(call, beats, _ramp(96, FF, 8)) + _phrase(echo, beats, _ramp(48, PP, 8))
             + _phrase(close, [1.0, 1.0, 1.0, 1.0, 1.5, 0.5, 2.0, 2.0], _ramp(70, FF, 8)))
    return SongSpec("march", tempo_bpm, tuple(notes))


def waltz(tempo_bpm: float = 90.0) -> SongSpec:
    """A waltz tune in 3/4 (24 notes): pickup quarters onto dotted halves, octave leaps D4–D5,
    repeated notes; a long crescendo from pp to ff."""
    pitches = [D4, D5, D5, B4, G4, G4, A4, B4, C5, C5, A4, F4,
               E4, E5, E5, C5, A4, A4, B4, C5, D5, D5, D4, G4]
    beats = [1.0, 3.0, 1.0, 1.0, 1.0, 3.0, 1.0, 1.0, 1.0, 3.0, 1.0, 2.0] * 2
    return SongSpec("waltz", tempo_bpm, tuple(_phrase(pitches, beats, _ramp(PP, FF, len(pitches)))))


def rise_and_fall(tempo_bpm: float = 100.0) -> SongSpec:
    """Thirty quarter notes: repeated notes, dotted rhythms, an octave leap, loudness rising
    from 40 to 88 and falling again (the kind of melody the play issue was measured on)."""
    pitches = [C4, C4, D4, E4, E4, F4, G4, G4, A4, G4, F4, E4, D4, D4, C4,
               E4, E4, F4, G4, G5, F5, E5, D5, D5, C5, B4, A4, G4, G4, C4]
    beats = [1.0, 1.0, 1.0, 1.5, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 2.0] * 2
    velocities = _ramp(40, 88, 16) + _ramp(85, 40, 14)
    return SongSpec("rise_and_fall", tempo_bpm, tuple(_phrase(pitches, beats, velocities)))


SONGS = {"scale_crescendo": scale_crescendo, "twinkle": twinkle, "mary": mary}
#: The play test songs (issue 11): 80–120 bpm, each with repeated notes, an octave leap, dynamics
#: from pp to ff and dotted rhythms.
TEST_SONGS = {"ode": ode, "frere": frere, "arpeggio": arpeggio, "march": march, "waltz": waltz,
              "rise_and_fall": rise_and_fall}
