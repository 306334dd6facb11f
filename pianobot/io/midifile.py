"""Standard MIDI files: songs in (notes on a seconds axis), performances out.

Reading rules (`read_song`):

- Type 0 and type 1 files; a type-2 file (independent sequences, no shared time axis) is refused.
- Times go through the tempo map (every `set_tempo`, in whichever track it sits) to absolute
  seconds; tracks are merged; `--track N` keeps the notes of one track (tempo still applies).
- Channel 10 (index 9, General MIDI drums) is dropped: it holds no pitches.
- The written tempo (`Song.tempo_bpm`) is the one in force at the first note; a tempo of 0 is refused.
- A key signature mido cannot decode (8 sharps) is kept as an unknown meta event: it changes no note.
- A `note_on` with velocity 0 is a note-off.
- Overlapping notes of the same pitch on one channel: a new `note_on` while the key sounds
  re-strikes it — the earlier note ends at the new onset (a key cannot sound twice), and the
  next note-off ends the new note. A note-off with no sounding note is ignored; a note still
  sounding at the end of its track ends there. Zero-length notes are dropped.
- Pitches outside the piano (21–108, after `transpose`) are reported, not silently dropped.
- The sustain pedal (controller 64) is reported, not played: a note lasts until its key-up.

Every such decision is counted in `Song.warnings`, so a caller can say what happened.
`write_performance` writes played notes with 1 tick = 1 ms (1000 ticks per beat at 60 bpm).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from pianobot.errors import InputError
from pianobot.output import write_output
from pianobot.physics.keyboard import HIGHEST_NOTE, LOWEST_NOTE

DRUM_CHANNEL = 9  # channel 10 in 1-based numbering
SUSTAIN_PEDAL = 64  # the damper pedal's controller number
DEFAULT_TEMPO_US = 500_000  # 120 bpm until the first set_tempo
PERFORMANCE_TICKS_PER_BEAT = 1000
PERFORMANCE_TEMPO_US = 1_000_000  # 60 bpm: with 1000 ticks per beat, 1 tick = 1 ms
# Limits checked before the notes are paired: a piano piece has a few thousand notes (a fast
# hour of playing is ~20,000); a 16 MB standard MIDI file holds millions of events.
MAX_SONG_NOTES = 100_000
MAX_SONG_BYTES = 16 << 20


@dataclass(frozen=True)
class Note:
    """One note of a song or a performance (seconds from the start, MIDI velocity 1–127)."""

    pitch: int
    onset_s: float
    offset_s: float
    velocity: int
    track: int = 0
    channel: int = 0

    @property
    def duration_s(self) -> float:
        return self.offset_s - self.onset_s


@dataclass(frozen=True)
class Song:
    """The notes of a MIDI file on a seconds axis, with what reading it decided."""

    notes: tuple[Note, ...]  # playable pitches, sorted by onset then pitch
    unplayable: tuple[Note, ...]  # outside 21–108 after transposition
    source: str
    tempo_bpm: float  # the first tempo of the file, after tempo scaling
    warnings: tuple[str, ...] = ()

    @property
    def duration_s(self) -> float:
        return max((n.offset_s for n in self.notes), default=0.0)


@dataclass(frozen=True)
class Melody:
    """A one-finger line taken from a song, and how much polyphony was removed."""

    notes: tuple[Note, ...]
    chords: int  # onsets where several notes started together (only one kept)
    dropped: int  # notes removed: under a chord's chosen note or under a sounding melody note
    shortened: int  # melody notes cut short because the next melody note starts earlier
    lead_in_s: float = 0.0  # silence before the first note, skipped (`without_lead_in`)

    @property
    def warnings(self) -> tuple[str, ...]:
        """One line per kind of reduction that happened (empty for a monophonic song)."""
        out = []
        if self.chords or self.dropped:
            out.append(
                f"one finger plays one note at a time: kept the melody of {self.chords} chord(s), "
                f"dropped {self.dropped} note(s) under a melody note"
            )
        if self.shortened:
            out.append(f"shortened {self.shortened} overlapping melody note(s) to the next onset")
        if self.lead_in_s:
            out.append(f"the first note comes {self.lead_in_s:.1f} s into the song: the silence before it is skipped")
        return tuple(out)

    def without_lead_in(self, longest_s: float) -> Melody:
        """The line started at its first note when the silence before it is longer than
        `longest_s` (a robot waiting out a long silence plays nothing the better for it)."""
        first = self.notes[0].onset_s if self.notes else 0.0
        if first <= longest_s:
            return self
        notes = tuple(replace(n, onset_s=n.onset_s - first, offset_s=n.offset_s - first) for n in self.notes)
        return replace(self, notes=notes, lead_in_s=self.lead_in_s + first)


def read_song(
    path: str | Path,
    *,
    tempo_scale: float = 1.0,
    transpose: int = 0,
    track: int | None = None,
) -> Song:
    """Read a type-0/1 MIDI file into notes on a seconds axis (see the module doc for the rules).

    Args:
        tempo_scale: multiplies the tempo (2 plays twice as fast, 0.5 at half speed).
        transpose: semitones added to every pitch.
        track: keep only this track (0-based index into the file's tracks).

    Raises:
        InputError: missing file, not a MIDI file, a type-2 file, a bad option value.
    """
    source = Path(path)
    where = str(source)
    if not (math.isfinite(tempo_scale) and tempo_scale > 0):
        raise InputError(f"tempo scale should be > 0, got {tempo_scale}", "--tempo-scale")
    if not source.is_file():
        raise InputError("song file not found", where)
    size = source.stat().st_size
    if size > MAX_SONG_BYTES:
        raise InputError(f"is {size / 2**20:.0f} MB; a song file is read up to "
                         f"{MAX_SONG_BYTES >> 20} MB", where)
    if size == 0:
        raise InputError("not a standard MIDI file (the file is empty)", where)
    mid = _midi_file(source)
    if mid.type == 2:
        raise InputError(
            "type-2 MIDI file (independent sequences without a shared time axis) is not supported; "
            "export the song as type 0 or 1",
            where,
        )
    if track is not None and not 0 <= track < len(mid.tracks):
        raise InputError(
            f"track should be in [0, {len(mid.tracks) - 1}] for this file, got {track}", "--track"
        )
    if mid.ticks_per_beat <= 0:
        raise InputError(
            f"ticks per beat should be > 0, got {mid.ticks_per_beat} (SMPTE timing is not supported)",
            where,
        )
    stalled = next((i for i, trk in enumerate(mid.tracks) for msg in trk
                    if getattr(msg, "type", "") == "set_tempo" and int(msg.tempo) <= 0), None)
    if stalled is not None:
        raise InputError(f"track {stalled} sets a tempo of 0 µs per beat (time would stand still)", where)
    n_notes = sum(1 for trk in mid.tracks for msg in trk
                  if getattr(msg, "type", "") == "note_on" and getattr(msg, "velocity", 0) > 0)
    if n_notes > MAX_SONG_NOTES:
        raise InputError(f"has {n_notes:,} notes; a song is played up to {MAX_SONG_NOTES:,} notes "
                         "(split it)", where)
    notes, counts, first_tempo_us = _notes(mid, tempo_scale)
    warnings: list[str] = []
    if counts["drums"]:
        warnings.append(f"dropped {counts['drums']} drum note(s) on channel 10")
    if counts["restruck"]:
        warnings.append(
            f"{counts['restruck']} same-pitch overlap(s): the earlier note ends at the re-strike"
        )
    if counts["unterminated"]:
        warnings.append(
            f"{counts['unterminated']} note(s) without a note-off end at the end of their track"
        )
    if counts["zero_length"]:
        warnings.append(f"dropped {counts['zero_length']} zero-length note(s)")
    pedal = sum(1 for trk in mid.tracks for msg in trk if getattr(msg, "type", "") == "control_change"
                and int(getattr(msg, "control", -1)) == SUSTAIN_PEDAL and int(getattr(msg, "value", 0)) >= 64)
    if pedal:
        warnings.append(f"the sustain pedal (pressed {pedal} time(s)) is not played: each note lasts until "
                        "its key is released")
    if track is not None:
        notes = [n for n in notes if n.track == track]
    notes = [replace(n, pitch=n.pitch + transpose) for n in notes]
    playable = tuple(n for n in notes if LOWEST_NOTE <= n.pitch <= HIGHEST_NOTE)
    unplayable = tuple(n for n in notes if not LOWEST_NOTE <= n.pitch <= HIGHEST_NOTE)
    if unplayable:
        pitches = sorted({n.pitch for n in unplayable})
        warnings.append(
            f"{len(unplayable)} note(s) outside the piano's keys [{LOWEST_NOTE}, {HIGHEST_NOTE}] "
            f"cannot be played (pitches {pitches[:6]}{'…' if len(pitches) > 6 else ''})"
        )
    return Song(
        notes=playable,
        unplayable=unplayable,
        source=where,
        tempo_bpm=60e6 / first_tempo_us * tempo_scale,
        warnings=tuple(warnings),
    )


#: A key signature meta event's type byte (`FF 59`).
KEY_SIGNATURE = 0x59


def _midi_file(source: Path) -> Any:
    """The file as mido reads it; a key signature mido cannot decode (8 sharps: notation programs
    write such) is kept as an unknown meta event, since it changes no note."""
    import mido
    from mido.midifiles import meta

    where = str(source)
    try:
        try:
            return mido.MidiFile(source)
        except meta.KeySignatureError:
            specs = getattr(meta, "_META_SPECS", None)
            if not isinstance(specs, dict) or KEY_SIGNATURE not in specs:
                raise
            spec = specs.pop(KEY_SIGNATURE)
            try:
                return mido.MidiFile(source)
            finally:
                specs[KEY_SIGNATURE] = spec
    except EOFError:
        raise InputError("not a standard MIDI file (it ends inside a chunk: truncated?)", where) from None
    except (OSError, ValueError, KeyError, IndexError, meta.KeySignatureError) as exc:
        # mido's own words, without its exception's class name (which says nothing to a musician)
        detail = str(exc).strip("'\"") or "a malformed chunk or event"
        raise InputError(f"not a standard MIDI file (a damaged track or header: {detail})", where) from None


def _notes(mid: Any, tempo_scale: float) -> tuple[list[Note], dict[str, int], int]:
    """Pair note events of all tracks on the seconds axis of the (merged) tempo map."""
    tracks = mid.tracks
    ticks_per_beat = int(mid.ticks_per_beat)
    events: list[tuple[int, int, int, Any]] = []  # (tick, track, order, message)
    for index, trk in enumerate(tracks):
        tick = 0
        for order, msg in enumerate(trk):
            tick += int(msg.time)
            events.append((tick, index, order, msg))
        events.append((tick, index, len(trk), None))  # end of this track
    # Stable by tick; at one tick, tempo changes first, then offs before ons (a legato repeat).
    events.sort(key=lambda e: (e[0], _rank(e[3]), e[1], e[2]))
    counts = {"drums": 0, "restruck": 0, "unterminated": 0, "zero_length": 0}
    tempo_us = DEFAULT_TEMPO_US
    first_tempo_us: int | None = None  # the tempo in force at the first note
    last_tick, t_s = 0, 0.0
    open_notes: dict[tuple[int, int, int], tuple[float, int]] = {}  # (track, ch, pitch) → (on, vel)
    # Note-offs that found no sounding note, by key: (tick, order in the track). One written after
    # a note-on of its tick ends that note at once (a zero-length note, dropped): offs are sorted
    # before ons of a tick for legato repeats, so it came first.
    unmatched_offs: dict[tuple[int, int, int], list[tuple[int, int]]] = {}
    notes: list[Note] = []

    def close(key: tuple[int, int, int], end_s: float) -> None:
        on_s, velocity = open_notes.pop(key)
        if end_s - on_s <= 0.0:
            counts["zero_length"] += 1
            return
        notes.append(Note(key[2], on_s, end_s, velocity, track=key[0], channel=key[1]))

    for tick, index, order, msg in events:
        t_s += (tick - last_tick) * tempo_us / 1e6 / ticks_per_beat / tempo_scale
        last_tick = tick
        if msg is None:
            for key in [k for k in open_notes if k[0] == index]:
                counts["unterminated"] += 1
                close(key, t_s)
            continue
        kind = getattr(msg, "type", "")
        if kind == "set_tempo":
            tempo_us = int(msg.tempo)
            continue
        if kind not in ("note_on", "note_off"):
            continue
        channel, pitch, velocity = (int(getattr(msg, a)) for a in ("channel", "note", "velocity"))
        if channel == DRUM_CHANNEL:
            if kind == "note_on" and velocity > 0:
                counts["drums"] += 1
            continue
        key = (index, channel, pitch)
        if kind == "note_on" and velocity > 0:
            offs = unmatched_offs.get(key, [])
            later = next((off for off in offs if off[0] == tick and off[1] > order), None)
            if later is not None:
                offs.remove(later)
                counts["zero_length"] += 1
                continue
            if key in open_notes:
                counts["restruck"] += 1
                close(key, t_s)
            if first_tempo_us is None:
                first_tempo_us = tempo_us
            open_notes[key] = (t_s, velocity)
        elif key in open_notes:
            close(key, t_s)
        else:
            unmatched_offs.setdefault(key, []).append((tick, order))
    notes.sort(key=lambda n: (n.onset_s, n.pitch))
    return notes, counts, first_tempo_us or _first_tempo(events) or DEFAULT_TEMPO_US


def _rank(msg: Any) -> int:
    if msg is None:
        return 3
    kind = getattr(msg, "type", "")
    if kind == "set_tempo":
        return 0
    if kind == "note_off" or (kind == "note_on" and getattr(msg, "velocity", 1) == 0):
        return 1
    return 2


def _first_tempo(events: Sequence[tuple[int, int, int, Any]]) -> int | None:
    for _, _, _, msg in events:
        if msg is not None and getattr(msg, "type", "") == "set_tempo":
            return int(msg.tempo)
    return None


def melody(notes: Iterable[Note], *, rule: str = "highest", chord_window_s: float = 0.03) -> Melody:
    """Reduce polyphony to one line a single finger can play (the "skyline" of the notes).

    Notes starting within `chord_window_s` of each other form a chord; the highest (or lowest,
    `rule="lowest"`) is kept. A note that starts while a kept note still sounds is dropped if it
    is below it (above it for "lowest"); otherwise the sounding note is cut at the new onset.
    """
    if rule not in ("highest", "lowest"):
        raise InputError(f"melody rule should be 'highest' or 'lowest', got {rule!r}", "melody")
    sign = 1 if rule == "highest" else -1
    ordered = sorted(notes, key=lambda n: (n.onset_s, -sign * n.pitch))
    kept: list[Note] = []
    chords = dropped = shortened = 0
    i = 0
    while i < len(ordered):
        group = [ordered[i]]
        while i + len(group) < len(ordered) and (
            ordered[i + len(group)].onset_s - ordered[i].onset_s <= chord_window_s
        ):
            group.append(ordered[i + len(group)])
        i += len(group)
        top = max(group, key=lambda n: sign * n.pitch)
        if len(group) > 1:
            chords += 1
            dropped += len(group) - 1
        if kept and kept[-1].offset_s > top.onset_s:
            if sign * top.pitch < sign * kept[-1].pitch:
                dropped += 1  # accompaniment under a sounding melody note
                continue
            kept[-1] = replace(kept[-1], offset_s=top.onset_s)
            shortened += 1
        kept.append(top)
    return Melody(tuple(kept), chords, dropped, shortened)


def write_song(
    path: str | Path, notes: Sequence[Note], *, tempo_bpm: float, ticks_per_beat: int = 480
) -> Path:
    """Write notes (seconds) as a type-0 MIDI file with one tempo, quantised to its ticks."""
    tempo_us = round(60e6 / tempo_bpm)
    ticks_per_s = ticks_per_beat * 1e6 / tempo_us
    return _write(Path(path), notes, ticks_per_beat, tempo_us, ticks_per_s)


def write_performance(path: str | Path, notes: Sequence[Note], *, start_s: float | None = None) -> Path:
    """Write played notes as a type-0 MIDI file with 1 tick = 1 ms (1000 ticks/beat at 60 bpm).

    Tick 0 is `start_s` on the notes' axis (default: 0, or the earliest onset if a note was
    played before zero — a MIDI file has no negative times).
    """
    if start_s is None:
        start_s = min([0.0] + [n.onset_s for n in notes])
    shifted = [replace(n, onset_s=n.onset_s - start_s, offset_s=n.offset_s - start_s) for n in notes]
    return _write(Path(path), shifted, PERFORMANCE_TICKS_PER_BEAT, PERFORMANCE_TEMPO_US, 1000.0)


def _write(
    path: Path, notes: Sequence[Note], ticks_per_beat: int, tempo_us: int, ticks_per_s: float
) -> Path:
    import mido

    events: list[tuple[int, int, mido.Message]] = []
    for n in notes:
        on = max(0, round(n.onset_s * ticks_per_s))
        off = max(on + 1, round(n.offset_s * ticks_per_s))
        channel = n.channel if 0 <= n.channel <= 15 else 0
        velocity = min(127, max(1, int(n.velocity)))
        events.append(
            (on, 1, mido.Message("note_on", note=n.pitch, velocity=velocity, channel=channel))
        )
        events.append((off, 0, mido.Message("note_off", note=n.pitch, velocity=0, channel=channel)))
    events.sort(key=lambda e: (e[0], e[1]))  # at one tick, offs first (a repeat of the same key)
    track = mido.MidiTrack()
    track.append(mido.MetaMessage("set_tempo", tempo=tempo_us, time=0))
    last = 0
    for tick, _, msg in events:
        track.append(msg.copy(time=tick - last))
        last = tick
    track.append(mido.MetaMessage("end_of_track", time=0))
    mid = mido.MidiFile(type=0, ticks_per_beat=ticks_per_beat)
    mid.tracks.append(track)
    return write_output(path, lambda tmp: mid.save(tmp))
