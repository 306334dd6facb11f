"""Synthetic Motive CSV takes for the mocap tests (imported by file name: tests/io is no package)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

RATE_HZ = 120.0


def arm_press_track(
    t: np.ndarray,
    starts_s: list[float],
    speeds_mps: list[float],
    travel_m: float,
    hold_s: float = 0.3,
) -> np.ndarray:
    """Downward arm displacement: constant-speed down/up ramps of `travel_m` at each speed."""
    x = np.zeros_like(t)
    for start, speed in zip(starts_s, speeds_mps, strict=True):
        ramp = travel_m / speed
        down = np.clip((t - start) / ramp, 0, 1)
        up = np.clip((t - start - ramp - hold_s) / ramp, 0, 1)
        x += travel_m * (down - up)
    return x


def motive_csv(
    path: Path,
    *,
    duration_s: float,
    starts_s: list[float],
    speeds_mps: list[float],
    travel_m: float = 0.0072,
    units: str = "Meters",
    first_cells: bool = False,
    seed: int = 0,
    split: dict[str, tuple[float, ...]] | None = None,
    markers: tuple[str, ...] = ("Unlabeled:100", "Unlabeled:101", "Unlabeled:102", "Unlabeled:103"),
    up: str = "y",
    sideways_m: float = 0.0,
) -> Path:
    """A Motive 1.2x export: arm, finger middle, fingertip, key markers (Y up) plus two ghosts.

    `up="z"`: exported Z-up, as Motive's export option writes it (X, −Z, Y of the Y-up take).
    `sideways_m`: halfway through, the arm (and the finger) moves this far along Z, to another key.

    `split`: marker -> fractions of the take where Motive lost it for a few frames and gave it a
    new ID (e.g. (0.4, 0.7): pieces of 40, 30 and 30 % of the frames, the later ones named
    `Unlabeled:5xx`). `markers`: which of the four markers are in view.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0, duration_s, 1 / RATE_HZ)
    arm = arm_press_track(t, starts_s, speeds_mps, travel_m)
    key = np.minimum(arm * 0.5, 0.004)
    tip = arm * 0.75
    heights = {
        "Unlabeled:100": 0.23,
        "Unlabeled:101": 0.016,
        "Unlabeled:102": -0.011,
        "Unlabeled:103": 0.008,
    }
    down = {
        "Unlabeled:100": arm,
        "Unlabeled:101": 0.9 * arm,
        "Unlabeled:102": tip,
        "Unlabeled:103": key,
    }
    scale = {"Meters": 1.0, "Millimeters": 1000.0}[units]
    names = [n for n in heights if n in markers] + ["Unlabeled:900", "Unlabeled:901"]
    columns = []
    for name in names:
        if name in heights:
            y = heights[name] - down[name] + rng.normal(0, 3e-6, t.size)
            x = np.full(t.size, 0.1) + rng.normal(0, 3e-6, t.size)
            z = np.full(t.size, 0.2) + (sideways_m * (t > duration_s / 2) if name != "Unlabeled:103" else 0.0)
            present = np.ones(t.size, bool)
            present[int(t.size * 0.4) : int(t.size * 0.4) + 3] = False  # dropped for all markers
        else:
            x, y, z = (rng.normal(0, 0.1, t.size) for _ in range(3))
            present = np.zeros(t.size, bool)
            begin = rng.integers(0, t.size - 30)
            present[begin : begin + 20] = True  # a short ghost track
        if up == "z":
            y, z = -z, y
        cuts = (split or {}).get(name, ())
        if not cuts:
            columns.append((name, x * scale, y * scale, z * scale, present))
            continue
        edges = [0, *(int(c * t.size) for c in cuts), t.size]
        for piece, (begin, end) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
            mask = present.copy()
            mask[:begin] = False
            mask[end:] = False
            if piece + 1 < len(edges) - 1:
                mask[end - int(rng.integers(2, 12)) : end] = False  # occluded for a few frames
            label = name if piece == 0 else f"Unlabeled:{500 + 10 * int(name[-1]) + piece}"
            columns.append((label, x * scale, y * scale, z * scale, mask))
    names = [c[0] for c in columns]
    meta = (
        "Format Version,1.21,Take Name,synthetic,Capture Frame Rate,120.000000,Export Frame Rate,"
        f"120.000000,Rotation Type,Quaternion,Length Units,{units},Coordinate Space,Global"
    )
    lead = ["Type", "Name", "ID", ""] if first_cells else ["", "", "", ""]
    rows = [meta, ""]
    rows.append(f"{lead[0]}," + "," + ",".join("Marker" for _ in names for _ in range(3)))
    rows.append(f"{lead[1]}," + "," + ",".join(n for n in names for _ in range(3)))
    rows.append(
        f"{lead[2]}," + "," + ",".join(f'"ID{i}"' for i, _ in enumerate(names) for _ in range(3))
    )
    rows.append("," + "," + ",".join("Position" for _ in names for _ in range(3)))
    rows.append("Frame,Time," + ",".join("X,Y,Z" for _ in names))
    for i, ti in enumerate(t):
        cells = [str(i), f"{ti:.6f}"]
        for _, x, y, z, present in columns:
            cells += [f"{x[i]:.6f}", f"{y[i]:.6f}", f"{z[i]:.6f}"] if present[i] else ["", "", ""]
        rows.append(",".join(cells))
    path.write_text("\r\n".join(rows) + "\r\n")
    return path


def six_press_take(folder: Path) -> Path:
    """Six presses at 10..60 mm/s, 7.2 mm of arm travel, starting every 3 s from t = 1 s."""
    speeds = [0.01, 0.02, 0.03, 0.04, 0.05, 0.06]
    starts = [1.0 + 3.0 * i for i in range(6)]
    return motive_csv(folder / "take.csv", duration_s=20.0, starts_s=starts, speeds_mps=speeds)


def as_z_up(source: Path, target: Path) -> Path:
    """A Y-up Motive export written again as Motive's Z-up option writes it (X, −Z, Y)."""
    lines = source.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("Frame,"))
    out = lines[: header + 1]
    for line in lines[header + 1 :]:
        cells = line.split(",")
        for c in range(2, len(cells) - 2, 3):
            if cells[c + 1] and cells[c + 2]:
                cells[c + 1], cells[c + 2] = f"{-float(cells[c + 2]):.6f}", cells[c + 1]
        out.append(",".join(cells))
    target.write_text("\n".join(out) + "\n")
    return target
