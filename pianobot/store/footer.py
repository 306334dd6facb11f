"""A Parquet file's footer, read without pyarrow: is the file whole, how many rows, what metadata.

    footer = read_footer(path)   # FooterError when the file is truncated, garbled or not Parquet
    footer.num_rows, batches_of(footer.metadata)

`pianobot runs` lists runs and checks their files; importing pyarrow to do so would cost 0.2 s
of start-up, so its quick check reads footers with this module instead. A Parquet file ends with
its footer: the `FileMetaData` struct in the Thrift compact protocol, its length (4 bytes,
little-endian) and the magic "PAR1", which also opens the file. This module checks both magics
and the footer length, walks the struct up to the fields it keeps (skipping the others value by
value, so a garbled footer is found) and keeps the row count (field 3) and the key-value metadata
(field 5), where pyarrow stores the Arrow schema's metadata (`pianobot.batches`, ...). It reads
only the end of the file and imports nothing beyond the standard library; data pages are not read.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

MAGIC = b"PAR1"
ENCRYPTED_MAGIC = b"PARE"  # a footer encrypted with the Parquet modular encryption
MAX_NESTING = 64  # nested structs and collections; Parquet's own footers nest about 6 deep

# Thrift compact protocol type codes: field headers carry booleans as their type (TRUE, FALSE).
STOP, TRUE, FALSE, BYTE, I16, I32, I64, DOUBLE, BINARY, LIST, SET, MAP, STRUCT = range(13)


class FooterError(ValueError):
    """The file is not a whole Parquet file (truncated, garbled, not Parquet)."""


@dataclass(frozen=True)
class ParquetFooter:
    """What a Parquet file's footer says: its rows and its key-value metadata."""

    num_rows: int
    metadata: dict[bytes, bytes]  # FileMetaData.key_value_metadata; empty when absent


def read_footer(path: Path) -> ParquetFooter:
    """The footer of the Parquet file at `path`, reading only the end of the file.

    Raises FooterError when the file is not a whole Parquet file; OSError (FileNotFoundError,
    ...) from opening or reading it passes through.
    """
    with open(path, "rb") as file:
        size = file.seek(0, 2)
        if size < 12:
            raise FooterError(f"too short to be Parquet ({size} bytes)")
        file.seek(0)
        head = file.read(4)
        file.seek(size - 8)
        tail = file.read(8)
        if tail[4:] == ENCRYPTED_MAGIC:
            raise FooterError("encrypted Parquet files are not supported")
        if tail[4:] != MAGIC:
            raise FooterError("no Parquet magic at the end")
        if head != MAGIC:
            raise FooterError("no Parquet magic at the start")
        length = int.from_bytes(tail[:4], "little")
        if length > size - 12:
            raise FooterError(f"footer length {length} exceeds the file ({size} bytes)")
        file.seek(size - 8 - length)
        data = file.read(length)
    if len(data) != length:
        raise FooterError("file shrank while its footer was read")
    return _parse_file_metadata(data)


def _parse_file_metadata(data: bytes) -> ParquetFooter:
    """`FileMetaData` from its compact-protocol bytes: field 3 (num_rows) and 5 (key_value)."""
    num_rows: int | None = None
    metadata: dict[bytes, bytes] | None = None
    try:
        pos = field_id = 0
        while num_rows is None or metadata is None:
            kind, field_id, pos = _field_header(data, pos, field_id)
            if kind == STOP:
                break
            if field_id == 3 and kind == I64:
                value, pos = _varint(data, pos)
                num_rows = (value >> 1) ^ -(value & 1)
            elif field_id == 5 and kind == LIST:
                metadata, pos = _key_values(data, pos)
            elif kind > FALSE:  # other fields, and fields of an unexpected type (as Thrift does)
                pos = _skip(data, pos, kind, 1)
    except IndexError:  # a byte read past the end
        raise _garbled("truncated") from None
    if num_rows is None:
        raise _garbled("no row count")
    if not 0 <= num_rows < 2**63:
        raise _garbled(f"row count {num_rows}")
    return ParquetFooter(num_rows, metadata or {})


def _garbled(why: str) -> FooterError:
    return FooterError(f"garbled footer ({why})")


# The readers below take the bytes and a position, and return what they read and the position
# after it. Reading a byte past the end raises IndexError; skipping past it raises FooterError.


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, pos
        shift += 7
        if shift > 63:
            raise _garbled("varint longer than 10 bytes")


def _field_header(data: bytes, pos: int, last_id: int) -> tuple[int, int, int]:
    """The next field's type (STOP at the end of the struct) and id."""
    byte = data[pos]
    kind, delta = byte & 0x0F, byte >> 4
    if kind == STOP or delta:
        return kind, last_id + delta, pos + 1
    value, pos = _varint(data, pos + 1)  # the long form: a zigzag i16 field id
    return kind, (value >> 1) ^ -(value & 1), pos


def _collection_header(data: bytes, pos: int) -> tuple[int, int, int]:
    """A list's or set's element type and size."""
    byte = data[pos]
    kind, size = byte & 0x0F, byte >> 4
    pos += 1
    if size == 15:
        size, pos = _varint(data, pos)
    if not TRUE <= kind <= STRUCT:
        raise _garbled(f"bad element type {kind}")
    if size > len(data) - pos:  # every element takes a byte at least
        raise _garbled(f"list of {size} elements in {len(data) - pos} bytes")
    return kind, size, pos


def _skip(data: bytes, pos: int, kind: int, depth: int) -> int:
    """Skip a value of type `kind` (a boolean takes a byte in a list or map, none in a field)."""
    if I16 <= kind <= I64:
        return pos + 1 if data[pos] < 0x80 else _varint(data, pos)[1]
    if kind == BINARY:
        size, pos = _varint(data, pos)
        pos += size
    elif kind == STRUCT:
        return _skip_struct(data, pos, depth)
    elif kind <= BYTE:
        pos += 1
    elif kind == DOUBLE:
        pos += 8
    elif depth >= MAX_NESTING:
        raise _garbled(f"nested more than {MAX_NESTING} deep")
    elif kind in (LIST, SET):
        element, size, pos = _collection_header(data, pos)
        for _ in range(size):
            pos = _skip(data, pos, element, depth + 1)
    elif kind == MAP:
        size, pos = _varint(data, pos)
        if size:
            key, value = data[pos] >> 4, data[pos] & 0x0F
            pos += 1
            if not (TRUE <= key <= STRUCT and TRUE <= value <= STRUCT):
                raise _garbled(f"bad map types {key}, {value}")
            if 2 * size > len(data) - pos:
                raise _garbled(f"map of {size} entries in {len(data) - pos} bytes")
            for _ in range(size):
                pos = _skip(data, _skip(data, pos, key, depth + 1), value, depth + 1)
    else:
        raise _garbled(f"bad type {kind}")
    if pos > len(data):
        raise _garbled("truncated")
    return pos


def _skip_struct(data: bytes, pos: int, depth: int) -> int:
    """Skip a struct up to its STOP; integers inline, since footers are mostly integers."""
    if depth >= MAX_NESTING:
        raise _garbled(f"nested more than {MAX_NESTING} deep")
    while True:
        byte = data[pos]
        kind = byte & 0x0F
        pos += 1
        if kind == STOP:
            return pos
        if not byte >> 4:  # the long form: a zigzag i16 field id
            pos = _varint(data, pos)[1]
        if I16 <= kind <= I64:
            start = pos
            while data[pos] >= 0x80:
                pos += 1
            if pos - start > 9:
                raise _garbled("varint longer than 10 bytes")
            pos += 1
        elif kind > FALSE:
            pos = _skip(data, pos, kind, depth + 1)


def _binary(data: bytes, pos: int) -> tuple[bytes, int]:
    size, pos = _varint(data, pos)
    if pos + size > len(data):
        raise _garbled("truncated")
    return data[pos:pos + size], pos + size


def _key_values(data: bytes, pos: int) -> tuple[dict[bytes, bytes], int]:
    """`list<KeyValue>`, KeyValue being {1: key (required), 2: value (optional)}.

    Of a repeated key, the first value counts, as in pyarrow.
    """
    element, size, pos = _collection_header(data, pos)
    if element != STRUCT:
        raise _garbled(f"key-value metadata of type {element}")
    pairs: dict[bytes, bytes] = {}
    for _ in range(size):
        key: bytes | None = None
        value = b""
        field_id = 0
        while True:
            kind, field_id, pos = _field_header(data, pos, field_id)
            if kind == STOP:
                break
            if field_id == 1 and kind == BINARY:
                key, pos = _binary(data, pos)
            elif field_id == 2 and kind == BINARY:
                value, pos = _binary(data, pos)
            elif kind > FALSE:
                pos = _skip(data, pos, kind, 2)
        if key is None:
            raise _garbled("key-value entry without a key")
        pairs.setdefault(key, value)
    return pairs, pos
