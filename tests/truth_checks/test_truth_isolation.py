"""The truth generators share nothing with pianobot: no module of tests/truth imports it."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from tests.truth import BASE_SETS
from tests.truth.base import PUBLISHED

TRUTH = Path(__file__).resolve().parents[1] / "truth"
REPO = TRUTH.parents[1]


def _imported_modules(path: Path) -> list[str]:
    """Every module an `import` / `from ... import` names (relative ones resolved)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                out.append("tests.truth." + (node.module or ""))
            else:
                out.append(node.module or "")
        elif isinstance(node, ast.Call):
            # importlib.import_module("...") / __import__("...") with a literal name
            name = getattr(node.func, "attr", getattr(node.func, "id", ""))
            if name in ("import_module", "__import__") and node.args:
                arg = node.args[0]
                if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                    out.append(arg.value)
    return out


def test_no_truth_module_imports_pianobot() -> None:
    modules = sorted(TRUTH.glob("*.py"))
    assert len(modules) >= 10
    offenders = {
        p.name: [m for m in _imported_modules(p) if m == "pianobot" or m.startswith("pianobot.")]
        for p in modules
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_truth_imports_only_numeric_libraries() -> None:
    allowed_roots = {"__future__", "argparse", "ast", "collections", "csv", "dataclasses", "json",
                     "math", "pathlib", "sys", "time", "types", "typing", "numpy", "numba",
                     "tests"}  # fmt: skip
    for path in TRUTH.glob("*.py"):
        roots = {m.split(".")[0] for m in _imported_modules(path)}
        assert roots <= allowed_roots, (path.name, roots - allowed_roots)


def test_suite_generates_with_pianobot_unimportable(tmp_path: Path) -> None:
    """At run time too: with every `pianobot` import refused, a take and a log are written."""
    script = f"""
import sys
class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name == "pianobot" or name.startswith("pianobot."):
            raise ImportError("pianobot must not be imported by the truth generators")
        return None
sys.meta_path.insert(0, Refuse())
from tests.truth import materialise, scenario
for name in ("mocap-clean-light-finger-hover-2", "midi-clean-light-finger-0"):
    made = materialise(scenario(name), {str(tmp_path)!r})
    assert made.data_file.stat().st_size > 1000
assert not [m for m in sys.modules if m.startswith("pianobot")]
print("ok")
"""
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().endswith("ok")


def test_no_base_set_uses_the_published_numbers() -> None:
    for base in BASE_SETS.values():
        d = base.to_dict()
        same = [k for k, v in PUBLISHED.items() if k in d and abs(float(d[k]) - v) < 1e-9]
        assert same == [], (base.name, same)
        assert base.k0_ratio != 1.0 and base.c0_nspm != base.c1_nspm  # k0 ≠ k1, c0 ≠ c1
