"""Read API: `load_run(run_id, data_dir) -> Run` and `list_runs(data_dir)`."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pianobot.store.integrity import READ_ERRORS, check_run, parquet_errors
from pianobot.store.journal import read_journal
from pianobot.store.layout import (
    TRIAL_STATUSES,
    RunDamaged,
    RunPaths,
    committed_batches,
    read_json,
    resolve_run,
    runs_dir,
)

if TYPE_CHECKING:  # pandas and pyarrow take half a second to import: only where tables are read
    import pandas as pd


@dataclass(frozen=True)
class Run:
    """One run folder. Tables are read from disk on each access, so a live run shows progress."""

    run_id: str
    path: Path

    @property
    def paths(self) -> RunPaths:
        return RunPaths(self.path)

    @property
    def meta(self) -> dict[str, Any]:
        """run.json: spec, versions, rig, seed, times, status, reason, interruptions.

        Raises:
            RunDamaged: run.json is missing or does not parse.
        """
        try:
            meta = read_json(self.paths.run_json)
        except READ_ERRORS as exc:
            why = "is missing" if isinstance(exc, FileNotFoundError) else "is not readable JSON"
            raise RunDamaged(f"run.json {why}", self.run_id) from None
        if not isinstance(meta, dict):
            raise RunDamaged("run.json is not a run record", self.run_id)
        return meta

    @property
    def status(self) -> str:
        return str(self.meta.get("status", "unknown"))

    @property
    def plan(self) -> pd.DataFrame:
        """Every planned trial (empty for a run without a plan, e.g. an import)."""
        if not self.paths.plan.is_file():
            import pandas as pd

            return pd.DataFrame()
        import pyarrow.parquet as pq

        try:
            frame: pd.DataFrame = pq.read_table(self.paths.plan).to_pandas()
        except parquet_errors() as exc:
            raise RunDamaged(f"plan.parquet is unreadable ({' '.join(str(exc).split())[:80]})",
                             self.run_id) from None
        return frame

    @property
    def trials(self) -> pd.DataFrame:
        """One row per executed keystroke (the latest row of a trial that was redone)."""
        return self.table("trials")

    @property
    def samples(self) -> pd.DataFrame:
        """Time series, long across sources (arm | mocap | sim-truth), t_s from motion start."""
        return self.table("samples")

    @property
    def midi(self) -> pd.DataFrame:
        """Raw MIDI events on the run clock."""
        return self.table("midi")

    @property
    def journal(self) -> list[dict[str, Any]]:
        """Every journal event, in order."""
        return read_journal(self.paths.journal)

    def table(self, name: str, columns: list[str] | None = None) -> pd.DataFrame:
        """Table `name` ("trials" | "samples" | "midi"), optionally only some columns."""
        from pianobot.store.tables import read_run_table

        frame: pd.DataFrame = read_run_table(self.paths, name, columns).to_pandas()
        return frame


@dataclass(frozen=True)
class RunSummary:
    """One line of `pianobot runs`."""

    run_id: str
    name: str
    kind: str
    status: str
    trials_done: int
    trials_planned: int | None
    silent_pct: float
    failed: int
    lab_time_s: float
    start_utc: str | None
    reason: str | None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def load_run(run_id: str, data_dir: Path, *, check: bool = True) -> Run:
    """Open a run by id or unique id prefix.

    With `check` (the default) the run's files are checked first (each readable: the quick
    check of `check_run`), so an analysis never runs on half a table; `runs check`, `repair`
    and `show` open damaged runs with `check=False`.

    Raises:
        InputError: no such run (the message says how to list runs) or an ambiguous prefix.
        RunDamaged: a file of the run is damaged (one line: which, and how to repair).
    """
    paths = resolve_run(Path(data_dir), run_id)
    if check:
        health = check_run(paths, deep=False)
        if not health.ok:
            raise RunDamaged(health.reason, paths.run_id)
    return Run(run_id=paths.run_id, path=paths.root)


def trial_counts(run: Run, meta: dict[str, Any] | None = None) -> dict[str, int]:
    """How many trials of a run ended ok, silent or failed (a redone trial counts once, as it
    ended last).

    The writer keeps these counts in run.json (`trial_counts`) with the last batch they
    include. They are used when that batch is the run's last committed one, so `pianobot runs`
    reads no table; otherwise (a run killed before its run.json caught up, an import of an older
    pianobot, a repaired run) they are counted from the trials table.

    Raises:
        RunDamaged: the trials table had to be read and a file of it is unreadable.
    """
    recorded = (run.meta if meta is None else meta).get("trial_counts")
    keys = ("batch", *TRIAL_STATUSES)
    if isinstance(recorded, dict) and all(type(recorded.get(k)) is int for k in keys):
        try:
            last: int | None = max(committed_batches(run.paths), default=0)
        except RunDamaged:
            last = None  # the table read below says what is wrong
        if last == recorded["batch"]:
            return {status: recorded[status] for status in TRIAL_STATUSES}
    from pianobot.store.tables import trial_status_counts

    return trial_status_counts(run.paths)


def summarize_run(run: Run) -> RunSummary:
    """The `pianobot runs` line of one run, from run.json and its trial counts."""
    meta = run.meta
    counts = trial_counts(run, meta)
    done = counts["ok"] + counts["silent"]
    lab_time = meta.get("lab_time_s")
    planned = meta.get("trials_planned")
    status, reason = str(meta.get("status", "unknown")), meta.get("reason")
    if status == "running" and live_holder(run) is None:
        # A live run and one whose process died used to look the same in the listing.
        status, reason = "died", f"its process died or lost the connection; {resume_command(run)} completes it"
    return RunSummary(
        run_id=run.run_id,
        name=str(meta.get("name", "")),
        kind=str(meta.get("kind", "")),
        status=status,
        trials_done=done,
        trials_planned=None if planned is None else int(planned),
        silent_pct=100.0 * counts["silent"] / done if done else math.nan,
        failed=counts["failed"],
        lab_time_s=math.nan if lab_time is None else float(lab_time),
        start_utc=meta.get("start_utc"),
        reason=reason,
    )


def live_holder(run: Run) -> Any | None:
    """The process holding the run's lock while its lease is fresh, else None (a run left
    `running` by a process that died has none)."""
    from pianobot.store.lock import read_holder

    holder = read_holder(run.paths.lock)
    return holder if holder is not None and not holder.is_stale() else None


def load_runs(run_ids: Sequence[str], data_dir: Path) -> list[Run]:
    """The runs named, each once, in the order first named: a run given twice (or by two
    prefixes) counts once in every analysis."""
    runs: dict[str, Run] = {}
    for run_id in run_ids:
        run = load_run(run_id, data_dir)
        runs.setdefault(run.run_id, run)
    return list(runs.values())


def resume_command(run: Run) -> str:
    """`pianobot sweep --resume ID`, with `--data` where the run is not under ./data (a hint
    without it pointed at the wrong folder)."""
    data = run.path.parent.parent
    here = data.resolve() == Path("data").resolve()
    return f"pianobot sweep --resume {run.run_id}" + ("" if here else f" --data {data}")


def unfinished_note(run: Run) -> str | None:
    """What an analysis of `run` should say when the run is not a finished one: still being
    recorded (its lock is held), left behind by a process that died, or stopped early. None for a
    completed run or an import."""
    meta = run.meta
    status = str(meta.get("status", "unknown"))
    counts = trial_counts(run, meta)
    done = counts["ok"] + counts["silent"]
    planned = meta.get("trials_planned")
    of = f"{done} of {int(planned)} planned" if planned is not None else f"{done}"
    resume = f"`{resume_command(run)}` completes it"
    if status == "running":
        holder = live_holder(run)
        if holder is not None:
            return f"run {run.run_id} is still running ({holder.describe()}): only its {of} keystrokes so far are analysed"
        return (f"run {run.run_id} did not finish (its process died or lost the connection; status still "
                f"'running'): {of} keystrokes are analysed; {resume}")
    if status in ("stopped", "interrupted", "failed") and (planned is None or done < int(planned)):
        reason = meta.get("reason")
        why = f" ({reason})" if reason else ""
        return f"run {run.run_id} {status}{why} after {of} keystrokes: only those are analysed; {resume}"
    return None


def list_runs(data_dir: Path) -> list[RunSummary]:
    """Every run under `data_dir/runs`, oldest first (run ids start with their UTC time).

    A run whose files are damaged is listed with status `damaged` and the first problem as
    its reason (a quick check: every file readable; `check_run` does the full one).
    """
    base = runs_dir(Path(data_dir))
    if not base.is_dir():
        return []
    summaries = []
    for folder in sorted(base.iterdir()):
        if not folder.is_dir() or folder.name.startswith("."):
            continue
        has_files = any((folder / name).exists() for name in ("run.json", "journal.jsonl", "parts"))
        if not has_files:
            continue  # not a run folder (or one being created this very moment)
        run = Run(run_id=folder.name, path=folder)
        health = check_run(run.paths, deep=False)
        if health.ok:
            try:
                summaries.append(summarize_run(run))
                continue
            except RunDamaged as exc:
                reason = exc.problem
        else:
            reason = health.reason
        summaries.append(_damaged_summary(run, reason))
    return summaries


def _damaged_summary(run: Run, reason: str) -> RunSummary:
    """A `pianobot runs` line for a damaged run: what run.json still says, and why."""
    try:
        meta = run.meta
    except RunDamaged:
        meta = {}
    planned = meta.get("trials_planned")
    return RunSummary(
        run_id=run.run_id,
        name=str(meta.get("name", "?")),
        kind=str(meta.get("kind", "?")),
        status="damaged",
        trials_done=0,
        trials_planned=planned if isinstance(planned, int) else None,
        silent_pct=math.nan,
        failed=0,
        lab_time_s=math.nan,
        start_utc=meta.get("start_utc") if isinstance(meta.get("start_utc"), str) else None,
        reason=reason,
    )


def rig_summary(meta: dict[str, Any]) -> str:
    """The rig a run ran on, in words; says so loudly when a resume mixed rigs."""
    rig = meta.get("rig")
    if not isinstance(rig, dict):
        return "-" if rig is None else str(rig)
    spec = rig.get("spec")
    kind = str((spec.get("kind") if isinstance(spec, dict) else None) or rig.get("kind") or "?")
    text = f"{kind} ({rig.get('file')})" if rig.get("file") and rig.get("file") != kind else kind
    sessions = meta.get("rig_sessions")
    if rig.get("mixed") and isinstance(sessions, list):
        parts = [f"{s.get('file')} from session {s.get('sessions_from')}" for s in sessions
                 if isinstance(s, dict)]
        return f"MIXED: {len(parts)} rigs over {meta.get('sessions', '?')} sessions: " + "; ".join(parts)
    return text


def software_summary(meta: dict[str, Any]) -> str:
    """The pianobot that wrote a run (version and commit); every one when resumes changed it."""
    sessions = [s for s in meta.get("software_sessions") or [] if isinstance(s, dict)]
    if len(sessions) < 2:
        return _software(meta.get("pianobot_version"), meta.get("git_commit"))
    parts = [f"{_software(s.get('pianobot_version'), s.get('git_commit'))} from session {s.get('sessions_from')}"
             for s in sessions]
    return f"MIXED: {len(parts)} versions over {meta.get('sessions', '?')} sessions: " + "; ".join(parts)


def _software(version: Any, commit: Any) -> str:
    return f"pianobot {version or '?'}" + (f" (git {str(commit)[:10]})" if commit else "")
