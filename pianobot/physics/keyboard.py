"""Key geometry of an 88-key piano: where each key's centre lies along the keyboard.

Positions are lateral (along the keyboard, towards the treble positive), metres, relative to a
reference key where the arm was calibrated (the study used B3 = MIDI 59, left of middle C).

White keys sit at multiples of the white-key pitch (23.5 mm on a standard keyboard, one octave
= 7 pitches = 164.5 mm). Black keys are not mid-way between their white neighbours: on a real
keyboard the back of the C–E group is split into 5 equal slots (C C♯ D D♯ E, each 3/5 pitch)
and the back of the F–B group into 7 (F F♯ G G♯ A A♯ B, each 4/7 pitch), and the black keys fill
the black slots. Measured from the left edge of C, in white pitches:

    C♯ 0.9   D♯ 2.1   (the C/D and D/E boundaries are at 1 and 2: C♯ leans left, D♯ right)
    F♯ 3.857 G♯ 5.0   A♯ 6.143   (F/G at 4, G/A at 5, A/B at 6: F♯ left, G♯ centred, A♯ right)

Real keyboards deviate by a millimetre or so; per-note calibrated offsets correct for that.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

LOWEST_NOTE = 21  # A0
HIGHEST_NOTE = 108  # C8
WHITE_PITCH_M = 0.0235
REFERENCE_NOTE = 59  # B3, the key the study calibrated the arm on

# Centre of each pitch class from the left edge of C, in white-key pitches (see module doc).
_CENTER_IN_OCTAVE: tuple[float, ...] = (
    0.5,  # C
    1.5 * 3 / 5,  # C♯ = 0.9
    1.5,  # D
    3.5 * 3 / 5,  # D♯ = 2.1
    2.5,  # E
    3.5,  # F
    3 + 1.5 * 4 / 7,  # F♯ ≈ 3.857
    4.5,  # G
    3 + 3.5 * 4 / 7,  # G♯ = 5.0
    5.5,  # A
    3 + 5.5 * 4 / 7,  # A♯ ≈ 6.143
    6.5,  # B
)
_BLACK_PITCH_CLASSES = frozenset({1, 3, 6, 8, 10})


def check_note(note: object) -> int:
    """The note as an int, or ValueError naming the valid range and the bad value."""
    if isinstance(note, float) and note.is_integer():
        note = int(note)
    if isinstance(note, bool) or not isinstance(note, int):
        raise ValueError(
            f"Key number should be an integer in [{LOWEST_NOTE}, {HIGHEST_NOTE}], got {note!r}."
        )
    if not LOWEST_NOTE <= note <= HIGHEST_NOTE:
        raise ValueError(f"Key number should be in [{LOWEST_NOTE}, {HIGHEST_NOTE}], got {note}.")
    return note


def is_black(note: int) -> bool:
    """Whether a MIDI note (21–108) is a black key."""
    return check_note(note) % 12 in _BLACK_PITCH_CLASSES


def _nominal_pitches(note: int) -> float:
    """Key centre in white pitches from the left edge of C at MIDI octave 0."""
    octave, pitch_class = divmod(note, 12)
    return 7 * octave + _CENTER_IN_OCTAVE[pitch_class]


def key_center_m(
    note: int,
    *,
    white_pitch_m: float = WHITE_PITCH_M,
    offsets: Mapping[int, float] | None = None,
    reference_note: int = REFERENCE_NOTE,
) -> float:
    """Lateral position of a key's centre relative to the reference key (metres, treble +).

    `offsets` maps notes to calibrated corrections (metres) added to the nominal position.
    """
    note = check_note(note)
    reference_note = check_note(reference_note)
    if not white_pitch_m > 0.0:
        raise ValueError(f"White-key pitch should be > 0 m, got {white_pitch_m}.")
    offset = 0.0 if offsets is None else float(offsets.get(note, 0.0))
    return (_nominal_pitches(note) - _nominal_pitches(reference_note)) * white_pitch_m + offset


@dataclass(frozen=True)
class KeyboardGeometry:
    """A calibrated keyboard: pitch, reference key and per-note offsets (metres)."""

    white_pitch_m: float = WHITE_PITCH_M
    reference_note: int = REFERENCE_NOTE
    offsets_m: tuple[tuple[int, float], ...] = ()  # (note, correction) pairs, sorted by note

    def __post_init__(self) -> None:
        if not self.white_pitch_m > 0.0:
            raise ValueError(f"White-key pitch should be > 0 m, got {self.white_pitch_m}.")
        object.__setattr__(self, "reference_note", check_note(self.reference_note))
        pairs = dict((check_note(n), float(dx)) for n, dx in self.offsets_m)
        if len(pairs) != len(self.offsets_m):
            raise ValueError("offsets_m names a key twice.")
        object.__setattr__(self, "offsets_m", tuple(sorted(pairs.items())))

    @property
    def offsets(self) -> dict[int, float]:
        """The calibrated offsets as a note → metres mapping."""
        return dict(self.offsets_m)

    def center_m(self, note: int) -> float:
        """Lateral position of a key's centre relative to the reference key."""
        return key_center_m(
            note,
            white_pitch_m=self.white_pitch_m,
            offsets=self.offsets,
            reference_note=self.reference_note,
        )

    def with_offset(self, note: int, offset_m: float) -> KeyboardGeometry:
        """A copy with one key's calibrated offset set (replacing any earlier one)."""
        offsets = self.offsets
        offsets[check_note(note)] = float(offset_m)
        return KeyboardGeometry(self.white_pitch_m, self.reference_note, tuple(offsets.items()))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (offsets as {"note": metres})."""
        return {
            "white_pitch_m": self.white_pitch_m,
            "reference_note": self.reference_note,
            "offsets_m": {str(n): dx for n, dx in self.offsets_m},
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> KeyboardGeometry:
        """Inverse of `to_dict`; unknown keys raise ValueError naming them."""
        unknown = sorted(set(data) - {"white_pitch_m", "reference_note", "offsets_m"})
        if unknown:
            raise ValueError(f"unknown keyboard field(s) {unknown}.")
        offsets = data.get("offsets_m", {})
        pairs = offsets.items() if isinstance(offsets, Mapping) else offsets
        return cls(
            white_pitch_m=float(data.get("white_pitch_m", WHITE_PITCH_M)),
            reference_note=int(data.get("reference_note", REFERENCE_NOTE)),
            offsets_m=tuple((int(n), float(dx)) for n, dx in pairs),
        )
