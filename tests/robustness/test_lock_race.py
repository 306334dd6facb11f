"""The run lock under contention: 4 forked processes race on it, 200 rounds, exactly one holder.

Each round starts from another state of the lock file: none, a dead writer's lock on this
machine, an old pid-only lock, a lock of another machine whose lease ran out, a stale lock
with a dead breaker's claim beside it, and a lock a live process holds. All four processes
call `acquire()` at the same moment (a barrier), report, wait until everyone has tried, and
only then release, so a second success could not hide behind an early release.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import socket
import time
from pathlib import Path
from typing import Any

import pytest

from pianobot.store.lock import RunLock, RunLocked, read_holder

N_PROCESSES = 4
N_ROUNDS = 200
KINDS = ("free", "dead-here", "legacy-dead", "expired-elsewhere", "dead-claim", "live")


def _dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
    return pid


def _boot_id() -> str:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return ""


def _record(token: str, pid: int, host: str) -> str:
    return json.dumps({"version": 1, "token": token, "pid": pid, "host": host,
                       "boot_id": _boot_id(), "start_utc": "2026-01-01T00:00:00Z",
                       "lease_s": 30.0, "purpose": "test"})


def _prepare(folder: Path, kind: str, dead_pid: int) -> None:
    folder.mkdir(parents=True)
    lock = folder / "run.lock"
    if kind == "dead-here":
        lock.write_text(_record("deadhere", dead_pid, socket.gethostname()))
    elif kind == "legacy-dead":
        lock.write_text(f"{dead_pid}\n")
    elif kind == "expired-elsewhere":
        lock.write_text(_record("elsewhere", 4242, "another-machine"))
        old = time.time() - 600
        os.utime(lock, (old, old))
    elif kind == "dead-claim":
        lock.write_text(_record("claimed", dead_pid, socket.gethostname()))
        claim = folder / "run.lock.claim-claimed-0000"
        claim.write_text(_record("breaker", dead_pid, socket.gethostname()))
        old = time.time() - 600
        os.utime(claim, (old, old))


def _worker(rank: int, root: str, barrier: Any, results: Any) -> None:
    for round_no in range(N_ROUNDS):
        lock = RunLock(Path(root) / f"r{round_no:03d}" / "run.lock", purpose=f"racer {rank}")
        barrier.wait()
        try:
            lock.acquire()
            results[round_no * N_PROCESSES + rank] = 1
        except RunLocked:
            results[round_no * N_PROCESSES + rank] = 0
        except Exception:  # noqa: BLE001 - any other failure is a finding, reported as such
            results[round_no * N_PROCESSES + rank] = -1
        barrier.wait()  # everyone has tried before anyone lets go
        lock.release()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_four_processes_race_200_rounds_and_exactly_one_holds_each(tmp_path: Path) -> None:
    dead = _dead_pid()
    kinds = [KINDS[i % len(KINDS)] for i in range(N_ROUNDS)]
    for i, kind in enumerate(kinds):
        _prepare(tmp_path / f"r{i:03d}", kind, dead)
    ctx = mp.get_context("fork")
    barrier = ctx.Barrier(N_PROCESSES + 1)
    results = ctx.Array("i", [9] * (N_PROCESSES * N_ROUNDS))
    workers = [ctx.Process(target=_worker, args=(r, str(tmp_path), barrier, results))
               for r in range(N_PROCESSES)]
    for w in workers:
        w.start()
    held_by_parent: list[RunLock] = []
    try:
        for i, kind in enumerate(kinds):
            parent_lock = RunLock(tmp_path / f"r{i:03d}" / "run.lock", purpose="parent")
            if kind == "live":
                held_by_parent.append(parent_lock.acquire())
            barrier.wait(timeout=60)
            barrier.wait(timeout=60)
            if kind == "live":
                parent_lock.release()
    finally:
        for w in workers:
            w.join(timeout=60)
    outcome = list(results)
    holders_per_round = []
    for i, kind in enumerate(kinds):
        row = outcome[i * N_PROCESSES:(i + 1) * N_PROCESSES]
        assert -1 not in row and 9 not in row, f"round {i} ({kind}): {row}"
        holders_per_round.append(sum(row) + (1 if kind == "live" else 0))
    bad = [(i, kinds[i], n) for i, n in enumerate(holders_per_round) if n != 1]
    assert not bad, f"rounds without exactly one holder: {bad[:10]}"
    # Every stale kind was taken over by a racer, never left for nobody.
    for i, kind in enumerate(kinds):
        if kind != "live":
            assert sum(outcome[i * N_PROCESSES:(i + 1) * N_PROCESSES]) == 1
    # After the last release no lock and no claim is left behind.
    leftovers = sorted(p.name for p in tmp_path.rglob("run.lock*"))
    assert leftovers == []


def _handoff_worker(root: str, rounds: int, violations: Any) -> None:
    lock_path = Path(root) / "run.lock"
    inside = Path(root) / "inside"
    done = 0
    while done < rounds:
        lock = RunLock(lock_path, purpose="handoff")
        try:
            lock.acquire()
        except RunLocked:
            continue
        try:
            fd = os.open(inside, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            with violations.get_lock():
                violations.value += 1
        else:
            os.close(fd)
            os.unlink(inside)
        lock.release()
        done += 1


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_acquire_and_release_in_a_loop_never_overlaps(tmp_path: Path) -> None:
    ctx = mp.get_context("fork")
    violations = ctx.Value("i", 0)
    workers = [ctx.Process(target=_handoff_worker, args=(str(tmp_path), 100, violations))
               for _ in range(N_PROCESSES)]
    for w in workers:
        w.start()
    for w in workers:
        w.join(timeout=120)
        assert w.exitcode == 0
    assert violations.value == 0
    assert not (tmp_path / "run.lock").exists()


def test_the_holder_record_is_complete_and_a_live_lock_names_its_holder(tmp_path: Path) -> None:
    path = tmp_path / "run.lock"
    with RunLock(path, purpose="sweep") as lock:
        holder = read_holder(path)
        assert holder is not None and holder.token == lock.token
        assert holder.pid == os.getpid() and holder.host == socket.gethostname()
        assert holder.here and not holder.is_stale()
        with pytest.raises(RunLocked, match=rf"pid {os.getpid()} on host .*\(sweep\)"):
            RunLock(path).acquire()
    assert read_holder(path) is None


def test_a_holder_that_lost_its_lock_finds_out_before_writing(tmp_path: Path) -> None:
    from pianobot.store.lock import LockLost

    path = tmp_path / "run.lock"
    lock = RunLock(path).acquire()
    lock.verify()
    # Another machine decided this holder was gone and took over (simulated by a rename).
    other = tmp_path / "other"
    other.write_text(_record("someone-else", 4242, "another-machine"))
    os.replace(other, path)
    with pytest.raises(LockLost, match="taken over by pid 4242 on host another-machine"):
        lock.verify()
    lock.release()  # does not remove the other holder's lock
    assert path.exists()


def test_a_heartbeat_keeps_the_lease_fresh(tmp_path: Path) -> None:
    path = tmp_path / "run.lock"
    with RunLock(path, lease_s=0.6, heartbeat_s=0.1):
        old = time.time() - 100
        os.utime(path, (old, old))
        time.sleep(0.35)
        holder = read_holder(path)
        assert holder is not None and holder.heartbeat_age_s < 0.6
