"""The arm log a UR lab records beside a take: ur_rtde's file recording of the controller's state.

`RTDEReceiveInterface.startFileRecording(path, ["timestamp", "actual_TCP_pose",
"target_TCP_pose"])` writes one comma-separated header line (vectors spread over `<name>_0` …
`<name>_5`) and one row per controller cycle, every number with six decimals. A CB3 UR5 runs at
125 Hz. `timestamp` is the controller's clock (seconds since it booted), so the log's first row
has an arbitrary time; this lab starts it on the take's first frame (the script starts both
recordings together). Poses are in the robot base frame (metres, z up): the tool point sits
above the key and moves down by the arm's travel; the target pose is the commanded profile.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
RATE_HZ = 125.0
TCP_REST_M = (0.4123, -0.1871, 0.2530)  # x, y, z of the tool point at rest (base frame)
TCP_ROTVEC = (2.2214, -2.2214, 0.0)  # tool pointing down
POSE_NOISE_M = 1e-6  # joint encoders: the pose is repeatable to about a micrometre


def write_arm_log(path: Path, t_s: FloatArray, x_arm_m: FloatArray, x_cmd_m: FloatArray,
                  rng: np.random.Generator, boot_s: float) -> None:
    """Write the log: `x_arm_m`/`x_cmd_m` are the actual/commanded downward travel at `t_s`."""
    names = ["timestamp"] + [f"{v}_{i}" for v in ("actual_TCP_pose", "target_TCP_pose") for i in range(6)]
    n = t_s.size
    columns = [boot_s + t_s]
    for travel, noisy in ((x_arm_m, True), (x_cmd_m, False)):
        jitter = rng.normal(0.0, POSE_NOISE_M, (n, 3)) if noisy else np.zeros((n, 3))
        columns += [TCP_REST_M[0] + jitter[:, 0], TCP_REST_M[1] + jitter[:, 1], TCP_REST_M[2] - travel + jitter[:, 2]]
        columns += [np.full(n, r) for r in TCP_ROTVEC]
    table = np.column_stack(columns)
    with path.open("w", encoding="utf-8", newline="") as handle:
        handle.write(",".join(names) + "\n")
        np.savetxt(handle, table, fmt="%.6f", delimiter=",")
