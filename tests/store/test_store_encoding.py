"""How sample rows are encoded: ids as dictionaries from a block to the file, strings for readers.

A samples part holds millions of rows whose run id, trial id and source repeat; they stay
dictionaries in memory, in the parts and through compaction (no string per row), and every
reader of the store gets them back as the strings `TABLE_SCHEMAS` declares, whether the rows are
still in parts (a live run) or compacted, and whatever an older pianobot wrote.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pianobot.run.rows import SampleChunk, TrialData, samples_table
from pianobot.store import RunWriter, load_run
from pianobot.store.layout import RunPaths
from pianobot.store.schema import TABLE_SCHEMAS
from pianobot.store.tables import read_run_table


def _data(trial_id: str, n: int, seed: int) -> TrialData:
    rng = np.random.default_rng(seed)
    chunks = tuple(
        SampleChunk(source, np.arange(n) * 1e-3, *(rng.normal(size=n) for _ in range(3)))
        for source in ("sim-truth", "arm")
    )
    return TrialData(row={"trial_id": trial_id, "index": seed, "attempt": 1, "status": "ok"},
                     samples=chunks)


def _expected(batch: list[TrialData]) -> pd.DataFrame:
    rows = [pd.DataFrame({"trial_id": d.trial_id, "source": c.source, "t_s": c.t_s, "x0_m": c.x0_m,
                          "x1_m": c.x1_m, "x2_m": c.x2_m}) for d in batch for c in d.samples]
    return pd.concat(rows, ignore_index=True)


def test_block_samples_keep_ids_as_dictionaries_and_read_back_as_strings(tmp_path: Path) -> None:
    batch = [_data(f"t{i}", 50 + 7 * i, i) for i in range(4)]
    table = samples_table(batch)
    assert table is not None
    assert all(pa.types.is_dictionary(table.schema.field(c).type) for c in ("trial_id", "source"))
    writer = RunWriter.create(tmp_path, name="enc", kind="sweep", meta={}, plan=None)
    with writer:
        writer.append(pd.DataFrame([d.row for d in batch[:2]]), samples_table(batch[:2]))
        # Live (parts only): strings, the same rows.
        live = load_run(writer.run_id, tmp_path).samples
        writer.append(pd.DataFrame([d.row for d in batch[2:]]), samples_table(batch[2:]))
        writer.finish("completed")
    run = load_run(writer.run_id, tmp_path)
    declared = TABLE_SCHEMAS["samples"].empty_table().to_pandas().dtypes
    for frame, rows in ((live, batch[:2]), (run.samples, batch)):
        assert frame.dtypes.equals(declared)  # not categorical
        got = frame.drop(columns=["run_id"]).reset_index(drop=True)
        pd.testing.assert_frame_equal(got, _expected(rows), check_dtype=False)
    assert set(run.samples["run_id"]) == {writer.run_id}
    # The stored samples (one file per batch, never re-encoded) keep the ids as dictionaries
    # and the floats split into byte streams.
    stored = pq.ParquetFile(run.path / "samples" / "samples-000002.parquet")
    assert pa.types.is_dictionary(stored.schema_arrow.field("trial_id").type)
    assert "BYTE_STREAM_SPLIT" in stored.metadata.row_group(0).column(3).encodings
    # Columns without nulls are declared so in the file (no definition levels to write); the
    # reader hands them out as declared, nullable, live or finished.
    assert not stored.schema_arrow.field("x0_m").nullable
    assert read_run_table(RunPaths(run.path), "samples").schema.field("x0_m").nullable


def test_parts_with_plain_string_ids_compact_with_dictionary_ones(tmp_path: Path) -> None:
    """A run started by an older pianobot (string columns) and resumed by this one."""
    old, new = [_data("a", 40, 1), _data("b", 30, 2)], [_data("c", 20, 3)]
    writer = RunWriter.create(tmp_path, name="mixed", kind="sweep", meta={}, plan=None)
    with writer:
        writer.append(pd.DataFrame([d.row for d in old]), _expected(old))  # plain strings
        writer.append(pd.DataFrame([d.row for d in new]), samples_table(new))
        writer.finish("completed")
    got = load_run(writer.run_id, tmp_path).samples.drop(columns=["run_id"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(got, _expected(old + new), check_dtype=False)
