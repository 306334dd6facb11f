"""The run lock: one writer per run folder, on one machine or on several sharing the data folder.

Guarantee (docs/architecture.md, "The run lock"): at most one `RunLock` holds a lock file at a
time, as long as a live holder heartbeats within its lease.

- **Acquire** writes the holder record (token, pid, host, boot id, start time, lease) to a
  private temp file and hard-links it to `run.lock`. `link` fails if the name exists,
  on local file systems and on NFS alike, so the lock appears with its full content in one step
  and never empty or half written.
- **Heartbeat**: a daemon thread touches the lock file every `heartbeat_s`; its mtime, set by the
  file server's clock, is the lease.
- **Stale**: on the holder's own machine (same host and boot id) a lock whose pid is gone (or is
  now another process) is stale at once; from another machine it is stale when its heartbeat is
  older than its lease, measured on the file server's clock (a probe file's mtime), so client
  clocks never matter.
- **Takeover** never unlinks the lock and creates a new one (two breakers could then both
  succeed). A breaker first wins an exclusive claim on the stale lock's token (`link` again:
  exactly one process can), checks the lock still carries that token, and atomically
  `rename`s its own record over it. Losers see a live lock and get `RunLocked`.
- **Fencing**: `verify()` re-reads the lock and raises `LockLost` when another process took
  over (a holder that stalled past its lease); writers call it before they write.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import secrets
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pianobot.errors import InputError

LEASE_S = 30.0
HEARTBEAT_S = 5.0
# A claim (a takeover in progress) lives for microseconds; one this old belongs to a dead breaker.
_CLAIM_STALE_S = 10.0
_LOCK_VERSION = 1
# Private files of the lock (records being written, clock probes). Not `.tmp`: a run's writer
# sweeps `.*.tmp` files away, and another process may be acquiring at that moment.
TEMP_SUFFIX = ".locktmp"


class RunLocked(InputError):
    """Another live process holds the lock (the CLI prints the one line and exits 2)."""


class LockLost(InputError):
    """This process held the lock, but another one has taken it over since."""


@dataclass(frozen=True)
class LockHolder:
    """Who holds a lock, as its file says."""

    token: str
    pid: int
    host: str
    boot_id: str
    start_utc: str
    lease_s: float
    purpose: str
    heartbeat_age_s: float  # seconds since the last heartbeat, on the file server's clock
    start_ticks: int | None = None  # the holder's process start (Linux), to tell a reused pid

    @property
    def here(self) -> bool:
        """Whether the holder runs on this machine (same host name and boot)."""
        return self.host == _HOST and self.boot_id == _BOOT_ID

    def describe(self) -> str:
        """`pid 4242 on host lab-pc (sweep) since 2026-11-21T08:30:12Z, heartbeat 2 s ago`."""
        purpose = f" ({self.purpose})" if self.purpose else ""
        return (f"pid {self.pid} on host {self.host}{purpose} since {self.start_utc}, "
                f"heartbeat {self.heartbeat_age_s:.0f} s ago")

    def is_stale(self) -> bool:
        """Whether the holder is gone: dead on this machine, or silent past its lease."""
        if self.heartbeat_age_s > self.lease_s:
            return True
        return self.here and not _pid_alive(self.pid, self.start_ticks)


def _boot_id() -> str:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return ""


_HOST = socket.gethostname()
_BOOT_ID = _boot_id()


def _pid_alive(pid: int, start_ticks: int | None) -> bool:
    """Whether `pid` on this machine is still the process that started at `start_ticks`."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except OSError as exc:
        if exc.errno != errno.EPERM:
            return False
    # A reused pid belongs to a process that started after the lock was written.
    start = _process_start(pid)
    return start is None or start_ticks is None or start == start_ticks


def _process_start(pid: int) -> int | None:
    """Start time of a process in clock ticks since boot (Linux), or None where unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[-1].split()
    try:
        return int(fields[19])
    except (IndexError, ValueError):
        return None


def _utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def _write_private(path: Path, payload: bytes) -> None:
    """A new file with `payload`, complete before anyone can see it under another name.

    Not fsync'd: a record a power cut leaves torn reads as garbage, which counts as stale
    (pid 0), and a lock never has to outlive the machine that holds it.
    """
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    try:
        os.write(fd, payload)
    finally:
        os.close(fd)


def _link_exclusive(source: Path, target: Path) -> bool:
    """Hard-link `source` to `target`; False if `target` exists. NFS-safe (checks st_nlink)."""
    try:
        os.link(source, target)
        return True
    except FileExistsError:
        return False
    except OSError:
        # NFS may report a failure for a link that the server made (a lost reply).
        with contextlib.suppress(OSError):
            if os.stat(source).st_nlink == 2:
                return True
        raise


def _server_now(folder: Path) -> float:
    """The file server's current time: the mtime of a file written just now."""
    probe = folder / f".clock.{secrets.token_hex(6)}{TEMP_SUFFIX}"
    try:
        _write_private(probe, b"")
        return os.stat(probe).st_mtime
    except OSError:
        return time.time()
    finally:
        with contextlib.suppress(OSError):
            probe.unlink()


def _read_record(path: Path) -> tuple[dict[str, Any], float] | None:
    """The lock file's record and mtime, or None when there is no lock file."""
    try:
        with open(path, "rb") as handle:
            raw = handle.read(65536)
            mtime = os.fstat(handle.fileno()).st_mtime
    except FileNotFoundError:
        return None
    try:
        record = json.loads(raw)
        if isinstance(record, dict) and isinstance(record.get("token"), str):
            return record, mtime
    except ValueError:
        pass
    # An old pid-only lock (`4242\n`), or garbage: a pid on this machine we can still check
    # (0 for garbage, which counts as dead). Old writers never heartbeat: no lease.
    try:
        pid = int(raw.strip() or b"0")
    except ValueError:
        pid = 0
    legacy = {"token": f"legacy-{pid}-{int(mtime * 1e6)}", "pid": pid, "host": _HOST,
              "boot_id": _BOOT_ID, "lease_s": float("inf") if pid > 0 else 0.0}
    return legacy, mtime


def read_holder(path: Path) -> LockHolder | None:
    """The holder recorded in lock file `path`, or None when there is no lock."""
    found = _read_record(path)
    if found is None:
        return None
    record, mtime = found
    ticks = record.get("start_ticks")
    return LockHolder(
        token=str(record["token"]),
        pid=_int(record.get("pid")),
        host=str(record.get("host", "")),
        boot_id=str(record.get("boot_id", "")),
        start_utc=str(record.get("start_utc", "?")),
        lease_s=_float(record.get("lease_s"), LEASE_S),
        purpose=str(record.get("purpose", "")),
        heartbeat_age_s=max(0.0, _server_now(path.parent) - mtime),
        start_ticks=ticks if isinstance(ticks, int) else None,
    )


def _int(value: Any) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) else 0


def _float(value: Any, default: float) -> float:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else default


class RunLock:
    """An exclusive, heartbeated lock file (see the module docstring for the guarantee).

        with RunLock(paths.lock, purpose="sweep"):   # raises RunLocked if someone holds it
            ...                                      # lock.verify() before each write
    """

    def __init__(
        self, path: Path, *, purpose: str = "", lease_s: float = LEASE_S,
        heartbeat_s: float = HEARTBEAT_S,
    ) -> None:
        if not 0 < heartbeat_s < lease_s:
            raise ValueError(f"heartbeat_s must be in (0, lease_s), got {heartbeat_s}")
        self.path = Path(path)
        self.purpose = purpose
        self.lease_s = lease_s
        self.heartbeat_s = heartbeat_s
        self.token = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def held(self) -> bool:
        return bool(self.token)

    def _record(self, token: str) -> bytes:
        record = {
            "version": _LOCK_VERSION, "token": token, "pid": os.getpid(), "host": _HOST,
            "boot_id": _BOOT_ID, "start_utc": _utc_now(), "lease_s": self.lease_s,
            "heartbeat_s": self.heartbeat_s, "purpose": self.purpose,
            "start_ticks": _process_start(os.getpid()),
        }
        return (json.dumps(record) + "\n").encode()

    def acquire(self) -> RunLock:
        """Take the lock, taking over a stale one; raises RunLocked if a live process holds it."""
        if self.held:
            raise RuntimeError(f"{self.path} is already held by this RunLock")
        token = secrets.token_hex(16)
        temp = self.path.with_name(f".{self.path.name}.{token}{TEMP_SUFFIX}")
        _write_private(temp, self._record(token))
        try:
            for _ in range(8):
                if _link_exclusive(temp, self.path):
                    return self._held(token)
                holder = read_holder(self.path)
                if holder is None:
                    continue  # released between our link and our read: try again
                if not holder.is_stale():
                    raise RunLocked(self._locked_message(holder))
                if self._take_over(holder, temp):
                    return self._held(token)
            holder = read_holder(self.path)
            raise RunLocked(self._locked_message(holder) if holder else f"could not lock {self.path}")
        finally:
            with contextlib.suppress(OSError):
                temp.unlink()

    def _take_over(self, stale: LockHolder, temp: Path) -> bool:
        """Replace the stale lock by ours, if we win the one open claim on its token.

        Claims on a token are numbered; each number can be created once (`link`), and a
        breaker may only create the number after the highest one, when that one was left by a
        dead breaker. So at most one live breaker per stale lock ever reaches the `rename`.
        """
        prefix = f"{self.path.name}.claim-{_safe(stale.token)}-"
        claims = self._claims(prefix)
        if claims:
            highest, path = claims[-1]
            if not self._abandoned(path):
                return False  # another process is taking over right now
            number = highest + 1
        else:
            number = 0
        claim = self.path.with_name(f"{prefix}{number:04d}")
        if not _link_exclusive(temp, claim):
            return False
        try:
            current = _read_record(self.path)
            if current is None or current[0]["token"] != stale.token:
                return False  # someone released or replaced it since we looked
            os.replace(temp, self.path)  # atomic: the name always points at a whole record
        finally:
            with contextlib.suppress(OSError):
                claim.unlink()
        # The stale token is gone for good, so its older (abandoned) claims can go too.
        for _, old in self._claims(prefix):
            with contextlib.suppress(OSError):
                old.unlink()
        return True

    def _claims(self, prefix: str) -> list[tuple[int, Path]]:
        found = []
        for entry in os.scandir(self.path.parent):
            tail = entry.name[len(prefix):]
            if entry.name.startswith(prefix) and tail.isdigit():
                found.append((int(tail), Path(entry.path)))
        return sorted(found)

    def _abandoned(self, claim: Path) -> bool:
        """Whether a claim was left by a breaker that died (it lives for microseconds)."""
        try:
            mtime = os.stat(claim).st_mtime
        except FileNotFoundError:
            return True
        return _server_now(claim.parent) - mtime > _CLAIM_STALE_S

    def _held(self, token: str) -> RunLock:
        self.token = token
        self._stop.clear()
        self._thread = threading.Thread(target=self._heartbeat, name=f"heartbeat {self.path}",
                                        daemon=True)
        self._thread.start()
        return self

    def _heartbeat(self) -> None:
        while not self._stop.wait(self.heartbeat_s):
            with contextlib.suppress(OSError):
                os.utime(self.path)

    def _locked_message(self, holder: LockHolder) -> str:
        what = self.path.parent.name
        if holder.here or holder.heartbeat_age_s <= self.heartbeat_s * 2:
            return f"run {what} is being written by {holder.describe()}"
        return (f"run {what} is being written by {holder.describe()}; if that machine is down, "
                f"the lock counts as abandoned after {holder.lease_s:.0f} s without a heartbeat")

    def verify(self) -> None:
        """Raise LockLost unless the lock file still carries this holder's token."""
        if not self.held:
            raise LockLost(f"{self.path} is not held")
        found = _read_record(self.path)
        if found is None or found[0]["token"] != self.token:
            holder = read_holder(self.path)
            by = f" by {holder.describe()}" if holder else ""
            raise LockLost(f"the lock on run {self.path.parent.name} was taken over{by}; "
                           "this process stopped writing")

    def release(self) -> None:
        """Stop the heartbeat and remove the lock if it is still ours (idempotent)."""
        if not self.held:
            return
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        found = _read_record(self.path)
        if found is not None and found[0]["token"] == self.token:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
        self.token = ""

    def __enter__(self) -> RunLock:
        return self.acquire() if not self.held else self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _safe(token: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in token)[:64]
