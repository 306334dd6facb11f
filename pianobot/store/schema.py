"""The fixed columns of a run's tables and their Parquet types (docs/architecture.md).

Every table carries the key-value metadata `pianobot.schema_version` so a reader can tell which
layout it holds. Parameter and outcome columns carry their units in their names. MIDI velocities
are stored as float64 so a silent keystroke's missing velocity is NaN in every reader (pandas,
polars, DuckDB) instead of a type that changes with the data.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa

from pianobot.spec.parameters import PARAMETER_NAMES, PARAMETERS
from pianobot.store.layout import METADATA_BATCHES_KEY, TRIAL_STATUSES, batches_of

if TYPE_CHECKING:  # pandas takes a third of a second to import: only where frames are made
    import pandas as pd

SCHEMA_VERSION = "1"
METADATA_VERSION_KEY = b"pianobot.schema_version"
METADATA_TABLE_KEY = b"pianobot.table"

RUN_STATUSES = ("running", "completed", "stopped", "interrupted", "failed")
RUN_KINDS = ("sweep", "import", "play")
SAMPLE_SOURCES = ("arm", "mocap", "sim-truth")

# The trials table has one column per spec parameter, in the spec's order.
PARAMETER_COLUMNS = PARAMETER_NAMES

TRIALS_SCHEMA = pa.schema(
    [
        ("run_id", pa.string()),
        ("trial_id", pa.string()),
        ("index", pa.int64()),
        ("attempt", pa.int64()),
        ("status", pa.string()),
        *((p.name, pa.int64() if p.integer else pa.float64()) for p in PARAMETERS.values()),
        ("t_start_s", pa.float64()),
        ("on_velocity", pa.float64()),
        ("off_velocity", pa.float64()),
        ("t_on_s", pa.float64()),
        ("t_off_s", pa.float64()),
        ("midi_hold_s", pa.float64()),
        ("n_note_on", pa.int64()),
        ("key_speed_at_trigger_mps", pa.float64()),
        ("max_key_travel_m", pa.float64()),
        ("error", pa.string()),
    ]
)

SAMPLES_SCHEMA = pa.schema(
    [
        ("run_id", pa.string()),
        ("trial_id", pa.string()),
        ("source", pa.string()),
        ("t_s", pa.float64()),
        ("x0_m", pa.float64()),
        ("x1_m", pa.float64()),
        ("x2_m", pa.float64()),
    ]
)

MIDI_SCHEMA = pa.schema(
    [
        ("run_id", pa.string()),
        ("trial_id", pa.string()),
        ("t_s", pa.float64()),
        ("type", pa.string()),
        ("note", pa.int64()),
        ("velocity", pa.int64()),
    ]
)

TABLE_SCHEMAS: dict[str, pa.Schema] = {
    "trials": TRIALS_SCHEMA,
    "samples": SAMPLES_SCHEMA,
    "midi": MIDI_SCHEMA,
}

# Tables whose text columns (run, trial and source ids: a few values over millions of rows) are
# kept as dictionaries in memory and in their Parquet files, so neither a block's writer nor
# compaction copies or hashes a string per row; readers get them back as `TABLE_SCHEMAS` says
# (`as_declared`). A text column given as a dictionary in another table stays one, too.
DICTIONARY_TABLES = frozenset({"samples"})
TEXT_DICTIONARY = pa.dictionary(pa.int32(), pa.string())


def storage_schema(name: str) -> pa.Schema:
    """The Arrow schema of table `name`'s files: `TABLE_SCHEMAS`' with dictionary text columns
    in `DICTIONARY_TABLES`."""
    schema = TABLE_SCHEMAS[name]
    if name not in DICTIONARY_TABLES:
        return schema
    return pa.schema([pa.field(f.name, TEXT_DICTIONARY) if pa.types.is_string(f.type) else f
                      for f in schema], metadata=schema.metadata)


def as_declared(table: pa.Table, name: str) -> pa.Table:
    """`table` with dictionary text columns turned back into the strings `TABLE_SCHEMAS` declares."""
    declared = TABLE_SCHEMAS[name]
    for i, field in enumerate(table.schema):
        if pa.types.is_dictionary(field.type) and field.name in declared.names and pa.types.is_string(
            declared.field(field.name).type
        ):
            table = table.set_column(i, field.name, table.column(i).cast(pa.string()))
    # A part declares its null-free columns non-nullable (`store.layout`); a run reads as declared.
    if any(not f.nullable and f.name in declared.names and declared.field(f.name).nullable
           for f in table.schema):
        fields = [f.with_nullable(True) if f.name in declared.names and declared.field(f.name).nullable
                  else f for f in table.schema]
        table = table.cast(pa.schema(fields, metadata=table.schema.metadata))
    return table


def _repeat_text(value: str, n_rows: int, *, dictionary: bool) -> pa.Array:
    if not dictionary:
        return pa.repeat(pa.scalar(value, type=pa.string()), n_rows)
    zeros = pa.array(np.zeros(n_rows, dtype=np.int32))
    return pa.DictionaryArray.from_arrays(zeros, pa.array([value], type=pa.string()))
# Columns a writer may leave out (they are filled with nulls); the rest identify the row.
_REQUIRED = {
    "trials": ("trial_id",),
    "samples": ("trial_id", "source", "t_s"),
    "midi": ("trial_id", "t_s", "type", "note", "velocity"),
}


def with_metadata(table: pa.Table, name: str, batches: list[int] | None = None) -> pa.Table:
    """Attach the pianobot key-value metadata (schema version, table name, included batches)."""
    metadata = dict(table.schema.metadata or {})
    metadata[METADATA_VERSION_KEY] = SCHEMA_VERSION.encode()
    metadata[METADATA_TABLE_KEY] = name.encode()
    if batches is not None:
        metadata[METADATA_BATCHES_KEY] = ",".join(str(b) for b in batches).encode()
    return table.replace_schema_metadata(metadata)


def to_table(frame: pd.DataFrame | pa.Table, name: str, run_id: str) -> pa.Table:
    """Coerce a frame to the fixed schema of table `name` (column order, types, run_id).

    Missing optional columns become nulls; `trials` may carry extra columns after the fixed
    ones (an importer's own fields), `samples` and `midi` may not, so their parts can be streamed
    into one file at compaction.

    Raises:
        ValueError: a required column is missing or a value cannot take the column's type.
    """
    schema = TABLE_SCHEMAS[name]
    source = frame if isinstance(frame, pa.Table) else pa.Table.from_pandas(frame, preserve_index=False)
    n_rows = source.num_rows
    missing = [c for c in _REQUIRED[name] if c not in source.column_names]
    if missing:
        raise ValueError(f"{name} table lacks required column(s) {missing}")
    extra = [c for c in source.column_names if c not in schema.names]
    if extra and name != "trials":
        raise ValueError(f"{name} table has unknown column(s) {extra}; allowed: {schema.names}")
    arrays: list[pa.Array | pa.ChunkedArray] = []
    fields = []
    for column in schema:
        if column.name == "run_id":
            # Never a Python list of n_rows strings (a samples part has millions of rows).
            array = _repeat_text(run_id, n_rows, dictionary=name in DICTIONARY_TABLES)
        elif column.name in source.column_names:
            array = source.column(column.name)
            if not (pa.types.is_string(column.type) and array.type == TEXT_DICTIONARY):
                array = array.cast(column.type)
        else:
            array = pa.nulls(n_rows, type=column.type)
        arrays.append(array)
        fields.append(pa.field(column.name, array.type))
    for column_name in extra:
        arrays.append(source.column(column_name))
        fields.append(source.schema.field(column_name))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


def empty_frame(name: str) -> pd.DataFrame:
    """An empty DataFrame with the columns and dtypes of table `name`."""
    frame: pd.DataFrame = with_metadata(TABLE_SCHEMAS[name].empty_table(), name).to_pandas()
    return frame


def schema_version_of(metadata: dict[bytes, bytes] | None) -> str | None:
    """The schema version recorded in a Parquet file's key-value metadata, if any."""
    if not metadata or METADATA_VERSION_KEY not in metadata:
        return None
    return metadata[METADATA_VERSION_KEY].decode()



__all__ = [
    "MIDI_SCHEMA",
    "PARAMETER_COLUMNS",
    "RUN_KINDS",
    "RUN_STATUSES",
    "SAMPLES_SCHEMA",
    "SAMPLE_SOURCES",
    "SCHEMA_VERSION",
    "TABLE_SCHEMAS",
    "TRIALS_SCHEMA",
    "TRIAL_STATUSES",
    "batches_of",
    "empty_frame",
    "schema_version_of",
    "to_table",
    "with_metadata",
]
