"""One name, one place: no two modules of pianobot define the same public top-level name.

A second `Layout`, `PLAN_COLUMNS` or `format_duration` is how a reader ends up in the wrong module.
The names allowed below are conventions (type aliases, a command module's `register`) or known
cases left to their owners; a new duplicate, or a known one spreading to another module, fails.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "pianobot"

#: Every module may define these (array/type-variable aliases, typer's per-module entry points).
CONVENTIONS = {"FloatArray", "IntArray", "BoolArray", "T", "R", "register", "main"}

#: Known duplicates, each with the modules that may hold it (left to the owners of those files).
KNOWN: dict[str, set[str]] = {}


def _public_definitions() -> dict[str, set[str]]:
    found: dict[str, set[str]] = defaultdict(set)
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.FunctionDef | ast.ClassDef):
                names = [node.name]
            elif isinstance(node, ast.Assign):
                names = [t.id for t in node.targets if isinstance(t, ast.Name)]
            elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                names = [node.target.id]
            else:
                continue
            for name in names:
                if not name.startswith("_"):
                    found[name].add(module)
    return found


def test_no_public_name_is_defined_in_two_modules() -> None:
    new = {
        name: sorted(modules)
        for name, modules in _public_definitions().items()
        if len(modules) > 1 and name not in CONVENTIONS and not modules <= KNOWN.get(name, set())
    }
    assert not new, f"defined in more than one module (rename one, or import it from the other): {new}"


def test_every_known_duplicate_is_still_one() -> None:
    """A fixed duplicate leaves KNOWN too, so the list only ever names what is left to do."""
    found = _public_definitions()
    fixed = {name: sorted(found.get(name, set())) for name in KNOWN if len(found.get(name, set())) < 2}
    assert not fixed, f"no longer defined twice, delete from KNOWN: {fixed}"


def test_the_names_this_issue_renamed_are_each_defined_once() -> None:
    found = _public_definitions()
    for name in ("Layout", "PLAN_COLUMNS", "format_duration", "ParamSpec", "MOTION_COLUMNS"):
        assert len(found[name]) == 1, (name, found[name])


def _calls(name_set: set[str]) -> list[tuple[str, int, str, int]]:
    """(module path under pianobot/, line, callee, positional args) of calls to the named classes."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call):
                func = node.func
                callee = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
                if callee in name_set:
                    found.append((rel, node.lineno, callee, len(node.args)))
    return found


def test_presses_and_trials_are_built_in_one_place() -> None:
    """Outside physics/ (below plan's layer), every Press comes from `plan.trial.press_from`; a
    Trial is built only in plan/, by name (its id, index and repeat, then keywords)."""
    presses = [(rel, line) for rel, line, _, _ in _calls({"Press"})
               if not rel.startswith("physics/") and rel != "plan/trial.py"]
    assert not presses, f"build these with plan.trial.press_from: {presses}"
    trials = [(rel, line, n) for rel, line, _, n in _calls({"Trial", "SequenceTrial"})
              if rel not in ("plan/trial.py", "plan/expand.py") or n > 3]
    assert not trials, f"build these with plan.trial.trial_from (parameters by name): {trials}"


def test_the_velocity_curve_is_written_once() -> None:
    """MIDI velocity = 127·g(speed) lives in physics/piano.py (`on_velocity_from_speed`) only."""
    curve = re.compile(r"127(\.0)?\s*\*|\*\s*127\b")
    found = [f"{path.relative_to(PACKAGE)}:{i}" for path in sorted(PACKAGE.rglob("*.py"))
             if path.relative_to(PACKAGE).as_posix() != "physics/piano.py"
             for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if curve.search(line.split("#", 1)[0])]
    assert not found, f"use physics.piano.on_velocity_from_speed: {found}"
