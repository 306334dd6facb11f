"""The executor: settings from flags, environment and config file; serial and Dask agree.

The Dask tests use a real `distributed.LocalCluster` with 2 worker processes (started once per
test session: a few seconds).
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from pianobot.errors import InputError
from pianobot.executor import (
    IN_PROCESS,
    MALLOC_TRIM,
    MIN_PARALLEL_WORK_S,
    Executor,
    ExecutorSettings,
    open_executor,
    usable_cores,
)
from pianobot.run import run_sweep
from pianobot.store import Run, StagedPart, check_run, load_run, read_journal
from pianobot.store.records import FileRecord
from tests.run.test_batched_sweep import OUTCOME, _spec
from tests.run.test_crash_resume import SWEEP_ONLY, _journal_lines, _run_folder

TWO = ExecutorSettings(workers=2)


def test_settings_come_from_flags_then_environment_then_config_file(tmp_path: Path) -> None:
    config = tmp_path / "pianobot.toml"
    config.write_text('[executor]\nworkers = 3\nscheduler = "tcp://10.1.2.3:8786"\n')
    assert ExecutorSettings.resolve(environ={}, config=config) == ExecutorSettings(
        3, "tcp://10.1.2.3:8786", str(config))
    env = {"PIANOBOT_WORKERS": "5", "PIANOBOT_SCHEDULER": "tcp://127.0.0.1:9999"}
    from_env = ExecutorSettings.resolve(environ=env, config=config)
    assert (from_env.workers, from_env.scheduler) == (5, "tcp://127.0.0.1:9999")
    flags = ExecutorSettings.resolve(workers=2, scheduler="tcp://h:1", environ=env, config=config)
    assert (flags.workers, flags.scheduler, flags.source) == (2, "tcp://h:1", "--workers, --scheduler")
    env_file = {"PIANOBOT_CONFIG": str(config)}
    assert ExecutorSettings.resolve(environ=env_file).workers == 3


@pytest.mark.parametrize(("kwargs", "where"), [
    ({"workers": 0}, "--workers"),
    ({"scheduler": "localhost:8786"}, "--scheduler"),
    ({"environ": {"PIANOBOT_WORKERS": "many"}}, "PIANOBOT_WORKERS"),
    ({"environ": {"PIANOBOT_SCHEDULER": "http://x:1"}}, "PIANOBOT_SCHEDULER"),
])
def test_bad_settings_name_where_they_came_from(kwargs: dict[str, object], where: str) -> None:
    kwargs.setdefault("environ", {})
    with pytest.raises(InputError) as info:
        ExecutorSettings.resolve(**kwargs)  # type: ignore[arg-type]
    assert info.value.where == where


def test_bad_config_file_is_one_clear_error(tmp_path: Path) -> None:
    config = tmp_path / "pianobot.toml"
    config.write_text("[executor]\nworker = 3\n")
    with pytest.raises(InputError, match="unknown key"):
        ExecutorSettings.resolve(environ={}, config=config)
    config.write_text("[executor\n")
    with pytest.raises(InputError, match="TOML"):
        ExecutorSettings.resolve(environ={}, config=config)
    with pytest.raises(InputError, match="not found"):
        ExecutorSettings.resolve(environ={}, config=tmp_path / "missing.toml")


def test_small_work_and_one_worker_stay_in_this_process() -> None:
    assert open_executor(ExecutorSettings(workers=1)) is IN_PROCESS
    assert open_executor(ExecutorSettings(), work_s=MIN_PARALLEL_WORK_S / 2) is IN_PROCESS
    assert usable_cores() >= 1
    assert IN_PROCESS.map(math.sqrt, [4.0, 9.0]) == [2.0, 3.0]


def test_unreachable_scheduler_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot reach"):
        open_executor(ExecutorSettings(scheduler="tcp://127.0.0.1:9", connect_timeout_s=1.0))
    # Checked before the run folder exists: it used to leave a run 'failed 0/N' behind.
    with pytest.raises(InputError, match="cannot reach"):
        run_sweep(_spec(tmp_path / "spec", 20), data_dir=tmp_path / "data", progress=False,
                  executor=ExecutorSettings(scheduler="tcp://127.0.0.1:9", connect_timeout_s=1.0))
    assert not (tmp_path / "data" / "runs").exists() or not any((tmp_path / "data" / "runs").iterdir())


def _bootstrap_mean(task: tuple[int, int]) -> float:
    """A seeded piece of work, as a bootstrap replicate would be."""
    seed, n = task
    rng = np.random.default_rng(seed)
    return float(rng.normal(size=n).mean())


def test_a_local_cluster_of_two_processes_gives_the_serial_results() -> None:
    tasks = [(seed, 1000) for seed in range(20)]
    serial = IN_PROCESS.map(_bootstrap_mean, tasks)
    cluster = open_executor(TWO)
    assert cluster.kind == "local-cluster" and cluster.workers == 2
    assert cluster.map(_bootstrap_mean, tasks) == serial
    assert list(cluster.imap(_bootstrap_mean, tasks, ahead=3)) == serial


def _timed_sleep(seconds: float) -> tuple[float, float]:
    start = time.time()
    time.sleep(seconds)
    return start, time.time()


def _this_worker(seconds: float) -> str:
    import distributed

    time.sleep(seconds)  # long enough that both workers get some
    return str(distributed.get_worker().address)


def test_a_long_task_does_not_hold_up_the_tasks_behind_it() -> None:
    """In-order results, yet a worker that finishes early takes the next task at once: while
    the first task runs on one worker, the other works through the ones behind it (before,
    the next task waited for the first one's result)."""
    cluster = open_executor(TWO)
    slow, quick = sorted(set(cluster.map(_this_worker, [0.3] * 6)))
    seconds = [3.0] + [0.05] * 7
    out = list(cluster.imap(_timed_sleep, seconds, ahead=2, where=lambda s: slow if s > 1 else quick))
    assert all(end - start >= s for (start, end), s in zip(out, seconds, strict=True))  # in order
    first_end = out[0][1]
    assert sum(start < first_end for start, _ in out[1:]) == 3  # the window: 2 running, 2 waiting


def test_cross_validation_folds_on_two_worker_processes_equal_the_serial_table() -> None:
    """`pianobot fit`'s folds as Dask tasks: the same CV table as in this process (each fold is
    seeded alike and warm-started from the same full fit), whatever ran where."""
    sys.path.insert(0, str(Path(__file__).resolve().parent / "analysis"))
    from _synthetic_runs import sounded_trials

    from pianobot.analysis.learn.training import cross_validate_models, training_set

    data = training_set(sounded_trials(3))
    serial, _ = cross_validate_models(data, ["poly", "gp"], folds=4)
    seen: list[float] = []

    def on_cluster(work_s: float) -> Executor:
        seen.append(work_s)
        return open_executor(TWO)

    parallel, fitted = cross_validate_models(data, ["poly", "gp"], folds=4, executor=on_cluster)
    assert seen and seen[0] > 0.0 and set(fitted) == {"mean", "poly", "gp"}
    columns = ["model", "rmse", "mae", "r2", "hold_rmse_s", "silent_accuracy", "n_trials", "folds"]
    pd.testing.assert_frame_equal(parallel[columns], serial[columns])


def test_identify_and_discover_on_two_worker_processes_equal_the_serial_results(tmp_path: Path) -> None:
    """Identify's free-coupling fits and bootstrap refits, and discovery's candidate fits, as
    Dask tasks: the same estimates, intervals, decisions and fitted values as in this process."""
    sys.path.insert(0, str(Path(__file__).resolve().parent / "analysis"))
    import own_world as ow

    from pianobot.analysis.discover.loop import discover
    from pianobot.analysis.identify.fit import identify_trajectories

    batch = ow.generate(ow.reduced(ow.hidden_effect("keybed", "strong", seed=5), n_speeds=3), tmp_path)
    cluster = open_executor(TWO)

    def identified(mapper: Any) -> list[tuple[str, float, Any]]:
        fit = identify_trajectories(batch, bootstrap=4, seed=2, mapper=mapper)
        return [(e.name, e.value, e.ci_bootstrap) for e in fit.estimates]

    assert identified(cluster.imap) == identified(IN_PROCESS.imap)

    def discovered(mapper: Any) -> tuple[Any, ...]:
        result = discover(batch, mapper=mapper)
        return (result.accepted_effects, result.final_model.effects.to_dict(), result.verdict)

    assert discovered(cluster.imap) == discovered(IN_PROCESS.imap)


# What the user exported, read at collection, before any cluster starts (Dask's nanny writes its
# worker settings into the environment of the process that starts the cluster).
EXPORTED_TRIM = os.environ.get(MALLOC_TRIM)


def _malloc_trim(_: int) -> str | None:
    return os.environ.get(MALLOC_TRIM)


def test_local_workers_keep_glibc_memory_defaults_unless_the_user_set_them() -> None:
    """Dask's default MALLOC_TRIM_THRESHOLD_ (64 KiB) maps every large array afresh: a bootstrap
    refit ran 2.2x slower in a worker than in the driver. Our workers start without it."""
    cluster = open_executor(TWO)
    seen = set(cluster.map(_malloc_trim, range(4)))
    assert seen == {EXPORTED_TRIM}  # None unless the user exported a value


def _count_adoptions(_: object = None) -> int:
    """On a worker: count the blocks whose run took the truths worked out for their times."""
    from pianobot.physics import world

    if not getattr(world.World.adopt, "counted", False):
        adopt = world.World.adopt

        def counted(self: world.World, truths: Any) -> None:
            world.ADOPTED = getattr(world, "ADOPTED", 0) + 1  # type: ignore[attr-defined]
            adopt(self, truths)

        counted.counted = True  # type: ignore[attr-defined]
        world.World.adopt = counted  # type: ignore[method-assign]
    return int(getattr(world, "ADOPTED", 0))


@pytest.mark.slow
def test_a_sweep_on_two_worker_processes_equals_the_serial_sweep(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = _spec(tmp_path, 70, "approach: fast\n")  # faulty rig: drops, MIDI and mocap losses
    serial = run_sweep(spec, data_dir=tmp_path / "serial", progress=False, batch_trials=16,
                       executor=ExecutorSettings(workers=1))
    committed: list[str] = []  # samples parts the workers staged and the driver renamed
    commit = StagedPart.commit

    def counted(self: StagedPart, path: Path, relative: str) -> FileRecord:
        committed.append(relative)
        return commit(self, path, relative)

    monkeypatch.setattr(StagedPart, "commit", counted)
    client = open_executor(TWO)._client
    adopted_before = sum(client.run(_count_adoptions).values())
    dask = run_sweep(spec, data_dir=tmp_path / "dask", progress=False, batch_trials=16,
                     executor=TWO)
    assert load_run(dask.run_id, tmp_path / "dask").meta["executor"]["kind"] == "local-cluster"
    assert (dask.status, dask.trials, dask.lab_time_s) == (serial.status, serial.trials, serial.lab_time_s)
    a = load_run(serial.run_id, tmp_path / "serial")
    b = load_run(dask.run_id, tmp_path / "dask")
    x = a.trials.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    y = b.trials.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    pd.testing.assert_frame_equal(x, y, check_exact=True)
    for table, keys in (("samples", ["trial_id", "source", "t_s"]), ("midi", ["trial_id", "t_s"])):
        u = getattr(a, table).drop(columns="run_id").sort_values(keys).reset_index(drop=True)
        v = getattr(b, table).drop(columns="run_id").sort_values(keys).reset_index(drop=True)
        pd.testing.assert_frame_equal(u, v, check_exact=True)
    retried = [e for e in b.journal if e["event"] == "retried"]
    assert retried and len(retried) == len([e for e in a.journal if e["event"] == "retried"])
    # Parts the workers encoded are journalled (rows, SHA-256) like the serial path's.
    def parts(run: Run) -> int:
        return sum(e["event"] == "part" for e in read_journal(run.paths.journal, bookkeeping=True))

    assert parts(b) == parts(a) > 0
    assert check_run(b.paths, deep=True).ok
    # The workers wrote the samples parts themselves (staged, then renamed by the driver).
    assert committed and all(c.startswith("samples/") for c in committed)
    assert not list(b.paths.samples.glob(".*.tmp"))
    # Blocks run where their times were worked out and take the truths simulated for those,
    # instead of simulating them again (one sample part per block).
    adopted = sum(client.run(_count_adoptions).values()) - adopted_before
    assert adopted >= len(committed) / 2


@pytest.mark.slow
def test_a_protective_stop_on_the_workers_stops_the_run_like_the_serial_one(tmp_path: Path) -> None:
    spec = _spec(tmp_path, 40)
    rig = tmp_path / "rig.yaml"
    rig.write_text(rig.read_text().replace("faults:\n", "faults:\n  protective_stop_at_trial: 21\n"))
    serial = run_sweep(spec, data_dir=tmp_path / "serial", progress=False, batch_trials=8,
                       executor=ExecutorSettings(workers=1))
    dask = run_sweep(spec, data_dir=tmp_path / "dask", progress=False, batch_trials=8, executor=TWO)
    assert serial.status == dask.status == "stopped" and serial.reason == dask.reason
    # 21 keystrokes before the stop; a note-on the faulty MIDI link lost makes one of them failed
    assert serial.trials == dask.trials and serial.failed == dask.failed
    assert serial.trials + serial.failed == 21
    resumed = run_sweep(None, data_dir=tmp_path / "dask", resume=dask.run_id, progress=False,
                        batch_trials=8, executor=TWO)
    assert resumed.status == "completed" and resumed.trials + resumed.failed == 40


@pytest.mark.slow
def test_kill_9_of_the_driver_with_dask_workers_and_resume(tmp_path: Path) -> None:
    """The driver holds the lock and journal; a kill loses only the blocks in flight."""
    spec = _spec(tmp_path, 64)
    rig = tmp_path / "rig.yaml"
    rig.write_text(rig.read_text().replace("  drop_connection_every_n_presses: 9\n", ""))
    reference = run_sweep(spec, data_dir=tmp_path / "reference", progress=False, seed=3,
                          executor=ExecutorSettings(workers=1))
    data_dir = tmp_path / "data"
    args = [sys.executable, "-c", SWEEP_ONLY, "sweep", str(spec), "--data", str(data_dir), "--json",
            "--no-progress", "--seed", "3", "--workers", "2", "--batch-trials", "16"]
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    killed = False
    deadline = time.monotonic() + 300
    while process.poll() is None and time.monotonic() < deadline:
        folder = _run_folder(data_dir)
        if folder is not None and _journal_lines(folder / "journal.jsonl") >= 20:
            process.send_signal(signal.SIGKILL)
            process.wait()
            killed = True
            break
        time.sleep(0.005)
    assert killed, process.communicate()[1].decode()[-2000:]
    folder = _run_folder(data_dir)
    assert folder is not None
    resume = subprocess.run([*args[:3], "sweep", "--resume", folder.name, "--data", str(data_dir),
                             "--json", "--no-progress", "--workers", "2"],
                            capture_output=True, text=True, timeout=600)
    assert resume.returncode == 0, resume.stderr[-2000:]
    assert json.loads(resume.stdout)["status"] == "completed"
    run = load_run(folder.name, data_dir)
    expected = load_run(reference.run_id, tmp_path / "reference")
    cols = [c for c in OUTCOME if c != "t_start_s"]
    a = run.trials.sort_values("trial_id")[cols].reset_index(drop=True)
    b = expected.trials.sort_values("trial_id")[cols].reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9, atol=1e-12)
    assert not list(run.paths.samples.glob(".*.tmp"))  # staged parts the kill stranded were swept
    counts = run.samples.groupby(["trial_id", "source"]).size().sort_index()
    pd.testing.assert_series_equal(counts, expected.samples.groupby(["trial_id", "source"]).size().sort_index())
