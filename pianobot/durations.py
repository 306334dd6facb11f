"""Durations as people read them: `42 s`, `3 min 05 s`, `1 h 23 min`.

A leaf module (no imports of the package): the run list, the dry run and reports all print lab
times, and `pianobot runs` must not load the planning code just for that.
"""

from __future__ import annotations

import math


def format_duration(seconds: float) -> str:
    """`42 s`, `3 min 05 s`, `1 h 23 min`; `-` when unknown (NaN)."""
    if not math.isfinite(seconds):
        return "-"
    s = int(round(seconds))
    if s < 60:
        return f"{seconds:.1f} s" if seconds < 10 else f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"
