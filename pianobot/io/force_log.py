"""Reader of force-sensor serial captures (`Analog reading = N`, one per line, no timestamps).

The lab's Arduino printed one reading per line at about 47.8 samples/s; a capture program saved
them, so the first and last lines are often cut (`g reading = 0`, `Analog rea`): those are dropped
quietly, other junk lines are reported. Readings become newtons with a linear calibration (the
study's F = 0.0353·reading + 0.204 N by default) and time from the sample index and rate.

Bursts (one press of the finger on the sensor) are found with a hysteresis threshold above a
robust baseline: a burst starts when the force rises above `baseline + on_n` and ends when it
falls back below `baseline + off_n`; bursts closer than `merge_gap_s` are merged (a one-sample dip
is not a release) and bursts shorter than `min_duration_s` are dropped (a one-sample spike is not
a press). `on_n` defaults to a fraction of the signal's range so the same rule works for the 1 N
presses on the piano and the 2.5 N presses without it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.keystroke_log import SkippedLine
from pianobot.io.source import read_input_bytes

FloatArray = npt.NDArray[np.float64]

DEFAULT_RATE_HZ = 47.8
DEFAULT_GAIN_N = 0.0353  # newtons per reading (the study's calibration)
DEFAULT_OFFSET_N = 0.204
# An ADC reading has a few digits; a longer number is a garbled line, never a force (and
# a 100,000-digit one must not reach int()).
_LINE = re.compile(r"Analog reading = (-?\d{1,9})")
_PREFIX = "Analog reading = "
BURST_COLUMNS = (
    "start_s", "end_s", "duration_s", "t_peak_s", "peak_force_n", "peak_above_baseline_n",
    "impulse_ns", "start_index", "end_index",
)  # fmt: skip


@dataclass(frozen=True)
class ForceCalibration:
    """Linear reading → force map and the sample rate."""

    gain_n: float = DEFAULT_GAIN_N
    offset_n: float = DEFAULT_OFFSET_N
    rate_hz: float = DEFAULT_RATE_HZ

    def force_n(self, reading: npt.ArrayLike) -> FloatArray:
        return np.asarray(reading, dtype=np.float64) * self.gain_n + self.offset_n


@dataclass(frozen=True)
class BurstRule:
    """Burst segmentation settings (None = derived from the signal)."""

    on_n: float | None = None  # rise above baseline that starts a burst
    off_n: float | None = None  # level above baseline below which it ends
    on_fraction: float = 0.15  # default on_n: this fraction of (99.9th percentile − baseline)
    min_duration_s: float = 0.15
    merge_gap_s: float = 0.25


@dataclass(frozen=True)
class ForceLog:
    """A parsed capture: `samples` (t_s, reading, force_n), `bursts` (one row per press)."""

    path: Path
    calibration: ForceCalibration
    samples: pd.DataFrame
    bursts: pd.DataFrame
    baseline_n: float
    skipped: tuple[SkippedLine, ...]
    truncated_lines: tuple[int, ...]


def read_force_log(
    path: Path | str,
    calibration: ForceCalibration | None = None,
    rule: BurstRule | None = None,
) -> ForceLog:
    """Parse a capture and segment its bursts.

    Raises:
        InputError: missing, empty or binary file, no `Analog reading = N` line, or a
            non-positive rate.
    """
    path = Path(path)
    where = str(path)
    calibration = calibration or ForceCalibration()
    rule = rule or BurstRule()
    if not (calibration.rate_hz > 0 and math.isfinite(calibration.rate_hz)):
        raise InputError(f"sample rate should be > 0 Hz, got {calibration.rate_hz}", "--rate-hz")
    for option, value in (("--gain-n", calibration.gain_n), ("--offset-n", calibration.offset_n)):
        if not math.isfinite(value):
            raise InputError(f"must be a finite number of newtons, got {value}", option)
    lines = _read_text(path).splitlines()
    readings, skipped, truncated = parse_readings(lines)
    if not readings:
        raise InputError("no 'Analog reading = N' line found (not a force capture)", where)
    reading = np.asarray(readings, dtype=np.float64)
    force = calibration.force_n(reading)
    t = np.arange(len(reading)) / calibration.rate_hz
    samples = pd.DataFrame({"t_s": t, "reading": reading.astype(np.int64), "force_n": force})
    baseline = float(np.median(force[force <= np.percentile(force, 50)]))
    bursts = segment_bursts(t, force, baseline, rule)
    return ForceLog(path, calibration, samples, bursts, baseline, tuple(skipped), tuple(truncated))


def _read_text(path: Path) -> str:
    return read_input_bytes(path, "a force capture").decode("utf-8", errors="replace")


def parse_readings(lines: list[str]) -> tuple[list[int], list[SkippedLine], list[int]]:
    """Readings in order, junk lines (reported), and cut first/last lines (tolerated).

    A first line that is the tail of a reading line, or a last line that is its head, is a capture
    cut mid-line: dropped without complaint (its number may be cut too).
    """
    readings: list[int] = []
    skipped: list[SkippedLine] = []
    truncated: list[int] = []
    numbered = [(n, line.strip()) for n, line in enumerate(lines, start=1) if line.strip()]
    for position, (number, text) in enumerate(numbered):
        match = _LINE.fullmatch(text)
        if match:
            readings.append(int(match.group(1)))
            continue
        edge = position in (0, len(numbered) - 1)
        if edge and _is_cut(text, first=position == 0):
            truncated.append(number)
        else:
            skipped.append(SkippedLine(number, f"not 'Analog reading = N': {text[:40]!r}"))
    return readings, skipped, truncated


def _is_cut(text: str, *, first: bool) -> bool:
    """A first line that is the tail of a reading line, or a last line that is its head."""
    if first:
        return any(
            text.startswith(_PREFIX[k:]) and text[len(_PREFIX) - k :].isdigit()
            for k in range(len(_PREFIX) + 1)
        )
    return _PREFIX.startswith(text) or (
        text.startswith(_PREFIX) and text[len(_PREFIX) :].lstrip("-").isdigit()
    )


def segment_bursts(
    t_s: FloatArray, force_n: FloatArray, baseline_n: float, rule: BurstRule
) -> pd.DataFrame:
    """One row per burst (see the module docstring for the rule)."""
    above = force_n - baseline_n
    top = float(np.percentile(above, 99.9)) if above.size else 0.0
    on = rule.on_n if rule.on_n is not None else rule.on_fraction * top
    off = rule.off_n if rule.off_n is not None else 0.4 * on
    if not (on > 0 and math.isfinite(on)):
        return pd.DataFrame(columns=list(BURST_COLUMNS))
    dt = float(t_s[1] - t_s[0]) if t_s.size > 1 else 1.0
    spans: list[list[int]] = []
    inside = False
    for i, value in enumerate(above):
        if not inside and value > on:
            start = i
            while start > 0 and above[start - 1] > off:  # back to where the rise began
                start -= 1
            inside = True
            spans.append([start, i])
        elif inside:
            if value <= off:
                spans[-1][1] = i
                inside = False
    if inside:
        spans[-1][1] = len(above)
    merged: list[list[int]] = []
    for span in spans:
        if merged and (span[0] - merged[-1][1]) * dt < rule.merge_gap_s:
            merged[-1][1] = span[1]
        else:
            merged.append(span)
    rows = []
    for start, end in merged:
        if (end - start) * dt < rule.min_duration_s:
            continue
        segment = force_n[start:end]
        peak = start + int(np.argmax(segment))
        rows.append(
            {
                "start_s": float(t_s[start]),
                "end_s": float(t_s[end - 1]) + dt,
                "duration_s": (end - start) * dt,
                "t_peak_s": float(t_s[peak]),
                "peak_force_n": float(force_n[peak]),
                "peak_above_baseline_n": float(force_n[peak] - baseline_n),
                "impulse_ns": float(np.sum(segment - baseline_n) * dt),
                "start_index": start,
                "end_index": end,
            }
        )
    return pd.DataFrame(rows, columns=list(BURST_COLUMNS))


@dataclass(frozen=True)
class RateAlignment:
    """Force-capture clock fitted to MIDI note-ons: t_note ≈ offset_s + sample_index / rate_hz."""

    rate_hz: float
    offset_s: float
    n_matched: int
    rms_s: float
    matches: tuple[tuple[int, int], ...]  # (burst row, note-on position) pairs


def align_to_note_ons(
    burst_index: npt.ArrayLike,
    note_on_t_s: npt.ArrayLike,
    nominal_rate_hz: float = DEFAULT_RATE_HZ,
    max_shift: int = 8,
) -> RateAlignment | None:
    """Estimate the capture's sample rate from burst onsets and the run's note-on times.

    Each note-on comes from a press that also made a burst, but presses that stayed silent make
    bursts without note-ons. Starting from the nominal rate and each pairing of one of the first
    bursts with one of the first note-ons, notes are matched one-to-one to the nearest predicted
    burst time (within 40 % of the typical burst spacing) and the line t = offset + index/rate is
    refitted by least squares until the matches stop changing, over a span of notes that doubles
    (8, 16, ...) until it covers them all. The fit matching most notes (then
    the smallest rms) wins. None when fewer than 3 pairs match.
    """
    index = np.asarray(burst_index, dtype=np.float64)
    notes = np.sort(np.asarray(note_on_t_s, dtype=np.float64))
    notes = notes[np.isfinite(notes)]
    if index.size < 3 or notes.size < 3:
        return None
    spacing_s = float(np.median(np.diff(index))) / nominal_rate_hz
    tolerance = 0.4 * spacing_s
    best: RateAlignment | None = None
    for j in range(min(max_shift, index.size)):
        for i in range(min(max_shift, notes.size)):
            slope, offset = 1.0 / nominal_rate_hz, notes[i] - index[j] / nominal_rate_hz
            pairs: list[tuple[int, int]] = []
            # Grow the matched span gradually: a wrong nominal rate drifts far from the truth
            # over a long capture, but barely over the first few presses.
            horizon = 8
            while slope > 0:
                span = notes[: min(horizon, notes.size)]
                for _ in range(10):
                    found = _match(offset + slope * index, span, tolerance)
                    if len(found) < 3 or found == pairs:
                        break
                    pairs = found
                    x = index[[p[0] for p in pairs]]
                    y = notes[[p[1] for p in pairs]]
                    slope, offset = (float(c) for c in np.polyfit(x, y, 1))
                    if slope <= 0:
                        break
                if horizon >= notes.size:
                    break
                horizon *= 2
            if len(pairs) < 3 or slope <= 0:
                continue
            residual = notes[[p[1] for p in pairs]] - (
                offset + slope * index[[p[0] for p in pairs]]
            )
            candidate = RateAlignment(
                1.0 / slope, offset, len(pairs), float(np.sqrt(np.mean(residual**2))), tuple(pairs)
            )
            if best is None or (candidate.n_matched, -candidate.rms_s) > (
                best.n_matched,
                -best.rms_s,
            ):
                best = candidate
    return best


def _match(predicted: FloatArray, notes: FloatArray, tolerance: float) -> list[tuple[int, int]]:
    """One-to-one nearest pairs (burst, note) closer than `tolerance`, closest first."""
    order = np.argsort(predicted)
    pos = np.searchsorted(predicted[order], notes)
    candidates = []
    for n, p in enumerate(pos):
        for q in (p - 1, p):
            if 0 <= q < order.size:
                distance = abs(predicted[order[q]] - notes[n])
                if distance < tolerance:
                    candidates.append((distance, int(order[q]), n))
    used_b: set[int] = set()
    used_n: set[int] = set()
    pairs = []
    for _, b, n in sorted(candidates):
        if b not in used_b and n not in used_n:
            used_b.add(b)
            used_n.add(n)
            pairs.append((b, n))
    return sorted(pairs)
