"""CLI start-up: `--version`, `--help` and `runs` import only what they need.

Wall-clock start-up times are measured in benchmarks/bench_startup.py; here the test is which
heavy libraries a command loads at all (deterministic on any machine).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import typer.main

from pianobot.cli import COMMANDS, _register, app

HEAVY = ("scipy", "sklearn", "numba", "matplotlib", "dask", "distributed", "mir_eval", "mido")
PROBE = """
import json, sys
sys.argv = ["pianobot", *{args!r}]
from pianobot.cli import main
try:
    main()
except SystemExit:
    pass
sys.stdout = sys.__stdout__
print("\\nMODULES=" + json.dumps(sorted({{m.split(".")[0] for m in sys.modules}})))
"""


def _loaded(args: list[str]) -> tuple[str, set[str]]:
    done = subprocess.run([sys.executable, "-c", PROBE.format(args=args)], capture_output=True,
                          text=True, check=True)
    out, _, modules = done.stdout.rpartition("MODULES=")
    return out, set(json.loads(modules))


@pytest.mark.parametrize("args", [["--version"], ["--help"], []])
def test_version_and_help_load_no_command_module(args: list[str]) -> None:
    out, modules = _loaded(args)
    assert "pianobot" in out
    assert not modules & {*HEAVY, "pandas", "pyarrow", "pydantic"}, modules & {*HEAVY, "pandas"}


def test_runs_loads_the_store_but_no_physics_or_analysis(tmp_path: object) -> None:
    out, modules = _loaded(["runs", "--data", str(tmp_path)])
    assert "no runs" in out
    # (typer itself loads pydantic to convert a command's parameters)
    assert not modules & {*HEAVY, "pandas"}, modules & {*HEAVY, "pandas"}


def test_runs_lists_written_runs_without_pyarrow_pandas_or_numpy(tmp_path: Path) -> None:
    """The quick check reads Parquet footers in pure Python and the counts come from run.json:
    listing runs loads none of the table libraries (a third of a second of start-up)."""
    import pandas as pd

    from pianobot.store import RunWriter

    data = tmp_path / "data"
    for status in ("ok", "silent"):
        plan = pd.DataFrame({"trial_id": ["a", "b", "c"], "index": range(3)})
        writer = RunWriter.create(data, name=f"listed {status}", kind="sweep", meta={}, plan=plan)
        trials = pd.DataFrame({"trial_id": ["a", "b"], "index": [0, 1], "status": ["ok", status]})
        writer.append(trials)
        writer.finish("interrupted", reason="test")
        writer.close()
    out, modules = _loaded(["runs", "--data", str(data)])
    assert out.count("2/3") == 2 and "50%" in out and "0%" in out, out
    assert not modules & {*HEAVY, "pandas", "pyarrow", "numpy"}, modules & {*HEAVY, "pandas", "pyarrow", "numpy"}


def test_the_table_of_contents_matches_every_command_s_own_help() -> None:
    _register(None)
    commands = typer.main.get_command(app).commands  # type: ignore[attr-defined]
    assert set(commands) == set(COMMANDS)
    for name, command in commands.items():
        first = (command.help or "").split("\n\n")[0].strip()
        assert COMMANDS[name][1] == first, name
