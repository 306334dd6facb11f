"""docs/architecture.md's "Where to find what" table is true: its modules exist and define its names."""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _rows() -> list[tuple[str, list[str], list[str]]]:
    text = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## Where to find what", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not cells[1].startswith("`pianobot/"):
            continue
        rows.append((cells[0], re.findall(r"`([^`]+)`", cells[1]), re.findall(r"`([^`]+)`", cells[2])))
    return rows


def _defined(path: Path) -> set[str]:
    """Top-level names a module defines (functions, classes, assignments, imports)."""
    names: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.FunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.ImportFrom | ast.Import):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
    return names


def test_every_concept_names_existing_modules_that_define_its_names() -> None:
    rows = _rows()
    assert len(rows) >= 20, "the table was not found or lost its rows"
    for concept, modules, names in rows:
        paths = [REPO / m for m in modules]
        missing = [m for m, p in zip(modules, paths, strict=True) if not p.is_file()]
        assert not missing, f"{concept}: no module {missing}"
        defined = set().union(*(_defined(p) for p in paths))
        undefined = [n for n in names if n not in defined]
        assert not undefined, f"{concept}: {modules} do not define {undefined}"


def test_the_main_concepts_of_the_issue_each_have_a_row() -> None:
    concepts = " ".join(row[0] for row in _rows())
    for word in ("parameter", "press", "trial", "keystroke", "model", "predictor", "effect", "phase"):
        assert word in concepts, word


def test_every_module_says_what_it_holds() -> None:
    """A module's docstring is where a reader who opened the wrong file learns where they are."""
    package = REPO / "pianobot"
    silent = [str(p.relative_to(REPO)) for p in sorted(package.rglob("*.py"))
              if not (ast.get_docstring(ast.parse(p.read_text(encoding="utf-8"))) or "").strip()]
    assert not silent, f"modules without a docstring: {silent}"
