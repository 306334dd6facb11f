"""Hostile spec and rig files: one line, exit 2, nothing stored — and fast, whatever the file.

Every case runs `sweep` (which would store a run) against a data folder that already holds a
run, and also `--dry-run` where the survey found a hang there.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from robustness.harness import QUICKSTART, assert_cli_refused

SPEC = """\
name: hostile
finger: soft
sweep:
  mode: grid
  params:
    down_velocity_mps: [0.02, 0.04]
    depth_m: [0.03]
"""


def _bomb(levels: int) -> str:
    """The "billion laughs": each anchor aliases the previous one ten times."""
    lines = ["name: bomb", "finger: soft", "x0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"x{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\nsweep: {mode: grid, params: {down_velocity_mps: [0.02], depth_m: [0.03]}}\n"


CASES: dict[str, tuple[str, tuple[str, ...]]] = {
    "alias bomb (9 levels)": (_bomb(9), ("aliases expand to more than", "alias bomb")),
    "alias that contains itself": ("name: t\nfinger: soft\nx: &a [1, *a]\n", ("contains itself", "x[1]")),
    "nesting 5,000 deep": ("name: t\nx: " + "[" * 5000 + "]" * 5000 + "\n", ("nesting deeper than",)),
    "NaN": (SPEC + "  fixed: {acceleration_mps2: .nan}\n", ("sweep.fixed.acceleration_mps2", "finite", "line 8")),
    "infinity": (SPEC + "  fixed: {hold_s: .inf}\n", ("sweep.fixed.hold_s", "finite")),
    "1e400 overflows to inf": (SPEC + "  fixed: {hold_s: 1.0e+400}\n", ("sweep.fixed.hold_s", "finite")),
    "NaN in a level list": (SPEC.replace("[0.03]", "[0.03, .nan]"), ("sweep.params.depth_m[1]", "finite")),
    "a bool for a number": (SPEC + "  fixed: {acceleration_mps2: true}\n", ("must be a number in m/s²", "got True")),
    "text for a number": (SPEC + '  fixed: {acceleration_mps2: "1.0"}\n', ("must be a number", "got '1.0'")),
    "a bool for a whole number": (SPEC + "  repeats: true\n", ("sweep.repeats", "whole number")),
    "2.0 for a whole number": (SPEC + "  repeats: 2.0\n", ("sweep.repeats", "whole number")),
    "100,000-digit integer": (SPEC + "  seed: " + "9" * 100_000 + "\n", ("100,000 characters", "too long")),
    "seed beyond 64 bits": (SPEC + "  seed: 99999999999999999999\n", ("sweep.seed",)),
    "duplicate key": (SPEC + "  repeats: 1\n  repeats: 2\n", ("duplicate key 'repeats'",)),
    "empty file": ("", ("empty",)),
    "a list, not a mapping": ("- 1\n- 2\n", ("must be a YAML mapping",)),
    "python object tag": (SPEC + "  seed: !!python/object/apply:os.system ['true']\n", ("YAML",)),
    "syntax error": ("name: [unclosed\n", ("YAML syntax error",)),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("dry_run", [False, True], ids=["sweep", "dry-run"])
def test_a_hostile_spec_is_refused_in_one_line(
    case: str, dry_run: bool, completed_run: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    text, mentions = CASES[case]
    spec = tmp_path / "hostile.yaml"
    spec.write_text(text)
    args: list[str | Path] = ["sweep", spec, "--data", completed_run, *(["--dry-run"] if dry_run else [])]
    assert_cli_refused(args, completed_run, capsys, monkeypatch, str(spec), *mentions)


RIGS: dict[str, tuple[str, tuple[str, ...]]] = {
    "NaN in the simulated world": ("kind: sim\nworld: {msd: {c1_nspm: .nan}}\n", ("world.msd.c1_nspm", "finite")),
    "a bool in the simulated world": ("kind: sim\nworld: {msd: {c1_nspm: true}}\n", ("world", "must be a number")),
    "text in the simulated world": ("kind: sim\nworld: {piano: {trigger_depth_m: '2'}}\n", ("must be a number",)),
    "a bool for a pause": ("kind: sim\nsettle_s: {between_presses_s: true}\n", ("settle_s.between_presses_s",)),
    "infinite envelope": ("kind: sim\nenvelope: {soft: {depth_m: [0.02, .inf]}}\n", ("envelope.soft.depth_m[1]", "finite")),
    "alias bomb": (_bomb(9).replace("name: bomb\nfinger: soft\n", "kind: sim\n").split("sweep:")[0],
                   ("alias bomb",)),
}


@pytest.mark.parametrize("case", list(RIGS))
def test_a_hostile_rig_file_is_refused_in_one_line(
    case: str, completed_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    text, mentions = RIGS[case]
    rig = tmp_path / "rig.yaml"
    rig.write_text(text)
    assert_cli_refused(["sweep", QUICKSTART, "--rig", rig, "--data", completed_run], completed_run, capsys,
            monkeypatch, *mentions)


@pytest.mark.parametrize("target", ["folder", "/dev/zero", "missing.yaml", "binary"])
def test_a_spec_that_is_not_a_yaml_file_is_refused(
    target: str, completed_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    path = {"folder": tmp_path, "/dev/zero": Path("/dev/zero"), "missing.yaml": tmp_path / "missing.yaml",
            "binary": tmp_path / "binary.yaml"}[target]
    if target == "binary":
        path.write_bytes(b"\xff\xfe\x00\x01" * 100)
    if target == "/dev/zero" and not path.exists():
        pytest.skip("no /dev/zero")
    assert_cli_refused(["sweep", path, "--dry-run", "--data", completed_run], completed_run, capsys, monkeypatch,
            str(path))
