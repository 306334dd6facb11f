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
            members = value.items() if isinstance(value, dict) else [("", value)]
            for key, item in members:
                if isinstance(item, CPUDispatcher) and not attr.startswith("_") and attr not in IN_KERNEL_ONLY:
                    found[f"{name}.{attr}{f'[{key}]' if key != '' else ''}"] = item
    return found


def test_every_kernel_is_compiled_by_the_warm_up() -> None:
    dispatchers = _dispatchers()
    # The integrator: five model classes in two block sizes; the observation loops; the rest.
    assert sum(".integrate" in k for k in dispatchers) == 10 and len(dispatchers) >= 17
    kernels.compile_physics()
    kernels.compile_readout()
    kernels.compile_import()
    missed = sorted(k for k, d in dispatchers.items() if not d.signatures)
    assert not missed, f"kernels the warm-up does not compile: {missed}"
