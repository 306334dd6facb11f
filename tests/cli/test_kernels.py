"""`python -m pianobot.cli.kernels` (run by `make install`) compiles every numba kernel, so no
command compiles one on first use."""

from __future__ import annotations

import importlib
from typing import Any

from numba.core.registry import CPUDispatcher

from pianobot.cli import kernels

KERNEL_MODULES = (
    "pianobot.physics._kernel",
    "pianobot.physics._observe_kernel",
    "pianobot.analysis.greybox._midi_kernel",
    "pianobot.io._assign_kernel",
)


# Compiled helpers that only other kernels call: compiled into their callers (a caller loaded
# from the cache leaves the helper's own dispatcher empty). Private names are such helpers too.
IN_KERNEL_ONLY = frozenset({"arm_lag"})


def _dispatchers() -> dict[str, Any]:
    """The kernels the commands call: every compiled function of the kernel modules (the
    integrator's per-class dicts too), except the helpers only other kernels call."""
    found: dict[str, Any] = {}
    for name in KERNEL_MODULES:
        module = importlib.import_module(name)
        for attr, value in vars(module).items():
            for key, item in _members(value):
                if isinstance(item, CPUDispatcher) and not attr.startswith("_") and attr not in IN_KERNEL_ONLY:
                    found[f"{name}.{attr}{key}"] = item
    return found


def _members(value: Any, key: str = "") -> list[tuple[str, Any]]:
    """A value with its key path: a kernel, or the kernels of a (nested) dict of them."""
    if not isinstance(value, dict):
        return [(key, value)]
    return [m for k, v in value.items() for m in _members(v, f"{key}[{k}]")]


def test_every_kernel_is_compiled_by_the_warm_up() -> None:
    dispatchers = _dispatchers()
    # The integrator: 33 model classes (linear, and the full step's 32 flag combinations) in
    # three block sizes; the observation loops; the rest.
    assert sum(".integrate" in k for k in dispatchers) == 99 and len(dispatchers) >= 106
    kernels.compile_physics()
    kernels.compile_readout()
    kernels.compile_import()
    missed = sorted(k for k, d in dispatchers.items() if not d.signatures)
    assert not missed, f"kernels the warm-up does not compile: {missed}"
