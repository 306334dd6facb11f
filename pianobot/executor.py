"""The one place that runs work that splits: in this process, or as Dask tasks on a cluster.

Simulated sweep blocks, bootstrap refits, discovery's candidate fits and cross-validation folds
are independent pieces of work. They go through an `Executor`:

    with open_executor(ExecutorSettings.resolve(workers=None, scheduler=None), work_s=40.0) as ex:
        results = ex.map(refit, replicates, progress=progress, description="bootstrap refits")

Where the work runs:

- `--scheduler tcp://HOST:PORT` (or `PIANOBOT_SCHEDULER`, or `scheduler =` in the config file):
  the tasks go to that Dask cluster. Its workers need the same pianobot version installed; they
  get everything a task needs as its arguments and return results, and never write to a run.
- otherwise a local Dask cluster of `--workers N` processes (default: the cores this process may
  use), started on first use and kept for the rest of the command;
- or this process itself, when only one worker is wanted or the work is too small to pay for
  starting processes (`MIN_PARALLEL_WORK_S`, measured: starting and stopping a 2-process local
  cluster costs about 4 s, each task about 5 ms on a busy 2-core machine).

Results come back in the order of the inputs, and a task's result may depend only on its
arguments (seed them explicitly), so the same seed gives the same results serially, on a local
cluster and on a remote one; tests assert this with a real `LocalCluster` of 2 processes.

Settings are read, most specific first, from the command line, the environment
(`PIANOBOT_WORKERS`, `PIANOBOT_SCHEDULER`) and a TOML config file (`PIANOBOT_CONFIG`, else
`pianobot.toml` in the working directory, else `~/.config/pianobot/config.toml`):

    [executor]
    workers = 8
    scheduler = "tcp://10.0.0.5:8786"

Dask is imported only when a cluster is used, so commands that split no work never load it.
"""

from __future__ import annotations

import atexit
import importlib
import os
import threading
import tomllib
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypeVar

from pianobot.errors import InputError
from pianobot.progress import NO_PROGRESS, Progress

T = TypeVar("T")
R = TypeVar("R")
Kind = Literal["in-process", "local-cluster", "scheduler"]

# Below this much estimated serial work (seconds) a local cluster costs more than it saves.
MIN_PARALLEL_WORK_S = 8.0
#: The glibc tunable Dask sets for its workers (see `_local_client`).
MALLOC_TRIM = "MALLOC_TRIM_THRESHOLD_"
ENV_WORKERS = "PIANOBOT_WORKERS"
ENV_SCHEDULER = "PIANOBOT_SCHEDULER"
ENV_CONFIG = "PIANOBOT_CONFIG"
USER_CONFIG = Path("~/.config/pianobot/config.toml")
LOCAL_CONFIG = Path("pianobot.toml")


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS tells, else the count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class ExecutorSettings:
    """Where split work runs: `workers` processes (None: sized to the machine) or `scheduler`."""

    workers: int | None = None
    scheduler: str | None = None
    source: str = "default"  # where the settings came from (shown in run.json and errors)
    connect_timeout_s: float = 10.0  # how long to try reaching a scheduler

    @classmethod
    def resolve(
        cls, *, workers: int | None = None, scheduler: str | None = None,
        environ: dict[str, str] | None = None, config: Path | None = None,
    ) -> ExecutorSettings:
        """Command-line values, else the environment, else the config file, else defaults.

        Raises InputError naming the source of a bad value.
        """
        env = dict(os.environ if environ is None else environ)
        file_values, file_label = _config_file(env, config)
        sources: list[str] = []
        if workers is not None:
            workers = _positive(workers, "--workers")
            sources.append("--workers")
        elif env.get(ENV_WORKERS):
            workers = _positive(env[ENV_WORKERS], ENV_WORKERS)
            sources.append(ENV_WORKERS)
        elif "workers" in file_values:
            workers = _positive(file_values["workers"], f"{file_label}: executor.workers")
            sources.append(file_label)
        if scheduler is not None:
            scheduler = _address(scheduler, "--scheduler")
            sources.append("--scheduler")
        elif env.get(ENV_SCHEDULER):
            scheduler = _address(env[ENV_SCHEDULER], ENV_SCHEDULER)
            sources.append(ENV_SCHEDULER)
        elif "scheduler" in file_values:
            scheduler = _address(file_values["scheduler"], f"{file_label}: executor.scheduler")
            sources.append(file_label)
        return cls(workers=workers, scheduler=scheduler,
                   source=", ".join(dict.fromkeys(sources)) or "default")


class Executor:
    """Runs a function over many inputs, in input order, here or on a Dask cluster."""

    def __init__(self, kind: Kind, workers: int, client: Any = None, address: str | None = None) -> None:
        self.kind = kind
        self.workers = workers
        self._client = client
        self._address = address

    def map(
        self, fn: Callable[[T], R], items: Sequence[T], *, progress: Progress = NO_PROGRESS,
        description: str = "tasks",
    ) -> list[R]:
        """`[fn(item) for item in items]`, the items run in parallel where the executor can."""
        out: list[R] = []
        with progress.task(description, total=len(items)) as task:
            for result in self.imap(fn, items):
                out.append(result)
                task.advance()
        return out

    def imap(self, fn: Callable[[T], R], items: Iterable[T], *, ahead: int | None = None,
             where: Callable[[T], str | None] | None = None) -> Iterator[R]:
        """Results of `fn` over `items` in order, at most `ahead` tasks running at once.

        With `ahead` None: twice the workers, enough to keep every worker busy. A task that
        finishes before the ones ahead of it frees its place at once (its result waits for its
        turn), so one long task does not idle the other workers; finished results waiting
        their turn are bounded too (`ahead` more), which bounds memory. `where` names the
        worker an item should run on (what it needs is kept there); another takes it when that
        one is gone.
        """
        if self._client is None:
            for item in items:
                yield fn(item)
            return
        finished = threading.Event()  # set whenever a task of this map finishes
        window: deque[Any] = deque()
        limit = max(1, ahead if ahead is not None else 2 * self.workers)
        pending = iter(items)
        exhausted = False
        # The function goes to each worker once, not with every task: a discovery round's
        # candidate fit carries its keystrokes and current fit (tens of MB) in its closure.
        shared = self._client.scatter(fn, broadcast=True, hash=False)
        try:
            while True:
                finished.clear()  # before looking: a task finishing from here on sets it again
                running = [f for f in window if not f.done()]
                while not exhausted and len(running) < limit and len(window) < 2 * limit:
                    try:
                        item = next(pending)
                    except StopIteration:
                        exhausted = True
                        break
                    worker = where(item) if where is not None else None
                    pinned = {"workers": [worker], "allow_other_workers": True} if worker else {}
                    window.append(self._client.submit(_apply, shared, item, pure=False, **pinned))
                    window[-1].add_done_callback(lambda _: finished.set())
                    running.append(window[-1])
                if not window:
                    return
                if window[0].done():
                    yield window.popleft().result()
                else:
                    finished.wait()
        finally:
            for future in window:  # a consumer that stops early leaves nothing running
                future.cancel()
            shared.release()

    def describe(self) -> dict[str, Any]:
        """What run.json records about where the work ran."""
        return {"kind": self.kind, "workers": self.workers, "scheduler": self._address}

    def close(self) -> None:
        """Disconnect from a remote scheduler (local clusters live until the process ends)."""
        if self.kind == "scheduler" and self._client is not None:
            self._client.close()
            self._client = None

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


IN_PROCESS = Executor("in-process", 1)


def open_executor(settings: ExecutorSettings | None = None, *, work_s: float | None = None) -> Executor:
    """The executor the settings ask for; `work_s` is the caller's estimate of the serial time.

    Without a scheduler, small work (`work_s` < MIN_PARALLEL_WORK_S) and one worker run in this
    process. Raises InputError when the scheduler cannot be reached.
    """
    settings = settings if settings is not None else ExecutorSettings()
    if settings.scheduler is not None:
        client = _connect(settings.scheduler, settings.connect_timeout_s)
        workers = max(1, len(client.scheduler_info().get("workers", {})))
        return Executor("scheduler", workers, client, settings.scheduler)
    workers = settings.workers if settings.workers is not None else usable_cores()
    small = settings.workers is None and work_s is not None and work_s < MIN_PARALLEL_WORK_S
    if workers <= 1 or small:
        return IN_PROCESS
    return Executor("local-cluster", workers, _local_client(workers))


def _apply(fn: Callable[[T], R], item: T) -> R:
    """A task: `fn` (scattered once to the workers) applied to one item."""
    return fn(item)


_LOCAL: dict[int, Any] = {}


def _local_client(workers: int) -> Any:
    """A client of a local cluster of `workers` single-threaded processes (one per size)."""
    if workers in _LOCAL:
        return _LOCAL[workers]
    distributed: Any = importlib.import_module("distributed")
    dask: Any = importlib.import_module("dask")
    # Dask starts its workers with glibc's MALLOC_TRIM_THRESHOLD_ fixed at 64 KiB, which also
    # fixes the mmap threshold: every array above 128 KiB is then mapped and unmapped afresh, and
    # a bootstrap refit ran 2.2x slower in a worker than in this process (measured;
    # benchmarks/bench_dask_fits.py). Our tasks hold bounded memory: glibc's defaults serve them.
    # A value the user exported still wins (Dask's own precedence).
    with dask.config.set({f"distributed.nanny.pre-spawn-environ.{MALLOC_TRIM}": None}):
        cluster = distributed.LocalCluster(
            # ":0": any free port. None still tries 8787 and warns on stderr when another cluster
            # (another user's, another command's) holds it.
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
            worker_dashboard_address=None, silence_logs=50,
            # Each task is one block of numba-compiled work: keep BLAS/numba from oversubscribing.
            env={"OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"},
        )
    client = distributed.Client(cluster, set_as_default=False)
    _LOCAL[workers] = client

    def stop() -> None:
        client.close()
        cluster.close()

    atexit.register(stop)
    return client


def _connect(address: str, timeout_s: float) -> Any:
    distributed: Any = importlib.import_module("distributed")
    try:
        return distributed.Client(address, timeout=f"{timeout_s}s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address}: {exc}", "--scheduler") from None


def _config_file(env: dict[str, str], config: Path | None) -> tuple[dict[str, Any], str]:
    """The `[executor]` table of the first config file that exists, and its label."""
    candidates = [config] if config is not None else (
        [Path(env[ENV_CONFIG])] if env.get(ENV_CONFIG) else [LOCAL_CONFIG, USER_CONFIG.expanduser()]
    )
    for path in candidates:
        if path is None or not path.is_file():
            if config is not None or env.get(ENV_CONFIG):
                raise InputError("config file not found", str(path))
            continue
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"not valid TOML: {exc}", str(path)) from None
        table = data.get("executor", {})
        if not isinstance(table, dict):
            raise InputError("[executor] must be a table", str(path))
        unknown = sorted(set(table) - {"workers", "scheduler"})
        if unknown:
            raise InputError(f"unknown key(s) {unknown} in [executor]; known: workers, scheduler", str(path))
        return table, str(path)
    return {}, "config file"


def _positive(value: object, where: str) -> int:
    try:
        number = int(str(value))
    except ValueError:
        raise InputError(f"must be a positive whole number, got {value!r}", where) from None
    if number < 1:
        raise InputError(f"must be a positive whole number, got {value!r}", where)
    return number


def _address(value: object, where: str) -> str:
    text = str(value).strip()
    if not text.startswith(("tcp://", "tls://", "inproc://", "ucx://")) or ":" not in text.split("://", 1)[1]:
        raise InputError(f"must be a scheduler address like tcp://HOST:PORT, got {value!r}", where)
    return text
