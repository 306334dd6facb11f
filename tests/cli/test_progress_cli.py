"""Progress of long commands: on stderr at a terminal, never under --json, --no-progress or a pipe."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import pytest

from pianobot.cli import main
from pianobot.run import run_sweep

ROOT = Path(__file__).resolve().parents[2]
QUICKSTART = ROOT / "experiments" / "quickstart.yaml"


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal (what a researcher's shell gives the command)."""

    def isatty(self) -> bool:
        return True


def _run(args: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
         *, terminal: bool) -> tuple[int, str, str]:
    err = _Terminal() if terminal else io.StringIO()
    monkeypatch.setattr(sys, "argv", ["pianobot", *args])
    monkeypatch.setattr(sys, "stderr", err)
    code = 0
    try:
        main()
    except SystemExit as exc:
        code = int(exc.code or 0)
    finally:
        monkeypatch.setattr(sys, "stderr", sys.__stderr__)
    return code, capsys.readouterr().out, err.getvalue()


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    data = tmp_path_factory.mktemp("data")
    return data, run_sweep(QUICKSTART, data_dir=data, progress=False).run_id


def test_sweep_draws_wall_clock_and_lab_eta_on_a_terminal(monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str],
                                                         data_dir: Path) -> None:
    code, out, err = _run(["sweep", str(QUICKSTART), "--data", str(data_dir)], monkeypatch, capsys,
                          terminal=True)
    assert code == 0
    assert "sweep" in err and "16/16" in err and "ETA" in err and "lab " in err
    # The work before the first trial (seconds for a large spec or a cold simulator) has its rows.
    assert "sweep: expanding the plan" in err and "sweep: opening the rig" in err
    assert "ETA" not in out  # progress never lands on stdout


@pytest.mark.parametrize("quiet", [["--json"], ["--no-progress"], []])
def test_sweep_progress_is_silenced(quiet: list[str], monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str], data_dir: Path) -> None:
    # [] runs with stderr not a terminal (a pipe, a log file, CI): silent as well.
    code, out, err = _run(["sweep", str(QUICKSTART), "--data", str(data_dir), *quiet], monkeypatch, capsys,
                          terminal=bool(quiet))
    assert code == 0 and err == ""
    if quiet == ["--json"]:
        assert json.loads(out)["status"] == "completed"


def test_report_progress_only_without_json(quick_run: tuple[Path, str], tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    data, run_id = quick_run
    base = ["report", run_id, "--data", str(data), "--out", str(tmp_path / "r.html")]
    code, out, err = _run(base, monkeypatch, capsys, terminal=True)
    assert code == 0 and "report" in err and "6/6" in err
    code, out, err = _run([*base, "--json"], monkeypatch, capsys, terminal=True)
    assert code == 0 and err == "" and json.loads(out)["report"].endswith("r.html")


def test_fit_progress_counts_folds_times_models(quick_run: tuple[Path, str], tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    data, run_id = quick_run
    base = ["fit", run_id, "--data", str(data), "--model", "poly", "--folds", "3",
            "--out-dir", str(tmp_path)]
    code, _, err = _run(base, monkeypatch, capsys, terminal=True)
    # mean baseline + poly, each: one full fit and three folds
    assert code == 0 and "cross-validation" in err and "8/8" in err
    code, out, err = _run([*base, "--json"], monkeypatch, capsys, terminal=True)
    # Plausibility warnings still reach stderr (as with every command), progress does not.
    assert code == 0 and json.loads(out)["cv"]
    assert "ETA" not in err and "cross-validation" not in err
    assert all(line.startswith("warning: ") for line in err.splitlines())


def test_import_mocap_shows_its_stages_on_a_terminal_only(zhang2022: Path, data_dir: Path,
                                                          monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    base = ["import", "mocap", str(zhang2022 / "zzz" / "zzz40.csv"), "--vacuum-kpa", "-40", "--data", str(data_dir)]
    code, out, err = _run(base, monkeypatch, capsys, terminal=True)
    assert code == 0 and "reading the take (2.4 MB)" in err and "segmenting keystrokes" in err
    assert "writing the run" in err and "reading" not in out
    for quiet in (["--json"], ["--no-progress"]):
        code, out, err = _run([*base, *quiet], monkeypatch, capsys, terminal=True)
        assert code == 0 and err == ""


def test_identify_is_visibly_alive_on_a_terminal_and_silent_under_json(data_dir: Path, tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    sys.path.insert(0, str(ROOT / "tests" / "analysis"))
    from _synthetic_runs import linear_keystrokes, write_run

    from pianobot.physics.msd import MSDParams

    trials, samples = linear_keystrokes(MSDParams(), seed=0, levels_kpa=(-40.0,),
                                        speeds_mps=(0.015, 0.025, 0.035, 0.045, 0.055))
    run = write_run(data_dir, trials, samples)
    base = ["identify", run, "--data", str(data_dir), "--bootstrap", "2", "--out", str(tmp_path / "m.json")]
    code, _, err = _run(base, monkeypatch, capsys, terminal=True)
    assert code == 0 and "identify: held-out fit" in err and "bootstrap refits" in err and "0/?" not in err
    code, out, err = _run([*base, "--json"], monkeypatch, capsys, terminal=True)
    assert code == 0 and json.loads(out)["parameters"]
    assert "identify:" not in err and all(line.startswith("warning: ") for line in err.splitlines())


def test_a_slow_load_gets_a_row_a_quick_one_does_not(monkeypatch: pytest.MonkeyPatch) -> None:
    import time

    from pianobot.cli.common import loading_row

    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    with loading_row("play: loading", ["play", "song.mid"], delay_s=0.05):
        time.sleep(0.4)
    assert "play: loading" in terminal.getvalue()
    quick = _Terminal()
    monkeypatch.setattr(sys, "stderr", quick)
    with loading_row("runs: loading", ["runs"], delay_s=5.0):
        pass
    for quiet in (["play", "--json"], ["play", "--no-progress"], ["play", "--help"]):
        with loading_row("play: loading", quiet, delay_s=0.0):
            time.sleep(0.2)
    assert quick.getvalue() == ""
