"""Read spec and rig files: YAML in, validated models out, one-line InputErrors for bad input.

Every error names the file and the YAML path (`spec.yaml: sweep.params.depth_m[2]`), the bad
value and what would be valid, with the line number; a YAML syntax error names line:column.
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import tempfile
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeVar, get_args

import yaml
from pydantic import BaseModel, ValidationError

from pianobot.errors import InputError
from pianobot.spec.checks import Problem, spec_problems
from pianobot.spec.experiment import SIM_RIG, ExperimentSpec
from pianobot.spec.messages import Location, error_message, format_path
from pianobot.spec.parameters import PARAMETER_NAMES
from pianobot.spec.rig import RigSpec
from pianobot.spec.yaml_safe import parse_yaml, read_text_bounded

ModelT = TypeVar("ModelT", bound=BaseModel)


def _read_yaml(path: Path) -> tuple[Any, yaml.Node | None]:
    """The parsed document and its node tree (for line numbers); bounded, see `yaml_safe`."""
    return _parse_yaml(read_text_bounded(path), str(path))


def _parse_yaml(text: str, label: str) -> tuple[Any, yaml.Node | None]:
    data, root = parse_yaml(text, label)
    if data is None:
        raise InputError("the file is empty", label)
    if not isinstance(data, dict):
        raise InputError(f"must be a YAML mapping (key: value), got {type(data).__name__}", label)
    return data, root


def _line_of(root: yaml.Node | None, path: Location) -> int | None:
    """1-based line of the deepest node of `path` present in the YAML."""
    if root is None:
        return None
    node, line = root, root.start_mark.line
    for part in path:
        if isinstance(node, yaml.MappingNode):
            match = next(((k, v) for k, v in node.value if str(k.value) == str(part)), None)
            if match is None:
                break
            node, line = match[1], match[0].start_mark.line
        elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) and part < len(node.value):
            node = node.value[part]
            line = node.start_mark.line
        else:
            break
    return line + 1


def _input_error(label: str, root: yaml.Node | None, path: Location, message: str) -> InputError:
    line = _line_of(root, path)
    suffix = f" (line {line})" if line is not None else ""
    return InputError(f"{message}{suffix}", f"{label}: {format_path(path)}")


@functools.cache
def spec_keys() -> tuple[str, ...]:
    """Every key a spec or rig file may hold (parameter names and the models' fields, nested)."""
    names: set[str] = set(PARAMETER_NAMES)
    for model in (ExperimentSpec, RigSpec):
        stack: list[Any] = [model]
        while stack:
            cls = stack.pop()
            for field_name, field in cls.model_fields.items():
                names.add(field_name)
                for arg in _model_types(field.annotation):
                    if arg not in stack:
                        stack.append(arg)
    return tuple(sorted(names))


def _model_types(annotation: Any) -> list[Any]:
    """Pydantic model classes inside a (possibly nested) type annotation."""
    found: list[Any] = []
    if isinstance(annotation, type) and hasattr(annotation, "model_fields"):
        found.append(annotation)
    for arg in get_args(annotation):
        found.extend(_model_types(arg))
    return found


def _validate(model: type[ModelT], data: Any, label: str, root: yaml.Node | None) -> ModelT:
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors()
        path, message = error_message(errors[0], spec_keys=spec_keys())
        if len(errors) > 1:
            message += f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})"
        raise _input_error(label, root, path, message) from None


def load_rig(path: str | Path) -> RigSpec:
    """The rig described by a rig file, or the default simulated rig for `"sim"`."""
    if str(path) == SIM_RIG:
        return RigSpec()
    label = str(path)
    data, root = _read_yaml(Path(path))
    return _validate(RigSpec, data, label, root)


def load_rig_for(spec: ExperimentSpec) -> RigSpec:
    """The rig a spec names (a rig file resolves relative to the spec file)."""
    rig_path = spec.rig_path()
    if rig_path is None:
        return RigSpec()
    if not rig_path.exists():
        label = str(spec.source_path) if spec.source_path else "spec"
        raise InputError(
            f"rig file {spec.rig!r} not found (paths are relative to the spec file)",
            f"{label}: rig",
        )
    return load_rig(rig_path)


def load_spec(path: str | Path, rig: str | Path | None = None) -> ExperimentSpec:
    """Read, validate and envelope-check an experiment spec.

    Raises InputError naming the file and YAML path for an unreadable file, a YAML syntax
    error, an unknown key, a wrong type, an empty grid or a value outside the finger's
    safety envelope (as the spec's rig file sets it, or `rig`, a rig file used instead).
    """
    label = str(path)
    data, root = _read_yaml(Path(path))
    spec = _validate(ExperimentSpec, data, label, root).with_source(Path(path))
    rig_spec = load_rig_for(spec) if rig is None else load_rig(rig)
    rig_label = spec.rig if rig is None else str(rig)
    problems: list[Problem] = spec_problems(spec, rig_spec, rig_label)
    if problems:
        first = problems[0]
        message = first.message
        if len(problems) > 1:
            message += f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''})"
        raise _input_error(label, root, first.path, message)
    return spec


def parse_spec_text(text: str, label: str) -> ExperimentSpec:
    """A spec from its YAML text (as a run records it), validated but not envelope-checked.

    For rebuilding what a run already accepted (its plan); new runs go through `load_spec`.
    """
    data, root = _parse_yaml(text, label)
    return _validate(ExperimentSpec, data, label, root)


def spec_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a spec file's bytes, as recorded with a run."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc}", str(path)) from None


def write_rig_calibration(path: str | Path, pose: Sequence[float], when: datetime) -> RigSpec:
    """Set `ur5.reference_pose` and `ur5.calibrated_utc` in a rig file, keeping the rest as is.

    Only the two values are rewritten (comments and layout stay); the result is validated
    before it replaces the file atomically. Returns the updated rig.
    """
    label = str(path)
    values = [float(v) for v in pose]
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise InputError(f"a pose is 6 finite numbers [x, y, z, rx, ry, rz], got {list(pose)}", "pose")
    stamp = when.astimezone(UTC) if when.tzinfo else when.replace(tzinfo=UTC)
    replacements = {
        "reference_pose": "[" + ", ".join(f"{round(v, 7)!r}" for v in values) + "]",
        "calibrated_utc": f'"{stamp.strftime("%Y-%m-%dT%H:%M:%SZ")}"',
    }
    text = read_text_bounded(Path(path))
    _, root = _parse_yaml(text, label)
    new_text = _replace_values(text, root, "ur5", replacements, label)
    data, new_root = _parse_yaml(new_text, label)
    rig = _validate(RigSpec, data, label, new_root)
    _write_atomically(Path(path), new_text)
    return rig


def _replace_values(
    text: str, root: yaml.Node | None, section: str, values: dict[str, str], label: str
) -> str:
    """`text` with the values of `section.<key>` replaced by the given YAML snippets."""
    if not isinstance(root, yaml.MappingNode):
        raise InputError("must be a YAML mapping", label)
    block = next((v for k, v in root.value if k.value == section), None)
    if not isinstance(block, yaml.MappingNode) or not block.value or block.flow_style:
        raise InputError(f"needs a block-style `{section}:` section to calibrate", f"{label}: {section}")
    edits: list[tuple[int, int, str]] = []
    first_key = block.value[0][0]
    for key, snippet in values.items():
        node = next((v for k, v in block.value if k.value == key), None)
        if node is None:
            # Insert a new line before the section's first key, with the same indentation.
            start = first_key.start_mark.index - first_key.start_mark.column
            indent = " " * first_key.start_mark.column
            edits.append((start, start, f"{indent}{key}: {snippet}\n"))
            continue
        start, end = node.start_mark.index, node.end_mark.index
        # A block list's node runs on to the next key; replace only the list itself.
        end = start + len(text[start:end].rstrip())
        gap = "" if text[start - 1 : start].isspace() else " "
        edits.append((start, end, gap + snippet))
    for start, end, snippet in sorted(edits, reverse=True):
        text = text[:start] + snippet + text[end:]
    return text


def _write_atomically(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_yaml_model(path: str | Path, model: type[ModelT]) -> ModelT:
    """Any YAML file validated into a pydantic model, with the spec's one-line errors."""
    label = str(path)
    data, root = _read_yaml(Path(path))
    return _validate(model, data, label, root)
