"""Song reading (tempo map, drums, re-strikes, melody), performance writing (1 tick = 1 ms)."""

from __future__ import annotations

from pathlib import Path

import mido
import pytest

from pianobot.errors import InputError
from pianobot.io.midifile import Note, melody, read_song, write_performance, write_song


def _file(path: Path, tracks: list[list[mido.Message | mido.MetaMessage]], *, type_: int = 1,
          ticks_per_beat: int = 480) -> Path:
    mid = mido.MidiFile(type=type_, ticks_per_beat=ticks_per_beat)
    for messages in tracks:
        track = mido.MidiTrack()
        track.extend(messages)
        mid.tracks.append(track)
    mid.save(path)
    return path


def on(note: int, time: int, velocity: int = 64, channel: int = 0) -> mido.Message:
    return mido.Message("note_on", note=note, velocity=velocity, time=time, channel=channel)


def off(note: int, time: int, channel: int = 0) -> mido.Message:
    return mido.Message("note_off", note=note, velocity=0, time=time, channel=channel)


def test_tempo_map_applies_across_tracks(tmp_path: Path) -> None:
    # Conductor track: 120 bpm, then 60 bpm from beat 2. Notes in track 1, one per beat.
    conductor = [mido.MetaMessage("set_tempo", tempo=500_000, time=0),
                 mido.MetaMessage("set_tempo", tempo=1_000_000, time=960)]
    notes = [on(60, 0), off(60, 480), on(62, 0), off(62, 480), on(64, 0), off(64, 480)]
    song = read_song(_file(tmp_path / "t.mid", [conductor, notes]))
    assert [n.pitch for n in song.notes] == [60, 62, 64]
    assert [round(n.onset_s, 6) for n in song.notes] == [0.0, 0.5, 1.0]
    assert round(song.notes[2].duration_s, 6) == 1.0  # the third beat is at 60 bpm
    assert song.tempo_bpm == pytest.approx(120.0)


def test_tempo_scale_transpose_and_track(tmp_path: Path) -> None:
    path = _file(tmp_path / "t.mid", [[on(60, 0), off(60, 480)], [on(72, 0, 90), off(72, 960)]])
    song = read_song(path, tempo_scale=2.0, transpose=-12, track=1)
    assert [(n.pitch, n.velocity) for n in song.notes] == [(60, 90)]
    assert song.notes[0].offset_s == pytest.approx(0.5)  # 2 beats at 120 bpm, twice as fast
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        read_song(path, track=5)
    with pytest.raises(InputError, match="tempo"):
        read_song(path, tempo_scale=0.0)


def test_drums_velocity_zero_and_restrike(tmp_path: Path) -> None:
    messages = [
        on(36, 0, channel=9), off(36, 100, channel=9),  # drums: dropped
        on(60, 0), on(60, 240, 80),  # a re-strike ends the first note
        on(60, 240, 0),  # velocity 0 = note-off of the second
        off(60, 240),  # a note-off without a sounding note: ignored
    ]
    song = read_song(_file(tmp_path / "d.mid", [messages], type_=0))
    assert [(round(n.onset_s, 4), round(n.offset_s, 4), n.velocity) for n in song.notes] == [
        (0.1042, 0.3542, 64), (0.3542, 0.6042, 80)]
    assert any("drum" in w for w in song.warnings)
    assert any("re-strike" in w for w in song.warnings)


def test_the_sustain_pedal_is_reported_not_played(tmp_path: Path) -> None:
    pedal = [mido.Message("control_change", control=64, value=127, time=0), on(60, 0), off(60, 240),
             mido.Message("control_change", control=64, value=0, time=480)]
    song = read_song(_file(tmp_path / "p.mid", [pedal], type_=0))
    assert [round(n.duration_s, 4) for n in song.notes] == [0.25]  # to the key-up, not the pedal-up
    assert any("sustain pedal (pressed 1 time(s)) is not played" in w for w in song.warnings)
    plain = read_song(_file(tmp_path / "q.mid", [[on(60, 0), off(60, 240)]], type_=0))
    assert not any("pedal" in w for w in plain.warnings)


def test_zero_length_notes_are_dropped_and_legato_repeats_kept(tmp_path: Path) -> None:
    messages = [
        on(60, 0), off(60, 0),  # zero length: its note-off follows at the same tick
        on(62, 240), off(62, 240),
        on(62, 0), off(62, 240),  # a legato repeat: the note-off of one, the note-on of the next
        on(64, 0), off(64, 0),  # zero length again
        on(65, 240), off(65, 240),
    ]
    song = read_song(_file(tmp_path / "z.mid", [messages], type_=0))
    assert [(n.pitch, round(n.onset_s, 4), round(n.offset_s, 4)) for n in song.notes] == [
        (62, 0.25, 0.5), (62, 0.5, 0.75), (65, 1.0, 1.25)]
    assert "dropped 2 zero-length note(s)" in song.warnings


def test_the_written_tempo_is_the_one_in_force_at_the_first_note(tmp_path: Path) -> None:
    notes = [on(60, 0), off(60, 480), on(62, 0), off(62, 480)]
    two_at_zero = [mido.MetaMessage("set_tempo", tempo=500_000, time=0),
                   mido.MetaMessage("set_tempo", tempo=750_000, time=0)]  # 120 then 80 bpm
    song = read_song(_file(tmp_path / "a.mid", [two_at_zero, notes]))
    assert song.tempo_bpm == pytest.approx(80.0) and song.notes[1].onset_s == pytest.approx(0.75)
    later = [mido.MetaMessage("set_tempo", tempo=1_000_000, time=960)]  # 120 bpm (default), then 60
    song = read_song(_file(tmp_path / "b.mid", [later, notes]))
    assert song.tempo_bpm == pytest.approx(120.0) and song.notes[1].onset_s == pytest.approx(0.5)


def test_a_key_signature_mido_cannot_decode_changes_no_note(tmp_path: Path) -> None:
    path = _file(tmp_path / "k.mid", [[mido.MetaMessage("key_signature", key="C", time=0), on(60, 0), off(60, 480)]],
                 type_=0)
    data = path.read_bytes()
    at = data.index(bytes([0xFF, 0x59, 0x02]))
    path.write_bytes(data[: at + 3] + bytes([8, 0]) + data[at + 5 :])  # 8 sharps, as some notation programs write
    with pytest.raises(mido.midifiles.meta.KeySignatureError):
        mido.MidiFile(path)
    assert [n.pitch for n in read_song(path).notes] == [60]


def test_a_tempo_of_zero_is_refused_naming_its_track(tmp_path: Path) -> None:
    conductor = [mido.MetaMessage("set_tempo", tempo=0, time=0)]
    with pytest.raises(InputError, match="track 0 sets a tempo of 0"):
        read_song(_file(tmp_path / "t0.mid", [conductor, [on(60, 0), off(60, 480)]]))


def test_a_long_silence_before_the_first_note_is_skipped_for_the_robot(tmp_path: Path) -> None:
    from pianobot.play.session import MAX_LEAD_IN_S, load_song

    path = _file(tmp_path / "late.mid", [[on(60, 480 * 60), off(60, 480), on(62, 0), off(62, 480)]], type_=0)
    song, line = load_song(path)
    assert song.notes[0].onset_s == pytest.approx(30.0)  # the file as written
    assert [(n.pitch, round(n.onset_s, 6)) for n in line.notes] == [(60, 0.0), (62, 0.5)]
    assert line.lead_in_s == pytest.approx(30.0) and any("30.0 s into the song" in w for w in line.warnings)
    short = _file(tmp_path / "soon.mid", [[on(60, 480), off(60, 480)]], type_=0)
    assert load_song(short)[1].notes[0].onset_s == pytest.approx(0.5) and 0.5 < MAX_LEAD_IN_S  # kept as written


def test_a_song_left_without_notes_says_why(tmp_path: Path) -> None:
    from pianobot.play.session import load_song

    path = _file(tmp_path / "zero.mid", [[on(60, 0), off(60, 0), on(62, 0), off(62, 0)]], type_=0)
    with pytest.raises(InputError, match=r"no playable notes \(dropped 2 zero-length note\(s\)\)"):
        load_song(path)


def test_unplayable_pitches_are_reported(tmp_path: Path) -> None:
    path = _file(tmp_path / "u.mid", [[on(100, 0), off(100, 480), on(60, 0), off(60, 480)]], type_=0)
    song = read_song(path, transpose=12)
    assert [n.pitch for n in song.notes] == [72]
    assert [n.pitch for n in song.unplayable] == [112]
    assert any("outside the piano" in w for w in song.warnings)


@pytest.mark.parametrize(("content", "match"), [
    (b"this is not a MIDI file", "not a standard MIDI file"),
    (b"", r"not a standard MIDI file \(the file is empty\)"),
    (b"MThd\x00\x00\x00\x06\x00\x00\x00\x01\x01\xe0MTrk\x00\x00\x00\x10\x00\x90", "truncated"),
])
def test_bad_files(tmp_path: Path, content: bytes, match: str) -> None:
    path = tmp_path / "bad.mid"
    path.write_bytes(content)
    with pytest.raises(InputError, match=match):
        read_song(path)
    with pytest.raises(InputError, match="not found"):
        read_song(tmp_path / "missing.mid")


def test_type_2_is_refused(tmp_path: Path) -> None:
    path = _file(tmp_path / "t2.mid", [[on(60, 0), off(60, 480)], [on(62, 0), off(62, 480)]], type_=2)
    with pytest.raises(InputError, match="type-2"):
        read_song(path)


def test_melody_keeps_top_note_and_counts() -> None:
    notes = [Note(60, 0.0, 1.0, 50), Note(64, 0.0, 1.0, 60), Note(67, 0.01, 1.0, 70),  # a chord
             Note(48, 0.5, 1.5, 40),  # accompaniment under the sounding melody note
             Note(72, 0.9, 2.0, 80)]  # melody note starting before the previous ends
    line = melody(notes)
    assert [n.pitch for n in line.notes] == [67, 72]
    assert line.notes[0].offset_s == pytest.approx(0.9)
    assert (line.chords, line.dropped, line.shortened) == (1, 3, 1)
    assert line.warnings and "melody" in line.warnings[0]
    assert [n.pitch for n in melody(notes, rule="lowest").notes][0] == 60


def test_performance_file_is_one_tick_per_ms(tmp_path: Path) -> None:
    played = [Note(60, -0.004, 0.5, 30), Note(62, 1.2345, 1.5, 9)]
    path = write_performance(tmp_path / "p.mid", played)
    mid = mido.MidiFile(path)
    tempo = next(m.tempo for m in mid.tracks[0] if m.type == "set_tempo")
    assert mido.tick2second(1, mid.ticks_per_beat, tempo) == pytest.approx(1e-3)
    back = read_song(path)
    assert [(n.pitch, n.velocity) for n in back.notes] == [(60, 30), (62, 9)]
    # The early note moved the file's zero to its onset: every time shifted by 4 ms, whole ms.
    assert back.notes[1].onset_s == pytest.approx(1.238, abs=1e-9)


def test_write_song_round_trip(tmp_path: Path) -> None:
    notes = [Note(60, 0.0, 0.6, 40), Note(67, 2 / 3, 1.2, 100)]
    back = read_song(write_song(tmp_path / "s.mid", notes, tempo_bpm=90))
    assert back.tempo_bpm == pytest.approx(90.0, rel=1e-6)
    assert [(n.pitch, n.velocity) for n in back.notes] == [(60, 40), (67, 100)]
    assert back.notes[1].onset_s == pytest.approx(2 / 3, abs=2e-3)
