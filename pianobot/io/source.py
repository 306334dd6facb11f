"""Reading a user's input file, with the one-line errors every importer gives."""

from __future__ import annotations

from pathlib import Path

from pianobot.errors import InputError


def read_input_bytes(path: Path, kind: str) -> bytes:
    """The bytes of a text file the user named; `kind` says what it should be ("a force capture").

    Raises InputError naming the file when it is missing, unreadable, empty or binary.
    """
    where = str(path)
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
