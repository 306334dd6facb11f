"""Analysis tests run their split work in the test process: a Dask cluster per test would cost
more than the fits (tests/test_executor.py checks that clusters give the same results)."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _in_process(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PIANOBOT_WORKERS", "1")
