"""Importers: new runs through the store, meta, derived mocap runs, nothing stored on bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from motive_synth import RATE_HZ, arm_press_track, motive_csv, six_press_take

from pianobot.errors import InputError
from pianobot.io.importers import file_sha256, import_force_log, import_keystroke_log, import_mocap
from pianobot.store import RunWriter, list_runs, load_run


def log_file(tmp_path: Path) -> Path:
    lines = []
    for i in range(6):
        midi = (
            []
            if i == 2
            else [[[144, 57, 5 + i, 0], 1000 + 3000 * i], [[128, 57, 20, 0], 2200 + 3000 * i]]
        )
        lines.append(repr({"control": [40, 20, 0.5, 0.01 * (i + 1), 0.03, 0.05, 0], "midi": midi}))
    lines.insert(3, "{'control': [40, 20")
    path = tmp_path / "soft_40_angle_20.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_keystroke_log_becomes_a_run(tmp_path: Path, data_dir: Path) -> None:
    path = log_file(tmp_path)
    result = import_keystroke_log(path, data_dir)
    out = result.to_dict()
    assert (out["trials"], out["silent"]) == (6, 1)
    assert out["skipped_lines"] == [{"line": 4, "reason": out["skipped_lines"][0]["reason"]}]
    run = load_run(result.run_id, data_dir)
    assert run.meta["kind"] == "import" and run.meta["status"] == "completed"
    assert run.meta["source"] == {
        "file": path.name,
        "sha256": file_sha256(path),
        "format": "keystroke-log",
    }
    assert run.meta["layout"] == "soft-2022"
    trials = run.trials
    assert trials["vacuum_kpa"].unique().tolist() == [-40.0]
    assert trials["status"].value_counts().to_dict() == {"ok": 5, "silent": 1}
    assert set(run.midi["trial_id"]) <= set(trials["trial_id"])
    assert len(run.midi) == 10


def test_same_file_gives_same_trial_ids(tmp_path: Path, data_dir: Path) -> None:
    path = log_file(tmp_path)
    a = load_run(import_keystroke_log(path, data_dir).run_id, data_dir).trials["trial_id"]
    b = load_run(import_keystroke_log(path, data_dir).run_id, data_dir).trials["trial_id"]
    assert a.tolist() == b.tolist()


def test_bad_file_stores_nothing(tmp_path: Path, data_dir: Path) -> None:
    bad = tmp_path / "bad.txt"
    bad.write_bytes(b"\x00\x01")
    for call in (import_keystroke_log, import_force_log, import_mocap):
        with pytest.raises(InputError):
            call(bad, data_dir)
    assert list_runs(data_dir) == []
    assert not (data_dir / "runs").exists() or not any((data_dir / "runs").iterdir())


def test_force_log_aligned_to_a_run(tmp_path: Path, data_dir: Path) -> None:
    keys = import_keystroke_log(log_file(tmp_path), data_dir)
    rate = 50.0
    readings = [0] * 40
    for i in range(6):  # the force capture starts 2 s before the MIDI clock's 1 s mark
        onset = int((1.0 + 3.0 * i - 0.3 + 2.0) * rate)
        readings += [0] * (onset - len(readings)) + [25] * 30
    readings += [0] * 50
    path = tmp_path / "force.txt"
    path.write_text("\n".join(f"Analog reading = {r}" for r in readings))
    result = import_force_log(path, data_dir, align_run=keys.run_id)
    out = result.to_dict()
    assert out["bursts"] == 6 and out["matched"] == 5
    assert out["rate_hz"] == pytest.approx(rate, rel=0.01)
    run = load_run(result.run_id, data_dir)
    assert run.meta["aligned_to"]["run_id"] == keys.run_id
    assert run.trials["matched_trial_id"].notna().sum() == 5
    assert run.trials["peak_force_n"].to_numpy() == pytest.approx(0.0353 * 25 + 0.204)


def test_mocap_without_run(synthetic_take_path: Path, data_dir: Path) -> None:
    result = import_mocap(synthetic_take_path, data_dir)
    out = result.to_dict()
    assert out["keystrokes"] == 6 and out["trials"] == 6
    run = load_run(result.run_id, data_dir)
    assert run.trials["down_velocity_mps"].to_numpy() == pytest.approx(
        [0.01, 0.02, 0.03, 0.04, 0.05, 0.06], rel=0.05
    )
    samples = run.samples
    assert set(samples["source"]) == {"mocap"}
    first = samples[samples["trial_id"] == run.trials["trial_id"].iloc[0]]
    rest = first[first["t_s"] < 0]
    assert rest["x0_m"].abs().max() < 1e-4  # from the rest position, downward positive
    assert first["x0_m"].max() == pytest.approx(0.0072, abs=2e-4)


def test_a_press_lost_to_a_long_occlusion_is_said(synthetic_take_path: Path, tmp_path: Path, data_dir: Path) -> None:
    """Every marker lost for 2 s over the fourth press (7-9 s): the press cannot be segmented,
    and the import says where the take went unseen (it used to lose the press silently)."""
    lines = synthetic_take_path.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("Frame,"))
    for i in range(header + 1, len(lines)):
        cells = lines[i].split(",")
        if 7.0 <= float(cells[1]) <= 9.0:
            lines[i] = ",".join(cells[:2] + [""] * (len(cells) - 2))
    occluded = tmp_path / "occluded.csv"
    occluded.write_text("\n".join(lines) + "\n")
    out = import_mocap(occluded, data_dir).to_dict()
    assert out["keystrokes"] == 5
    (said,) = [w for w in out["warnings"] if "arm marker is lost" in w]
    assert "1 time(s) (7.0–9.0 s)" in said and "not seen" in said
    assert not any("arm marker is lost" in w for w in import_mocap(synthetic_take_path, data_dir).to_dict().get("warnings") or [])


def test_mocap_exported_z_up_gives_the_y_up_takes_keystrokes(tmp_path: Path, data_dir: Path) -> None:
    speeds, starts = [0.01, 0.03, 0.05], [1.0, 4.0, 7.0]
    takes = {up: motive_csv(tmp_path / f"{up}.csv", duration_s=10.0, starts_s=starts, speeds_mps=speeds, up=up)
             for up in ("y", "z")}
    results = {up: import_mocap(path, data_dir) for up, path in takes.items()}
    assert {up: r.extra["up_axis"] for up, r in results.items()} == {"y": "y", "z": "z"}
    runs = {up: load_run(r.run_id, data_dir) for up, r in results.items()}
    assert runs["z"].meta["up_axis"] == "z"
    columns = ["down_velocity_mps", "arm_travel_m", "fingertip_travel_m", "key_travel_m", "t_start_s"]
    pd.testing.assert_frame_equal(runs["z"].trials[columns], runs["y"].trials[columns])
    positions = ["t_s", "x0_m", "x1_m", "x2_m"]
    pd.testing.assert_frame_equal(runs["z"].samples[positions], runs["y"].samples[positions])


def test_take_without_keystrokes_is_refused_naming_the_axis(tmp_path: Path, data_dir: Path) -> None:
    z_up = motive_csv(tmp_path / "z.csv", duration_s=10.0, starts_s=[1.0, 4.0], speeds_mps=[0.01, 0.03], up="z")
    with pytest.raises(InputError, match=r"no keystroke found: no marker moves along the vertical axis \(Y\).*--up-axis"):
        import_mocap(z_up, data_dir, up_axis="y")
    still = motive_csv(tmp_path / "still.csv", duration_s=5.0, starts_s=[], speeds_mps=[])
    with pytest.raises(InputError, match="no keystroke found"):
        import_mocap(still, data_dir)
    assert list_runs(data_dir) == []


def test_mocap_aligned_to_a_run_makes_a_derived_run(tmp_path: Path, data_dir: Path) -> None:
    speeds = [0.02, 0.03, 0.04, 0.05]
    starts_run = [5.0, 8.0, 11.0, 14.0]
    offset = 3.7  # run clock = mocap clock + offset
    take = motive_csv(tmp_path / "t.csv", duration_s=16.0, starts_s=[s - offset for s in starts_run],
                      speeds_mps=speeds, seed=2)  # fmt: skip
    writer = RunWriter.create(data_dir, name="sweep", kind="sweep", meta={}, plan=None)
    t_rel = np.arange(0, 2.0, 1 / 500)
    trials = pd.DataFrame({"trial_id": [f"t{i}" for i in range(4)], "index": range(4), "status": "ok",
                           "t_start_s": starts_run, "down_velocity_mps": speeds})  # fmt: skip
    samples = pd.concat(
        pd.DataFrame(
            {
                "trial_id": f"t{i}",
                "source": "arm",
                "t_s": t_rel,
                "x0_m": arm_press_track(t_rel, [0.0], [v], 0.0072),
            }
        )  # fmt: skip
        for i, v in enumerate(speeds)
    )
    writer.append(trials, samples=samples)
    writer.finish("completed")
    writer.close()
    before = sorted(p.name for p in writer.path.rglob("*"))
    result = import_mocap(take, data_dir, run_id=writer.run_id)
    out = result.to_dict()
    assert out["clock_offset_s"] == pytest.approx(offset, abs=1.5 / RATE_HZ)
    assert sorted(p.name for p in writer.path.rglob("*")) == before  # the original is untouched
    derived = load_run(result.run_id, data_dir)
    assert derived.meta["derived_from"] == writer.run_id
    assert set(derived.samples["source"]) == {"arm", "mocap"}
    mocap = derived.samples[
        (derived.samples["source"] == "mocap") & (derived.samples["trial_id"] == "t1")
    ]
    moving = mocap[mocap["x0_m"] > 0.0036]
    assert moving["t_s"].min() == pytest.approx(0.0036 / 0.03, abs=0.03)  # half travel at 30 mm/s


@pytest.fixture()
def synthetic_take_path(tmp_path: Path) -> Path:
    return six_press_take(tmp_path)


def test_fixture_imports(zhang2022: Path, data_dir: Path) -> None:
    soft = import_keystroke_log(zhang2022 / "data/soft/ctrl_midi/soft_60_angle_45.txt", data_dir)
    assert (soft.trials, soft.silent, soft.extra["sounded"]) == (135, 32, 103)
    force = import_force_log(
        zhang2022 / "data/soft/force/P60A45.txt", data_dir, align_run=soft.run_id
    )
    assert force.extra["bursts"] == 135 and force.extra["matched"] == 103
    take = import_mocap(zhang2022 / "zzz/zzz40.csv", data_dir)
    assert take.extra["keystrokes"] == 24
