"""Turn pydantic validation errors into one-line messages that name the YAML path and value.

pydantic reports `('sweep', 'grid', 'params', 'depth_m', 'values', 2)` and "Input should be a
valid number"; an experimenter wants `sweep.params.depth_m[2]` and "must be a number in m, got
'20 mm'". The union tags pydantic inserts into the location are dropped here.
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from typing import Any

from pydantic_core import ErrorDetails

from pianobot.spec.parameters import PARAMETER_NAMES, PARAMETERS, unit_of
from pianobot.spec.sweep import SWEEP_MODES

Location = tuple[str | int, ...]
_VALUE_TAGS = ("values", "linspace", "choices", "range")
_PARAMETER_MAPPINGS = ("params", "fixed")


def format_path(path: Sequence[str | int]) -> str:
    """A YAML path as people write it: `sweep.params.depth_m[2]`."""
    text = ""
    for part in path:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += f".{part}" if text else str(part)
    return text or "(top level)"


def clean_location(loc: Sequence[str | int]) -> Location:
    """The YAML path of a pydantic error location, without the union tags pydantic adds."""
    parts = list(loc)
    # ('sweep', 'grid', ...): the sweep mode is a tag, not a key in the YAML.
    if len(parts) > 1 and parts[0] == "sweep" and parts[1] in SWEEP_MODES:
        del parts[1]
    # ('sweep', 'params', 'depth_m', 'values', 2): the value shape is a tag too.
    if (
        len(parts) > 3
        and parts[:2] == ["sweep", "params"]
        and parts[2] in PARAMETERS
        and parts[3] in _VALUE_TAGS
    ):
        del parts[3]
    return tuple(parts)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _field_name(path: Location) -> str:
    """The nearest key in the path (the field a list item belongs to)."""
    for part in reversed(path):
        if isinstance(part, str):
            return part
    return ""


def _in_unit(name: str) -> str:
    unit = unit_of(name)
    return f" in {unit}" if unit else ""


def unknown_key_message(
    path: Location, key: str, known: Sequence[str] | None = None, spec_keys: Sequence[str] = ()
) -> str:
    """`unknown key 'depth_mm'; did you mean 'depth_m'?` (with the valid names for parameters).

    `known` are the valid keys at that place, when the caller knows them; otherwise a key under
    `params`/`fixed` is matched against the parameter names and any other against `spec_keys`
    (every key a spec or rig file may hold: the loader, which sits above both models, passes them,
    so this module never imports the models that import it).
    """
    in_parameters = len(path) >= 2 and path[-2] in _PARAMETER_MAPPINGS
    pool = list(known or (PARAMETER_NAMES if in_parameters else spec_keys))
    message = f"unknown key {key!r}"
    close = difflib.get_close_matches(key, pool, n=1, cutoff=0.6)
    if close:
        message += f"; did you mean {close[0]!r}?"
    if in_parameters:
        message += f" Parameters are: {', '.join(PARAMETER_NAMES)}"
    return message


def error_message(
    error: ErrorDetails, known: Sequence[str] | None = None, spec_keys: Sequence[str] = ()
) -> tuple[Location, str]:
    """(YAML path, one-line message) for one pydantic error.

    `known`: the valid keys at the error's place, if known; `spec_keys`: every key of a spec or rig
    file, for "did you mean" when `known` is not given (see `unknown_key_message`).
    """
    path = clean_location(error["loc"])
    kind, ctx, value = error["type"], error.get("ctx", {}), error.get("input")
    name = _field_name(path)
    got = f", got {_short(value)}"
    if kind == "extra_forbidden":
        return path, unknown_key_message(path, str(path[-1]), known, spec_keys)
    if kind == "missing":
        if path and isinstance(path[-1], int):
            return path, "missing item: this list has too few values"
        return path, f"missing required key {path[-1]!r}" if path else "missing value"
    if kind == "union_tag_invalid":
        return (*path, "mode"), f"must be one of {ctx['expected_tags']}, got {ctx['tag']!r}"
    if kind == "union_tag_not_found":
        return (*path, "mode"), f"missing required key 'mode' (one of {', '.join(SWEEP_MODES)})"
    if kind in ("float_parsing", "float_type", "finite_number"):
        return path, f"must be a number{_in_unit(name)}{got}"
    if kind in ("int_parsing", "int_type", "int_from_float"):
        return path, f"must be a whole number{_in_unit(name)}{got}"
    if kind in ("bool_parsing", "bool_type"):
        return path, f"must be true or false{got}"
    if kind in ("string_type", "str_type"):
        return path, f"must be text{got}"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        if name in PARAMETERS:
            return path, PARAMETERS[name].bounds_message(value)
        op = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<"}.get(kind, "<=")
        bound = next(iter(ctx.values()))
        return path, f"must be {op} {bound}{_in_unit(name).replace(' in ', ' ')}{got}"
    if kind == "too_short":
        if path[:2] == ("sweep", "params"):
            return path, "an empty grid: list at least one level"
        return path, f"needs at least {ctx.get('min_length')} item(s){got}"
    if kind == "too_long":
        return path, f"allows at most {ctx.get('max_length')} item(s)"
    if kind == "literal_error":
        return path, f"must be one of {ctx['expected']}{got}"
    if kind == "string_pattern_mismatch" and name == "name":
        return path, f"must be a slug (lowercase letters, digits, - and _){got}"
    if kind in ("list_type", "tuple_type"):
        if path[:2] == ("sweep", "params") and name in PARAMETERS:
            if "choices" in error["loc"]:
                shape = "{low, high} or a list of choices"
            elif PARAMETERS[name].integer:
                shape = "a list of whole numbers"
            else:
                shape = "a list of levels or {start, stop, num}"
            return path, f"must be {shape}{_in_unit(name)}{got}"
        return path, f"must be a list{got}"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return path, f"must be a mapping (key: value){got}"
    if kind == "value_error":
        return path, str(ctx.get("error", error["msg"]))
    return path, f"{error['msg'][0].lower()}{error['msg'][1:]}{got}"
