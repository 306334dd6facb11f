"""Atomic file writes: a reader sees the old file or the whole new one, never a torn one.

    write_bytes_atomic(path, data)       # a run's part, a plan
    write_text_atomic(path, text)        # a model file
    write_json_atomic(path, payload)     # run.json

Each write goes to a hidden temp file beside `path` (same folder, so the same file system and
`os.replace` is atomic; dot-prefixed and ending in `.tmp`, so readers that match finished names
never see it and the store sweeps leftovers), is fsync'd, renamed over `path`, and then the
folder is fsync'd so that the rename itself survives a power cut. A failed write leaves `path`
as it was and removes its temp file.

A bottom-layer module so that every package can use the one writer: the store (run files) and
physics (model files) both write through here.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path
from typing import Any


def fsync_dir(path: Path) -> None:
    """Make a rename or a new file in `path` durable (POSIX; a no-op where unsupported)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def temp_name(path: Path) -> Path:
    """A fresh temp file name beside `path` (dot-prefixed, process id and a random tag, `.tmp`)."""
    # Same folder: same file system (so os.replace is atomic) and invisible to readers, which
    # only match finished names. The pid and tag keep concurrent writers of one name apart.
    return path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(3)}.tmp")


def write_bytes_atomic(path: Path, data: bytes | memoryview) -> None:
    """Write a file's bytes so readers see either nothing (or the old file) or all of `data`."""
    temp = write_temp(path, data)
    try:
        os.replace(temp, path)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    fsync_dir(path.parent)


def write_temp(path: Path, data: bytes | memoryview) -> Path:
    """The first half of an atomic write: `data` in a fresh temp file beside `path`, fsync'd
    (nothing is left behind if that fails). Renaming it over `path` and fsyncing the folder
    completes the write (`write_bytes_atomic`; or later, by the process that commits it)."""
    temp = temp_name(path)
    try:
        with open(temp, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    return temp


def write_text_atomic(path: Path, text: str) -> None:
    """`write_bytes_atomic` for text (UTF-8)."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: Path, payload: dict[str, Any]) -> None:
    """Write a JSON file atomically (indented, anything unknown as its str, a final newline)."""
    write_text_atomic(path, json.dumps(payload, indent=2, default=str, allow_nan=True) + "\n")
