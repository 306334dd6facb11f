"""Shared checks of the robustness suite: one line on stderr, exit 2, the data folder untouched.

    with unchanged(data_dir):
        code, out, err = cli(["sweep", str(spec), "--data", str(data_dir)], capsys, monkeypatch)
    assert_refused(code, err, "must be a finite number")

`unchanged` hashes every file (path, bytes, and which files exist) before and after; any new,
removed or altered file fails the test. `assert_refused` wants exit code 2 and exactly one
stderr line starting with `error:` — no traceback, no usage box.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from cli_runner import invoke_cli

REPO = Path(__file__).resolve().parents[2]
QUICKSTART = REPO / "experiments" / "quickstart.yaml"


def tree_digest(root: Path) -> dict[str, str]:
    """Every file under `root` (relative path → SHA-256 of its bytes); folders as entries too."""
    out: dict[str, str] = {}
    if not root.exists():
        return out
    for path in sorted(root.rglob("*")):
        key = path.relative_to(root).as_posix()
        out[key] = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "<dir>"
    return out


@contextmanager
def unchanged(root: Path) -> Iterator[None]:
    """Fail if anything under `root` is created, removed or altered inside the block."""
    before = tree_digest(root)
    yield
    after = tree_digest(root)
    added = sorted(set(after) - set(before))
    removed = sorted(set(before) - set(after))
    altered = sorted(k for k in set(before) & set(after) if before[k] != after[k])
    assert not (added or removed or altered), (
        f"data folder changed: added {added[:5]}, removed {removed[:5]}, altered {altered[:5]}")


def cli(args: list[str | Path], capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of `pianobot ARGS`, in this process."""
    return invoke_cli([str(a) for a in args], capsys, monkeypatch)


def assert_refused(code: int, err: str, *mentions: str) -> str:
    """Exit 2 and exactly one `error: ...` line on stderr that mentions each of `mentions`."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, f"exit {code}, stderr: {err[-2000:]}"
    assert len(lines) == 1, f"{len(lines)} stderr lines: {err[-2000:]}"
    assert lines[0].startswith("error: ") and "Traceback" not in err
    for text in mentions:
        assert text in lines[0], f"{text!r} not in {lines[0]!r}"
    return lines[0]


def assert_cli_refused(args: list[str | Path], data_dir: Path, capsys: pytest.CaptureFixture[str],
            monkeypatch: pytest.MonkeyPatch, *mentions: str) -> str:
    """Run the CLI, assert a one-line refusal that left `data_dir` as it was; the line."""
    with unchanged(data_dir):
        code, _, err = cli(args, capsys, monkeypatch)
    return assert_refused(code, err, *mentions)


def copy_tree(source: Path, target: Path) -> Path:
    shutil.copytree(source, target)
    return target


def only_run(data_dir: Path) -> Path:
    """The one run folder in `data_dir`."""
    (run,) = sorted((data_dir / "runs").iterdir())
    return run


def as_unprivileged(args: list[str]) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of `pianobot ARGS` in a forked child that cannot override
    file permissions (root ignores a folder's read-only mode, so as root the child becomes
    `nobody`). For read-only folder tests; the CLI is imported before the fork, since `nobody`
    may not read the interpreter's own files.
    """
    import encodings.utf_8_sig  # noqa: F401 - codecs load lazily, from files `nobody` cannot read

    from pianobot.cli import _register

    _register()  # every command module, imported while we still can
    out_r, out_w = os.pipe()
    err_r, err_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: drop privileges, run the command, report through the pipes
        code = 70
        try:
            os.dup2(out_w, 1)
            os.dup2(err_w, 2)
            sys.stdout = os.fdopen(1, "w", closefd=False)
            sys.stderr = os.fdopen(2, "w", closefd=False)
            if os.geteuid() == 0:
                os.setgid(65534)
                os.setuid(65534)
            sys.argv = ["pianobot", *args]
            from pianobot.cli import main

            try:
                main()
                code = 0
            except SystemExit as exc:
                code = int(exc.code or 0) if not isinstance(exc.code, str) else 1
        except BaseException:  # noqa: BLE001 - reported to the parent as a traceback
            import traceback

            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    os.close(out_w)
    os.close(err_w)
    with os.fdopen(out_r, "rb") as out_file, os.fdopen(err_r, "rb") as err_file:
        out, err = out_file.read(), err_file.read()
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), out.decode(errors="replace"), err.decode(errors="replace")
