"""Where a run's files live, how run ids are made and found, and how its Parquet files are written.

    <data>/runs/<run_id>/
      run.json  plan.parquet  journal.jsonl  parts/{trials,midi}-NNNNNN.parquet
      samples/samples-NNNNNN.parquet                          (the samples, one file per batch)
      trials.parquet  midi.parquet                            (after compaction)

A part batch `NNNNNN` is committed by its trials part: the samples and midi parts of a batch are
written first, so a reader (or a resume) ignores samples/midi parts whose trials part is missing.
Compaction merges the small tables (trials, midi) into one file each; then a batch counts as
committed when trials.parquet holds it. Samples, the bulk of a run, are written once: their parts
are the stored samples, never re-encoded; samples/ is a Parquet dataset folder
(`pd.read_parquet(run / "samples")`; a killed batch's file, not yet committed, is skipped by
pianobot's readers and removed on resume). Runs of an older pianobot keep a compacted
samples.parquet (and samples parts in parts/), which readers still join.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import secrets
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

# The atomic writers live in a bottom-layer module (physics writes model files with them too);
# the store's modules keep importing them from here.
from pianobot.atomic_files import fsync_dir as fsync_dir
from pianobot.atomic_files import write_bytes_atomic as write_bytes_atomic
from pianobot.atomic_files import write_json_atomic as write_json_atomic
from pianobot.errors import InputError
from pianobot.store.footer import read_footer

if TYPE_CHECKING:  # pyarrow costs 0.2 s of start-up: `pianobot runs` lists runs without it
    import pyarrow as pa

RUNS_FOLDER = "runs"
QUARANTINE_FOLDER = "quarantine"
SAMPLES_FOLDER = "samples"
TABLE_NAMES = ("trials", "samples", "midi")
METADATA_BATCHES_KEY = b"pianobot.batches"  # a compacted file's key-value metadata
TRIAL_STATUSES = ("ok", "silent", "failed")
COMPACTED_TABLES = ("trials", "midi")  # merged into one file each at the end of a run
_PART_RE = re.compile(r"^(trials|samples|midi)-(\d{6})\.parquet$")


class RunDamaged(InputError):
    """A run's files are damaged (unreadable, truncated, not what was written).

    An InputError: the CLI prints one line (what is damaged, how to repair) and exits 2.
    """

    def __init__(self, problem: str, run_id: str) -> None:
        self.problem = problem
        self.run_id = run_id
        super().__init__(f"{problem}; details: `pianobot runs check {run_id}`, repair: "
                         f"`pianobot runs repair {run_id}`", f"run {run_id} is damaged")


@dataclass(frozen=True)
class RunPaths:
    """The files of one run folder."""

    root: Path

    @property
    def run_id(self) -> str:
        return self.root.name

    @property
    def run_json(self) -> Path:
        return self.root / "run.json"

    @property
    def plan(self) -> Path:
        return self.root / "plan.parquet"

    @property
    def journal(self) -> Path:
        return self.root / "journal.jsonl"

    @property
    def parts(self) -> Path:
        return self.root / "parts"

    @property
    def lock(self) -> Path:
        return self.root / "run.lock"

    @property
    def quarantine(self) -> Path:
        """Where repair moves damaged files (never deleted)."""
        return self.root / QUARANTINE_FOLDER

    def relative(self, path: Path) -> str:
        """`path` relative to the run folder, as the journal names files (`parts/x.parquet`)."""
        return path.relative_to(self.root).as_posix()

    def table(self, name: str) -> Path:
        """The compacted file of table `name`."""
        return self.root / f"{name}.parquet"

    @property
    def samples(self) -> Path:
        """The folder of the samples parts: the run's samples, one Parquet file per batch."""
        return self.root / SAMPLES_FOLDER

    def measurement_files(self) -> list[Path]:
        """The files holding the run's trials and samples, in a stable order (samples.parquet in
        runs of an older pianobot, else one file per batch in samples/): what an analysis
        fingerprints."""
        candidates = [self.table("trials"), self.table("samples"), *sorted(self.samples.glob("*.parquet"))]
        return [path for path in candidates if path.is_file()]

    def part(self, name: str, batch: int) -> Path:
        folder = self.samples if name == "samples" else self.parts
        return folder / f"{name}-{batch:06d}.parquet"

    def part_batches(self) -> dict[str, dict[int, Path]]:
        """Every finished part file, by table and batch number (temporary files are skipped).

        Samples parts live in samples/ (in parts/ for runs of an older pianobot)."""
        found: dict[str, dict[int, Path]] = {name: {} for name in TABLE_NAMES}
        for folder in (self.parts, self.samples):
            try:
                entries = list(os.scandir(folder))
            except FileNotFoundError:
                continue
            for entry in entries:
                match = _PART_RE.match(entry.name)
                if match:
                    found[match.group(1)][int(match.group(2))] = Path(entry.path)
        return found


def runs_dir(data_dir: Path) -> Path:
    return Path(data_dir) / RUNS_FOLDER


def slugify(name: str, max_len: int = 40) -> str:
    """A file-name-safe lowercase slug of a run name ("Soft grid #2" -> "soft-grid-2")."""
    slug = re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")
    return slug[:max_len].strip("-") or "run"


def new_run_id(name: str) -> str:
    """UTC timestamp + name slug + 4 random hex digits, e.g. `20261121-083012-quickstart-3f9a`.

    The timestamp makes `ls` sort runs by start time; the random suffix keeps two runs started
    in the same second apart.
    """
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    return f"{stamp}-{slugify(name)}-{secrets.token_hex(2)}"


def resolve_run(data_dir: Path, run_id: str) -> RunPaths:
    """Find a run folder by exact id or unique id prefix.

    Raises:
        InputError: no run, or a prefix that matches several runs.
    """
    base = runs_dir(data_dir)
    hint = f"list the runs with `pianobot runs --data {data_dir}`"
    if not run_id or "/" in run_id or run_id in (".", ".."):
        raise InputError(f"{run_id!r} is not a run id; {hint}", "run_id")
    exact = base / run_id
    if (exact / "run.json").is_file():
        return RunPaths(exact)
    candidates = sorted(p.name for p in base.glob(f"{glob_escape(run_id)}*") if (p / "run.json").is_file()) if base.is_dir() else []
    if len(candidates) == 1:
        return RunPaths(base / candidates[0])
    if not candidates:
        raise InputError(f"no run {run_id!r} in {base}; {hint}", "run_id")
    shown = ", ".join(candidates[:5]) + (", ..." if len(candidates) > 5 else "")
    raise InputError(f"{run_id!r} matches {len(candidates)} runs ({shown}); give more of the id", "run_id")


def glob_escape(text: str) -> str:
    """Escape glob metacharacters so a run id prefix matches literally."""
    return re.sub(r"([\[\]*?])", r"[\1]", text)


def write_parquet_atomic(path: Path, table: pa.Table) -> None:
    """Write a Parquet file so readers see either nothing or the whole file, never a torn one."""
    write_bytes_atomic(path, encode_parquet(table))


def encode_parquet(table: pa.Table, *, part: bool = False) -> bytes:
    """`table` as the bytes of a Parquet file (written with `parquet_options`; `part`: a part).

    Also for work done elsewhere (a parallel sweep's worker) that only the run's writer stores.
    """
    return encode_parquet_view(table, part=part).tobytes()


def encode_parquet_view(table: pa.Table, *, part: bool = False) -> memoryview:
    """`encode_parquet` without copying the file into a `bytes` (a part is megabytes: the copy
    cost a simulated sweep ~20 µs per trial); for bytes written and hashed here and now."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    if part:
        table = _without_nulls_declared(table)
    pq.write_table(table, sink, **parquet_options(table.schema, part=part))
    return memoryview(sink.getvalue())


def _without_nulls_declared(table: pa.Table) -> pa.Table:
    """`table` with every column that holds no null declared non-nullable.

    The Parquet writer then skips the definition levels (a bit per value, worked out for every
    value): half the CPU of encoding a simulated sweep's samples part, and the same bytes of
    data. Readers get the fields as `TABLE_SCHEMAS` declares them (`schema.as_declared`).
    """
    import pyarrow as pa

    fields = [f.with_nullable(False) if f.nullable and table.column(i).null_count == 0 else f
              for i, f in enumerate(table.schema)]
    return table.cast(pa.schema(fields, metadata=table.schema.metadata))


def batches_of(metadata: dict[bytes, bytes] | None) -> set[int]:
    """The part batches a compacted file already holds (empty for a part or a foreign file)."""
    if not metadata or METADATA_BATCHES_KEY not in metadata:
        return set()
    raw = metadata[METADATA_BATCHES_KEY].decode()
    return {int(b) for b in raw.split(",") if b}


def committed_batches(paths: RunPaths, parts: dict[str, dict[int, Path]] | None = None) -> set[int]:
    """Batches whose trials part (or a compacted trials file holding them) is on disk.

    `parts`: the run's parts as just listed (`paths.part_batches()`). They are listed before
    the compacted file is read: compaction replaces trials.parquet before it removes the trials
    parts it merged, so a batch is seen committed in one or the other, never in neither. The
    compacted file's batches come from its footer (no pyarrow: `pianobot runs` uses this).

    Raises:
        RunDamaged: trials.parquet is there but its footer is unreadable.
    """
    listed = set((paths.part_batches() if parts is None else parts)["trials"])
    compacted = paths.table("trials")
    try:
        held = batches_of(read_footer(compacted).metadata)
    except FileNotFoundError:
        held = set()
    except (OSError, ValueError) as exc:
        why = " ".join(str(exc).split())[:80] or type(exc).__name__
        raise RunDamaged(f"{paths.relative(compacted)} is unreadable ({why})", paths.run_id) from None
    return held | listed


def sha256_file(path: Path) -> str:
    """SHA-256 (hex) of a file's bytes, read in 1 MB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(1 << 20):
            digest.update(block)
    return digest.hexdigest()


def check_data_dir(data_dir: Path) -> None:
    """InputError unless `data_dir` is (or can become) a folder this process can write runs into.

    Checked before anything is stored or any device is opened, so a typo in `--data` or a
    read-only share costs one line, not a half-made run.
    """
    data = Path(data_dir)
    probe = data
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        what = "is a file, not a folder" if probe == data else f"{probe} is a file, not a folder"
        raise InputError(what, f"--data {data}")
    runs = runs_dir(data)
    if runs.exists() and not runs.is_dir():
        raise InputError(f"{runs} is a file, not a folder", f"--data {data}")
    target = runs if runs.is_dir() else probe
    if not os.access(target, os.W_OK | os.X_OK):
        raise InputError(f"{target} is not writable (read-only folder or file system?)", f"--data {data}")


def parquet_options(schema: pa.Schema, *, part: bool = False) -> dict[str, Any]:
    """Writer options: dictionary encoding and no statistics for text columns, byte-stream-split
    floats; zstd for the files a run keeps, lz4 for its parts (`part`: read once, by compaction).

    Ids and sources repeat endlessly and shrink to almost nothing as dictionaries, but their
    min/max statistics cost as much as writing them and no reader filters on them. Measured
    floats (noise in every digit) gain nothing from dictionaries; split into byte streams their
    exponents compress well: 20 % smaller samples files than plain zstd, written faster.
    """
    import pyarrow as pa

    text = [f.name for f in schema if _is_text(f.type)]
    floats = [f.name for f in schema if pa.types.is_floating(f.type)]
    return {
        "compression": "lz4" if part else "zstd",
        "use_dictionary": text,
        # Parts are read whole: statistics only in the files a run keeps.
        "write_statistics": False if part else [f.name for f in schema if f.name not in text] or False,
        "use_byte_stream_split": floats or False,
    }


def _is_text(kind: pa.DataType) -> bool:
    import pyarrow as pa

    if pa.types.is_dictionary(kind):
        kind = kind.value_type
    return bool(pa.types.is_string(kind) or pa.types.is_large_string(kind))


def read_json(path: Path) -> dict[str, Any]:
    with open(path, encoding="utf-8") as handle:
        payload: dict[str, Any] = json.load(handle)
    return payload


def git_commit(start: Path | None = None) -> str | None:
    """The commit of the git checkout holding pianobot's own code, or None without git."""
    where = start or Path(__file__).resolve().parent
    try:
        done = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=where,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    commit = done.stdout.strip()
    return commit if done.returncode == 0 and commit else None


def utc_now() -> str:
    """The current UTC time in ISO 8601 with a Z suffix, to the millisecond."""
    now = time.time()
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(now)) + f".{int(now % 1 * 1000):03d}Z"
