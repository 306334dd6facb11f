"""The fakes of ur_rtde offer only what the installed SDK offers, with the SDK's signatures.

ur_rtde is a pybind11 module: each method's docstring starts with its signature(s), e.g.
`moveL(self: rtde_control.RTDEControlInterface, pose: list[float], speed: float = 0.25, ...)
-> bool`. Every public method of a fake must match one of its SDK method's signatures: same
parameters in the same order, same names (pybind's `argN` are positional-only, so the fake's
must be too: a keyword call that works on the fake would fail on the robot), same defaults,
same types and return type. Constructors take the fake controller first, then a prefix of the
SDK's parameters.
"""

from __future__ import annotations

import ast
import inspect
import re
from dataclasses import dataclass
from typing import Any

import pytest
from fake_rtde import FakeAsyncStatus, FakeControl, FakeDashboard, FakeIO, FakeReceive

PAIRS = [
    (FakeControl, "rtde_control", "RTDEControlInterface"),
    (FakeReceive, "rtde_receive", "RTDEReceiveInterface"),
    (FakeIO, "rtde_io", "RTDEIOInterface"),
    (FakeDashboard, "dashboard_client", "DashboardClient"),
    (FakeAsyncStatus, "rtde_control", "AsyncOperationStatus"),
]
# SDK type names → the fakes' annotations.
TYPE_NAMES = {"rtde_control.AsyncOperationStatus": "FakeAsyncStatus"}
NO_DEFAULT = object()


@dataclass(frozen=True)
class Param:
    name: str
    type: str
    default: str | None  # the default as written in the docstring


@dataclass(frozen=True)
class Signature:
    params: tuple[Param, ...]
    returns: str

    def text(self) -> str:
        inner = ", ".join(f"{p.name}: {p.type}" + (f" = {p.default}" if p.default else "")
                          for p in self.params)
        return f"({inner}) -> {self.returns}"


def split_top_level(text: str) -> list[str]:
    """Split at commas outside brackets and angle brackets."""
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        if ch in "[(<":
            depth += 1
        elif ch in "])>":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i].strip())
            start = i + 1
    if text[start:].strip():
        parts.append(text[start:].strip())
    return parts


def sdk_signatures(cls: Any, name: str) -> list[Signature]:
    """Every overload's signature from the pybind docstring (self dropped)."""
    doc = getattr(cls, name).__doc__ or ""
    found = []
    for line in doc.splitlines():
        match = re.match(rf"^(?:\d+\. )?{re.escape(name)}\((.*)\) -> (.+)$", line.strip())
        if not match:
            continue
        params = []
        for part in split_top_level(match.group(1))[1:]:
            head, _, default = part.partition(" = ")
            pname, _, ptype = head.partition(": ")
            params.append(Param(pname.strip(), ptype.strip(), default.strip() or None))
        found.append(Signature(tuple(params), match.group(2).strip()))
    return found


def fake_params(fake: Any, name: str) -> tuple[list[inspect.Parameter], str]:
    signature = inspect.signature(getattr(fake, name))
    params = list(signature.parameters.values())[1:]  # self
    if name == "__init__":
        params = params[1:]  # the fake controller
    return params, str(signature.return_annotation)


def mismatch(params: list[inspect.Parameter], returns: str, sdk: Signature, *,
             prefix: bool = False) -> str | None:
    """Why the fake's parameters do not match `sdk`, or None when they do."""
    wanted = sdk.params[:len(params)] if prefix else sdk.params
    if len(params) != len(wanted):
        return f"{len(params)} parameters, the SDK has {len(wanted)}"
    for mine, theirs in zip(params, wanted, strict=True):
        if re.fullmatch(r"arg\d+", theirs.name):
            if mine.kind is not inspect.Parameter.POSITIONAL_ONLY:
                return f"{mine.name} must be positional-only (the SDK's {theirs.name})"
        elif mine.name != theirs.name or mine.kind is not inspect.Parameter.POSITIONAL_OR_KEYWORD:
            return f"parameter {mine.name!r} is {theirs.name!r} in the SDK"
        if str(mine.annotation) != TYPE_NAMES.get(theirs.type, theirs.type):
            return f"{mine.name}: {mine.annotation} is {theirs.type} in the SDK"
        has_default = mine.default is not inspect.Parameter.empty
        if has_default != (theirs.default is not None):
            return f"{mine.name}: default {'given' if has_default else 'missing'}"
        if has_default and theirs.default is not None:
            try:
                expected = ast.literal_eval(theirs.default)
            except (ValueError, SyntaxError):
                continue  # an enum default such as <Flags.FLAG_UPLOAD_SCRIPT: 1>
            if mine.default != expected or type(mine.default) is not type(expected):
                return f"{mine.name}: default {mine.default!r}, the SDK's is {theirs.default}"
    if not prefix and returns != TYPE_NAMES.get(sdk.returns, sdk.returns):
        return f"returns {returns}, the SDK returns {sdk.returns}"
    return None


def public_methods(fake: Any) -> list[str]:
    return [n for n, v in vars(fake).items() if callable(v) and not n.startswith("_")]


@pytest.mark.parametrize(("fake", "module", "name"), PAIRS, ids=[p[2] for p in PAIRS])
def test_every_fake_method_has_the_sdk_signature(fake: Any, module: str, name: str) -> None:
    sdk_class = getattr(pytest.importorskip(module), name)
    problems = []
    for method in [*public_methods(fake), "__init__"]:
        if not hasattr(sdk_class, method):
            problems.append(f"{method}: not in {module}.{name}")
            continue
        signatures = sdk_signatures(sdk_class, method)
        assert signatures, f"no signature in the docstring of {name}.{method}"
        params, returns = fake_params(fake, method)
        reasons = [mismatch(params, returns, s, prefix=method == "__init__") for s in signatures]
        if all(reasons):
            problems.append(f"{method}: {reasons[0]} (SDK: {signatures[0].text()})")
    assert not problems, f"{fake.__name__} drifted from {module}.{name}:\n" + "\n".join(problems)


def test_the_signature_check_catches_drift() -> None:
    """The comparison itself can fail: a renamed, re-defaulted or keyword argN is caught."""
    sdk = pytest.importorskip("rtde_control").RTDEControlInterface
    (move,) = [s for s in sdk_signatures(sdk, "moveL") if len(s.params) == 4]

    def check(fn: Any) -> str | None:
        params = list(inspect.signature(fn).parameters.values())[1:]
        return mismatch(params, str(inspect.signature(fn).return_annotation), move)

    def good(self, pose: list[float], speed: float = 0.25, acceleration: float = 1.2,
             asynchronous: bool = False) -> bool: ...
    def renamed(self, pose: list[float], speed: float = 0.25, acceleration: float = 1.2,
                is_async: bool = False) -> bool: ...
    def slow(self, pose: list[float], speed: float = 0.1, acceleration: float = 1.2,
             asynchronous: bool = False) -> bool: ...

    assert check(good) is None
    assert "asynchronous" in str(check(renamed))
    assert "default 0.1" in str(check(slow))
    (within,) = sdk_signatures(sdk, "isPoseWithinSafetyLimits")

    def keyword(self, pose: list[float]) -> bool: ...
    params = list(inspect.signature(keyword).parameters.values())[1:]
    assert "positional-only" in str(mismatch(params, "bool", within))


@pytest.mark.parametrize("word", [0, 32768, 32768 + 17, (5 << 24) + (3 << 16), (127 << 24) + 32768 + 1,
                                  (64 << 24) + (255 << 16) + 32767 + 32768])
def test_fake_async_status_decodes_like_the_sdk(word: int) -> None:
    real = pytest.importorskip("rtde_control").AsyncOperationStatus(word)
    fake = FakeAsyncStatus(word)
    for method in ("operationId", "isAsyncOperationRunning", "changeCount", "value"):
        assert getattr(fake, method)() == getattr(real, method)(), method
    if real.isAsyncOperationRunning():
        assert fake.progress() == real.progress()
