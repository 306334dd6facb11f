"""Mocap takes written as OptiTrack Motive CSV exports (format 1.21, 120 Hz unless the scenario says otherwise, metres, Y up).

What the cameras see: four persistent markers (UR end effector, middle of the finger,
fingertip, key surface) with micrometre noise, a slow common-mode drift of the whole capture
volume (the study's zzz40 take drifts by about half a millimetre), a few frames dropped for every
marker at once, a rare short occlusion of one marker, and ghost tracks (reflections that live for
a few frames to a few seconds). Marker names are Motive's `Unlabeled:<id>`; the roles are
recorded in truth.json (pianobot infers them from geometry: the end effector is highest, the key
moves least, the fingertip is the lowest of the rest).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
RATE_HZ = 120.0
ROLES = ("arm", "finger_middle", "fingertip", "key")
# Rest positions (X, Y, Z in metres, Y up) of the markers, as on the study's rig.
REST_XYZ_M = {
    "arm": (-0.2801, 0.2295, 0.3824),
    "finger_middle": (-0.2787, 0.0164, 0.2531),
    "fingertip": (-0.2666, -0.0118, 0.2180),
    "key": (-0.2643, 0.0079, 0.1632),
}
MIDDLE_FRACTION = 0.55  # the middle marker moves like x0 + 0.55·(x1 − x0)


@dataclass(frozen=True)
class MocapObservation:
    """How the capture degrades the truth (all lengths in metres)."""

    noise_m: float = 3e-6
    drift_peak_m: float = 1e-4
    dropouts: int = 2  # runs of 2–4 frames with every marker missing
    occlusions: int = 1  # runs of 2–6 frames with the fingertip or middle marker missing
    ghosts: int = 24

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class Take:
    """Marker tracks (frames × 3, NaN where missing) with names and roles."""

    name: str
    t_s: FloatArray
    tracks: dict[str, FloatArray]  # marker name → positions
    roles: dict[str, str]  # role → marker name
    start_text: str
    rate_hz: float = RATE_HZ


def build_take(
    name: str,
    x0_m: FloatArray,
    x1_m: FloatArray,
    x2_m: FloatArray,
    obs: MocapObservation,
    rng: np.random.Generator,
    rate_hz: float = RATE_HZ,
) -> Take:
    """Marker tracks from the true downward displacements at the frame times k/rate_hz s."""
    n = x0_m.size
    t = np.arange(n) / rate_hz
    base_id = int(rng.integers(100, 600))
    drift = _drift(t, obs.drift_peak_m, rng)
    down = {
        "arm": x0_m,
        "finger_middle": x0_m + MIDDLE_FRACTION * (x1_m - x0_m),
        "fingertip": x1_m,
        "key": x2_m,
    }
    tracks: dict[str, FloatArray] = {}
    roles: dict[str, str] = {}
    for i, role in enumerate(ROLES):
        rest = np.asarray(REST_XYZ_M[role]) + rng.uniform(-0.003, 0.003, 3)
        xyz = np.tile(rest, (n, 1))
        xyz[:, 1] += drift - down[role]
        xyz += rng.normal(0.0, obs.noise_m, (n, 3))
        label = f"Unlabeled:{base_id + i}"
        tracks[label] = xyz
        roles[role] = label
    _drop(tracks, roles, n, obs, rng, rate_hz)
    ghost_id = base_id + 250
    for _ in range(obs.ghosts):
        ghost_id += int(rng.integers(1, 9))
        tracks[f"Unlabeled:{ghost_id}"] = _ghost(n, rng)
    day = int(rng.integers(1, 28))
    start = f"2022-03-{day:02d} {int(rng.integers(1, 12)):02d}.{int(rng.integers(0, 60)):02d}." \
            f"{int(rng.integers(0, 60)):02d}.{int(rng.integers(0, 1000)):03d} PM"  # fmt: skip
    return Take(name, t, tracks, roles, start, rate_hz)


def _drift(t: FloatArray, peak_m: float, rng: np.random.Generator) -> FloatArray:
    """Slow common-mode drift: a few long sinusoids and a trend, scaled to `peak_m`."""
    if peak_m <= 0 or t.size < 2:
        return np.zeros_like(t)
    span = max(float(t[-1]), 1.0)
    d = rng.uniform(-1.0, 1.0) * t / span
    for _ in range(3):
        period = rng.uniform(0.5, 3.0) * span
        d = d + rng.uniform(0.2, 1.0) * np.sin(
            2 * math.pi * t / period + rng.uniform(0, 2 * math.pi)
        )
    d = d - d[0]
    return peak_m * d / max(float(np.max(np.abs(d))), 1e-12)


def _drop(
    tracks: dict[str, FloatArray],
    roles: dict[str, str],
    n: int,
    obs: MocapObservation,
    rng: np.random.Generator,
    rate_hz: float = RATE_HZ,
) -> None:
    lead = int(rate_hz)  # nothing is lost in the first second (the rest level is taken there)
    for _ in range(obs.dropouts):
        i0 = int(rng.integers(lead, max(lead + 1, n - 5)))
        for xyz in tracks.values():
            xyz[i0 : i0 + int(rng.integers(2, 5))] = np.nan
    for _ in range(obs.occlusions):
        i0 = int(rng.integers(lead, max(lead + 1, n - 7)))
        role = "fingertip" if rng.random() < 0.5 else "finger_middle"
        tracks[roles[role]][i0 : i0 + int(rng.integers(2, 7))] = np.nan


def _ghost(n: int, rng: np.random.Generator) -> FloatArray:
    """A reflection: a short, jittery track somewhere near the rig."""
    xyz = np.full((n, 3), np.nan)
    length = int(min(n - 1, rng.choice([1, 3, 8, 30, 120, 400])) * rng.uniform(0.5, 1.0)) + 1
    i0 = int(rng.integers(0, max(1, n - length)))
    where = np.asarray([-0.27, 0.05, 0.25]) + rng.uniform(-0.15, 0.15, 3)
    walk = np.cumsum(rng.normal(0.0, 2e-4, (length, 3)), axis=0)
    xyz[i0 : i0 + length] = where + walk
    return xyz


def write_take(path: Path, take: Take) -> None:
    """Write the take as a Motive 1.21 CSV export."""
    names = list(take.tracks)
    n = take.t_s.size
    meta = [
        "Format Version", "1.21", "Take Name", take.name,
        "Capture Frame Rate", f"{take.rate_hz:.6f}", "Export Frame Rate", f"{take.rate_hz:.6f}",
        "Capture Start Time", take.start_text, "Total Frames in Take", str(n),
        "Total Exported Frames", str(n), "Rotation Type", "Quaternion",
        "Length Units", "Meters", "Coordinate Space", "Global",
    ]  # fmt: skip
    prefix = "8392B20CF49E357"
    lines = [",".join(meta), ""]
    lines.append(",," + ",".join("Marker" for _ in names for _ in range(3)))
    lines.append(",," + ",".join(name for name in names for _ in range(3)))
    lines.append(",," + ",".join(f'"{prefix}{int(name.split(":")[1]):X}"' for name in names
                                 for _ in range(3)))  # fmt: skip
    lines.append(",," + ",".join("Position" for _ in names for _ in range(3)))
    lines.append("Frame,Time," + ",".join("X,Y,Z" for _ in names))
    columns = []
    for name in names:
        xyz = take.tracks[name]
        for axis in range(3):
            values = xyz[:, axis]
            cells = np.full(n, "", dtype=object)
            good = np.isfinite(values)
            cells[good] = [f"{v:.6f}" for v in values[good].tolist()]
            columns.append(cells)
    frames = [f"{k},{t:.6f}" for k, t in enumerate(take.t_s.tolist())]
    rows = np.stack([np.asarray(frames, dtype=object), *columns], axis=1)
    lines.extend(",".join(row) for row in rows.tolist())
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
