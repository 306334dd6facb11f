"""UR5 arm trace against the emulated controller: `python benchmarks/bench_ur5_trace.py`.

The real ur_rtde client records the same presses on an emulated e-Series (500 Hz) and CB3
(125 Hz) controller (tests/hardware_emulator, its own process), twice per controller in the same
run: with pianobot's sampling (timestamp, pose, timestamp: the pose kept only when both
timestamps agree) and with the sampling it replaced (timestamp, then pose), the baseline.
Every sample is compared with the emulator's ground truth for its controller cycle. Reported
per controller and sampling: samples, cycles captured (%), samples whose pose belongs to
another cycle than their timestamp, and the test process's CPU per press — as ratios of
pianobot's sampling to the baseline. JSON on stdout and in benchmarks/results/ur5_trace.json.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from hardware_emulator import CB3, ESERIES, ControllerConfig, EmulatedUR  # noqa: E402

import pianobot.rig.ur5 as ur5  # noqa: E402
from pianobot.physics.trajectory import Press  # noqa: E402
from pianobot.rig.clock import WallClock  # noqa: E402
from pianobot.rig.ur5_trace import TcpRecorder  # noqa: E402
from pianobot.spec.rig import UR5Config  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "ur5_trace.json"
HOVER = (-0.5, -0.1, 0.17, 0.0, math.pi, 0.0)
PRESS = Press(distance_m=0.005, depth_m=0.015, down_velocity_mps=0.04, up_velocity_mps=0.1,
              acceleration_mps2=1.0, hold_s=0.05)


class Baseline(TcpRecorder):
    """The sampling before issue 14: the pose read after the timestamp, nothing re-checked."""

    def sample(self) -> None:
        ts = float(self._receive.getTimestamp())
        if ts == self._last_ts:
            return
        read_s = self._clock.now()
        pose = self._receive.getActualTCPPose()
        self._last_ts = ts
        self.ctrl_s.append(ts)
        self.read_s.append(read_s)
        self.z_m.append(float(pose[2]))


def measure(generation: str, recorder: type[TcpRecorder], presses: int) -> dict[str, Any]:
    kept: list[TcpRecorder] = []

    class Keeping(recorder):  # type: ignore[valid-type, misc]
        def __init__(self, *args: Any) -> None:
            super().__init__(*args)
            kept.append(self)

    ur5.TcpRecorder = Keeping  # type: ignore[misc]
    config = UR5Config.model_validate({
        "host": "pending", "workspace_min_m": [-0.75, -0.35, 0.05], "workspace_max_m": [-0.3, 0.1, 0.3],
        "reference_pose": [-0.5, -0.1, 0.15, 0.0, math.pi, 0.0], "calibrated_utc": "bench",
        "safe_lift_m": 0.01,
    })
    with EmulatedUR(ControllerConfig(generation=generation, start_pose=HOVER)) as ur:
        arm = ur5.UR5Arm.connect_to(config.model_copy(update={"host": ur.host}), clock=WallClock())
        try:
            arm.move_to_key(59, PRESS.distance_m)
            cpu0 = time.process_time()
            for _ in range(presses):
                arm.press(PRESS, 59)
            cpu_s = time.process_time() - cpu0
            truth = {round(t, 6): pose[2] for t, pose in ur.truth_between(0.0, 1e12)}
        finally:
            arm.close()
    samples = torn = cycles = 0
    for rec in kept:
        samples += len(rec.ctrl_s)
        torn += sum(truth[round(t, 6)] != z for t, z in zip(rec.ctrl_s, rec.z_m, strict=True))
        cycles += round((rec.ctrl_s[-1] - rec.ctrl_s[0]) * arm.rate_hz) + 1
    return {"samples": samples, "captured_pct": round(100.0 * samples / cycles, 2),
            "pose_from_another_cycle": torn, "cpu_ms_per_press": round(1000 * cpu_s / presses, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presses", type=int, default=20)
    args = parser.parse_args()
    out: dict[str, Any] = {"presses": args.presses, "python": platform.python_version(),
                           "machine": platform.machine(), "controllers": {}}
    for generation in (ESERIES, CB3):
        new = measure(generation, TcpRecorder, args.presses)
        old = measure(generation, Baseline, args.presses)
        out["controllers"][generation] = {
            "pianobot": new, "baseline": old,
            "captured_ratio": round(new["captured_pct"] / old["captured_pct"], 3),
            "cpu_ratio": round(new["cpu_ms_per_press"] / max(old["cpu_ms_per_press"], 1e-9), 3),
        }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
