"""Shared test fixtures: the real study data (skipped when absent) and a scratch data folder."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
ZHANG2022 = REPO_ROOT.parent / "shared" / "fixtures" / "zhang2022"


@pytest.fixture(scope="session")
def zhang2022() -> Path:
    """The zhang2022 fixture folder; tests that use it skip when it is absent."""
    if not ZHANG2022.is_dir():
        pytest.skip("fixture folder shared/fixtures/zhang2022 is absent")
    return ZHANG2022


@pytest.fixture()
def data_dir(tmp_path: Path) -> Path:
    """An empty dataset folder for one test."""
    path = tmp_path / "data"
    path.mkdir()
    return path


@pytest.fixture(autouse=True)
def _split_work_in_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """Commands under test run their split work (bootstrap refits, discovery candidates, sweep
    blocks) in the test process: a Dask cluster per test would cost more than the work.
    tests/test_executor.py passes explicit settings and checks that clusters give the same
    results."""
    monkeypatch.setenv("PIANOBOT_WORKERS", "1")
