"""Write the example songs of `pianobot play` as MIDI files next to this script.

    python experiments/songs/make_songs.py

The note lists live in `pianobot.play.library` (so tests build the same songs in code): a
C-major scale with a crescendo, Twinkle Twinkle Little Star and Mary Had a Little Lamb (the
songs of the study's demos) with varied dynamics, in the usual notation at ♩ = 90 (one syllable
per quarter note), and Twinkle in robot notation (one syllable per whole note: the tempo at
which one soft finger keeps every note and its whole dynamic range).
"""

from __future__ import annotations

from pathlib import Path

from pianobot.io.midifile import write_song
from pianobot.play.library import ROBOT_BEAT, SongSpec, mary, scale_crescendo, twinkle

HERE = Path(__file__).resolve().parent


def songs() -> dict[str, SongSpec]:
    """File stem → song."""
    return {
        "scale_crescendo": scale_crescendo(),
        "twinkle": twinkle(),
        "mary": mary(),
        "twinkle_robot": twinkle(beat=ROBOT_BEAT),
    }


def main() -> None:
    for stem, spec in songs().items():
        path = write_song(HERE / f"{stem}.mid", spec.to_notes(), tempo_bpm=spec.tempo_bpm)
        print(f"{path.name}: {len(spec.notes)} notes at {spec.tempo_bpm:g} bpm")


if __name__ == "__main__":
    main()
