"""Keyboard geometry: key centres along an 88-key piano."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.physics.keyboard import (
    HIGHEST_NOTE,
    LOWEST_NOTE,
    KeyboardGeometry,
    is_black,
    key_center_m,
)

NOTES = range(LOWEST_NOTE, HIGHEST_NOTE + 1)
WHITE = [n for n in NOTES if not is_black(n)]
BLACK = [n for n in NOTES if is_black(n)]


def test_eighty_eight_keys_52_white_36_black() -> None:
    assert len(WHITE) == 52 and len(BLACK) == 36
    assert is_black(61) and is_black(70) and not is_black(60) and not is_black(64)


def test_reference_key_is_zero_and_positions_are_monotone() -> None:
    assert key_center_m(59) == 0.0
    centres = [key_center_m(n) for n in NOTES]
    assert all(b > a for a, b in zip(centres, centres[1:], strict=False))
    assert key_center_m(60) == pytest.approx(0.0235)  # middle C is one white key right of B3


@pytest.mark.parametrize("pitch", [0.0235, 0.022])
def test_white_keys_at_multiples_of_the_pitch(pitch: float) -> None:
    for i, note in enumerate(WHITE):
        expected = (i - WHITE.index(59)) * pitch
        assert key_center_m(note, white_pitch_m=pitch) == pytest.approx(expected, abs=1e-12)
    # An octave is seven white keys, for black keys too.
    for note in (n for n in BLACK if n + 12 <= HIGHEST_NOTE):
        octave = key_center_m(note + 12, white_pitch_m=pitch) - key_center_m(
            note, white_pitch_m=pitch
        )
        assert octave == pytest.approx(7 * pitch)


def test_black_keys_sit_off_centre() -> None:
    w = 0.0235
    c, d, e, f, g, a, b = (key_center_m(n) for n in (60, 62, 64, 65, 67, 69, 71))
    cs, ds, fs, gs, as_ = (key_center_m(n) for n in (61, 63, 66, 68, 70))
    assert c < cs < d < ds < e and f < fs < g < gs < a < as_ < b
    # C♯ leans towards C, D♯ towards E (0.1 pitch off the boundary between their neighbours).
    assert cs == pytest.approx((c + d) / 2 - 0.1 * w)
    assert ds == pytest.approx((d + e) / 2 + 0.1 * w)
    # In the F–B group: F♯ leans left, G♯ centred, A♯ leans right, by 1/7 pitch.
    assert fs == pytest.approx((f + g) / 2 - w / 7)
    assert gs == pytest.approx((g + a) / 2)
    assert as_ == pytest.approx((a + b) / 2 + w / 7)


@pytest.mark.parametrize("bad", [20, 110, 0, -5])
def test_out_of_range_keys_name_range_and_value(bad: int) -> None:
    with pytest.raises(ValueError, match=rf"Key number should be in \[21, 108\], got {bad}\."):
        key_center_m(bad)
    with pytest.raises(ValueError, match="got"):
        is_black(bad)
    with pytest.raises(ValueError, match="integer"):
        key_center_m(60.5)  # type: ignore[arg-type]


def test_other_reference_and_offsets() -> None:
    assert key_center_m(60, reference_note=60) == 0.0
    assert key_center_m(59, reference_note=60) == pytest.approx(-0.0235)
    assert key_center_m(62, offsets={62: 0.001}) == pytest.approx(2 * 0.0235 + 0.001)
    assert key_center_m(64, offsets={62: 0.001}) == pytest.approx(3 * 0.0235)


@settings(deadline=None)  # no wall-clock limits: the machine is shared
@given(st.integers(LOWEST_NOTE, HIGHEST_NOTE), st.floats(-0.003, 0.003))
def test_geometry_object_matches_function(note: int, offset: float) -> None:
    geo = KeyboardGeometry().with_offset(note, offset)
    assert geo.center_m(note) == pytest.approx(key_center_m(note) + offset, abs=1e-12)
    assert KeyboardGeometry.from_dict(geo.to_dict()) == geo


def test_geometry_validation() -> None:
    with pytest.raises(ValueError, match="got 110"):
        KeyboardGeometry(reference_note=110)
    with pytest.raises(ValueError, match="pitch"):
        KeyboardGeometry(white_pitch_m=0.0)
    with pytest.raises(ValueError, match="twice"):
        KeyboardGeometry(offsets_m=((60, 0.001), (60, 0.002)))
    with pytest.raises(ValueError, match="unknown"):
        KeyboardGeometry.from_dict({"pitch": 0.02})
    geo = KeyboardGeometry(offsets_m=((64, 0.001), (60, -0.001)))
    assert geo.offsets_m == ((60, -0.001), (64, 0.001))
    assert geo.with_offset(60, 0.0).offsets == {60: 0.0, 64: 0.001}
