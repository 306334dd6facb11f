"""Pytest fixtures for the emulated UR controller (imported by the conftest files that use it).

`ur_emulator(**config)` starts an emulator process with a `ControllerConfig` built from the
keyword arguments (optionally a `piano=PianoConfig(...)`) and stops it after the test; the test
fails if pianobot sent the control script a command the emulator does not implement (a real
controller would have done something the test never checked). The ur_rtde SDK is required:
without it the tests that use these fixtures are skipped.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest

from .controller import ControllerConfig
from .emulator import EmulatedUR
from .piano import PianoConfig

LIFETIME_S = 240.0  # no emulator outlives its test by more than this, whatever happens

EmulatorFactory = Callable[..., EmulatedUR]


@pytest.fixture()
def ur_emulator() -> Iterator[EmulatorFactory]:
    """A factory of started emulators: `ur_emulator(generation="cb3", speed_slider=0.3)`."""
    for module in ("rtde_control", "rtde_receive", "rtde_io", "dashboard_client"):
        pytest.importorskip(module)
    started: list[EmulatedUR] = []

    def start(piano: PianoConfig | None = None, **config: Any) -> EmulatedUR:
        emulator = EmulatedUR(ControllerConfig(**config), lifetime_s=LIFETIME_S, piano=piano)
        emulator.start()
        started.append(emulator)
        return emulator

    yield start
    unsupported = []
    for emulator in started:
        if emulator.alive:
            unsupported += emulator.get("unsupported")
        emulator.stop()
    assert not unsupported, f"commands the emulated control script does not implement: {unsupported}"
