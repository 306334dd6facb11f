"""Reading a user's input file, with the one-line errors every importer gives."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from pianobot.errors import InputError

# Larger than any log, capture or take a lab records (a 10-minute 120 Hz Motive take with 30
# markers is ~60 MB); a bigger file is a mistake, and is refused before it is read into memory.
MAX_INPUT_BYTES = 1 << 30


def read_input_bytes(path: Path, kind: str) -> bytes:
    """The bytes of a text file the user named; `kind` says what it should be ("a force capture").

    Raises InputError naming the file when it is missing, unreadable, empty or binary.
    """
    where = str(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise InputError("no such file", where) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or exc})", where) from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError(f"is a folder, not {kind}", where)
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"is not a regular file (expected {kind})", where)
    if info.st_size > MAX_INPUT_BYTES:
        raise InputError(f"is {info.st_size / 2**30:.1f} GiB; {kind} is read up to "
                         f"{MAX_INPUT_BYTES / 2**30:.0f} GiB", where)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError("no such file", where) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or exc})", where) from None
    if not data.strip():
        raise InputError("the file is empty", where)
    if b"\x00" in data:
        raise InputError(f"not {kind} (binary data)", where)
    return data
