"""Atomic writes: the old file survives a failed write, nothing is left behind, data is fsync'd."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from pianobot.atomic_files import write_bytes_atomic, write_json_atomic, write_text_atomic
from pianobot.physics.model import KeystrokeModel, load_model, save_model


def _fsyncs(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Record what os.fsync is called on ("file" or "dir"), still calling it."""
    seen: list[str] = []
    real = os.fsync

    def spy(fd: int) -> None:
        seen.append("dir" if _is_dir_fd(fd) else "file")
        real(fd)

    monkeypatch.setattr(os, "fsync", spy)
    return seen


def _is_dir_fd(fd: int) -> bool:
    return stat.S_ISDIR(os.fstat(fd).st_mode)


def test_writes_replace_the_file_whole_and_leave_no_temp(tmp_path: Path) -> None:
    path = tmp_path / "a.json"
    write_json_atomic(path, {"x": 1.5, "nan": float("nan"), "when": tmp_path})
    assert json.loads(path.read_text().replace("NaN", "null")) == {"x": 1.5, "nan": None, "when": str(tmp_path)}
    assert path.read_text().endswith("}\n")
    write_text_atomic(path, "ünïcode\n")
    assert path.read_text(encoding="utf-8") == "ünïcode\n"
    write_bytes_atomic(path, b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_data_and_folder_are_fsynced(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _fsyncs(monkeypatch)
    write_text_atomic(tmp_path / "m.json", "{}\n")
    assert seen == ["file", "dir"]  # the data before the rename, the folder (the rename) after


def test_a_failed_write_keeps_the_old_file_and_removes_the_temp(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "m.json"
    path.write_text("old\n")

    def no_space(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", no_space)
    with pytest.raises(OSError, match="No space"):
        write_text_atomic(path, "new\n")
    assert path.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_model_files_are_written_through_the_atomic_writer(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "model.json"
    first = KeystrokeModel.study()
    save_model(first, path)
    seen = _fsyncs(monkeypatch)
    monkeypatch.setattr(os, "replace", lambda src, dst: (_ for _ in ()).throw(OSError(5, "I/O error")))
    with pytest.raises(OSError):
        save_model(first.with_effect("contact"), path)
    assert seen == ["file"]  # fsync'd before the (failed) rename
    assert load_model(path) == first  # the old model file is whole
    assert [p.name for p in tmp_path.iterdir()] == ["model.json"]  # no model.json.tmp left
