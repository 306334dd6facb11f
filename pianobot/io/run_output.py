"""What every importer shares: the result it reports, stable trial ids, writing the new run."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from pianobot.progress import NO_PROGRESS, Progress
from pianobot.store import RunWriter, runs_dir


@dataclass(frozen=True)
class ImportResult:
    """What an import stored; `to_dict()` is the CLI's JSON."""

    run_id: str
    kind: str  # "keystroke-log" | "force-log" | "mocap"
    trials: int
    silent: int
    skipped_lines: tuple[tuple[int, str], ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)
    run_dir: str = ""  # the folder the run was written to

    def to_dict(self) -> dict[str, Any]:
        return {
            "run_id": self.run_id,
            "run_dir": self.run_dir,
            "trials": self.trials,
            "silent": self.silent,
            "skipped_lines": [{"line": n, "reason": r} for n, r in self.skipped_lines],
            **self.extra,
        }


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def trial_ids(sha: str, n: int) -> list[str]:
    """Stable ids: the same file always gives the same trial ids."""
    return [f"{sha[:10]}-{i:05d}" for i in range(n)]


def write_run(
    data_dir: Path,
    name: str,
    meta: dict[str, Any],
    trials: pd.DataFrame,
    samples: pd.DataFrame | None,
    midi: pd.DataFrame | None,
    journal: list[tuple[str, dict[str, Any]]] | None = None,
    progress: Progress = NO_PROGRESS,
) -> str:
    """Create the run, write one batch and finish it; a failure marks the run failed.

    `journal`: extra events recorded between "import started" and "import done".
    """
    writer = RunWriter.create(data_dir, name=name, kind="import", meta=meta, plan=None)
    try:
        with progress.task("writing the run", total=None) as task:
            task.update(note=writer.run_id)
            writer.journal("import started", source=meta["source"]["file"])
            if journal:
                writer.journal_many(journal)
            writer.append(trials, samples=samples, midi=midi)
            writer.journal("import done", trials=len(trials))
            writer.finish("completed")
    except BaseException:
        writer.finish("failed", reason="import aborted")
        raise
    finally:
        writer.close()
    return writer.run_id


def run_dir(data_dir: Path, run_id: str) -> str:
    """Where a run lives on disk (what the CLI tells the user)."""
    return str(runs_dir(Path(data_dir)) / run_id)


def jsonable(value: Any) -> Any:
    """A value JSON can hold (NaN and infinities become None, unknown objects their repr)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value if isinstance(value, str | int | float | bool) or value is None else repr(value)
