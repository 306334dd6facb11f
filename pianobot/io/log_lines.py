"""Reading an old keystroke log line by line: one Python-literal dict per line.

    {'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': [[[144, 57, 1, 0], 468620], ...]}
    {'group': 0, 'order': 0, 'note': 'F', 'down_vel': 0.5, ..., 'midi': [...]}

A line is a *positional* record (a `control` list), a *named* record (named keys and `midi`), a
*header* (a dict with neither, e.g. `start_position_l`: metadata that also starts a new MIDI
clock session) or skipped with the reason (line number kept). Lines are parsed with
`ast.literal_eval` semantics (never `eval`); also accepted, as the scripts that write such logs
print them: bare `nan`/`inf`, numpy scalars (`np.float64(0.015)`: numpy 2's repr of a value taken
from an array), Python 2 longs (`468620L`) and whole numbers written as floats (`468620.0`). Keys
of a positional record besides `control` and `midi` are ignored and listed (`LogLines.ignored`).
The common shape goes through `json` first, which is ~20x faster and gives the same values, so a
log of hundreds of thousands of lines reads in seconds. Records are kept in flat arrays, not one
object per line.
"""

from __future__ import annotations

import ast
import json
import math
import re
import warnings
from array import array
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from pianobot.progress import NO_PROGRESS, Progress

MIDI_KEY = "midi"
CONTROL_KEY = "control"


@dataclass(frozen=True)
class SkippedLine:
    """A line that was not imported, and why."""

    line: int
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {"line": self.line, "reason": self.reason}


@dataclass
class LogLines:
    """The records of a log in flat arrays (record i = i-th keystroke line)."""

    line: array[int] = field(default_factory=lambda: array("q"))
    header_acc: array[float] = field(default_factory=lambda: array("d"))  # NaN: none
    after_header: array[int] = field(default_factory=lambda: array("b"))
    # positional records: control values flattened, with each record's count
    control: array[float] = field(default_factory=lambda: array("d"))
    n_control: array[int] = field(default_factory=lambda: array("i"))
    # named records: one list per key, None where a record lacks the key
    named: dict[str, list[Any]] = field(default_factory=dict)
    # events: one row per MIDI event, in file order
    ev_record: array[int] = field(default_factory=lambda: array("q"))
    ev_status: array[int] = field(default_factory=lambda: array("q"))
    ev_note: array[int] = field(default_factory=lambda: array("q"))
    ev_velocity: array[int] = field(default_factory=lambda: array("q"))
    ev_t_ms: array[int] = field(default_factory=lambda: array("q"))
    headers: list[tuple[int, dict[str, Any]]] = field(default_factory=list)
    skipped: list[SkippedLine] = field(default_factory=list)
    ignored: dict[str, int] = field(default_factory=dict)  # keys of positional records not read: lines
    n_positional: int = 0
    n_named: int = 0

    def __len__(self) -> int:
        return len(self.line)


def parse_lines(
    lines: Iterable[tuple[int, str]],
    progress: Progress = NO_PROGRESS,
    total_bytes: int | None = None,
) -> LogLines:
    """Parse numbered lines into records, headers and skipped lines.

    `total_bytes` (the file size) lets the progress display show how far the reading is.
    """
    out = LogLines()
    header_acc = math.nan
    after_header = False
    done_bytes = 0
    with progress.task("reading log lines", total=total_bytes) as task:
        for number, raw in lines:
            done_bytes += len(raw) + 1
            if number % 8192 == 0:
                task.update(completed=done_bytes, note=f"line {number}")
            text = raw.strip()
            if not text:
                continue
            try:
                value = literal(text)
            except ValueError as exc:
                out.skipped.append(SkippedLine(number, f"not a Python literal ({exc})"))
                continue
            if not isinstance(value, dict):
                out.skipped.append(SkippedLine(number, f"not a dict but a {type(value).__name__}"))
                continue
            if CONTROL_KEY not in value and MIDI_KEY not in value:
                out.headers.append((number, value))
                acc: Any = value.get("acc")
                header_acc = float(acc) if is_number(acc) else math.nan
                after_header = True
                continue
            try:
                _add_record(out, number, value)
            except ValueError as exc:
                out.skipped.append(SkippedLine(number, str(exc)))
                continue
            out.header_acc.append(header_acc)
            out.after_header.append(1 if after_header else 0)
            after_header = False
        task.update(completed=done_bytes)
    for column in out.named.values():
        column.extend([None] * (len(out.line) - len(column)))
    return out


def _add_record(out: LogLines, number: int, value: dict[Any, Any]) -> None:
    """Validate one record and append it (nothing is appended when it is rejected)."""
    events = _events(value.get(MIDI_KEY))
    if CONTROL_KEY in value:
        control = _control(value[CONTROL_KEY])
        for key in value:
            if key not in (CONTROL_KEY, MIDI_KEY):
                name = str(key)
                out.ignored[name] = out.ignored.get(name, 0) + 1
        out.control.extend(control)
        out.n_control.append(len(control))
        out.n_positional += 1
    else:
        keys = [k for k in value if k != MIDI_KEY]
        bad = [k for k in keys if not isinstance(k, str)]
        if bad:
            raise ValueError(f"key {bad[0]!r} is not a name")
        for key in keys:
            item = value[key]
            if not (
                is_number(item) or isinstance(item, str) or item is None or isinstance(item, bool)
            ):
                raise ValueError(f"{key!r} is neither a number nor a text: {item!r:.60}")
        record = len(out.line)
        for key in keys:
            column = out.named.setdefault(key, [])
            column.extend([None] * (record - len(column)))  # records that lacked the key
            column.append(value[key])
        out.n_named += 1
    record = len(out.line)
    out.line.append(number)
    for status, note, velocity, t_ms in events:
        out.ev_record.append(record)
        out.ev_status.append(status)
        out.ev_note.append(note)
        out.ev_velocity.append(velocity)
        out.ev_t_ms.append(t_ms)


def literal(text: str) -> Any:
    """`ast.literal_eval` of one line, also accepting the bare `nan`/`inf` Python prints.

    The usual shape (quotes, numbers, lists, dicts) goes through `json`, which gives the same
    values; anything else (tuples, escapes, nan) takes the `ast` path.
    """
    if '"' not in text and "\\" not in text and "nan" not in text and "inf" not in text:
        try:
            return json.loads(text.replace("'", '"'), parse_constant=_no_constant)
        except (ValueError, RecursionError):
            pass
    try:
        tree = _parse(text)
    except SyntaxError:
        if not _PY2_LONG.search(text):
            raise ValueError("invalid syntax") from None
        try:
            tree = _parse(_PY2_LONG.sub(r"\1", text))
        except SyntaxError as exc:
            raise ValueError(exc.msg or "invalid syntax") from None
    except (ValueError, MemoryError, RecursionError) as exc:
        raise ValueError(getattr(exc, "msg", None) or type(exc).__name__) from None
    try:
        return ast.literal_eval(_Floats().visit(tree))
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError) as exc:
        message = str(exc).split("\n")[0]
        if message.startswith("malformed node"):  # literal_eval names an AST object: say what it was
            message = "holds a call or a name, not a literal value"
        raise ValueError(message or type(exc).__name__) from None


#: A Python 2 long (`468620L`), outside a name or a decimal fraction.
_PY2_LONG = re.compile(r"(?<![\w.])(\d+)[lL]\b")


def _parse(text: str) -> ast.Expression:
    """The expression tree of one line (SyntaxError when it is none; also ValueError, MemoryError,
    RecursionError on a garbled or hostile line)."""
    with warnings.catch_warnings():  # "invalid escape sequence" in a garbled line is not news
        warnings.simplefilter("ignore")
        return ast.parse(text, mode="eval")


def _no_constant(name: str) -> Any:
    raise ValueError(name)  # JSON's NaN/Infinity are not Python literals: let ast decide


#: numpy scalar types whose repr a log written from numpy values holds (`np.float64(0.015)`).
_NUMPY_SCALARS = frozenset({"float64", "float32", "float16", "double", "single", "longdouble", "int64", "int32",
                            "int16", "int8", "uint64", "uint32", "uint16", "uint8", "intc", "intp", "longlong",
                            "str_"})
_NUMPY_MODULES = frozenset({"np", "numpy"})


class _Floats(ast.NodeTransformer):
    """Turns the names `nan` and `inf` into float constants and a numpy scalar's repr
    (`np.float64(0.015)`, `numpy.int64(60)`) into its argument; nothing is evaluated, and
    `literal_eval` still refuses any other call."""

    def visit_Name(self, node: ast.Name) -> ast.AST:
        if node.id in ("nan", "inf"):
            return ast.copy_location(ast.Constant(float(node.id)), node)
        return node

    def visit_Call(self, node: ast.Call) -> ast.AST:
        func = node.func
        if (isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) and func.value.id in _NUMPY_MODULES
                and func.attr in _NUMPY_SCALARS and len(node.args) == 1 and not node.keywords):
            inner: ast.AST = self.visit(node.args[0])
            return inner
        return node


def _whole(value: Any) -> Any:
    """A float holding a whole number (`468620.0`) as that int; anything else unchanged."""
    if type(value) is float and value.is_integer() and abs(value) < 2**53:
        return int(value)
    return value


def is_number(value: Any) -> bool:
    """A finite int or float (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _control(value: Any) -> list[float]:
    if not isinstance(value, list | tuple) or not value:
        raise ValueError("'control' is not a non-empty list")
    # exact type checks are the fast path (bool is an int subclass and must not pass)
    if not all(type(v) is float or type(v) is int for v in value) or not all(
        map(math.isfinite, value)
    ):
        raise ValueError(f"'control' holds a non-number: {value!r:.80}")
    return [float(v) for v in value]


def _events(value: Any) -> list[tuple[int, int, int, int]]:
    if value is None:
        raise ValueError("no 'midi' list")
    if not isinstance(value, list | tuple):
        raise ValueError("'midi' is not a list")
    events = []
    for i, item in enumerate(value):
        try:
            message, timestamp = item
            status, note, velocity = message[0], message[1], message[2]
        except (TypeError, ValueError, IndexError, KeyError):
            raise ValueError(
                f"MIDI event {i} is not [[status, note, velocity, 0], timestamp_ms]"
            ) from None
        status, note, velocity, timestamp = (_whole(v) for v in (status, note, velocity, timestamp))
        if not (
            type(status) is int
            and type(note) is int
            and type(velocity) is int
            and type(timestamp) is int
        ):
            raise ValueError(f"MIDI event {i} holds a non-integer: {item!r:.80}")
        if not (
            0 <= status <= 255
            and 0 <= note <= 127
            and 0 <= velocity <= 127
            and 0 <= timestamp < 2**53
        ):
            raise ValueError(f"MIDI event {i} is out of range: {item!r:.80}")
        events.append((status, note, velocity, timestamp))
    return events
