"""Compile pianobot's numba kernels once, so that no command pays for it on first use.

    python -m pianobot.cli.kernels        (`make install` runs it)

numba compiles a kernel on its first call and caches the machine code on disk (`cache=True`:
beside the kernel's source, or in numba's user cache when that folder is read-only). Without
this step the first simulated sweep of an installation spends ~6 s compiling, and the first
`pianobot identify` or `discover` ~50 s (measured: the quickstart sweep 7.6 s cold, 1.5 s
warm; a 24-keystroke discovery 134 s cold, 82 s warm). Each kernel is called here with tiny
inputs of the types the commands pass, so every specialisation they use is compiled and
cached: the integrator in each of its 33 model classes (the linear step; the full step in 16
classes, each with explicit and with implicit dampers) and its three block sizes, the simulated
world's observation loops, the MIDI readout of the grey-box fitter and the keystroke-log
importer's assignment.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pianobot.physics.model import KeystrokeModel


def _models() -> list[KeystrokeModel]:
    """One model of each compiled class of the integrator (see `physics.simulate._kernels`): the
    linear one, and the full step with each combination of its four flags."""
    from pianobot.physics._kernel import FULL_FLAGS
    from pianobot.physics.effects import Effects
    from pianobot.physics.model import KeystrokeModel
    from pianobot.physics.msd import MSDParams

    full = Effects.default_world()
    classes = []
    for power, hysteresis, smooth_stop, cohesive, implicit in FULL_FLAGS:
        if implicit:  # not an effect: the same models, simulated with implicit dampers
            continue
        fx = full.with_effect("finger_stiffening", form="power") if power else full
        fx = fx.with_effect("finger_hysteresis") if hysteresis else fx
        fx = fx.with_effect("key_preload", form="smooth") if smooth_stop else fx
        classes.append(fx.with_effect("adhesion", form="cohesive") if cohesive else fx)
    return [KeystrokeModel(msd=MSDParams(), effects=fx) for fx in (Effects.none(), *classes)]


def compile_physics() -> int:
    """The integrator (commanded presses and measured arm traces, 1, 5 and 9 keystrokes: its
    three block sizes), the world's observation and the rig's rest check. Returns the calls made."""
    from pianobot.physics._observe_kernel import last_beyond
    from pianobot.physics.simulate import simulate_arm, simulate_presses
    from pianobot.physics.world import World
    from pianobot.plan.trial import press_from

    depth_m, speed_mps = 0.01, 0.05  # the rest from the parameter table's defaults
    press = press_from({"depth_m": depth_m, "down_velocity_mps": speed_mps})
    calls = 0
    t = np.linspace(0.0, 0.05, 51)
    for model in _models():
        for n in (1, 5, 9):
            simulate_presses([press] * n, np.full(n, -40.0), model, duration_s=0.01)
            arm = np.tile(np.minimum(t, 0.02)[None, :] * 0.5, (n, 1))
            for implicit in (False, True):
                simulate_arm(t, arm, np.full(n, -40.0), model, duration_s=0.01, implicit_damping=implicit)
            calls += 3
    World(seed=0).keystroke(press, -40.0, key="warm")
    last_beyond(np.zeros(3), 1e-3, True)
    return calls + 2


def compile_readout() -> int:
    """The grey-box fitter's MIDI readout of simulated key traces."""
    from pianobot.analysis.greybox.commanded import midi_outcomes
    from pianobot.physics.piano import PianoParams

    x2 = np.tile(np.linspace(0.0, 0.01, 20), (2, 1))
    midi_outcomes(x2, np.ones_like(x2, dtype=bool), PianoParams(), 1e-3)
    return 1


def compile_import() -> int:
    """The keystroke-log importer's assignment of MIDI events to keystrokes (a tiny log, imported
    into a scratch folder)."""
    from pianobot.io.keystroke_import import import_keystroke_log

    lines = []
    for i in range(12):
        on_ms = 1000 + 2500 * i
        events = f"[[[144, 57, {40 + i}, 0], {on_ms}], [[128, 57, 64, 0], {on_ms + 300}]]"
        lines.append(f"{{'control': [60, 45, 0.5, 0.03, 0.04, {0.02 + 0.005 * i:.3f}, 0], 'midi': {events}}}")
    with tempfile.TemporaryDirectory(prefix="pianobot-kernels-") as scratch:
        log = Path(scratch) / "log.txt"
        log.write_text("\n".join(lines) + "\n")
        import_keystroke_log(log, Path(scratch) / "data")
    return 1


def main() -> None:
    start = time.perf_counter()
    calls = compile_physics() + compile_readout() + compile_import()
    print(f"pianobot: numba kernels compiled and cached ({calls} calls, {time.perf_counter() - start:.0f} s)",
          file=sys.stderr)


if __name__ == "__main__":
    main()
