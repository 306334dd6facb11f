"""Turning parsed old data into runs (kind "import") through the store.

Every import creates a NEW run and never modifies a stored one. A run's meta records the source
file name, its sha256, the layout or settings used and the skipped lines. A mocap take aligned to
an existing run becomes a *derived* run: a copy of that run's trials, samples and MIDI plus the
mocap samples re-timed to its trials, with `derived_from` naming the original. Nothing is written
when the input is rejected (InputError is raised before the run folder is created).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.arm_log import arm_samples, read_arm_log
from pianobot.io.arm_log_checks import check_direction, check_rate, check_travel
from pianobot.io.force_log import BurstRule, ForceCalibration, align_to_note_ons, read_force_log
from pianobot.io.keystroke_import import import_keystroke_log
from pianobot.io.mocap import AUTO_AXIS, MocapTake, axis_hint, read_mocap
from pianobot.io.mocap_align import ClockAlignment, run_arm_trace, starts_offset, xcorr_offset
from pianobot.io.mocap_segment import MAX_BRIDGE_S, rest_level_before, segment_take, unseen_spans
from pianobot.io.run_output import ImportResult, file_sha256, run_dir, trial_ids, write_run
from pianobot.progress import NO_PROGRESS, Progress
from pianobot.store import load_run

SAMPLE_PRE_S = 0.2  # mocap samples kept before each keystroke's motion start
SAMPLE_POST_S = 0.5  # ... and after its end (the key rings after release)


def _size(path: Path) -> str:
    """The file's size for a progress line (MB), or "" when it cannot be read."""
    try:
        return f"{path.stat().st_size / 1e6:.1f} MB"
    except OSError:
        return "?"


def import_force_log(
    path: Path | str,
    data_dir: Path | str,
    calibration: ForceCalibration | None = None,
    align_run: str | None = None,
    rule: BurstRule | None = None,
    progress: Progress = NO_PROGRESS,
) -> ImportResult:
    """Import a force capture as a new run: one trial per burst (press) with its peak force.

    With `align_run`, the capture's sample rate and clock offset are fitted to that run's note-ons
    and each burst names the trial whose note-on it matched (`matched_trial_id`).
    """
    path, data_dir = Path(path), Path(data_dir)
    calibration = calibration or ForceCalibration()
    with progress.task(f"reading the force log ({_size(path)})"):
        force = read_force_log(path, calibration, rule)
    bursts = force.bursts.copy()
    if bursts.empty:  # a run of no trials is no import: say so, store nothing
        raise InputError(f"no press found: no force burst above the baseline in "
                         f"{len(force.samples)} readings", str(path))
    extra: dict[str, Any] = {"bursts": len(bursts), "rate_hz": calibration.rate_hz}
    meta_align: dict[str, Any] | None = None
    if align_run is not None:
        run = load_run(align_run, data_dir)
        midi = run.midi
        ons = (
            midi[midi["type"] == "note_on"].drop_duplicates("trial_id") if not midi.empty else midi
        )
        fit = align_to_note_ons(
            bursts["start_index"], ons["t_s"] if not ons.empty else [], calibration.rate_hz
        )
        if fit is None:
            raise InputError(
                f"cannot align: fewer than 3 bursts match note-ons of run {run.run_id}",
                "--align-run",
            )
        bursts["start_s"] = fit.offset_s + bursts["start_index"] / fit.rate_hz
        bursts["end_s"] = fit.offset_s + bursts["end_index"] / fit.rate_hz
        note_trials = ons.sort_values("t_s")["trial_id"].tolist()
        matched: list[str | None] = [None] * len(bursts)
        for b, n in fit.matches:
            matched[b] = note_trials[n]
        bursts["matched_trial_id"] = matched
        meta_align = {"run_id": run.run_id, "rate_hz": fit.rate_hz, "clock_offset_s": fit.offset_s,
                      "matched": fit.n_matched, "rms_s": fit.rms_s}  # fmt: skip
        extra.update(rate_hz=fit.rate_hz, clock_offset_s=fit.offset_s, matched=fit.n_matched)
    sha = file_sha256(path)
    trials = pd.DataFrame(
        {
            "trial_id": trial_ids(sha, len(bursts)),
            "index": np.arange(len(bursts)),
            "attempt": 1,
            "status": "ok",
        }
    )
    trials["t_start_s"] = bursts["start_s"].to_numpy()
    for column in bursts.columns:
        if column not in ("start_s",):
            trials[column] = bursts[column].to_numpy()
    skipped = tuple((s.line, s.reason) for s in force.skipped)
    meta = {
        "source": {"file": path.name, "sha256": sha, "format": "force-log"},
        "calibration": {
            "gain_n": calibration.gain_n,
            "offset_n": calibration.offset_n,
            "rate_hz": calibration.rate_hz,
        },
        "baseline_n": force.baseline_n,
        "samples": len(force.samples),
        "truncated_lines": list(force.truncated_lines),
        "skipped_lines": [{"line": n, "reason": r} for n, r in skipped],
        "aligned_to": meta_align,
    }
    run_id = write_run(data_dir, f"import-{path.stem}", meta, trials, None, None, progress=progress)
    return ImportResult(run_id, "force-log", len(trials), 0, skipped, extra, run_dir(data_dir, run_id))


def import_mocap(
    path: Path | str,
    data_dir: Path | str,
    run_id: str | None = None,
    markers: dict[str, str] | None = None,
    min_coverage: float = 0.5,
    up_axis: str = AUTO_AXIS,
    vacuum_kpa: float | None = None,
    progress: Progress = NO_PROGRESS,
    arm_log: Path | str | None = None,
    arm_log_start_s: float | None = None,
) -> ImportResult:
    """Import a Motive take: a new run with one trial per keystroke, or aligned to `run_id`.

    Without `run_id`: trials carry the segmented keystrokes (arm speed estimate as
    down_velocity_mps, arm travel, key travel and speed) and mocap samples from motion start.
    With `run_id`: a derived run = that run's tables + mocap samples re-timed to its trials.
    `vacuum_kpa` (gauge, ≤ 0; a magnitude such as 40 is read as −40): the finger's vacuum during the take, stored on every trial (a
    Motive take does not record it); with `run_id` it fills only trials that lack one.
    `arm_log`: the UR arm log recorded with the take (`arm_log.read_arm_log`), stored as the
    trials' arm samples; `arm_log_start_s` is its controller timestamp at the take's time 0 (its
    first frame, unless the export is of a range that starts later) (default: its first row, i.e.
    the two recordings started together). Not with `run_id`, whose
    run has its own arm trace.
    """
    path, data_dir = Path(path), Path(data_dir)
    if arm_log is not None and run_id is not None:
        raise InputError("a take aligned to a run uses the run's arm trace; give --arm-log or --run, not both",
                         "--arm-log")
    if arm_log_start_s is not None and arm_log is None:
        raise InputError("gives the arm log's timestamp at the take's time 0: give --arm-log too",
                         "--arm-log-start")
    if vacuum_kpa is not None and not (math.isfinite(vacuum_kpa) and abs(vacuum_kpa) <= 100.0):
        raise InputError(f"vacuum is a gauge pressure in [-100, 0] kPa, got {vacuum_kpa:g}", "--vacuum-kpa")
    if vacuum_kpa is not None:
        vacuum_kpa = -abs(vacuum_kpa) or 0.0  # a magnitude (40) is −40 kPa, as every other command reads it
    # Stages without a count: each shows its elapsed time (a long take reads for tens of seconds).
    with progress.task(f"reading the take ({_size(path)})"):
        take = read_mocap(path, markers, min_coverage, up_axis)
    with progress.task("segmenting keystrokes"):
        strokes = segment_take(take)
    if run_id is None and strokes.empty:
        raise InputError(_no_keystrokes(take), str(path))
    sha = file_sha256(path)
    meta: dict[str, Any] = {
        "source": {"file": path.name, "sha256": sha, "format": "motive-csv"},
        "take": take.meta.get("Take Name"),
        "motive_format": take.meta.get("Format Version"),
        "frame_rate_hz": take.frame_rate_hz,
        "roles": take.roles,
        "coverage_dropped": sorted(n for n, c in take.coverage.items() if c < min_coverage),
        "stitched": take.stitched,
        "joins": [j.to_dict() for j in take.joins if take.stitched.get(j.chain)],
        "stitch_doubts": list(take.stitch_doubts),
        "up_axis": take.up_axis,
        "vacuum_kpa": vacuum_kpa,
        "skipped_lines": [],
    }
    extra: dict[str, Any] = {"keystrokes": len(strokes), "roles": take.roles, "stitched": take.stitched,
                             "up_axis": take.up_axis}
    warnings = list(take.notes)
    if take.repeated_frames:
        meta["repeated_frames"] = take.repeated_frames
        warnings.append(f"{take.repeated_frames} row(s) of the take repeated the frame number and time of the row "
                        "before: each was read once")
    unseen = unseen_spans(take)
    if unseen:
        shown = ", ".join(f"{a:.1f}–{b:.1f} s" for a, b in unseen[:3]) + (" …" if len(unseen) > 3 else "")
        warnings.append(f"the arm marker is lost for longer than the {MAX_BRIDGE_S:g} s bridged {len(unseen)} "
                        f"time(s) ({shown}): a press in those spans is not seen")
    if warnings:
        extra["warnings"] = warnings  # the arm log's are added to them; the run records them all
    if run_id is None:
        trials = _stroke_trials(strokes, sha)
        trials["vacuum_kpa"] = math.nan if vacuum_kpa is None else float(vacuum_kpa)
        samples = _stroke_samples(
            take, strokes, trials["trial_id"].tolist(), strokes["t_start_s"].to_numpy(), 0.0
        )
        if arm_log is not None:
            with progress.task("reading the arm log"):
                arm = _arm_log_samples(Path(arm_log), arm_log_start_s, take, strokes, trials, meta, extra)
            samples = pd.concat([samples, arm], ignore_index=True)
        if extra.get("warnings"):
            meta["import_warnings"] = list(extra["warnings"])  # what the import said, kept with the run
        new_id = write_run(data_dir, f"import-{path.stem}", meta, trials, samples, None, progress=progress)
        return ImportResult(new_id, "mocap", len(trials), 0, (), extra, run_dir(data_dir, new_id))
    run = load_run(run_id, data_dir)
    trials = run.trials
    if trials.empty:
        raise InputError(f"run {run.run_id} has no trials to align to", "--run")
    alignment = _align(take, strokes, trials, run.samples)
    if alignment is None:
        raise InputError(
            f"cannot align take to run {run.run_id}: no arm trace and no trial start times", "--run"
        )
    starts = trials["t_start_s"].to_numpy(dtype=np.float64) - alignment.clock_offset_s
    mocap = _stroke_samples(take, None, trials["trial_id"].tolist(), starts, 0.0, trials)
    samples = pd.concat([run.samples, mocap], ignore_index=True) if not run.samples.empty else mocap
    meta.update(derived_from=run.run_id, clock_offset_s=alignment.clock_offset_s,
                alignment={"method": alignment.method, "score": alignment.score})  # fmt: skip
    if extra.get("warnings"):
        meta["import_warnings"] = list(extra["warnings"])
    base = trials.drop(columns=["run_id"], errors="ignore")
    if vacuum_kpa is not None:
        known = base["vacuum_kpa"] if "vacuum_kpa" in base else pd.Series(math.nan, index=base.index)
        base = base.assign(vacuum_kpa=known.fillna(float(vacuum_kpa)))
    midi = run.midi.drop(columns=["run_id"], errors="ignore")
    new_id = write_run(
        data_dir,
        f"{run.run_id}-mocap",
        meta,
        base,
        samples.drop(columns=["run_id"], errors="ignore"),
        midi,
        progress=progress,
    )
    extra.update(
        clock_offset_s=alignment.clock_offset_s, derived_from=run.run_id, method=alignment.method
    )
    return ImportResult(
        new_id, "mocap", len(base), int((base["status"] == "silent").sum()), (), extra, run_dir(data_dir, new_id)
    )


def _no_keystrokes(take: MocapTake) -> str:
    """Why a take gave no keystroke to import, and what to try."""
    axis = take.up_axis.upper()
    arm = take.roles.get("arm")
    if arm is None:
        why = f"no marker moves along the vertical axis ({axis}) as an arm that presses a key does"
    else:
        down = take.down_m("arm")
        travel = 0.0 if down is None or not np.isfinite(down).any() else float(np.nanmax(down) - np.nanmin(down))
        why = f"the arm marker {arm} never moves down and back along the vertical axis ({axis}; it spans {1e3 * travel:.2f} mm)"
    hint = axis_hint(take.positions(), take.up_axis) or "; if the export's vertical axis is another one, give --up-axis"
    return f"no keystroke found: {why}{hint}; or name the arm's marker with --marker arm=NAME"


#: Recordings "started together" that the arm marker shows this far apart did not: refused.
MAX_START_SKEW_S = 0.25


def _arm_log_samples(path: Path, start_s: float | None, take: MocapTake, strokes: pd.DataFrame,
                     trials: pd.DataFrame, meta: dict[str, Any], extra: dict[str, Any]) -> pd.DataFrame:
    """The arm log's samples per keystroke, on the take's clock (meta and summary filled in)."""
    log = read_arm_log(path)
    check_rate(log, str(path))
    shift = 0.0 if start_s is None else start_s - log.first_timestamp_s
    if not math.isfinite(shift):
        raise InputError(f"expected a controller timestamp in seconds, got {start_s}", "--arm-log-start")
    marker = take.down_m("arm")
    if marker is not None:
        dt = max(1.0 / take.frame_rate_hz, 1.0 / log.rate_hz)
        check_direction(log, shift, take.t_s, marker, dt, str(path))  # a flipped log also looks shifted
        found = xcorr_offset(log.t_s - shift, log.down_m, take.t_s, marker, dt)
        if found is not None and abs(found.clock_offset_s) > MAX_START_SKEW_S:
            # x_log(t) ≈ x_marker(t − offset): the log's rows sit `offset` late on the take's clock.
            start = log.first_timestamp_s + shift + found.clock_offset_s
            raise InputError(f"the arm log and the take's arm marker are {abs(found.clock_offset_s):.3f} s apart, so the "
                             f"two recordings did not start together; give --arm-log-start {start:.3f} (the log's "
                             "timestamp at the take's time 0, as the marker suggests)", str(path))
    samples = arm_samples(log, shift, trials["trial_id"].tolist(), strokes["t_start_s"].to_numpy(),
                          strokes["t_end_s"].to_numpy(), SAMPLE_PRE_S, SAMPLE_POST_S)
    covered = int(samples["trial_id"].nunique()) if not samples.empty else 0
    if covered == 0:
        raise InputError(f"the arm log ({log.t_s[-1]:.1f} s from its first row) covers none of the take's "
                         f"{len(trials)} keystrokes; give --arm-log-start", str(path))
    if marker is not None:
        check_travel(log, shift, take.t_s, marker, strokes["t_start_s"].to_numpy(), strokes["t_end_s"].to_numpy(),
                     str(path))
    if covered < len(trials):
        extra.setdefault("warnings", []).append(
            f"the arm log covers {covered} of the take's {len(trials)} keystrokes (it ends {log.t_s[-1] - shift:.1f} s "
            f"into the take): identify and discover drive the model with it only where it covers at least 90 % "
            "of them, with the arm marker otherwise")
    meta["arm_log"] = {**log.meta(), "sha256": file_sha256(path), "start_timestamp_s": log.first_timestamp_s + shift}
    extra.update(arm_log_keystrokes=covered, arm_log_rate_hz=round(log.rate_hz, 1))
    return samples


def _align(
    take: MocapTake, strokes: pd.DataFrame, trials: pd.DataFrame, samples: pd.DataFrame
) -> ClockAlignment | None:
    t_ref, x_ref = run_arm_trace(trials, samples)
    arm = take.down_m("arm")
    if t_ref.size >= 4 and arm is not None:
        dt = min(
            1.0 / take.frame_rate_hz, float(np.median(np.diff(t_ref))) if t_ref.size > 1 else 1.0
        )
        found = xcorr_offset(t_ref, x_ref, take.t_s, arm, max(dt, 1e-3))
        if found is not None:
            return found
    if "t_start_s" in trials and not strokes.empty:
        return starts_offset(
            trials["t_start_s"].to_numpy(dtype=np.float64),
            strokes["t_start_s"].to_numpy(dtype=np.float64),
        )
    return None


def _stroke_trials(strokes: pd.DataFrame, sha: str) -> pd.DataFrame:
    """One trial per segmented keystroke; the arm speed estimate stands for the down velocity."""
    trials = pd.DataFrame(
        {
            "trial_id": trial_ids(sha, len(strokes)),
            "index": np.arange(len(strokes)),
            "attempt": 1,
            "status": "ok",
            "t_start_s": strokes["t_start_s"].to_numpy(),
            "down_velocity_mps": strokes["arm_speed_mps"].to_numpy(),
            "max_key_travel_m": strokes["key_travel_m"].to_numpy(),
        }
    )
    for column in ("t_bottom_s", "t_end_s", "duration_s", "arm_travel_m", "arm_speed_mps",
                   "fingertip_travel_m", "key_travel_m", "key_speed_mps", "key_rest_m",
                   "key_rest_after_m"):  # fmt: skip
        trials[column] = strokes[column].to_numpy()
    return trials


def _stroke_samples(
    take: MocapTake,
    strokes: pd.DataFrame | None,
    trial_ids: list[str],
    starts_s: np.ndarray,
    offset_s: float,
    trials: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """Mocap samples per trial: t_s from motion start, x0/x1/x2 from each role's rest before it.

    The window runs from SAMPLE_PRE_S before the start to SAMPLE_POST_S after the end (the
    keystroke's end, or the trial's next start / start + its own span when aligned to a run).
    """
    t = take.t_s
    signals = {
        col: take.down_m(role)
        for col, role in (("x0_m", "arm"), ("x1_m", "fingertip"), ("x2_m", "key"))
    }
    ends = strokes["t_end_s"].to_numpy() if strokes is not None else _trial_ends(starts_s)
    pieces = []
    for trial_id, start, end in zip(trial_ids, starts_s, ends, strict=True):
        if not (np.isfinite(start) and np.isfinite(end)):
            continue
        window = (t >= start - SAMPLE_PRE_S) & (t <= end + SAMPLE_POST_S)
        if not window.any():
            continue
        first = int(np.argmax(t >= start)) if (t >= start).any() else t.size - 1
        piece = {"trial_id": trial_id, "source": "mocap", "t_s": t[window] - start + offset_s}
        for column, x in signals.items():
            piece[column] = (
                (x[window] - rest_level_before(t, x, first))
                if x is not None
                else np.full(int(window.sum()), np.nan)
            )
        pieces.append(pd.DataFrame(piece))
    if not pieces:
        return pd.DataFrame(columns=["trial_id", "source", "t_s", "x0_m", "x1_m", "x2_m"])
    return pd.concat(pieces, ignore_index=True)


def _trial_ends(starts_s: np.ndarray) -> np.ndarray:
    """Without segmentation, a trial's window ends where the next trial starts (last: +2 s)."""
    order = np.argsort(starts_s)
    ends = np.full(starts_s.size, np.nan)
    sorted_starts = starts_s[order]
    following = (
        np.append(sorted_starts[1:] - SAMPLE_POST_S - SAMPLE_PRE_S, sorted_starts[-1] + 2.0)
        if starts_s.size
        else sorted_starts
    )
    ends[order] = following
    return ends


__all__ = ["ImportResult", "file_sha256", "import_force_log", "import_keystroke_log", "import_mocap"]
