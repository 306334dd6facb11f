"""Plausibility checks: numbers an identification or a learned map should not produce silently.

Each check takes plain values (what a result object publishes) and returns `Finding`s: what is
implausible, with its numbers and units, and the likely cause with what to do about it. The
commands print them as `warning:` lines and store them in the model or predictor file, so a
number that looks fine in a table but is physically odd never travels on unremarked.

The yardstick is the study's published model (`MSDParams()`): a soft finger whose stiffness grows
with vacuum by about 1.19 N/m per kPa, a key that rings at 7–11 Hz.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.atomic_files import write_text_atomic
from pianobot.physics.linear import frequency_response, peak_response
from pianobot.physics.msd import LinearParams, MSDParams

#: The study's law k1 = a + b·|p|: its slope b (N/m per kPa of vacuum).
STUDY_K1_SLOPE_NPM_PER_KPA = MSDParams().k1_b_npm_per_kpa
#: A slope more than this factor away from the study's (either way) is "far from the law".
SLOPE_FACTOR_FAR = 3.0
#: Fewer keystrokes than this at one vacuum level cannot pin that level's finger stiffness.
MIN_KEYSTROKES_IDENTIFY = 5
#: A learned map needs more: it has no physics to lean on between its points.
MIN_KEYSTROKES_FIT = 10
#: A parameter within this relative distance of a limit of its search range sits "at the bound".
BOUND_TOLERANCE = 0.01


@dataclass(frozen=True)
class Finding:
    """One implausible number: what it is, and what probably caused it."""

    check: str  # stable name: no_resonance, at_bound, stiffness_slope, wide_interval, few_keystrokes, ...
    message: str  # what is implausible, with numbers and units
    cause: str  # the likely cause and what to do
    subject: str = ""  # the parameter or vacuum level concerned

    def text(self) -> str:
        """One line for a terminal: the finding, then its likely cause."""
        return f"{self.message}; likely cause: {self.cause}"

    def to_dict(self) -> dict[str, str]:
        return asdict(self)


@dataclass(frozen=True)
class Interval:
    """An estimate with its 95 % interval and, when the fitter had one, its search range."""

    name: str
    value: float
    unit: str
    ci95: tuple[float, float]
    bounds: tuple[float, float] | None = None
    range_kind: str = "search range"  # what `bounds` are, as the warning names them
    at_limit: bool = False  # the fitter itself ended on a limit of this parameter (bounds unknown here)


def _kpa(levels: Iterable[float]) -> str:
    return ", ".join(f"{v:g}" for v in sorted(levels)) + " kPa"


def local_resonance_hz(lp: LinearParams) -> float:
    """The strongest interior maximum of |X2/X0| (Hz), even when the static gain is higher; NaN
    when the response has none (`physics.peak_response` reports 0 Hz in both cases)."""
    f = np.geomspace(0.1, 1000.0, 3000)
    gain, _ = frequency_response(lp, f)
    inner = np.flatnonzero((gain[1:-1] > gain[:-2]) & (gain[1:-1] > gain[2:])) + 1
    return float(f[inner[np.argmax(gain[inner])]]) if inner.size else math.nan


def no_resonance(params: MSDParams, levels_kpa: Iterable[float], *,
                 damping_ratios: Mapping[str, float] | None = None) -> list[Finding]:
    """A key response whose largest value is at 0 Hz (no resonance peak), per vacuum level.

    Args:
        params: the identified model.
        levels_kpa: the vacuum levels of the data.
        damping_ratios: identified / study value of each damping parameter; a large one names
            the cause (a stop or friction absorbed into viscous damping).
    """
    flat = {level: local_resonance_hz(params.at(level)) for level in sorted(set(levels_kpa))
            if not peak_response(params.at(level))[0] > 0.0}
    if not flat:
        return []
    hidden = {level: hz for level, hz in flat.items() if math.isfinite(hz)}
    if hidden:
        shown = ", ".join(f"{hz:.1f} Hz at {level:g} kPa" for level, hz in hidden.items())
        what = (f"the identified key response to the arm is largest at 0 Hz at {_kpa(flat)}: its resonance "
                f"({shown}) is weaker than the static response, so the key is heavily damped")
    else:
        what = f"no resonance at all in the identified key response at {_kpa(flat)}"
    worst = max((damping_ratios or {}).items(), key=lambda kv: kv[1], default=None)
    if worst is not None and worst[1] >= 10.0:
        cause = (f"{worst[0]} came out {worst[1]:.0f}× the study's value: the model absorbs something it "
                 "lacks (the key's end stop or friction) into viscous damping; run `pianobot discover` on "
                 "these runs to name the missing effect")
    else:
        cause = ("the keystrokes do not excite the resonance (slow presses, no free ringing of the key after "
                 "release) or the key marker does not follow the key; check the take with "
                 "`pianobot import mocap --plot`")
    return [Finding("no_resonance", f"{what} (the study's model and the real key ring at 7–11 Hz)", cause,
                    _kpa(flat))]


def damping_ratios(params: MSDParams) -> dict[str, float]:
    """Identified / study value of each damping parameter, named as a person reads them."""
    study = MSDParams()
    ratios = {f"key damping c2 = {params.c2_nspm:.3g} N·s/m": params.c2_nspm / study.c2_nspm,
              f"finger damping c1 = {params.c1_nspm:.3g} N·s/m": params.c1_nspm / study.c1_nspm}
    if params.c0_nspm is not None:
        ratios[f"arm–fingertip damping c0 = {params.c0_nspm:.3g} N·s/m"] = params.c0_nspm / study.c1_nspm
    return ratios


def at_bounds(estimates: Sequence[Interval], *, finger_separates: bool | None = None) -> list[Finding]:
    """Parameters that ended at a limit of the fitter's search range."""
    found = []
    for e in estimates:
        if (e.bounds is None and not e.at_limit) or not math.isfinite(e.value):
            continue
        lo, hi = e.bounds if e.bounds is not None else (math.nan, math.nan)
        # "At" includes beyond: a log-parameterised fit has no hard limit, only a plausible range.
        near = [side for side, limit in (("lower", lo), ("upper", hi)) if math.isfinite(limit)
                and (abs(e.value - limit) <= BOUND_TOLERANCE * max(abs(limit), 1e-12)
                     or (e.value < limit if side == "lower" else e.value > limit))]
        if not near and not e.at_limit:
            continue
        coupling = e.name.startswith(("k0", "c0"))
        if coupling and finger_separates is False:
            cause = ("the finger never separates from the key in this take: k0 and k1 are not separately "
                     "identifiable; identify with --coupling tied (k0 = k1, c0 = c1, as the study did)")
        elif coupling:
            cause = ("the arm–fingertip coupling is barely excited by these keystrokes; identify with "
                     "--coupling tied (k0 = k1, c0 = c1, as the study did)")
        else:
            cause = ("the data do not constrain it, so it ran to the limit the fitter allows and its "
                     "interval means nothing; add keystrokes that excite it (other speeds, depths, vacuum "
                     "levels) or fix it from another measurement")
        where = (f"the {near[0]} limit of its {e.range_kind} [{lo:.3g}, {hi:.3g}]" if near
                 else "a limit of the fitter's search range")  # the fitter said so (`Estimate.on_bound`)
        unit = "" if e.unit in ("", "1") else f" {e.unit}"  # a ratio has no unit to print ("0.001 1")
        found.append(Finding("at_bound", f"{e.name} = {e.value:.4g}{unit} is at {where}", cause, e.name))
    return found


def stiffness_slope(slope: Interval, *, levels: int) -> list[Finding]:
    """The finger's stiffness–vacuum slope b of k1 = a + b·|p| against the study's law."""
    b, (lo, hi) = slope.value, slope.ci95
    study = STUDY_K1_SLOPE_NPM_PER_KPA
    few = (f"only {levels} vacuum level{'s' if levels != 1 else ''}: the slope rests on "
           f"{'two estimates' if levels == 2 else 'too few estimates'} of k1, each trading off against "
           "the arm–fingertip coupling; record three or more levels, identify with --coupling tied, or "
           "anchor k1 with --force-log (static presses)") if levels < 3 else ""
    if not math.isfinite(b):
        return []
    if b <= 0.0:
        cause = few or ("k1 per level trades off against another parameter (the coupling k0, or the key's "
                        "stop absorbed into k1); identify with --coupling tied or anchor k1 with --force-log")
        return [Finding("stiffness_slope",
                        f"finger stiffness falls with vacuum: b = {b:.3g} N/m/kPa "
                        f"(95 % [{lo:.3g}, {hi:.3g}]); the study's law has b = +{study:g} (a jammed finger "
                        "is stiffer)", cause, slope.name)]
    ratio = b / study
    contains_study = lo <= study <= hi
    if (ratio > SLOPE_FACTOR_FAR or ratio < 1.0 / SLOPE_FACTOR_FAR) and not contains_study:
        cause = few or ("a different finger (another granular fill or membrane) or a vacuum gauge that reads "
                        "another scale; check the vacuum column and the finger, or anchor k1 with --force-log")
        return [Finding("stiffness_slope",
                        f"finger stiffness–vacuum slope b = {b:.3g} N/m/kPa is {ratio:.2g}× the study's "
                        f"{study:g} (95 % [{lo:.3g}, {hi:.3g}])", cause, slope.name)]
    return []


def wide_intervals(estimates: Sequence[Interval]) -> list[Finding]:
    """Estimates whose 95 % interval is wider than the value itself (one finding lists them all)."""
    wide = [e for e in estimates
            if math.isfinite(e.value) and e.value != 0 and (e.ci95[1] - e.ci95[0]) > abs(e.value)]
    if not wide:
        return []
    shown = "; ".join(f"{e.name} = {e.value:.3g} {e.unit} [{e.ci95[0]:.3g}, {e.ci95[1]:.3g}]" for e in wide)
    return [Finding("wide_interval", f"95 % interval wider than the value: {shown}",
                    "these keystrokes barely excite the parameter (e.g. damping needs fast presses or free "
                    "ringing, the coupling needs the finger to leave the key); treat the value as unknown, "
                    "or add keystrokes that excite it", ", ".join(e.name for e in wide))]


def few_keystrokes(counts: Mapping[float, int], minimum: int, *, kind: str = "keystrokes",
                   needed_for: str = "to identify the finger's stiffness there") -> list[Finding]:
    """Vacuum levels with fewer than `minimum` keystrokes (one finding lists them)."""
    thin = {level: n for level, n in counts.items() if n < minimum}
    if not thin:
        return []
    shown = ", ".join(f"{n} at {level:g} kPa" for level, n in sorted(thin.items()))
    return [Finding("few_keystrokes", f"too few {kind} per vacuum level: {shown} (at least {minimum} are "
                    f"needed {needed_for})", "the run has too few presses at that vacuum; add keystrokes "
                    "there (repeats of one setting help least) or leave the level out", _kpa(thin))]


#: A fitter searching log(value) has no hard limits: a value this factor below or above the
#: study's has run off (it collapsed to zero or grew without bound) and is "at a bound".
LOG_RANGE_FACTOR = 1000.0


def study_value(name: str) -> float | None:
    """The study's value of an identified parameter (`k1_npm@-40kPa`, `c0_nspm`, ...), or None
    for derived quantities. The coupling k0/c0 is compared with the finger's k1/c1 (the study ties
    them)."""
    study = MSDParams()
    base, _, where = name.partition("@")
    if base == "k1_npm" or base == "k0_npm":
        level = float(where.removesuffix("kPa")) if where.endswith("kPa") else -40.0
        return study.k1_a_npm + study.k1_b_npm_per_kpa * abs(level)
    if base == "c0_nspm":
        return study.c1_nspm
    value = getattr(study, base, None) if base in ("m1_kg", "m2_kg", "c1_nspm", "k2_npm", "c2_nspm") else None
    return float(value) if value is not None else None


def identify_findings(params: MSDParams, estimates: Sequence[Interval], counts_by_level: Mapping[float, int],
                      *, finger_separates: bool | None = None) -> list[Finding]:
    """Every check of `pianobot identify` on its result's published values.

    Args:
        params: the identified model.
        estimates: identified quantities with their 95 % intervals; parameters without `bounds`
            get the plausible range 1/1000 to 1000× the study's value (`LOG_RANGE_FACTOR`).
        counts_by_level: keystrokes fitted per vacuum level (kPa).
        finger_separates: whether the finger left the key in the data, when known.
    """
    ranged = []
    for e in estimates:
        study = study_value(e.name)
        if e.bounds is None and study is not None and study > 0:
            e = Interval(e.name, e.value, e.unit, e.ci95, (study / LOG_RANGE_FACTOR, study * LOG_RANGE_FACTOR),
                         f"plausible range (1/{LOG_RANGE_FACTOR:g} to {LOG_RANGE_FACTOR:g}× the study's value)",
                         e.at_limit)
        ranged.append(e)
    levels = sorted(counts_by_level)
    found = no_resonance(params, levels, damping_ratios=damping_ratios(params))
    found += at_bounds(ranged, finger_separates=finger_separates)
    slope = next((e for e in estimates if e.name == "k1_b_npm_per_kpa"), None)
    # With one level the slope is the study's, held fixed: there is nothing to check.
    if slope is not None and len(levels) >= 2:
        found += stiffness_slope(slope, levels=len(levels))
    # A parameter run off to a limit already has its finding; its interval adds nothing.
    stuck = {f.subject for f in found if f.check == "at_bound"}
    checked = [e for e in estimates if e.name not in stuck
               and (study_value(e.name) is not None or (e is slope and len(levels) >= 2))]
    found += wide_intervals(checked)
    found += few_keystrokes(dict(counts_by_level), MIN_KEYSTROKES_IDENTIFY)
    return found


def store_findings(path: Path, findings: Iterable[Finding]) -> Path:
    """Add the findings to a model or predictor file (JSON) as its `warnings`, atomically."""
    payload = json.loads(path.read_text(encoding="utf-8"))
    payload["warnings"] = as_dicts(findings)
    write_text_atomic(path, json.dumps(payload, indent=2, default=str) + "\n")
    return path


def as_dicts(findings: Iterable[Finding]) -> list[dict[str, Any]]:
    """JSON-able form for model and predictor files."""
    return [f.to_dict() for f in findings]


#: A learned map whose best cross-validated R² is below this explains almost nothing.
MIN_USEFUL_R2 = 0.2
#: Rank correlation of on-velocity with arm speed below this (within a level) is "louder when slower".
FALLING_RHO = -0.3


def midi_outcome(frame: pd.DataFrame) -> pd.Series:
    """Per keystroke: was its MIDI recorded (sounded, or silent by the piano's word)? False for
    a mocap take's keystrokes, which record none."""
    none = pd.Series(False, index=frame.index)
    sounded = frame["on_velocity"].notna() if "on_velocity" in frame else none
    silent = (frame["status"] == "silent") if "status" in frame else none
    noted = frame["n_note_on"].notna() if "n_note_on" in frame else none
    return sounded | silent | noted


def fit_findings(trials: pd.DataFrame, cv: pd.DataFrame) -> list[Finding]:
    """Checks of `pianobot fit`: its training keystrokes and its cross-validation table."""
    frame = trials[trials["status"].isin(["ok", "silent"])] if "status" in trials else trials
    frame = frame.dropna(subset=["down_velocity_mps"])
    found: list[Finding] = []
    outcome = midi_outcome(frame)
    if outcome.any() and not outcome.all():  # as `training_set` leaves them out
        left = int((~outcome).sum())
        found.append(Finding("no_midi", f"{left} keystroke(s) without a MIDI outcome (a take that recorded none) "
                             "are left out", "fit learns loudness, hold and silence from keystrokes with MIDI",
                             "keystrokes"))
        frame = frame[outcome]
    levels = frame["vacuum_kpa"].fillna(0.0) if "vacuum_kpa" in frame else pd.Series(0.0, index=frame.index)
    sounded = frame["on_velocity"].notna() if "on_velocity" in frame else pd.Series(False, index=frame.index)
    per_level = {float(level): int(n) for level, n in sounded.groupby(levels).sum().items()}  # type: ignore[arg-type]
    silent_levels = sorted(level for level, n in per_level.items() if n == 0)
    if silent_levels:
        found.append(Finding("silent_level", f"every keystroke at {_kpa(silent_levels)} is silent: the maps "
                             "learn nothing there but silence",
                             "the finger is too soft at that vacuum to sound the key at these speeds and "
                             "depths; `play` will not choose it (faster or deeper presses would)",
                             _kpa(silent_levels)))
    counts = {level: n for level, n in per_level.items() if n > 0}
    found += few_keystrokes(counts, MIN_KEYSTROKES_FIT, kind="sounded keystrokes",
                            needed_for="to learn a map there")
    learned = cv[~cv["model"].isin(["mean", "physics"])] if "model" in cv else cv.iloc[0:0]
    if not learned.empty and learned["r2"].notna().any():
        best = learned.iloc[int(np.nanargmax(learned["r2"].to_numpy(float)))]
        if float(best["r2"]) < MIN_USEFUL_R2:
            found.append(Finding("no_better_than_mean",
                                 f"no learned map explains on-velocity: the best cross-validated R² is "
                                 f"{float(best['r2']):.2f} ({best['model']})",
                                 "on-velocity hardly depends on the varied press parameters in these runs "
                                 "(nearly every keystroke quiet, velocities stuck at 1–2) or it depends on "
                                 "something the runs do not record (finger angle, key, a drifting finger)",
                                 str(best["model"])))
    for level, group in frame[sounded].groupby(levels[sounded]):
        if len(group) < MIN_KEYSTROKES_FIT or group["down_velocity_mps"].nunique() < 3:
            continue
        rho = float(group["down_velocity_mps"].rank().corr(group["on_velocity"].rank()))
        if rho < FALLING_RHO:
            found.append(Finding("falls_with_speed",
                                 f"at {level:g} kPa on-velocity falls as the arm presses faster "
                                 f"(rank correlation {rho:.2f})",
                                 "MIDI events assigned to the wrong keystrokes (a clock offset), or the speed "
                                 "column is not the press speed (the up speed, or mm/s stored as m/s)",
                                 f"{level:g} kPa"))
    return found
