"""One name, one place: no two modules of pianobot define the same public top-level name.

A second `Layout`, `PLAN_COLUMNS` or `format_duration` is how a reader ends up in the wrong module.
The names allowed below are conventions (type aliases, a command module's `register`) or known
cases left to their owners; a new duplicate, or a known one spreading to another module, fails.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "pianobot"

#: Every module may define these (array/type-variable aliases, typer's per-module entry points).
CONVENTIONS = {"FloatArray", "IntArray", "BoolArray", "T", "R", "register", "main"}

#: Known duplicates, each with the modules that may hold it (left to the owners of those files).
KNOWN: dict[str, set[str]] = {
    # issue 10: constants written in two grey-box modules, two checks called Finding, two base fits
    "BOUND_TOLERANCE": {"analysis.greybox.layout", "analysis.plausibility"},
    "Finding": {"analysis.discover.measured", "analysis.plausibility"},
    "GROUP": {"analysis.greybox.commanded", "analysis.greybox.forward"},
    "SIM_STEP_S": {"analysis.greybox.commanded", "analysis.greybox.forward"},
    "STEP_PER_TIME_SCALE": {"analysis.greybox.commanded", "analysis.greybox.forward"},
    "Z95": {"analysis.discover.loop", "analysis.identify.fit", "analysis.identify.static_stiffness"},
    "base_fit": {"analysis.discover.search", "analysis.identify.fit"},
    "TAIL_S": {"analysis.greybox.commanded", "play.perform"},
    # issue 15: one tolerance with two values
    "SAME_VACUUM_KPA": {"plan.labtime", "rig.station"},
    # a command and the figure it draws; two typer argument types of the same shape
    "bode": {"cli.model", "reports.figures"},
    "RunIds": {"cli.analysis", "cli.discover"},
}


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


def test_the_names_this_issue_renamed_are_each_defined_once() -> None:
    found = _public_definitions()
    for name in ("Layout", "PLAN_COLUMNS", "format_duration", "ParamSpec", "MOTION_COLUMNS"):
        assert len(found[name]) == 1, (name, found[name])
