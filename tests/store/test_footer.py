"""The pyarrow-free footer reader agrees with pyarrow, and any damage is a FooterError.

pyarrow writes the files (many column types, row groups, codecs, with and without statistics
and metadata); hand-built footers exercise what pyarrow never writes but a compact-protocol
reader must skip (maps, sets, doubles, long field ids, long lists), and pyarrow's own reader
is the judge of how they decode. Cut, flipped and random bytes must give FooterError or a footer,
never another exception.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import tracemalloc
from datetime import UTC, datetime
from decimal import Decimal
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pianobot.store.footer import FooterError, ParquetFooter, read_footer

# One bug shrunk, not all: shrinking several distinct failures of these tests takes minutes.
FUZZ = settings(max_examples=150, deadline=None, report_multiple_bugs=False,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def _table(rows: int) -> pa.Table:
    """A table with one column of each kind the store (and pyarrow) might write."""
    ints = list(range(rows))
    return pa.table({
        "i64": pa.array(ints, pa.int64()),
        "i8": pa.array([i % 100 - 50 for i in ints], pa.int8()),
        "u32": pa.array(ints, pa.uint32()),
        "f64": pa.array([i / 7 for i in ints], pa.float64()),
        "f32": pa.array([None if i % 5 == 0 else i / 3 for i in ints], pa.float32()),
        "s": pa.array([f"trial-{i:06d}" for i in ints]),
        "dict": pa.array([("sim-truth", "arm", "key")[i % 3] for i in ints]).dictionary_encode(),
        "big_s": pa.array([str(i) * 3 for i in ints], pa.large_string()),
        "bin": pa.array([bytes([i % 256]) * (i % 4) for i in ints], pa.binary()),
        "fixed": pa.array([i.to_bytes(4, "little") for i in ints], pa.binary(4)),
        "lst": pa.array([list(range(i % 4)) for i in ints], pa.list_(pa.int32())),
        "st": pa.array([{"a": i % 30_000, "b": str(i)} for i in ints],
                       pa.struct([("a", pa.int16()), ("b", pa.string())])),
        "mp": pa.array([[("k", i)] for i in ints], pa.map_(pa.string(), pa.int64())),
        "ts": pa.array([datetime(2024, 1, 1, tzinfo=UTC)] * rows,
                       pa.timestamp("us", tz="UTC")),
        "ts_ns": pa.array([i * 1000 for i in ints], pa.timestamp("ns")),
        "date": pa.array(ints, pa.int32()).cast(pa.date32()),
        "dec": pa.array([Decimal(i) / 100 for i in ints], pa.decimal128(12, 2)),
        "flag": pa.array([i % 2 == 0 for i in ints]),
        "nul": pa.nulls(rows),
    })


META = {b"pianobot.batches": b"[1, 2, 3]", b"pianobot.schema_version": b"4", b"empty": b""}
WRITES: dict[str, dict[str, Any]] = {
    "default": {},
    "metadata": {"meta": META},
    "row_groups": {"rows": 1000, "row_group_size": 7, "meta": META},
    "no_statistics": {"write_statistics": False, "meta": META},
    "no_compression": {"compression": "none"},
    "zstd_no_dictionary": {"compression": "zstd", "use_dictionary": False},
    "gzip_v1": {"compression": "gzip", "version": "1.0"},
    "page_v2": {"data_page_version": "2.0", "meta": META},
    "no_arrow_schema": {"store_schema": False},
    "empty": {"rows": 0, "meta": META},
    "empty_no_arrow_schema": {"rows": 0, "store_schema": False},
    "large": {"rows": 100_000, "row_group_size": 30_000, "meta": META},
}


@pytest.mark.parametrize("name", sorted(WRITES))
def test_agrees_with_pyarrow(tmp_path: Path, name: str) -> None:
    options = dict(WRITES[name])
    rows, meta = options.pop("rows", 50), options.pop("meta", None)
    table = _table(rows)
    if meta is not None:
        table = table.replace_schema_metadata(meta)
    path = tmp_path / "t.parquet"
    pq.write_table(table, path, **options)

    footer = read_footer(path)

    file_meta = pq.read_metadata(path)
    assert footer == ParquetFooter(file_meta.num_rows, file_meta.metadata or {})
    assert footer.num_rows == rows
    assert (pq.read_schema(path).metadata or {}).items() <= footer.metadata.items()
    if meta is not None:
        assert footer.metadata[b"pianobot.batches"] == b"[1, 2, 3]"


def test_no_columns_and_appended_tables(tmp_path: Path) -> None:
    pq.write_table(pa.table({}), tmp_path / "none.parquet")
    footer = read_footer(tmp_path / "none.parquet")
    assert footer.num_rows == 0
    assert footer.metadata == pq.read_metadata(tmp_path / "none.parquet").metadata
    table = _table(10).replace_schema_metadata(META)
    with pq.ParquetWriter(tmp_path / "parts.parquet", table.schema) as writer:
        for _ in range(3):
            writer.write_table(table)
        writer.add_key_value_metadata({"added": "later"})
    footer = read_footer(tmp_path / "parts.parquet")
    assert footer.num_rows == 30
    assert footer.metadata == pq.read_metadata(tmp_path / "parts.parquet").metadata
    assert footer.metadata[b"added"] == b"later"


def test_imports_only_the_standard_library(tmp_path: Path) -> None:
    """Loaded on its own (not through pianobot.store), reading a footer imports no pyarrow."""
    pq.write_table(_table(5), tmp_path / "t.parquet")
    module = Path(__file__).parents[2] / "pianobot" / "store" / "footer.py"
    code = (
        "import importlib.util, sys\n"
        f"spec = importlib.util.spec_from_file_location('footer', {str(module)!r})\n"
        "footer = importlib.util.module_from_spec(spec); sys.modules['footer'] = footer\n"
        "spec.loader.exec_module(footer)\n"
        f"assert footer.read_footer({str(tmp_path / 't.parquet')!r}).num_rows == 5\n"
        "heavy = {'pyarrow', 'numpy', 'pandas'} & set(sys.modules)\n"
        "assert not heavy, heavy\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# --- damage ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_file() -> bytes:
    """A small Parquet file with metadata, as bytes (about 3 kB, most of it footer)."""
    sink = pa.BufferOutputStream()
    pq.write_table(_table(20).select(["i64", "s", "dict", "st", "ts"])
                   .replace_schema_metadata(META), sink, row_group_size=8)
    return bytes(sink.getvalue().to_pybytes())


def _read(path: Path, data: bytes) -> ParquetFooter | FooterError:
    path.write_bytes(data)
    try:
        return read_footer(path)
    except FooterError as exc:
        return exc


def test_every_cut_is_a_footer_error(tmp_path: Path, small_file: bytes) -> None:
    """A file cut short at any byte (a killed write), or missing its start."""
    path = tmp_path / "cut.parquet"
    assert isinstance(_read(path, small_file), ParquetFooter)
    for cut in reversed(range(len(small_file))):
        os.truncate(path, cut)
        with pytest.raises(FooterError):
            read_footer(path)
    for cut in range(1, len(small_file), 3):
        assert isinstance(_read(path, small_file[cut:]), FooterError), cut


@pytest.mark.parametrize(("data", "message"), [
    (b"", "too short to be Parquet (0 bytes)"),
    (b"PAR1PAR1", "too short to be Parquet (8 bytes)"),
    (b"PAR1\0\0\0\0\0\0\0\0", "no Parquet magic at the end"),
    (b"PAR0\0\0\0\0\0\0\0\0PAR1", "no Parquet magic at the start"),
    (b"PAR1\0\0\0\0\0\0\0\0PARE", "encrypted Parquet files are not supported"),
    (b"PAR1\0\0\0\0\x05\0\0\0PAR1", "footer length 5 exceeds the file (16 bytes)"),
    (b"PAR1\0\0\0\0\xff\xff\xff\xffPAR1", "footer length 4294967295 exceeds the file"),
    (b"PAR1\0\0\0\0\0\0\0\0PAR1", "garbled footer (truncated)"),
    (b"PAR1\0\0\0\0\x01\0\0\0PAR1", "garbled footer (no row count)"),
])
def test_messages(tmp_path: Path, data: bytes, message: str) -> None:
    (tmp_path / "f.parquet").write_bytes(data)
    with pytest.raises(FooterError, match="^" + message.replace("(", r"\(").replace(")", r"\)")):
        read_footer(tmp_path / "f.parquet")


def test_missing_file_and_folder(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read_footer(tmp_path / "absent.parquet")
    with pytest.raises(OSError):
        read_footer(tmp_path)


@FUZZ
@given(flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)),
                      min_size=1, max_size=4))
def test_flipped_footer_bytes(tmp_path: Path, small_file: bytes,
                              flips: list[tuple[int, int]]) -> None:
    length = int.from_bytes(small_file[-8:-4], "little")
    start = len(small_file) - 8 - length
    data = bytearray(small_file)
    for at, mask in flips:
        data[start + at % length] ^= mask
    _assert_footer_or_error(_read(tmp_path / "flipped.parquet", bytes(data)))


@FUZZ
@given(body=st.binary(max_size=200), length=st.integers(0, 220) | st.integers(0, 2**32 - 1))
def test_garbage(tmp_path: Path, body: bytes, length: int) -> None:
    data = b"PAR1" + body + length.to_bytes(4, "little") + b"PAR1"
    _assert_footer_or_error(_read(tmp_path / "garbage.parquet", data))
    alone = _read(tmp_path / "garbage.parquet", body)
    if body[:4] == body[-4:] == b"PAR1" and len(body) >= 12:
        _assert_footer_or_error(alone)
    else:
        assert isinstance(alone, FooterError)  # no magic at one end or the other


def _assert_footer_or_error(result: ParquetFooter | FooterError) -> None:
    """A damaged file reads as a footer that makes sense or as a FooterError, nothing else."""
    if isinstance(result, FooterError):
        assert str(result)  # a message to show
        return
    assert isinstance(result, ParquetFooter) and result.num_rows >= 0
    assert all(isinstance(k, bytes) and isinstance(v, bytes) for k, v in result.metadata.items())


# --- hand-built footers: a small compact-protocol writer ------------------------------------

STOP, TRUE, FALSE, BYTE, I16, I32, I64, DOUBLE, BINARY, LIST, SET, MAP, STRUCT = range(13)
Field = tuple[int, int, Any]  # id, type, value (a bool field has type TRUE and a bool value)


def _varint(n: int) -> bytes:
    out = bytearray()
    while n > 0x7F:
        out.append(n & 0x7F | 0x80)
        n >>= 7
    return bytes(out + bytes([n]))


def _zigzag(n: int) -> bytes:
    return _varint((n << 1) ^ (n >> 63))


def _value(kind: int, value: Any) -> bytes:
    """A value as written in a list, map or (without the bool case) a field."""
    if kind == TRUE:
        return bytes([TRUE if value else FALSE])
    if kind == BYTE:
        return struct.pack("<b", value)
    if kind in (I16, I32, I64):
        return _zigzag(value)
    if kind == DOUBLE:
        return struct.pack("<d", value)
    if kind == BINARY:
        return _varint(len(value)) + bytes(value)
    if kind in (LIST, SET):
        element, items = value
        size = bytes([len(items) << 4 | element]) if len(items) < 15 else (
            bytes([0xF0 | element]) + _varint(len(items)))
        return size + b"".join(_value(element, item) for item in items)
    if kind == MAP:
        key, val, pairs = value
        head = _varint(len(pairs)) + (bytes([key << 4 | val]) if pairs else b"")
        return head + b"".join(_value(key, k) + _value(val, v) for k, v in pairs)
    assert kind == STRUCT
    return _struct(value)


def _struct(fields: list[Field]) -> bytes:
    out, last = bytearray(), 0
    for field_id, kind, value in fields:
        wire = (TRUE if value else FALSE) if kind == TRUE else kind
        if 0 < field_id - last <= 15:
            out.append((field_id - last) << 4 | wire)
        else:
            out += bytes([wire]) + _zigzag(field_id)
        if kind != TRUE:
            out += _value(kind, value)
        last = field_id
    return bytes(out + b"\0")


def _file(footer: bytes) -> bytes:
    return b"PAR1" + footer + len(footer).to_bytes(4, "little") + b"PAR1"


def _file_metadata(num_rows: int, key_values: list[list[Field]] | None = None,
                   extra: list[Field] | None = None) -> list[Field]:
    """A FileMetaData pyarrow accepts: a root schema without columns and no row groups."""
    fields: list[Field] = [
        (1, I32, 1),
        (2, LIST, (STRUCT, [[(4, BINARY, b"schema"), (5, I32, 0)]])),
        (3, I64, num_rows),
        (4, LIST, (STRUCT, [])),
    ]
    if key_values is not None:
        fields.append((5, LIST, (STRUCT, key_values)))
    return sorted(fields + (extra or []), key=lambda f: f[0])


def _agree(path: Path, fields: list[Field]) -> ParquetFooter:
    path.write_bytes(_file(_struct(fields)))
    footer = read_footer(path)
    file_meta = pq.read_metadata(path)
    assert footer == ParquetFooter(file_meta.num_rows, file_meta.metadata or {})
    return footer


def test_hand_built_footer(tmp_path: Path) -> None:
    kv: list[list[Field]] = [[(1, BINARY, b"pianobot.batches"), (2, BINARY, b"[7]")],
          [(1, BINARY, b"no value")],
          [(2, BINARY, b"value first"), (1, BINARY, b"k"), (9, MAP, (I32, TRUE, [(1, True)]))],
          [(1, BINARY, b"k"), (2, BINARY, b"the last of a repeated key")]]
    extra: list[Field] = [
        (-3, DOUBLE, 1.5),
        (30, TRUE, False),
        (31, SET, (BINARY, [b"x"] * 20)),
        (40, MAP, (BINARY, STRUCT, [(b"a", [(1, BYTE, -1), (2, TRUE, True)])])),
        (300, LIST, (TRUE, [True, False] * 10)),
        (301, LIST, (LIST, [(I16, [-1, 2**15 - 1]), (DOUBLE, [])])),
    ]
    footer = _agree(tmp_path / "f.parquet", _file_metadata(2**40, kv, extra))
    assert footer.num_rows == 2**40
    assert footer.metadata == {b"pianobot.batches": b"[7]", b"no value": b"",
                               b"k": b"value first"}  # of a repeated key, the first
    assert _agree(tmp_path / "f.parquet", _file_metadata(0, None, extra)).metadata == {}


SCALARS = [TRUE, BYTE, I16, I32, I64, DOUBLE, BINARY]
KINDS = [*SCALARS, LIST, SET, MAP, STRUCT]
BOUNDS = {BYTE: 2**7, I16: 2**15, I32: 2**31, I64: 2**63}


@st.composite
def _any_value(draw: st.DrawFn, kind: int, depth: int) -> Any:
    kinds = st.sampled_from(KINDS if depth < 3 else SCALARS)
    if kind == TRUE:
        return draw(st.booleans())
    if kind in BOUNDS:
        return draw(st.integers(-BOUNDS[kind], BOUNDS[kind] - 1))
    if kind == DOUBLE:
        return draw(st.floats())
    if kind == BINARY:
        return draw(st.binary(max_size=20))
    if kind in (LIST, SET):
        element = draw(kinds)
        return element, draw(st.lists(_any_value(element, depth + 1), max_size=17))
    if kind == MAP:
        key, val = draw(kinds), draw(kinds)
        return key, val, draw(st.lists(st.tuples(_any_value(key, depth + 1),
                                                 _any_value(val, depth + 1)), max_size=4))
    return draw(_fields(depth + 1, st.integers(-40, 40)))


def _fields(depth: int, ids: st.SearchStrategy[int]) -> st.SearchStrategy[list[Field]]:
    @st.composite
    def field(draw: st.DrawFn) -> Field:
        kind = draw(st.sampled_from(KINDS if depth < 3 else SCALARS))
        return draw(ids), kind, draw(_any_value(kind, depth))
    return st.lists(field(), max_size=4, unique_by=lambda f: f[0]).map(
        lambda fields: sorted(fields, key=lambda f: f[0]))


# FileMetaData has fields 1 to 9; the others, and negative ids, are unknown to pyarrow.
UNKNOWN_IDS = st.integers(10, 20) | st.integers(10, 2**15 - 1) | st.integers(-(2**15), -1)


@settings(FUZZ, max_examples=75)
@given(num_rows=st.integers(0, 2**63 - 1),
       extra=_fields(1, UNKNOWN_IDS),
       kv=st.none() | st.lists(st.tuples(st.binary(max_size=8), st.binary(max_size=8) | st.none(),
                                         _fields(2, st.integers(3, 40))), max_size=5))
def test_skips_what_pyarrow_skips(tmp_path: Path, num_rows: int, extra: list[Field],
                                  kv: list[tuple[bytes, bytes | None, list[Field]]] | None) -> None:
    """Unknown fields of any type in FileMetaData and KeyValue: skipped as pyarrow does."""
    key_values = None if kv is None else [
        sorted([(1, BINARY, key), *([] if value is None else [(2, BINARY, value)]), *more],
               key=lambda f: f[0]) for key, value, more in kv]
    footer = _agree(tmp_path / "f.parquet", _file_metadata(num_rows, key_values, extra))
    assert footer.num_rows == num_rows
    assert set(footer.metadata) == ({key for key, _, _ in kv} if kv else set())


@pytest.mark.parametrize(("fields", "message"), [
    ([(1, I32, 1)], "no row count"),
    ([(3, I32, 5)], "no row count"),  # a field of the wrong type is skipped, as Thrift does
    ([(3, I64, -1)], "row count -1"),
    ([(5, LIST, (BINARY, [b"k"])), (3, I64, 1)], "key-value metadata of type 8"),
    ([(3, I64, 1), (5, LIST, (STRUCT, [[(2, BINARY, b"v")]]))], "key-value entry without a key"),
])
def test_bad_file_metadata(tmp_path: Path, fields: list[Field], message: str) -> None:
    (tmp_path / "f.parquet").write_bytes(_file(_struct(fields)))
    with pytest.raises(FooterError, match=message):
        read_footer(tmp_path / "f.parquet")


def _nested(depth: int) -> bytes:
    """FileMetaData whose field 1 nests `depth` structs (an i32 inside), then num_rows 9."""
    inner = b"\x15\x00"  # field 1, i32 0
    return b"\x1c" * depth + inner + b"\x00" * depth + b"\x26\x12\x00"  # field 3, i64 9; stop


@pytest.mark.parametrize(("footer", "message"), [
    (b"\x1d", "bad type 13"),
    (b"\x19\x1f\x00", "bad element type 15"),
    (b"\x19\xf8\xff\xff\xff\xff\x0f", "list of 4294967295 elements in 0 bytes"),
    (b"\x1b\x02\xc8", "map of 2 entries in 0 bytes"),
    (b"\x1b\x01\x08", "bad map types 0, 8"),
    (b"\x16" + b"\xff" * 10, "varint longer than 10 bytes"),
    (b"\x36" + b"\xfe" + b"\xff" * 8 + b"\x03\x00", "row count 18446744073709551615"),
    (b"\x18\x05ab", "truncated"),
    (b"\x17\x00\x00", "truncated"),
    (b"\x15\x80", "truncated"),
    (b"\x19\xf5\x14" + b"\x02" * 10, "list of 20 elements in 10 bytes"),
    (b"\x3c" * 100, "nested more than 64 deep"),
    (_nested(64), "nested more than 64 deep"),
])
def test_garbled_thrift(tmp_path: Path, footer: bytes, message: str) -> None:
    (tmp_path / "f.parquet").write_bytes(_file(footer))
    with pytest.raises(FooterError, match=message):
        read_footer(tmp_path / "f.parquet")


def test_deep_but_not_too_deep(tmp_path: Path) -> None:
    """FileMetaData and 63 structs inside it are read; one more is too deep."""
    (tmp_path / "f.parquet").write_bytes(_file(_nested(63)))
    assert read_footer(tmp_path / "f.parquet").num_rows == 9
    for depth in (64, 500, 5000):  # a runaway nesting is an error, not a RecursionError
        (tmp_path / "f.parquet").write_bytes(_file(_nested(depth)))
        with pytest.raises(FooterError, match="nested"):
            read_footer(tmp_path / "f.parquet")


def test_reads_only_the_tail(tmp_path: Path, small_file: bytes) -> None:
    """A 4 GB file (sparse: its footer after a hole) is not read whole."""
    length = int.from_bytes(small_file[-8:-4], "little")
    path = tmp_path / "big.parquet"
    with open(path, "wb") as file:
        file.write(small_file[:4])
        file.seek(2**32)
        file.write(small_file[-8 - length:])
    tracemalloc.start()
    try:
        footer = read_footer(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert footer.num_rows == 20
    assert peak < 1_000_000
