"""What the integrator's wider blocks cost on this machine, measured once per kernel.

The integrator advances keystrokes side by side in SIMD blocks (`_kernel.BLOCKS`: 4, 8 or 16
lanes; a call runs the smallest block that holds its keystrokes). What a wider block costs per
step against the narrowest depends on the CPU. With 256-bit vectors 16 lanes fill four
registers, about four times the work of 4 lanes. With AVX-512 they fill two, and one keystroke's
step is a chain of dependent operations whose latency the extra lanes hide: measured on this
project's machines, 8 lanes cost 1.1x and 16 lanes 1.8x the 4-lane step, where a constant written
on another CPU had said 4x.

A caller that groups keystrokes of different length (`analysis.greybox.prediction.length_groups`)
needs these ratios to choose its groups. They change only which keystrokes run side by side,
never a number: a keystroke's samples do not depend on its companions nor on its block.
"""

from __future__ import annotations

import math
import time

import numpy as np

from pianobot.physics import _kernel as K
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import effect_vector, kernel_family, simulate_arm, simulate_presses
from pianobot.physics.trajectory import Press

#: The timed run: long enough that a call's fixed cost (~50 µs) is small beside its steps, short
#: enough that measuring the three blocks, best of `REPEATS`, costs 10-50 ms per kernel.
DURATION_S = 2.0
STEP_S = 2e-4
REPEATS = 5
_PRESS = Press(distance_m=0.01, depth_m=0.008, down_velocity_mps=0.02, up_velocity_mps=0.02,
               acceleration_mps2=1.0, hold_s=0.3)

_measured: dict[tuple[int, bool], dict[int, float]] = {}


def block_costs(model: KeystrokeModel, *, trace: bool, implicit: bool = False) -> dict[int, float]:
    """The step cost of each block size (`_kernel.BLOCKS`) over the smallest's, for the kernel
    that runs `model` driven by measured arm traces (`trace`) or by commanded presses, with
    explicit or implicit dampers. Measured on the first call for that kernel, then kept; never
    below the smaller block's cost nor above proportional to the lanes."""
    ep = effect_vector(model.effects)
    ep[K.E_IMPLICIT] = 1.0 if implicit else 0.0
    key = (id(kernel_family(ep)), trace)
    if key not in _measured:
        _measured[key] = _measure(model, trace, implicit)
    return dict(_measured[key])


def _measure(model: KeystrokeModel, trace: bool, implicit: bool) -> dict[int, float]:
    """Each block's best time over the 4-lane block's, on one press of the finger into the key,
    made non-decreasing with the lanes and capped at proportional."""
    t = np.arange(0.0, DURATION_S, 1e-3)
    arm = np.clip(0.02 * (t - 0.1), 0.0, 0.018) - np.clip(0.02 * (t - 1.2), 0.0, 0.018)

    def run(lanes: int) -> None:
        with np.errstate(all="ignore"):
            if trace:
                simulate_arm(t, np.tile(arm, (lanes, 1)), -40.0, model, distance_m=0.01, step_s=STEP_S,
                             implicit_damping=implicit)
            else:
                simulate_presses([_PRESS] * lanes, -40.0, model, duration_s=DURATION_S, step_s=STEP_S)

    best = dict.fromkeys(K.BLOCKS, math.inf)
    for block in K.BLOCKS:
        run(block)  # loads the kernel (compiled at install) before it is timed
    for _ in range(REPEATS):
        for block in K.BLOCKS:
            start = time.perf_counter()
            run(block)
            best[block] = min(best[block], time.perf_counter() - start)
    costs, last = {}, 1.0
    for block in K.BLOCKS:
        last = min(max(best[block] / best[K.SMALL_BLOCK], last), block / K.SMALL_BLOCK)
        costs[block] = last
    return costs
