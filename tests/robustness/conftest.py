"""Runs to damage: the quickstart sweep killed (parts, stale lock), stopped (compacted), done.

Made once per test session (per xdist worker); each test copies the one it needs.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from pianobot.run import run_sweep
from pianobot.run.records import Record, TrialDone
from pianobot.run.signals import StopControl
from robustness.harness import QUICKSTART, copy_tree

TRIALS_BEFORE_KILL = 8  # of the quickstart's 16; 2 per part batch


def _sweep_until(data_dir: Path, *, kill: bool) -> None:
    control = StopControl()
    done = [0]

    def stop_after(record: Record) -> None:
        if isinstance(record, TrialDone):
            done[0] += 1
            if done[0] == TRIALS_BEFORE_KILL:
                if kill:
                    os._exit(0)  # like kill -9: no cleanup, no compaction, the lock left behind
                control.request("stopped by the test")

    run_sweep(QUICKSTART, data_dir=data_dir, progress=False, batch_trials=2,
              subscribers=[stop_after], control=control)


@pytest.fixture(scope="session")
def templates(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("templates")
    killed = root / "killed"
    pid = os.fork()
    if pid == 0:  # the child runs the sweep and dies in the middle of it
        try:
            _sweep_until(killed, kill=True)
        finally:
            os._exit(1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, status
    stopped = root / "stopped"
    _sweep_until(stopped, kill=False)
    completed = root / "completed"
    run_sweep(QUICKSTART, data_dir=completed, progress=False, batch_trials=2)
    return {"killed": killed, "stopped": stopped, "completed": completed}


@pytest.fixture()
def killed_run(templates: dict[str, Path], tmp_path: Path) -> Path:
    """A data folder with a quickstart run killed after 8 trials (4 part batches, stale lock)."""
    return copy_tree(templates["killed"], tmp_path / "data")


@pytest.fixture()
def stopped_run(templates: dict[str, Path], tmp_path: Path) -> Path:
    """A data folder with a quickstart run stopped after 8 trials (compacted, interrupted)."""
    return copy_tree(templates["stopped"], tmp_path / "data")


@pytest.fixture()
def completed_run(templates: dict[str, Path], tmp_path: Path) -> Path:
    """A data folder with a completed quickstart run (16 trials, compacted)."""
    return copy_tree(templates["completed"], tmp_path / "data")
