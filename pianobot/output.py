"""Files the user asks for (`--out model.json`, a report, a MIDI file): checked first, written whole.

    check_output_path(out, "--out")               # InputError for a folder, a missing parent...
    write_output(out, lambda tmp: tmp.write_text(text), "--out")

The check runs before the work (an identification takes minutes; finding out at the end that
`--out` names a folder wastes them). The write goes to a hidden temp file beside the target
and is renamed over it, so a reader never sees half a file, and a failed write leaves nothing
behind: no `model.json.tmp`, no partial target.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

from pianobot.atomic_files import fsync_dir, temp_name
from pianobot.errors import InputError


def check_output_path(path: Path | str, option: str) -> Path:
    """`path` as a file that can be written, or InputError naming `option` and what is wrong."""
    target = Path(path)
    if str(path) == "" or target.name in ("", ".", ".."):
        raise InputError(f"needs a file name, got {str(path)!r}", option)
    if target.is_dir():
        raise InputError(f"{target} is a folder; give a file name (e.g. {target / 'out'}...)", option)
    if target.exists() and not target.is_file():
        raise InputError(f"{target} is not a regular file", option)
    parent = target.parent
    probe = parent
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise InputError(f"{probe} is a file, so {target} cannot be made", option)
    if not os.access(probe, os.W_OK | os.X_OK) or (probe.is_dir() and not can_create_in(probe)):
        raise InputError(f"cannot write in {probe} (read-only?)", option)
    return target


def can_create_in(folder: Path) -> bool:
    """Whether a file can be made in `folder` (tried: a read-only mount or /proc passes the
    permission check for root, and only a real attempt tells)."""
    try:
        handle, name = tempfile.mkstemp(dir=folder, prefix=".pianobot-check-")
    except OSError:
        return False
    os.close(handle)
    Path(name).unlink(missing_ok=True)
    return True


def write_output(path: Path | str, write: Callable[[Path], object], option: str = "--out") -> Path:
    """Call `write(temp)` and rename the temp file to `path`; nothing is left if anything fails.

    Raises:
        InputError: `path` cannot be written (a folder, a read-only place, a full disk).
    """
    target = check_output_path(path, option)
    temp = temp_name(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        write(temp)
        with open(temp, "rb+") as handle:  # durable before it replaces anything
            os.fsync(handle.fileno())
        os.replace(temp, target)
        fsync_dir(target.parent)
    except OSError as exc:
        raise InputError(f"cannot write {target}: {exc.strerror or exc}", option) from None
    finally:
        temp.unlink(missing_ok=True)
    return target

