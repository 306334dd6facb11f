"""Parts staged by workers that share the run's file system (`stage_part`): the writer only
renames them into place; a staged part it never committed is invisible and swept."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pandas as pd
import pytest

from pianobot.store import RunDamaged, RunWriter, encode_part, load_run, stage_part
from pianobot.store.integrity import check_run


def _writer(data_dir: Path) -> RunWriter:
    plan = pd.DataFrame({"trial_id": ["a", "b"], "index": [0, 1]})
    return RunWriter.create(data_dir, name="staged", kind="sweep", meta={}, plan=plan)


def _batch(run_id: str) -> tuple[bytes, bytes, int]:
    trials = pd.DataFrame({"trial_id": ["a", "b"], "index": [0, 1], "attempt": 1, "status": "ok", "note": 60})
    samples = pd.DataFrame({"trial_id": ["a"] * 3 + ["b"] * 2, "source": "mocap",
                            "t_s": [0.0, 0.1, 0.2, 0.0, 0.1], "x0_m": 0.0, "x1_m": 0.0, "x2_m": 0.01})
    return encode_part(trials, "trials", run_id), encode_part(samples, "samples", run_id), len(samples)


def test_a_staged_samples_part_is_committed_by_rename_with_the_workers_record(data_dir: Path) -> None:
    writer = _writer(data_dir)
    trials, samples, rows = _batch(writer.run_id)
    staged = stage_part(writer.paths.samples, samples, rows)
    assert Path(staged.temp).parent == writer.paths.samples and Path(staged.temp).name.startswith(".")
    assert staged.record.sha256 == hashlib.sha256(samples).hexdigest() and staged.record.size == len(samples)
    assert load_run(writer.run_id, data_dir).samples.empty  # staged: no reader sees it yet
    batch = writer.append_encoded({"samples": staged, "trials": trials})
    assert not Path(staged.temp).exists()
    part = writer.paths.part("samples", batch)
    assert part.read_bytes() == samples
    run = load_run(writer.run_id, data_dir)
    assert list(run.samples["trial_id"]) == ["a", "a", "a", "b", "b"]
    assert check_run(run.paths, deep=True).ok  # the journalled record is the part's own
    writer.finish("completed")
    writer.close()


def test_a_staged_part_that_is_gone_or_torn_is_refused_and_nothing_is_committed(data_dir: Path) -> None:
    writer = _writer(data_dir)
    trials, samples, rows = _batch(writer.run_id)
    torn = stage_part(writer.paths.samples, samples, rows)
    Path(torn.temp).write_bytes(samples[:-10])
    with pytest.raises(RunDamaged, match="not the"):
        writer.append_encoded({"samples": torn, "trials": trials})
    gone = stage_part(writer.paths.samples, samples, rows)
    Path(gone.temp).unlink()
    with pytest.raises(RunDamaged, match="gone"):
        writer.append_encoded({"samples": gone, "trials": trials})
    elsewhere = stage_part(writer.paths.root / "elsewhere", samples, rows)
    with pytest.raises(ValueError, match="cannot become"):
        writer.append_encoded({"samples": elsewhere, "trials": trials})
    assert load_run(writer.run_id, data_dir).trials.empty
    writer.close()


def test_a_part_staged_but_never_committed_is_swept_on_resume(data_dir: Path) -> None:
    writer = _writer(data_dir)
    _, samples, rows = _batch(writer.run_id)
    left = Path(stage_part(writer.paths.samples, samples, rows).temp)  # the driver was killed here
    writer.close()
    assert load_run(writer.run_id, data_dir).samples.empty
    RunWriter.reopen(data_dir, writer.run_id).close()
    assert not left.exists()
