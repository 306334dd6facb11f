"""Each kind of damaged run: named before any motion, repaired, then completed exactly once.

The kinds are those the hostile-input survey met: a truncated samples part, a truncated or
empty trials part, a truncated plan.parquet, a garbled run.json, and a truncated compacted
table. For each: resume refuses with one line and touches nothing (the rig is never opened);
`runs show` and `report` say the same in one line; `pianobot runs` lists the run as damaged
with the reason; `runs repair` quarantines (never deletes) and keeps every trial whose data
survived; and a resume then completes the run with every planned trial exactly once.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

import pianobot.run.sweep as sweep_module
from pianobot.store import check_run, load_run
from robustness.harness import assert_cli_refused, cli, copy_tree, only_run, tree_digest

Damage = Callable[[Path], None]


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _first(run: Path, table: str) -> Path:
    """The first part of `table` (samples parts live in samples/, the others in parts/)."""
    return sorted((run / ("samples" if table == "samples" else "parts")).glob(f"{table}-*.parquet"))[0]


def _batch_trials(run: Path, part: Path) -> int:
    """How many trial rows the batch of `part` committed (its journalled trials part)."""
    batch = int(part.stem.rsplit("-", 1)[1])
    for line in (run / "journal.jsonl").read_text().splitlines():
        event = json.loads(line)
        if event.get("event") == "part" and event.get("batch") == batch:
            return int(event["files"]["trials"]["rows"])
    raise AssertionError(f"batch {batch} is not in the journal")


def _rows(path: Path) -> int:
    return int(pq.read_metadata(path).num_rows)


def _none(run: Path) -> int:
    return 0


# kind → (template, damage, how many completed trials lose their data: counted before damage)
KINDS: dict[str, tuple[str, Damage, Callable[[Path], int]]] = {
    "samples part truncated": ("killed", lambda r: _truncate(_first(r, "samples")),
                               lambda r: _rows(_first(r, "trials"))),  # its batch is redone
    "trials part truncated": ("killed", lambda r: _truncate(_first(r, "trials")), _none),
    "trials part empty": ("killed", lambda r: _first(r, "trials").write_bytes(b""), _none),
    "plan.parquet truncated": ("killed", lambda r: _truncate(r / "plan.parquet"), _none),
    "run.json garbled": ("killed", lambda r: (r / "run.json").write_text('{"run_id": "x", gar'), _none),
    "trials.parquet truncated": ("stopped", lambda r: _truncate(r / "trials.parquet"), _none),
    # A finished run: its trials are in trials.parquet, its samples files stay as written.
    "finished run's samples file truncated": (
        "stopped", lambda r: _truncate(_first(r, "samples")),
        lambda r: _batch_trials(r, _first(r, "samples"))),  # that batch's trials are redone
}


Damaged = tuple[str, Path, Path, pd.DataFrame, int]


@pytest.fixture(params=list(KINDS))
def damaged(request: pytest.FixtureRequest, templates: dict[str, Path], tmp_path: Path) -> Damaged:
    """(kind, data folder, run folder, the trials it held before the damage, trials lost)."""
    kind = request.param
    template, damage, lost = KINDS[kind]
    data = copy_tree(templates[template], tmp_path / "data")
    run = only_run(data)
    before = load_run(run.name, data).trials
    n_lost = lost(run)
    damage(run)
    return kind, data, run, before, n_lost


def test_resume_refuses_a_damaged_run_before_the_rig_opens(
    damaged: Damaged, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    kind, data, run, _, _ = damaged

    def no_motion(*args: object, **kwargs: object) -> None:
        raise AssertionError("the rig was opened for a damaged run")

    monkeypatch.setattr(sweep_module, "open_rig", no_motion)
    line = assert_cli_refused(["sweep", "--resume", run.name, "--data", data], data, capsys, monkeypatch,
                   f"run {run.name} is damaged", "pianobot runs repair")
    assert len(line) < 400


def test_show_report_and_list_name_the_damage(
    damaged: Damaged, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    kind, data, run, _, _ = damaged
    assert_cli_refused(["runs", "show", run.name, "--data", data], data, capsys, monkeypatch, "is damaged")
    out_file = tmp_path / "report.html"
    assert_cli_refused(["report", run.name, "--data", data, "--out", out_file], data, capsys, monkeypatch,
            "is damaged")
    assert not out_file.exists()
    code, out, err = cli(["runs", "--data", data, "--json"], capsys, monkeypatch)
    assert code == 0 and not err
    (listed,) = json.loads(out)
    assert listed["run_id"] == run.name and listed["status"] == "damaged" and listed["reason"]
    code, out, _ = cli(["runs", "check", run.name, "--data", data], capsys, monkeypatch)
    assert code == 1 and "DAMAGED" in out


def test_repair_keeps_what_survived_and_resume_completes_each_trial_once(
    damaged: Damaged, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    kind, data, run, before, lost = damaged
    files_before = tree_digest(run)
    code, out, err = cli(["runs", "repair", run.name, "--data", data], capsys, monkeypatch)
    assert code == 0, out + err
    assert check_run(load_run(run.name, data, check=False).paths).ok
    # Nothing deleted: every file that left its place is in quarantine/, byte for byte.
    after = tree_digest(run)
    moved = [name for name in files_before if name not in after and name != "run.lock"]
    for name in moved:
        copies = [k for k in after if k.startswith("quarantine/") and k.endswith("/" + name)]
        assert copies and after[copies[0]] == files_before[name], name
    meta = load_run(run.name, data).meta
    assert meta["repairs"] and meta["repairs"][-1]["trials_lost"] == lost
    survived = load_run(run.name, data).trials
    assert len(survived) == len(before) - lost
    # The trials that survived are the very rows that were written.
    kept = before[before["trial_id"].isin(survived["trial_id"])].sort_values("trial_id")
    pd.testing.assert_frame_equal(
        kept.reset_index(drop=True),
        survived.sort_values("trial_id").reset_index(drop=True)[kept.columns],
    )

    code, out, err = cli(["sweep", "--resume", run.name, "--data", data, "--json", "--no-progress"],
                         capsys, monkeypatch)
    assert code == 0, err
    final = load_run(run.name, data)
    trials = final.trials
    assert final.meta["status"] == "completed"
    assert trials["trial_id"].is_unique and sorted(trials["trial_id"]) == sorted(final.plan["trial_id"])
    # The survivors were not pressed again: same rows as before the damage.
    again = trials[trials["trial_id"].isin(kept["trial_id"])].sort_values("trial_id")
    pd.testing.assert_frame_equal(kept.reset_index(drop=True),
                                  again.reset_index(drop=True)[kept.columns])
    samples = final.samples
    per_trial = samples.groupby(["trial_id", "source"]).size()
    assert set(samples["trial_id"]) == set(trials["trial_id"])
    assert per_trial.min() > 0
    assert check_run(final.paths).ok


def test_an_intact_run_needs_no_repair(completed_run: Path, capsys: pytest.CaptureFixture[str],
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    run = only_run(completed_run)
    code, out, _ = cli(["runs", "check", run.name, "--data", completed_run], capsys, monkeypatch)
    assert code == 0 and "intact" in out
    before = tree_digest(completed_run)
    code, out, _ = cli(["runs", "repair", run.name, "--data", completed_run], capsys, monkeypatch)
    assert code == 0 and "nothing to repair" in out
    after = tree_digest(completed_run)
    assert {k: v for k, v in after.items() if k.endswith(".lock")} == {}
    assert before == after


def test_a_part_with_other_bytes_is_caught_by_its_checksum(
    killed_run: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Same length, same rows, readable: only the SHA-256 recorded at write time can tell.
    run = only_run(killed_run)
    part = _first(run, "samples")
    data = bytearray(part.read_bytes())
    data[len(data) // 3] ^= 0x01
    part.write_bytes(bytes(data))
    code, out, _ = cli(["runs", "check", run.name, "--data", killed_run], capsys, monkeypatch)
    assert code == 1 and ("SHA-256 differs" in out or "unreadable" in out)
    assert_cli_refused(["sweep", "--resume", run.name, "--data", killed_run], killed_run, capsys, monkeypatch,
            "is damaged")


def test_compaction_verifies_before_it_declares_a_run_complete(
    killed_run: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    from pianobot.store import RunWriter

    run = only_run(killed_run)
    writer = RunWriter.reopen(killed_run, run.name)
    part = _first(run, "midi")
    _truncate(part)
    writer.finish("completed")
    writer.close()
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "damaged" and part.name in meta["reason"]
    assert list((run / "parts").glob("trials-*.parquet")), "parts of a damaged run stay as they are"
    assert not (run / "trials.parquet").exists()
