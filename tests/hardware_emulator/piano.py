"""A digital piano under the emulated arm: it watches the TCP and plays MIDI through JACK.

The fingertip is the TCP (a rigid finger). White keys lie along base +x from the reference
key, `white_pitch_m` apart, their surfaces at `surface_z_m`. A key pressed deeper than
`trigger_depth_m` sounds a note-on whose velocity grows with the TCP speed at that moment;
it is released (note-off) when the finger rises above `release_depth_m`. Events go to a JACK
MIDI output port `<client_name>:keys` (pianobot reads them like the lab's USB piano), and are
kept for the test.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

WHITE_NOTES = [n for n in range(21, 109) if n % 12 in (0, 2, 4, 5, 7, 9, 11)]


@dataclass(frozen=True)
class PianoConfig:
    reference_x_m: float
    surface_z_m: float
    reference_note: int = 59
    white_pitch_m: float = 0.0235
    trigger_depth_m: float = 0.006
    release_depth_m: float = 0.003
    jack_client_name: str | None = None
    full_velocity_mps: float = 0.3  # key speed for MIDI velocity 127
    lost_note_ons: tuple[int, ...] = ()  # note-ons (0, 1, ... in play order) the cable loses


class EmulatedPiano:
    """Called once per control cycle with the controller (runs in the emulator's process)."""

    def __init__(self, config: PianoConfig) -> None:
        self.config = config
        self.events: list[tuple[float, str, int, int]] = []  # (controller time, type, note, vel)
        self._down: int | None = None
        self._note_ons = 0
        self._port: Any = None
        if config.jack_client_name is not None:
            import rtmidi

            self._port = rtmidi.MidiOut(rtapi=rtmidi.API_UNIX_JACK, name=config.jack_client_name)
            self._port.open_virtual_port("keys")

    def note_at(self, x_m: float) -> int | None:
        steps = round((x_m - self.config.reference_x_m) / self.config.white_pitch_m)
        index = WHITE_NOTES.index(self.config.reference_note) + steps
        return WHITE_NOTES[index] if 0 <= index < len(WHITE_NOTES) else None

    def __call__(self, controller: Any) -> None:
        cfg = self.config
        x, z = controller.pose[0], controller.pose[2]
        depth = cfg.surface_z_m - z
        if self._down is None and depth >= cfg.trigger_depth_m:
            note = self.note_at(x)
            if note is None:
                return
            speed = max(-controller.velocity[2], 0.0)
            velocity = max(1, min(127, round(127 * speed / cfg.full_velocity_mps)))
            self._down = note
            self._play(controller.timestamp, "note_on", note, velocity)
        elif self._down is not None and depth < cfg.release_depth_m:
            note, self._down = self._down, None
            self._play(controller.timestamp, "note_off", note, 64)

    def _play(self, t_s: float, kind: str, note: int, velocity: int) -> None:
        self.events.append((t_s, kind, note, velocity))
        if kind == "note_on":
            self._note_ons += 1
            if self._note_ons - 1 in self.config.lost_note_ons:
                return  # played, but never reaches pianobot
        if self._port is not None:
            status = 0x90 if kind == "note_on" else 0x80
            self._port.send_message([status, note, velocity])

    def close(self) -> None:
        if self._port is not None:
            self._port.close_port()
            self._port.delete()
            self._port = None
