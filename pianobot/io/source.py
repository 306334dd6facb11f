"""Reading a user's input file, with the one-line errors every importer gives."""

from __future__ import annotations

import io
import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from pianobot.errors import InputError

# Larger than any log, capture or take a lab records (a 10-minute 120 Hz Motive take with 30
# markers is ~60 MB); a bigger file is a mistake, and is refused before it is read into memory.
MAX_INPUT_BYTES = 1 << 30


def check_input_file(path: Path, kind: str) -> None:
    """InputError unless `path` is a regular file of at most MAX_INPUT_BYTES (checked before reading)."""
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


def read_input_bytes(path: Path, kind: str) -> bytes:
    """The bytes of a text file the user named; `kind` says what it should be ("a force capture").

    Raises InputError naming the file when it is missing, unreadable, empty or binary.
    """
    where = str(path)
    check_input_file(path, kind)
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


def text_lines(path: Path, kind: str) -> Iterator[tuple[int, str]]:
    """The numbered lines (1-based, line ends removed) of a text file, read as a stream.

    UTF-8 (a byte-order mark dropped), or UTF-16 when the file starts with its byte-order mark
    (what Windows PowerShell 5 writes for `python script.py > log.txt`). Memory stays bounded
    however long the file is. Raises InputError naming the file (and line) when it is missing,
    unreadable, binary, not text in those encodings, or holds nothing but blank lines.
    """
    where = str(path)
    check_input_file(path, kind)
    try:
        handle = path.open("rb")
    except FileNotFoundError:
        raise InputError("no such file", where) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or exc})", where) from None
    blank = True
    with handle:
        utf16 = handle.peek(2)[:2] in (b"\xff\xfe", b"\xfe\xff")
        for number, text in (_utf16_lines if utf16 else _utf8_lines)(handle, kind, where):
            blank = blank and not text.strip()
            yield number, text
    if blank:
        raise InputError("the file is empty", where)


def _utf8_lines(handle: BinaryIO, kind: str, where: str) -> Iterator[tuple[int, str]]:
    for number, raw in enumerate(handle, start=1):
        if b"\x00" in raw:
            raise InputError(f"not {kind} (binary data on line {number})", where)
        if number == 1 and raw.startswith(b"\xef\xbb\xbf"):
            raw = raw[3:]
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(f"not {kind} (line {number} is not UTF-8 text)", where) from None
        yield number, text.rstrip("\r\n")


def _utf16_lines(handle: BinaryIO, kind: str, where: str) -> Iterator[tuple[int, str]]:
    text = io.TextIOWrapper(handle, encoding="utf-16", newline=None)  # its mark gives the byte order
    number = 0
    try:
        for number, line in enumerate(text, start=1):
            if "\x00" in line:
                raise InputError(f"not {kind} (binary data on line {number})", where)
            yield number, line.rstrip("\r\n")
    except UnicodeDecodeError:
        raise InputError(f"not {kind} (line {number + 1} is not UTF-16 text)", where) from None
    finally:
        text.detach()  # the caller closes the file
