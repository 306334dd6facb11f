"""Does an arm log show the arm the take's marker saw? Checked before an import stores it.

An arm log is read by its columns' names (`arm_log.read_arm_log`): the tool point's z in metres,
downward negative. A log that is not that still reads: one recorded in millimetres, one whose
press axis is another pose column (a robot mounted another way), one whose z points down. Stored,
it drives the model with a wrong arm, and identification and discovery find wrong physics and
clock offsets without a word about the log. The arm marker of the take saw the same motion, so
the two are compared on the take's keystrokes:

- direction: the log's cross-correlation with the marker is stronger with its sign flipped
  (checked first: a log moving the other way also looks shifted in time);
- size: the log's travel in each keystroke against the marker's (median ratio), with the units
  it suggests (x1000: millimetres, x100: centimetres);
- rate: a log sampled below `MIN_RATE_HZ` has timestamps in milliseconds, or is not a UR log.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pianobot.errors import InputError
from pianobot.io.arm_log import ArmLog
from pianobot.io.mocap_align import xcorr_offset

FloatArray = npt.NDArray[np.float64]

#: UR controllers stream at 125 or 500 Hz; a log far slower is not read in seconds.
MIN_RATE_HZ = 10.0
#: The log's travel per keystroke may differ from the marker's by this factor either way (the
#: marker sits on the finger's mount, a little off the tool point) before the log is refused.
TRAVEL_RATIO_LIMIT = 3.0
#: Units a travel ratio points at (the ratio of the log's numbers to metres).
_UNIT_RATIOS = ((1000.0, "millimetres"), (100.0, "centimetres"))


def check_rate(log: ArmLog, where: str) -> None:
    """InputError for a log whose timestamps cannot be seconds of a UR controller's stream."""
    if log.rate_hz < MIN_RATE_HZ:
        raise InputError(f"the arm log has {log.rate_hz:.3g} rows per second of its timestamps; a UR controller "
                         f"streams 125 or 500 Hz: are the timestamps in milliseconds (expected seconds)?", where)


def check_direction(log: ArmLog, shift_s: float, t_take_s: FloatArray, marker_down_m: FloatArray,
                    dt_s: float, where: str) -> None:
    """InputError when the log's tool point moves up as the arm marker moves down."""
    same = xcorr_offset(log.t_s - shift_s, log.down_m, t_take_s, marker_down_m, dt_s)
    flipped = xcorr_offset(log.t_s - shift_s, -log.down_m, t_take_s, marker_down_m, dt_s)
    if same is None or flipped is None:
        return
    if flipped.score > 0.5 and flipped.score > same.score + 0.2:
        raise InputError(f"the arm log's tool point moves up where the take's arm marker moves down (correlation "
                         f"{flipped.score:.2f} with its sign flipped, {same.score:.2f} as it is): is its z axis "
                         "pointing down? pianobot reads actual_TCP_pose_2 as the base frame's z, up positive", where)


def check_travel(log: ArmLog, shift_s: float, t_take_s: FloatArray, marker_down_m: FloatArray,
                 starts_s: FloatArray, ends_s: FloatArray, where: str) -> None:
    """InputError when the log's travel per keystroke is far from the arm marker's."""
    t_log = log.t_s - shift_s
    travels = []  # (log, marker) per keystroke both saw
    for start, end in zip(starts_s, ends_s, strict=True):
        in_log = (t_log >= start) & (t_log <= end)
        in_take = (t_take_s >= start) & (t_take_s <= end) & np.isfinite(marker_down_m)
        if in_log.sum() >= 3 and in_take.sum() >= 3 and np.ptp(marker_down_m[in_take]) > 0.0:
            travels.append((float(np.ptp(log.down_m[in_log])), float(np.ptp(marker_down_m[in_take]))))
    if not travels:
        return
    ratio = float(np.median([log_m / marker_m for log_m, marker_m in travels]))
    if 1.0 / TRAVEL_RATIO_LIMIT <= ratio <= TRAVEL_RATIO_LIMIT:
        return
    log_median, marker_median = (float(np.median(column)) for column in zip(*travels, strict=True))
    unit = next((name for factor, name in _UNIT_RATIOS if 0.5 * factor <= ratio <= 2.0 * factor), None)
    if unit is not None:
        why = f"is it in {unit}? pianobot reads the tool point's pose in metres, as ur_rtde records it"
    elif ratio < 1.0 / TRAVEL_RATIO_LIMIT:
        why = ("the tool point barely moves down: is the press along another pose column (a robot mounted "
               "another way)? pianobot reads actual_TCP_pose_2, the base frame's z")
    else:
        why = "its z does not move as the arm marker does"
    raise InputError(f"the arm log's tool point moves {log_median:.4g} (in its units, read as metres) per keystroke "
                     f"against {1e3 * marker_median:.3g} mm on the take's arm marker: {why}", where)
