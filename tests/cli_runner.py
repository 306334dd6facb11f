"""Run the real `pianobot` entry point in-process and capture what it prints."""

from __future__ import annotations

import sys

import pytest

from pianobot.cli import main


def invoke_cli(
    args: list[str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of `pianobot ARGS` (a subprocess would pay the import time)."""
    monkeypatch.setattr(sys, "argv", ["pianobot", *args])
    code = 0
    try:
        main()
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err
