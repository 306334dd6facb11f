"""Read YAML that may be hostile: bounded size, depth and alias expansion, checked before building.

PyYAML's safe loader refuses code, but not a "billion laughs": nine nested anchors, each
aliased ten times, expand to 10⁹ values, and anything that walks the expanded tree (a
duplicate-key check, pydantic, a dump into run.json) hangs and fills memory. Here the document
is composed into its node graph (aliases are references, nothing is copied yet), and before a
single Python object is built:

- the file is at most `MAX_BYTES` and a regular file (not a folder, a FIFO or /dev/zero);
- nesting is at most `MAX_DEPTH` levels, counted as written and as expanded;
- the expanded document has at most `MAX_VALUES` values, counted on the graph with each
  anchored node's size computed once, so the count itself costs what the file costs;
- an alias that contains itself is refused (the expansion would be infinite);
- a mapping may not repeat a key (PyYAML keeps the last silently).

Then the values are built (an alias still shares one object) and every number must be finite
and of sane size. Every refusal is an `InputError` naming the file, the line and the YAML path.
"""

from __future__ import annotations

import math
import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml

from pianobot.errors import InputError
from pianobot.spec.messages import Location, format_path

MAX_BYTES = 2_000_000  # a spec is a few kB; a rig file with measured key offsets maybe 20 kB
MAX_DEPTH = 32
MAX_VALUES = 200_000  # after alias expansion
MAX_NUMBER_CHARS = 64  # a whole number longer than this is a typo or an attack, not a setting


class _Refused(Exception):
    """A refusal at a YAML path (None: name the line and column only)."""

    def __init__(self, message: str, mark: yaml.Mark | None, path: Location | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.mark = mark
        self.path = path

    def error(self, label: str) -> InputError:
        if self.path is None:
            return _at(label, self.mark, self.message)
        line = f" (line {self.mark.line + 1})" if self.mark is not None else ""
        return InputError(f"{self.message}{line}", f"{label}: {format_path(self.path)}")


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader that stops composing past `MAX_DEPTH` levels or `MAX_VALUES` nodes."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._composed = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        self._depth += 1
        self._composed += 1
        if self._depth > MAX_DEPTH:
            raise _Refused(f"nesting deeper than {MAX_DEPTH} levels", self._mark())
        if self._composed > MAX_VALUES:
            raise _Refused(f"more than {MAX_VALUES:,} values", self._mark())
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def _mark(self) -> yaml.Mark | None:
        event = self.peek_event()  # type: ignore[no-untyped-call]
        mark: yaml.Mark | None = getattr(event, "start_mark", None)
        return mark

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        _refuse_long_number(node)
        value: int = super().construct_yaml_int(node)
        return value

    def construct_yaml_float(self, node: yaml.ScalarNode) -> float:
        _refuse_long_number(node)
        value: float = super().construct_yaml_float(node)
        return value


def _refuse_long_number(node: yaml.ScalarNode) -> None:
    """A number of thousands of digits is a typo or an attack, never a setting (and int() of
    100,000 digits raises, or takes seconds)."""
    length = len(str(node.value))
    if length > MAX_NUMBER_CHARS:
        raise _Refused(f"a number of {length:,} characters is too long to be a setting", node.start_mark)


_BoundedLoader.add_constructor("tag:yaml.org,2002:int", _BoundedLoader.construct_yaml_int)
_BoundedLoader.add_constructor("tag:yaml.org,2002:float", _BoundedLoader.construct_yaml_float)
# YAML 1.2 reads `5e-2` as a number, YAML 1.1 (PyYAML) as text unless it has a dot (`5.0e-2`):
# the spec's JSON schema and the editors that check against it take it as a number, so here too.
_BoundedLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"), list("-+0123456789"))


def read_text_bounded(path: Path) -> str:
    """The text of a small regular file; InputError for a folder, a device or a huge file."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise InputError("no such file", str(path)) from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", str(path)) from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError("is a folder, not a YAML file", str(path))
    if not stat.S_ISREG(info.st_mode):
        raise InputError("is not a regular file", str(path))
    if info.st_size > MAX_BYTES:
        raise InputError(f"is {info.st_size / 1e6:.1f} MB; a spec or rig file is at most "
                         f"{MAX_BYTES / 1e6:.0f} MB", str(path))
    try:
        with open(path, encoding="utf-8-sig") as handle:
            return handle.read(MAX_BYTES + 1)
    except UnicodeDecodeError as exc:
        raise InputError(f"cannot read the file: not UTF-8 text (byte {exc.start})", str(path)) from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", str(path)) from None


def parse_yaml(text: str, label: str) -> tuple[Any, yaml.Node | None]:
    """The document's values and its node tree (for line numbers), or an InputError."""
    if len(text) > MAX_BYTES:
        raise InputError(f"is longer than {MAX_BYTES / 1e6:.0f} MB", label)
    loader = _BoundedLoader(text)
    try:
        root = loader.get_single_node()
        if root is not None:
            _check_graph(root, label)
            data = loader.construct_document(root)
        else:
            data = None
    except _Refused as exc:
        raise exc.error(label) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or exc.context or "invalid YAML"
        raise _at(label, mark, f"YAML syntax error: {problem}") from None
    except yaml.YAMLError as exc:
        raise InputError(f"YAML syntax error: {' '.join(str(exc).split())}", label) from None
    except (ValueError, OverflowError, RecursionError) as exc:
        # A scalar PyYAML cannot turn into a value (an odd timestamp, a huge base-60 number).
        raise InputError(f"cannot read a value: {' '.join(str(exc).split())[:200]}", label) from None
    finally:
        loader.dispose()
    if root is not None:
        _check_numbers(data, root, (), label, set())
    return data, root


def _at(label: str, mark: yaml.Mark | None, message: str) -> InputError:
    where = f"{label}:{mark.line + 1}:{mark.column + 1}" if mark is not None else label
    return InputError(message, where)


def _check_graph(root: yaml.Node, label: str) -> None:
    """Refuse self-containing aliases, too deep or too large expansions, and duplicate keys."""
    sizes: dict[int, tuple[int, int]] = {}  # id(node) -> (expanded values, expanded depth)
    active: set[int] = set()
    checked_keys: set[int] = set()

    def walk(node: yaml.Node, path: Location, depth: int) -> tuple[int, int]:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in active:
            raise _Refused("an alias that contains itself (its expansion never ends)",
                           node.start_mark, path)
        if depth > MAX_DEPTH * 2:
            raise _Refused(f"aliases nest deeper than {MAX_DEPTH * 2} levels", node.start_mark, path)
        active.add(key)
        count, deepest = 1, 0
        if isinstance(node, yaml.MappingNode):
            if key not in checked_keys:
                checked_keys.add(key)
                _refuse_duplicate_keys(node, path)
            children = [(str(k.value) if isinstance(k, yaml.ScalarNode) else "?", v)
                        for k, v in node.value]
            for name, value in children:
                n, d = walk(value, (*path, name), depth + 1)
                count, deepest = count + n, max(deepest, d)
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                n, d = walk(item, (*path, i), depth + 1)
                count, deepest = count + n, max(deepest, d)
        active.discard(key)
        if count > MAX_VALUES:
            raise _Refused(f"aliases expand to more than {MAX_VALUES:,} values (an alias bomb?); "
                           "write the values out", node.start_mark, path)
        sizes[key] = (count, deepest + 1)
        if deepest + 1 > MAX_DEPTH * 2:
            raise _Refused(f"aliases nest deeper than {MAX_DEPTH * 2} levels", node.start_mark, path)
        return sizes[key]

    walk(root, (), 0)


def _refuse_duplicate_keys(node: yaml.MappingNode, path: Location) -> None:
    seen: dict[str, yaml.Node] = {}
    for key, _ in node.value:
        name = str(key.value) if isinstance(key, yaml.ScalarNode) else repr(key.value)[:40]
        if name in seen:
            raise _Refused(f"duplicate key {name!r} (first on line {seen[name].start_mark.line + 1})",
                           key.start_mark, (*path, name))
        seen[name] = key


def _check_numbers(value: Any, node: yaml.Node | None, path: Location, label: str,
                   seen: set[int]) -> None:
    """Every float must be finite (NaN and ±inf mean a broken setting, never a valid one)."""
    if isinstance(value, float):
        if not math.isfinite(value):
            mark = node.start_mark if node is not None else None
            raise _Refused(f"must be a finite number, got {value}", mark, path).error(label)
        return
    if not isinstance(value, dict | list):
        return
    if id(value) in seen:  # a shared (aliased) value is checked once
        return
    seen.add(id(value))
    if isinstance(value, dict):
        children = dict(_mapping_children(node))
        for k, v in value.items():
            if isinstance(k, float) and not math.isfinite(k):
                raise _Refused(f"a key must be a finite number, got {k}",
                               node.start_mark if node else None, path).error(label)
            _check_numbers(v, children.get(str(k)), (*path, str(k)), label, seen)
    else:
        items = node.value if isinstance(node, yaml.SequenceNode) else []
        for i, v in enumerate(value):
            _check_numbers(v, items[i] if i < len(items) else node, (*path, i), label, seen)


def _mapping_children(node: yaml.Node | None) -> list[tuple[str, yaml.Node]]:
    if not isinstance(node, yaml.MappingNode):
        return []
    return [(str(k.value), v) for k, v in node.value if isinstance(k, yaml.ScalarNode)]
