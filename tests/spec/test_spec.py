"""Experiment specs and rig files: loading, one-line errors naming the YAML path, calibration."""

from __future__ import annotations

import hashlib
import textwrap
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.errors import InputError
from pianobot.spec import (
    ExperimentSpec,
    GridSweep,
    RigSpec,
    load_rig,
    load_rig_for,
    load_spec,
    resolved_spec_dict,
    spec_sha256,
    write_rig_calibration,
)

REPO = Path(__file__).resolve().parents[2]
EXPERIMENTS = REPO / "experiments"

GOOD = """\
name: soft-test
finger: soft
sweep:
  mode: grid
  params:
    vacuum_kpa: [0, -40]
    down_velocity_mps: {start: 0.01, stop: 0.06, num: 6}
    depth_m: [0.02, 0.03]
  fixed: {distance_m: 0.05, hold_s: 0.0}
"""


def write(tmp_path: Path, text: str, name: str = "spec.yaml") -> Path:
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def spec_with(sweep_body: str, *, finger: str = "soft", extra: str = "") -> str:
    """A spec whose sweep section is `sweep_body` (indented under `sweep:`)."""
    body = textwrap.indent(textwrap.dedent(sweep_body), "  ")
    return f"name: t\nfinger: {finger}\n{extra}sweep:\n{body}"


def load_error(tmp_path: Path, text: str) -> InputError:
    path = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_spec(path)
    error = info.value
    assert "\n" not in str(error), "errors are one line"
    assert "pydantic" not in str(error).lower() and "errors.pydantic.dev" not in str(error)
    return error


def test_good_spec_loads(tmp_path: Path) -> None:
    spec = load_spec(write(tmp_path, GOOD))
    assert spec.finger == "soft" and spec.note == 57
    assert isinstance(spec.sweep, GridSweep)
    assert spec.sweep.params.names() == ["vacuum_kpa", "down_velocity_mps", "depth_m"]
    assert spec.record == ["midi", "arm"]
    assert spec.source_path == tmp_path / "spec.yaml"


def test_a_number_written_without_a_dot_in_exponent_form_loads(tmp_path: Path) -> None:
    # `5e-2` is a number in YAML 1.2 and in the spec's JSON schema; PyYAML's YAML 1.1 read it as
    # text ("must be a number in m, got '5e-2'").
    text = GOOD.replace("distance_m: 0.05", "distance_m: 5e-2").replace("start: 0.01", "start: 1E-2")
    spec = load_spec(write(tmp_path, text))
    assert spec.sweep.fixed.distance_m == pytest.approx(0.05)
    assert load_spec(write(tmp_path, GOOD, "plain.yaml")).sweep.params.names() == spec.sweep.params.names()


BAD_SPECS = [
    pytest.param(
        "name: t\nfinger: soft\ncolour: red\nsweep: {mode: grid}\n",
        ": colour", "unknown key 'colour'", id="unknown-top-level-key",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  depth_mm: [0.02]\n"),
        ": sweep.params.depth_mm", "did you mean 'depth_m'", id="unknown-parameter",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  down_velocity_mps: [0.02]\n  depth_m: [0.02, 20 mm]\n"),
        ": sweep.params.depth_m[1]", "must be a number in m, got '20 mm'", id="unit-in-value",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  depth_m: 20 mm\n"),
        ": sweep.params.depth_m", "must be a list of levels or {start, stop, num} in m",
        id="string-instead-of-list",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  depth_m: []\n"),
        ": sweep.params.depth_m", "an empty grid", id="empty-grid",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  depth_m: {start: 0.02, stop: 0.03, num: 0}\n"),
        ": sweep.params.depth_m.num", "must be >= 1, got 0", id="empty-linspace",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  down_velocity_mps: [0.02]\n  depth_m: [0.02, 0.03, 0.05]\n"),
        ": sweep.params.depth_m[2]", "must be in [0.02, 0.035] m for the soft finger, got 0.05",
        id="out-of-envelope-list-item",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  down_velocity_mps: {start: 0.01, stop: 0.08, num: 8}\n"
                  "  depth_m: [0.02]\n"),
        ": sweep.params.down_velocity_mps.stop", "[0, 0.06] m/s for the soft finger, got 0.08",
        id="out-of-envelope-linspace",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  down_velocity_mps: [0.02]\n  depth_m: [0.02]\n"
                  "fixed: {hold_s: 3}\n"),
        ": sweep.fixed.hold_s", "[0, 2] s for the soft finger, got 3", id="out-of-envelope-fixed",
    ),
    pytest.param(
        spec_with("mode: lhs\nsamples: 5\nparams:\n  down_velocity_mps: {low: 0.01, high: 0.9}\n"
                  "  depth_m: [0.01]\n", finger="rigid"),
        ": sweep.params.down_velocity_mps.high", "[0.01, 0.5] m/s for the rigid finger, got 0.9",
        id="out-of-envelope-range",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  vacuum_kpa: [0, -20]\n  down_velocity_mps: [0.02]\n"
                  "  depth_m: [0.01]\n", finger="rigid"),
        ": sweep.params.vacuum_kpa[1]", "must be 0 kPa for the rigid finger", id="rigid-vacuum",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  vacuum_kpa: [60]\n  down_velocity_mps: [0.02]\n"
                  "  depth_m: [0.02]\n"),
        ": sweep.params.vacuum_kpa[0]", "a vacuum is negative", id="positive-vacuum",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  down_velocity_mps: [0, 0.02]\n  depth_m: [0.02]\n"),
        ": sweep.params.down_velocity_mps[0]", "must be in (0, 3] m/s, got 0", id="zero-speed",
    ),
    pytest.param(
        spec_with("mode: gird\n"), ": sweep.mode", "got 'gird'", id="unknown-mode",
    ),
    pytest.param(
        spec_with("params: {}\n"), ": sweep.mode", "missing required key 'mode'", id="missing-mode",
    ),
    pytest.param(
        "name: t\nsweep: {mode: grid}\n", ": finger", "missing required key 'finger'",
        id="missing-finger",
    ),
    pytest.param(
        "name: t\nfinger: hard\nsweep: {mode: grid}\n", ": finger", "'soft' or 'rigid', got 'hard'",
        id="bad-finger",
    ),
    pytest.param(
        "name: My Test\nfinger: soft\nsweep: {mode: grid}\n", ": name", "must be a slug",
        id="name-not-slug",
    ),
    pytest.param(
        spec_with("mode: lhs\nsamples: 3\nparams:\n  depth_m: {low: 0.03, high: 0.02}\n"),
        ": sweep.params.depth_m", "high (0.02) must be >= low (0.03)", id="reversed-range",
    ),
    pytest.param(
        spec_with("mode: random\nparams:\n  depth_m: [0.02]\n"),
        ": sweep.samples", "missing required key 'samples'", id="random-without-samples",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  depth_m: [0.02]\n"),
        ": sweep.params", "down_velocity_mps is not set", id="required-parameter",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  down_velocity_mps: [0.02]\n  depth_m: [0.02]\n"
                  "fixed: {depth_m: 0.03}\n"),
        ": sweep.fixed.depth_m", "is also varied in sweep.params", id="fixed-and-varied",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  down_velocity_mps: [0.02, 0.03, 0.02]\n  depth_m: [0.02]\n"),
        ": sweep.params.down_velocity_mps[2]", "repeats the level 0.02", id="duplicate-level",
    ),
    pytest.param(
        spec_with("mode: grid\nrepeats: 0\n"), ": sweep.repeats", "must be >= 1, got 0",
        id="zero-repeats",
    ),
    pytest.param(
        spec_with("mode: grid\norder: random\n"), ": sweep.order", "got 'random'", id="bad-order",
    ),
    pytest.param(
        "name: t\nfinger: soft\nrecord: [midi, video]\nsweep: {mode: grid}\n",
        ": record[1]", "'midi', 'arm' or 'mocap', got 'video'", id="bad-stream",
    ),
    pytest.param(
        spec_with("mode: grid\nparams:\n  note: [60, 200]\n"), ": sweep.params.note[1]",
        "must be a whole number in [21, 108], got 200", id="note-range",
    ),
    pytest.param(
        spec_with("mode: grid\nseed: 1\nseed: 2\n"), ": sweep.seed", "duplicate key 'seed'",
        id="duplicate-key",
    ),
    pytest.param(
        "name: t\nfinger: soft\nrig: lab.txt\nsweep: {mode: grid}\n", ": rig",
        "must be 'sim' or a rig file", id="rig-not-yaml",
    ),
]


@pytest.mark.parametrize(("text", "where", "message"), BAD_SPECS)
def test_bad_spec_names_the_yaml_path(tmp_path: Path, text: str, where: str, message: str) -> None:
    error = load_error(tmp_path, text)
    assert error.where is not None
    assert error.where.startswith(str(tmp_path / "spec.yaml"))
    assert error.where.endswith(where), error.where
    assert message in error.message, error.message


def test_error_reports_the_line(tmp_path: Path) -> None:
    text = spec_with("mode: grid\nparams:\n  down_velocity_mps: [0.02]\n  depth_m: [0.02, 0.05]\n")
    error = load_error(tmp_path, text)
    line = 1 + text.splitlines().index("    depth_m: [0.02, 0.05]")
    assert error.message.endswith(f"(line {line})")


def test_more_problems_are_counted(tmp_path: Path) -> None:
    text = spec_with("mode: grid\nparams:\n  down_velocity_mps: [0.02]\n  depth_m: [0.05, 0.06]\n")
    assert "(and 1 more problem)" in load_error(tmp_path, text).message


def test_yaml_syntax_error_names_line_and_column(tmp_path: Path) -> None:
    error = load_error(tmp_path, "name: t\nfinger: soft\nsweep:\n  mode: grid\n  params: [depth_m: 3\n")
    assert error.where is not None
    file, line, column = error.where.rsplit(":", 2)
    assert file == str(tmp_path / "spec.yaml") and int(line) >= 5 and int(column) >= 1
    assert error.message.startswith("YAML syntax error")


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file") as info:
        load_spec(tmp_path / "absent.yaml")
    assert info.value.where == str(tmp_path / "absent.yaml")


def test_folder_and_undecodable_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="folder"):
        load_spec(tmp_path)
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00name")
    with pytest.raises(InputError, match="cannot read"):
        load_spec(binary)


@pytest.mark.parametrize(("text", "message"), [("", "empty"), ("- 1\n- 2\n", "mapping")])
def test_empty_or_non_mapping_file(tmp_path: Path, text: str, message: str) -> None:
    assert message in load_error(tmp_path, text).message


def test_rig_file_resolves_relative_to_the_spec(tmp_path: Path) -> None:
    write(tmp_path, "kind: sim\nseed: 5\n", "rigs/mine.yaml")
    spec = load_spec(write(tmp_path, GOOD + "rig: rigs/mine.yaml\n", "exp/../spec.yaml"))
    assert spec.rig_path() == tmp_path / "exp" / ".." / "rigs" / "mine.yaml"
    assert load_rig_for(spec).seed == 5


def test_missing_rig_file_is_a_spec_error(tmp_path: Path) -> None:
    error = load_error(tmp_path, GOOD + "rig: rigs/absent.yaml\n")
    assert error.where is not None and error.where.endswith(": rig")
    assert "not found" in error.message


def test_bad_rig_file_names_the_rig_file(tmp_path: Path) -> None:
    write(tmp_path, "kind: sim\nfaults: {midi_loss_prob: 2}\n", "rig.yaml")
    error = load_error(tmp_path, GOOD + "rig: rig.yaml\n")
    assert error.where == f"{tmp_path / 'rig.yaml'}: faults.midi_loss_prob"
    assert "got 2" in error.message


def test_rig_file_widens_the_envelope(tmp_path: Path) -> None:
    fast = GOOD.replace("stop: 0.06", "stop: 0.08")
    assert "0.06] m/s for the soft finger" in load_error(tmp_path, fast).message
    write(tmp_path, "kind: sim\nenvelope:\n  soft:\n    down_velocity_mps: [0, 0.08]\n", "wide.yaml")
    spec = load_spec(write(tmp_path, fast + "rig: wide.yaml\n"))
    assert spec.rig == "wide.yaml"
    # The widening is per finger: the rigid envelope stays as it was.
    assert load_rig_for(spec).envelope_for("rigid")["down_velocity_mps"].high == 0.5


def test_narrowed_default_is_reported(tmp_path: Path) -> None:
    write(tmp_path, "kind: sim\nenvelope:\n  soft:\n    acceleration_mps2: [1.0, 2.0]\n", "narrow.yaml")
    error = load_error(tmp_path, GOOD + "rig: narrow.yaml\n")
    assert error.where is not None and error.where.endswith(": sweep.fixed")
    assert "acceleration_mps2 defaults to 0.5" in error.message


def test_up_velocity_follows_down_velocity_in_the_envelope(tmp_path: Path) -> None:
    write(tmp_path, "kind: sim\nenvelope:\n  soft:\n    up_velocity_mps: [0.03, 0.7]\n", "rig.yaml")
    error = load_error(tmp_path, GOOD + "rig: rig.yaml\n")
    assert error.where is not None and error.where.endswith("sweep.params.down_velocity_mps.start")
    assert "also the up velocity" in error.message


def test_scalar_is_a_one_level_grid(tmp_path: Path) -> None:
    spec = load_spec(write(tmp_path, GOOD.replace("depth_m: [0.02, 0.03]", "depth_m: 0.025")))
    assert isinstance(spec.sweep, GridSweep)
    assert spec.sweep.params.items()[-1] == ("depth_m", [0.025])


def test_resolved_spec_is_idempotent_and_explicit(tmp_path: Path) -> None:
    spec = load_spec(write(tmp_path, GOOD))
    resolved = resolved_spec_dict(spec)
    assert resolved["sweep"]["params"]["down_velocity_mps"] == [0.01, 0.02, 0.03, 0.04, 0.05, 0.06]
    assert resolved["sweep"]["fixed"] == {
        "distance_m": 0.05, "hold_s": 0.0, "acceleration_mps2": 0.5, "finger_angle_deg": 0.0,
    }
    assert "up_velocity_mps" not in resolved["sweep"]["fixed"]  # follows the down velocity
    again = resolved_spec_dict(ExperimentSpec.model_validate(resolved))
    assert again == resolved
    assert list(resolved["sweep"]["params"]) == ["vacuum_kpa", "down_velocity_mps", "depth_m"]


def test_spec_sha256_is_of_the_bytes(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD)
    assert spec_sha256(path) == hashlib.sha256(path.read_bytes()).hexdigest()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 100_000), min_size=1, max_size=6, unique=True))
def test_depth_levels_fail_exactly_outside_the_envelope(micrometres: list[int]) -> None:
    depths = [um * 1e-6 for um in micrometres]
    data = yaml.safe_load(GOOD)
    data["sweep"]["params"]["depth_m"] = depths
    spec = ExperimentSpec.model_validate(data)
    from pianobot.spec import spec_problems

    problems = spec_problems(spec, RigSpec())
    bad = [i for i, d in enumerate(depths) if not 0.02 - 1e-9 <= d <= 0.035 + 1e-9]
    assert [p.path for p in problems] == [("sweep", "params", "depth_m", i) for i in bad]


# ---- rig files ------------------------------------------------------------------------------


def test_default_sim_rig() -> None:
    rig = load_rig("sim")
    assert rig.kind == "sim" and rig.realtime is False and rig.ur5 is None
    assert rig.retry.max_attempts == 3 and rig.retry.backoff_s == 1.0 and rig.retry.backoff_factor == 2.0
    assert rig.envelope_for("soft")["depth_m"].high == 0.035


def test_example_rig_files_load() -> None:
    faulty = load_rig(EXPERIMENTS / "rigs" / "sim-faulty.yaml")
    assert faulty.faults.drop_connection_every_n_presses == 7
    assert faulty.faults.protective_stop_at_trial == 12
    assert faulty.faults.midi_loss_prob == 0.02 and faulty.faults.mocap_drop_prob > 0
    lab = load_rig(EXPERIMENTS / "rigs" / "ur5-lab.yaml")
    assert lab.kind == "ur5" and lab.ur5 is not None and lab.midi is not None
    assert lab.ur5.frequency_hz is None and lab.ur5.reference_note == 59  # rate: from the controller
    assert lab.vacuum.regulator is not None and lab.vacuum.regulator.kpa_span == (0.0, -80.0)
    assert lab.mocap.markers is not None
    extended = load_rig(EXPERIMENTS / "rigs" / "sim-extended.yaml")
    assert extended.envelope_for("soft")["down_velocity_mps"].high == 0.08
    assert extended.envelope_for("soft")["depth_m"].high == 0.04


@pytest.mark.parametrize(
    ("text", "where", "message"),
    [
        ("kind: ur5\n", "(top level)", "needs both a `ur5:` and a `midi:` section"),
        ("kind: sim\nur5: {host: h, workspace_min_m: [0, 0, 0], workspace_max_m: [1, 1, 1]}\n",
         "(top level)", "only for kind: ur5"),
        ("world: {preset: cubic}\n", "world", "preset must be one of default, linear"),
        ("envelope: {soft: {depth_m: [0.04, 0.02]}}\n", "envelope.soft", "must be >= low"),
        ("envelope: {soft: {depth_m: [0.02, 0.5]}}\n", "envelope.soft", "physical bounds"),
        ("envelope: {soft: {depth: [0.02, 0.04]}}\n", "envelope.soft.depth", "did you mean 'depth_m'"),
        ("retry: {max_attempts: 0}\n", "retry.max_attempts", "must be >= 1"),
        ("vacuum: {mode: turbo}\n", "vacuum.mode", "got 'turbo'"),
        ("settle_s: {between_presses_s: fast}\n", "settle_s.between_presses_s",
         "must be a number in s"),
    ],
)
def test_bad_rig_file(tmp_path: Path, text: str, where: str, message: str) -> None:
    path = write(tmp_path, text, "rig.yaml")
    with pytest.raises(InputError) as info:
        load_rig(path)
    assert info.value.where == f"{path}: {where}"
    assert message in info.value.message


def test_ur5_workspace_must_be_a_box(tmp_path: Path) -> None:
    lab = (EXPERIMENTS / "rigs" / "ur5-lab.yaml").read_text()
    path = write(tmp_path, lab.replace("workspace_max_m: [-0.30, 0.10, 0.30]",
                                       "workspace_max_m: [-0.30, 0.10, 0.01]"), "lab.yaml")
    with pytest.raises(InputError, match="below workspace_max_m"):
        load_rig(path)


def test_write_rig_calibration_keeps_everything_else(tmp_path: Path) -> None:
    original = (EXPERIMENTS / "rigs" / "ur5-lab.yaml").read_text()
    path = write(tmp_path, original, "lab.yaml")
    pose = [-0.532687, -0.159821, 0.120106, -2.84144, 1.25881, -0.0957643]
    when = datetime(2024, 5, 1, 14, 30, tzinfo=timezone(timedelta(hours=2)))
    rig = write_rig_calibration(path, pose, when)
    assert rig.ur5 is not None and rig.ur5.reference_pose == tuple(pose)
    assert rig.ur5.calibrated_utc == "2024-05-01T12:30:00Z"
    new = path.read_text()
    changed = [(a, b) for a, b in zip(original.splitlines(), new.splitlines(), strict=True) if a != b]
    assert len(changed) == 2  # only the two calibration lines; comments and layout stay
    assert sorted(b.split(":")[0].strip() for _, b in changed) == ["calibrated_utc", "reference_pose"]
    # Calibrating again replaces the values.
    write_rig_calibration(path, [0.0] * 6, datetime(2025, 1, 1, tzinfo=UTC))
    again = load_rig(path)
    assert again.ur5 is not None and again.ur5.reference_pose == (0.0,) * 6
    assert again.ur5.calibrated_utc == "2025-01-01T00:00:00Z"


@pytest.mark.parametrize(
    "ur5_block",
    [
        "ur5:\n  host: h\n  workspace_min_m: [-1, -1, 0]\n  workspace_max_m: [1, 1, 1]\n",
        "ur5:\n  host: h\n  reference_pose:\n  calibrated_utc:\n"
        "  workspace_min_m: [-1, -1, 0]\n  workspace_max_m: [1, 1, 1]\n",
        "ur5:\n  host: h\n  reference_pose:\n    - 1\n    - 2\n    - 3\n    - 4\n    - 5\n    - 6\n"
        "  workspace_min_m: [-1, -1, 0]\n  workspace_max_m: [1, 1, 1]\n",
    ],
    ids=["keys-absent", "keys-empty", "block-list"],
)
def test_write_rig_calibration_layouts(tmp_path: Path, ur5_block: str) -> None:
    path = write(tmp_path, "kind: ur5\n" + ur5_block + "midi: {port: piano}\n", "lab.yaml")
    write_rig_calibration(path, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6], datetime(2024, 1, 2, 3, 4, 5))
    rig = load_rig(path)
    assert rig.ur5 is not None and rig.ur5.reference_pose == (0.1, 0.2, 0.3, 0.4, 0.5, 0.6)
    assert rig.ur5.calibrated_utc == "2024-01-02T03:04:05Z"
    assert rig.ur5.host == "h" and rig.midi is not None and rig.midi.port == "piano"


def test_write_rig_calibration_refuses_bad_input(tmp_path: Path) -> None:
    sim = write(tmp_path, "kind: sim\n", "sim.yaml")
    with pytest.raises(InputError, match="ur5"):
        write_rig_calibration(sim, [0.0] * 6, datetime(2024, 1, 1))
    lab = write(tmp_path, (EXPERIMENTS / "rigs" / "ur5-lab.yaml").read_text(), "lab.yaml")
    before = lab.read_text()
    with pytest.raises(InputError, match="6 finite numbers"):
        write_rig_calibration(lab, [0.0] * 5, datetime(2024, 1, 1))
    assert lab.read_text() == before


def test_world_overrides_are_validated(tmp_path: Path) -> None:
    ok = load_rig(write(tmp_path, "world: {preset: linear, vacuum_tau_s: 2.0}\n", "ok.yaml"))
    assert ok.world == {"preset": "linear", "vacuum_tau_s": 2.0}
    path = write(tmp_path, "world: {vacum_tau_s: 2.0}\n", "bad.yaml")
    with pytest.raises(InputError, match="did you mean 'vacuum_tau_s'") as info:
        load_rig(path)
    assert info.value.where == f"{path}: world"


def test_a_rig_given_instead_of_the_specs_own(tmp_path: Path) -> None:
    fast = GOOD.replace("stop: 0.06", "stop: 0.08")
    wide = write(tmp_path, "kind: sim\nenvelope:\n  soft:\n    down_velocity_mps: [0, 0.08]\n", "w.yaml")
    assert load_spec(write(tmp_path, fast), rig=wide).rig == "sim"
    narrow = write(tmp_path, "kind: sim\nenvelope:\n  soft:\n    depth_m: [0.02, 0.025]\n", "n.yaml")
    with pytest.raises(InputError, match=r"\[0.02, 0.025\] m for the soft finger \(set by .*n.yaml\)"):
        load_spec(write(tmp_path, GOOD), rig=narrow)


def test_world_model_names_are_checked(tmp_path: Path) -> None:
    rigid = load_rig(EXPERIMENTS / "rigs" / "sim-rigid.yaml")
    assert rigid.world["msd"]["k1_a_npm"] > 1000
    path = write(tmp_path, "world: {msd: {k1_a: 2000}}\n", "bad.yaml")
    with pytest.raises(InputError, match=r"unknown MSD parameter\(s\) \['k1_a'\]"):
        load_rig(path)
