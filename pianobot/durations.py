"""Durations as people read them: `42 s`, `3 min 05 s`, `1 h 23 min`; `12 days` for plan sizes.

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


def format_long_duration(seconds: float) -> str:
    """`3 h`, `12 days`, `31,710 years`: a size people can judge at a glance."""
    if not math.isfinite(seconds):
        return "unknown time"
    hours = seconds / 3600
    if hours < 0.1:  # "0.0 h" for a plan of two minutes says nothing
        return f"{max(seconds / 60, 0.1):.1f} min"
    if hours < 48:
        return f"{hours:.1f} h" if hours < 10 else f"{hours:.0f} h"
    days = hours / 24
    if days < 730:
        return f"{days:,.0f} days"
    return f"{days / 365.25:,.0f} years"
