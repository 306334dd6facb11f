"""What a resume must check before the arm moves: the run is intact, and it is the same rig.

A resume continues a run that may have sat on a disk for weeks. Two things are refused with
one line before anything moves:

- a damaged run (`store.check_run`, every file against its journal record): resuming would run
  hours of trials and then fail to compact, or silently mix bad data in;
- another rig than the run started with (settle pauses, envelope, world, arm): a run is one
  condition. `--rig-override` accepts it, and run.json then records the rig of every session
  (`rig_sessions`) and marks the run as mixing rigs (`rig.mixed`), which reports show.

A resume by another pianobot (version or git commit) is not refused: it is recorded the same way
(`software_sessions`), and `runs show` and reports name every version that wrote the run.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from pydantic import ValidationError

import pianobot
from pianobot.errors import InputError
from pianobot.spec import RigSpec
from pianobot.store import RunDamaged, RunPaths, RunWriter, check_run
from pianobot.store.layout import git_commit

_SHOWN_CHANGES = 3


def refuse_damaged(paths: RunPaths) -> None:
    """RunDamaged (one line: what, and how to repair) unless every file of the run is intact."""
    health = check_run(paths, deep=True)
    if not health.ok:
        raise RunDamaged(health.reason, paths.run_id)


def rig_changes(recorded: Any, rig: RigSpec) -> list[str]:
    """How `rig` differs from the rig recorded in run.json (`a.b: old → new`), [] if the same."""
    new = rig.model_dump(mode="json")
    if not isinstance(recorded, dict):
        return []  # a run from before rigs were recorded: nothing to compare with
    try:
        # Through today's model: a setting added since the run started takes its default on
        # both sides, so only what the experimenter changed counts.
        recorded = RigSpec.model_validate_json(json.dumps(recorded)).model_dump(mode="json")
    except ValidationError:
        pass  # a rig of an older layout: compared as recorded
    return [f"{path}: {_short(old)} → {_short(value)}" for path, old, value in _diff(recorded, new, "")]


def check_same_rig(meta: dict[str, Any], rig: RigSpec, rig_label: str, *, override: bool) -> list[str]:
    """Refuse (InputError) a resume on another rig unless `override`; the changes, if any."""
    changes = rig_changes((meta.get("rig") or {}).get("spec"), rig)
    if changes and not override:
        shown = "; ".join(changes[:_SHOWN_CHANGES]) + (
            f" (and {len(changes) - _SHOWN_CHANGES} more)" if len(changes) > _SHOWN_CHANGES else "")
        raise InputError(
            f"rig {rig_label} differs from the one run {meta.get('run_id')} started with ({shown}); "
            "resume with the same rig, or give --rig-override to mix rigs in one run (recorded)",
            "--rig",
        )
    return changes


def record_rig_session(writer: RunWriter, rig: RigSpec, rig_file: str, session: int) -> None:
    """Note the rig a session runs on; mark the run as mixing rigs when it changed."""
    meta = writer.meta
    rig_meta = dict(meta.get("rig") or {})
    sessions = list(meta.get("rig_sessions") or [])
    if not sessions:  # the first session's rig, as the run recorded it when it started
        first = rig_meta.get("spec")
        sessions.append({"sessions_from": 1, "file": rig_meta.get("file"),
                         "sha256": _digest(first) if isinstance(first, dict) else None})
    spec = rig.model_dump(mode="json")
    digest = _digest(spec)
    if sessions[-1].get("sha256") == digest:
        return
    sessions.append({"sessions_from": session, "file": rig_file, "sha256": digest, "spec": spec})
    rig_meta["mixed"] = True
    writer.update_meta(rig=rig_meta, rig_sessions=sessions)


def record_software_session(writer: RunWriter, session: int) -> None:
    """Note the pianobot (version, git commit) a session runs when it differs from the last one's."""
    meta = writer.meta
    sessions = list(meta.get("software_sessions") or [])
    if not sessions:  # the first session's, as the run recorded it when it was created
        sessions.append({"sessions_from": 1, "pianobot_version": meta.get("pianobot_version"),
                         "git_commit": meta.get("git_commit")})
    now = {"pianobot_version": pianobot.__version__, "git_commit": git_commit()}
    if all(sessions[-1].get(k) == v for k, v in now.items()):
        return
    sessions.append({"sessions_from": session, **now})
    writer.update_meta(software_sessions=sessions)


def _digest(spec: Any) -> str:
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:16]


def _diff(old: Any, new: Any, path: str) -> list[tuple[str, Any, Any]]:
    if isinstance(old, dict) and isinstance(new, dict):
        out: list[tuple[str, Any, Any]] = []
        for key in sorted(set(old) | set(new), key=str):
            out += _diff(old.get(key), new.get(key), f"{path}.{key}" if path else str(key))
        return out
    return [] if old == new else [(path or "(rig)", old, new)]


def _short(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 30 else text[:27] + "..."
