"""Property tests: random and truncated input never crashes the parsers.

Each parser either returns a result (with skipped lines) or raises pianobot's InputError.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pianobot.errors import InputError
from pianobot.io.force_log import read_force_log
from pianobot.io.keystroke_log import read_keystroke_log
from pianobot.io.mocap import read_mocap

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

LOG_LINES = [
    "{'start_position_l': [-0.5, -0.1, 0.1, -2.8, 1.2, -0.09], 'acc': 0.5}",
    "{'control': [60, 45, 0.5, 0.045000000000000005, 0.04, 0.05, 0], 'midi': [[[144, 57, 3, 0], 1000], [[128, 57, 9, 0], 2300]]}",
    "{'control': [60, 45, 0.5, 0.05, 0.04, 0.05, 0], 'midi': []}",
    "{'control': [0, 4.01, 3.61, 0.774, 0.035, 1], 'midi': [[[144, 60, 94, 0], 5376], [[144, 60, 52, 0], 5428]]}",
    "{'control': [0, 0.31, 0.07, 0.1361, 1], 'midi': [[[128, 60, 76, 0], 4512]]}",
]
FORCE_LINES = [
    "Analog reading = 0",
    "Analog reading = 17",
    "Analog reading = 35",
    "Analog rea",
    "g = 3",
]
MOCAP_HEAD = [
    "Format Version,1.21,Take Name,t,Capture Frame Rate,120.000000,Export Frame Rate,120.000000,Length Units,Meters",
    "",
    ",,Marker,Marker,Marker",
    ",,Unlabeled:1,Unlabeled:1,Unlabeled:1",
    ',,"A","A","A"',
    ",,Position,Position,Position",
    "Frame,Time,X,Y,Z",
] + [f"{i},{i / 120:.6f},0.1,{0.2 - (0.005 if 40 < i < 80 else 0):.6f},0.3" for i in range(120)]


def _check(parse, data: bytes) -> None:  # type: ignore[no-untyped-def]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "input"
        path.write_bytes(data)
        try:
            parse(path)
        except InputError as error:
            assert str(error)


def _mutated(lines: list[str]) -> st.SearchStrategy[bytes]:
    text = "\n".join(lines) + "\n"
    cut = st.tuples(st.integers(0, len(text)), st.integers(0, len(text))).map(
        lambda ab: text[min(ab) : max(ab)].encode()
    )
    shuffled = st.lists(
        st.sampled_from(lines + ["", "garbage", "{'control': [1, 2"]), max_size=30
    ).map(lambda ls: "\n".join(ls).encode())
    noisy = st.tuples(st.integers(0, len(text)), st.text(max_size=20)).map(
        lambda p: (text[: p[0]] + p[1] + text[p[0] :]).encode("utf-8", "replace")
    )
    return st.one_of(cut, shuffled, noisy, st.binary(max_size=300))


@SETTINGS
@given(_mutated(LOG_LINES))
def test_keystroke_log_never_crashes(data: bytes) -> None:
    _check(read_keystroke_log, data)


@SETTINGS
@given(_mutated(FORCE_LINES * 20))
def test_force_log_never_crashes(data: bytes) -> None:
    _check(read_force_log, data)


@SETTINGS
@given(_mutated(MOCAP_HEAD))
def test_mocap_never_crashes(data: bytes) -> None:
    _check(read_mocap, data)
