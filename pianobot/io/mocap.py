"""Reader of OptiTrack Motive CSV exports (format 1.2x) and marker-role assignment.

Layout of an export: line 1 is key/value metadata (`Format Version,1.21,Take Name,...`), then
rows labelled by asset type (`Marker`, `Rigid Body`, ...), name, ID and property (`Position`,
`Rotation`), then the `Frame,Time,X,Y,Z,...` header and the data. Rows are found by their labels,
never by fixed offsets (Motive 1.23 adds `Type`/`Name`/`ID` in the first cell, older exports
leave it empty). Empty cells are occlusions (NaN). Positions are converted to metres from the
`Length Units` field. Only positions are read; rotations are not needed for vertical travel.

Vertical axis: Motive is Y-up by default, so the downward displacement of a marker is
−(Y − Y_rest). `up_axis` names another axis; by default (`auto`) it is Y unless the markers
clearly move along another one, as in an export made Z-up: then that axis (`detect_up_axis`).

Motive gives a marker a new ID after an occlusion; the pieces of such a split track are joined
first (`mocap_tracks`), so a marker seen in three pieces of 40/30/30 % of the frames is one
persistent marker, not three ghosts. Markers present on fewer than `min_coverage` of the frames
after joining are ghosts and dropped.

Marker roles (arm, fingertip, key) come from a mapping (a rig file's `mocap.markers`, `--marker`)
or are inferred from the persistent markers only where the evidence is clear (`mocap_roles`):
the arm is the highest marker, the key the least moving of the rest (or, where that is unclear,
the one marker that barely moves but does so with the arm: a key a preload holds up), the
fingertip the lowest remaining one; when two markers fit a role about equally, the import stops
and names them.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.mocap_roles import STATIC_MOTION_M, assign_roles
from pianobot.io.mocap_tracks import Join, Stitched, Track, stitch
from pianobot.io.source import read_input_bytes

FloatArray = npt.NDArray[np.float64]
_UNITS_M = {
    "meters": 1.0,
    "metres": 1.0,
    "millimeters": 1e-3,
    "millimetres": 1e-3,
    "centimeters": 1e-2,
}
_TYPES = {"Marker", "Rigid Body", "Rigid Body Marker", "Bone", "Bone Marker"}
_POSITION_TYPES = {"Marker", "Rigid Body", "Rigid Body Marker"}
#: Cells that say "no value" in words: gaps, not unreadable numbers.
_GAP_WORDS = frozenset({"", "nan", "na", "n/a", "none", "null"})
#: A header frame rate this far from the Time column's own steps is not the take's rate.
RATE_TOLERANCE = 0.02
_AXES = {"x": 0, "y": 1, "z": 2}
AUTO_AXIS = "auto"
#: y stays the vertical axis when a marker moves this far along it (`detect_up_axis`): an arm
#: that presses keys moves millimetres along the vertical (the study's takes: 7 mm and more).
SURE_VERTICAL_M = 0.003
#: Otherwise another axis is vertical when the markers move this many times farther along it.
UP_AXIS_RATIO = 3.0


@dataclass(frozen=True)
class MocapTake:
    """One take: metadata, frame rate, marker positions (metres) and their roles.

    `markers` is long: t_s, frame, marker, x, y, z (positions in metres, NaN when occluded), only
    for markers kept by coverage. `coverage` holds every marker's fraction of frames present.
    `keystrokes` is filled by `mocap_segment.segment_take`.
    """

    path: Path
    meta: dict[str, str]
    frame_rate_hz: float
    t_s: FloatArray
    markers: pd.DataFrame
    coverage: dict[str, float]
    roles: dict[str, str]
    up_axis: str = "y"
    keystrokes: pd.DataFrame = field(default_factory=pd.DataFrame)
    pieces: dict[str, list[str]] = field(default_factory=dict)  # marker -> the track pieces joined into it
    joins: tuple[Join, ...] = ()
    stitch_doubts: tuple[str, ...] = ()  # pieces left unjoined because two tracks fit them equally
    repeated_frames: int = 0  # rows that repeated the previous one's frame number and time, read once
    notes: tuple[str, ...] = ()  # what the reader decided that a user should hear (an import warns)

    @property
    def stitched(self) -> dict[str, list[str]]:
        """Persistent markers whose track came in several pieces, with the pieces' names."""
        kept = set(self.markers["marker"].unique()) if not self.markers.empty else set()
        return {name: pieces for name, pieces in self.pieces.items() if len(pieces) > 1 and name in kept}

    def positions(self) -> list[FloatArray]:
        """Each kept marker's positions (frames x 3, metres) on the frames it was seen."""
        return [group[["x", "y", "z"]].to_numpy(dtype=np.float64) for _, group in self.markers.groupby("marker")]

    def up_m(self, marker: str) -> FloatArray:
        """The marker's coordinate along the up axis on every frame (NaN when missing)."""
        rows = self.markers[self.markers["marker"] == marker]
        out = np.full(self.t_s.size, np.nan)
        out[rows["frame_index"].to_numpy()] = rows[self.up_axis].to_numpy(dtype=np.float64)
        return out

    def down_m(self, role: str) -> FloatArray | None:
        """Downward displacement of a role's marker relative to its median height (None if absent)."""
        name = self.roles.get(role)
        if name is None:
            return None
        up = self.up_m(name)
        return -(up - np.nanmedian(up))


def read_mocap(
    path: Path | str,
    markers: dict[str, str] | None = None,
    min_coverage: float = 0.5,
    up_axis: str = AUTO_AXIS,
) -> MocapTake:
    """Read a Motive CSV export and assign marker roles.

    Args:
        path: the CSV file.
        markers: role → marker name (`arm`, `fingertip`, `key`); missing roles are inferred.
        min_coverage: markers present on fewer frames than this fraction are ghosts and dropped.
        up_axis: "x", "y" or "z", or "auto" (`detect_up_axis`: Motive's default y unless the
            markers move along another axis only).

    Raises:
        InputError: not a Motive CSV export, no position column, an unknown marker or role.
    """
    path = Path(path)
    where = str(path)
    if up_axis not in (*_AXES, AUTO_AXIS):
        raise InputError(f"up axis should be one of x, y, z or auto, got {up_axis!r}", "--up-axis")
    if not 0.0 <= min_coverage <= 1.0:  # also refuses NaN
        raise InputError(f"must be a fraction of frames in [0, 1], got {min_coverage}", "--min-coverage")
    try:
        return _read_mocap(path, markers, min_coverage, up_axis)
    except csv.Error as exc:  # a 50 MB line, a stray quote: not a Motive export
        raise InputError(f"not a readable CSV ({exc})", where) from None


def _read_mocap(
    path: Path, markers: dict[str, str] | None, min_coverage: float, up_axis: str
) -> MocapTake:
    where = str(path)
    text, resaved = _with_motive_commas(_read_text(path))
    lines = text.splitlines()
    meta = _metadata(lines[0] if lines else "", where)
    header_at = next((i for i, line in enumerate(lines[:100]) if line.startswith("Frame,")), None)
    if header_at is None:
        raise InputError("no 'Frame,Time,...' header row within the first 100 lines", where)
    label_rows = [next(csv.reader([line])) for line in lines[1:header_at] if line.strip()]
    columns = _position_columns(label_rows, next(csv.reader([lines[header_at]])), where)
    frame_rate = _frame_rate(meta, where)
    scale = _UNITS_M.get(meta.get("Length Units", "Meters").strip().lower())
    if scale is None:
        raise InputError(f"unknown length units {meta.get('Length Units')!r}", where)
    data, unreadable = _data(lines[header_at + 1 :], len(next(csv.reader([lines[header_at]]))), where)
    if data.shape[0] == 0:
        raise InputError("no data rows after the header", where)
    notes = [note for note in (resaved, unreadable) if note]
    stated = meta.get("Total Exported Frames", "").strip()
    if stated.isdigit() and int(stated) != data.shape[0]:
        notes.append(f"the take has {data.shape[0]} frames where its header states {int(stated)}: "
                     f"{'cut short (was the export interrupted?)' if int(stated) > data.shape[0] else 'more than exported'}")
    data, repeated = _without_repeated_frames(data)
    t = data[:, 1] if data.shape[1] > 1 else np.arange(data.shape[0]) / frame_rate
    _refuse_time_going_back(t, where)
    t = _filled_times(t, frame_rate)
    steps = np.diff(t)
    # (to 0.01 Hz: the Time column holds microseconds, so 120 Hz steps read as 120.005 Hz)
    measured = round(1.0 / float(np.median(steps)), 2) if steps.size and np.median(steps) > 0 else frame_rate
    if abs(measured / frame_rate - 1.0) > RATE_TOLERANCE:
        # Speeds and windows follow the frames' own times: the rate must be the one they show.
        notes.append(f"the header states {frame_rate:g} Hz but the Time column steps at {measured:.4g} Hz: read at "
                     f"{measured:.4g} Hz")
        frame_rate = measured
    stitched = stitch(_tracks(data, columns, scale), t)
    coverage = {track.name: track.frames.size / data.shape[0] for track in stitched.chains}
    kept = [track for track in stitched.chains if coverage[track.name] >= min_coverage]
    if not kept:
        best = max(coverage.values(), default=0.0)
        raise InputError(
            f"no marker is present on at least {min_coverage:.0%} of frames, even with split tracks "
            f"joined (best {best:.0%})",
            where,
        )
    long = pd.concat(
        [pd.DataFrame({"t_s": t[tr.frames], "frame_index": tr.frames, "marker": tr.name,
                       "x": tr.xyz[:, 0], "y": tr.xyz[:, 1], "z": tr.xyz[:, 2]}) for tr in kept],
        ignore_index=True,
    )  # fmt: skip
    if up_axis == AUTO_AXIS:
        up_axis = detect_up_axis(kept)
    take = MocapTake(path, meta, frame_rate, t, long, coverage, {}, up_axis, pieces=stitched.pieces,
                     joins=tuple(stitched.joins), stitch_doubts=_doubts(stitched, kept),
                     repeated_frames=repeated, notes=tuple(notes))  # fmt: skip
    try:
        roles = assign_roles([tr.name for tr in kept], take.up_m, markers or {}, stitched.chain_of, where)
    except InputError as exc:
        raise InputError(exc.message + axis_hint([tr.xyz for tr in kept], up_axis), exc.where) from None
    return dataclasses.replace(take, roles=roles)


def detect_up_axis(tracks: list[Track]) -> str:
    """The vertical axis of a take: y (Motive's default) unless the markers clearly move along
    another one (an export made Z-up); then that axis.

    The markers' motion along an axis is the sum over them of its 1st to 99th percentile. Another
    axis is taken only when no marker moves `SURE_VERTICAL_M` along y, and the markers move
    `UP_AXIS_RATIO` times farther along it: the study's zzz40 exported Z-up moves 24 mm along z
    (presses) against 3.9 mm along y (the markers' sideways wobble, 1.8 mm at most), while a Y-up
    take whose arm also moves from key to key keeps y, however far it moves sideways.
    """
    motion, along_y = axis_motion([track.xyz for track in tracks])
    best = max(motion, key=lambda axis: motion[axis])
    if (best != "y" and along_y < SURE_VERTICAL_M and motion[best] >= UP_AXIS_RATIO * motion["y"]
            and motion[best] >= STATIC_MOTION_M):
        return best
    return "y"


def axis_motion(positions: list[FloatArray]) -> tuple[dict[str, float], float]:
    """How far markers (frames x 3 positions each) move along each axis, summed over them, and
    the farthest one marker moves along y."""
    motion = dict.fromkeys(_AXES, 0.0)
    along_y = 0.0
    for xyz in positions:
        for axis, i in _AXES.items():
            moved = _motion(xyz[:, i])
            motion[axis] += moved
            if axis == "y":
                along_y = max(along_y, moved)
    return motion, along_y


def axis_hint(positions: list[FloatArray], up_axis: str) -> str:
    """A hint for an error when the markers (frames x 3 positions each) move farther along
    another axis than along the one read as vertical ("" when they do not)."""
    motion, _ = axis_motion(positions)
    best = max(motion, key=lambda axis: motion[axis])
    if best == up_axis or motion[best] < 2.0 * motion[up_axis]:
        return ""
    return (f" (the markers move {1e3 * motion[up_axis]:.1f} mm along {up_axis.upper()} and {1e3 * motion[best]:.1f} mm "
            f"along {best.upper()}: if {best.upper()} is vertical in this export, give --up-axis {best})")


def _motion(values: FloatArray) -> float:
    """How far a coordinate moves: its 1st to 99th percentile (0 when it has no samples)."""
    if values.size == 0:
        return 0.0
    low, high = np.percentile(values, [1, 99])
    return float(high - low)


def _doubts(stitched: Stitched, kept: list[Track]) -> tuple[str, ...]:
    """Pieces left unjoined because two persistent markers continue them about equally well."""
    names = {track.name for track in kept}
    return tuple(f"{piece} continues {a} and {b} about equally well; left unjoined"
                 for piece, a, b in stitched.ambiguous if a in names or b in names)  # fmt: skip


def _tracks(data: npt.NDArray[np.float64], columns: dict[str, dict[str, int]], scale: float) -> list[Track]:
    """Every named marker's positions on the frames where all its axes are present."""
    tracks = []
    for name, axes in columns.items():
        xyz = np.full((data.shape[0], 3), np.nan)
        for axis, col in axes.items():
            if col < data.shape[1]:
                xyz[:, _AXES[axis]] = data[:, col] * scale
        present = np.flatnonzero(np.isfinite(xyz).all(axis=1))
        tracks.append(Track(name, present.astype(np.int64), xyz[present]))
    return tracks


def _filled_times(t: FloatArray, frame_rate_hz: float) -> FloatArray:
    """Frame times with the missing ones filled: between two known times by the frame count,
    before the first and after the last at the frame rate (a take exported from a working range
    starts at its range's time, not at 0)."""
    known = np.flatnonzero(np.isfinite(t))
    if known.size == t.size:
        return t
    frames = np.arange(t.size, dtype=np.float64)
    if known.size == 0:
        return frames / frame_rate_hz
    filled = np.interp(frames, known, t[known])
    first, last = known[0], known[-1]
    filled[:first] = t[first] - (first - frames[:first]) / frame_rate_hz
    filled[last + 1 :] = t[last] + (frames[last + 1 :] - last) / frame_rate_hz
    return filled


def _without_repeated_frames(data: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], int]:
    """Rows that repeat the previous row's frame number and time (a glitch of the export), read
    once: a time step of zero divided speeds into infinities and NaN."""
    if data.shape[0] < 2 or data.shape[1] < 2:
        return data, 0
    repeat = np.concatenate([[False], (np.diff(data[:, 0]) == 0) & (np.diff(data[:, 1]) == 0)])
    return data[~repeat], int(repeat.sum())


def _refuse_time_going_back(t: FloatArray, where: str) -> None:
    """Frames out of time order (a spliced or reversed export) would segment into nonsense."""
    rows = np.flatnonzero(np.isfinite(t))
    back = np.flatnonzero(np.diff(t[rows]) < 0)
    if back.size:
        before, after = rows[back[0]], rows[back[0] + 1]
        raise InputError(f"time runs backwards at data row {after + 1} ({t[before]:.6g} s, then "
                         f"{t[after]:.6g} s); frames must be in time order", where)


def _read_text(path: Path) -> str:
    data = read_input_bytes(path, "a Motive CSV export")
    return data.decode("utf-8-sig", errors="replace")


def _with_motive_commas(text: str) -> tuple[str, str]:
    """An export a spreadsheet re-saved with ';' or tabs between fields (a European locale, whose
    decimal commas come along) as Motive writes it: commas between fields, decimal points.
    Returns the text and a note saying so ("" for an export as Motive wrote it)."""
    first = text[: text.find("\n")] if "\n" in text else text
    sep = next((s for s in (";", "\t") if first.startswith(f"Format Version{s}")), None)
    if sep is None:
        return text, ""
    decimal = bool(_DECIMAL_COMMA.search(text, 0, 200_000))
    if decimal:
        text = _DECIMAL_COMMA.sub(".", text)
    name = "';'" if sep == ";" else "tabs"
    return text.replace(sep, ","), (f"read as re-saved from a spreadsheet: {name} between fields"
                                    + (", decimal commas" if decimal else "") + " (Motive writes commas)")


_DECIMAL_COMMA = re.compile(r"(?<=\d),(?=\d)")

#: The keys Motive writes on line 1 (`_metadata` finds them by name when the pairs are off).
MOTIVE_KEYS = ("Format Version", "Take Name", "Take Notes", "Capture Frame Rate", "Export Frame Rate",
               "Capture Start Time", "Capture Start Frame", "Total Frames in Take", "Total Exported Frames",
               "Rotation Type", "Length Units", "Coordinate Space")


def _metadata(line: str, where: str) -> dict[str, str]:
    """Line 1's key/value pairs. Where a value holds an unquoted comma (a take named `a,b`),
    the pairs shift: the keys Motive writes are then found by name, each value running to the
    next key."""
    cells = next(csv.reader([line])) if line else []
    meta = {cells[i].strip(): cells[i + 1].strip() for i in range(0, len(cells) - 1, 2)}
    if "Format Version" not in meta:
        raise InputError("not a Motive CSV export (line 1 lacks 'Format Version')", where)
    if not _rate_of(meta) and _rate_of(by_name := _by_name(cells)):
        return by_name
    return meta


def _by_name(cells: list[str]) -> dict[str, str]:
    out: dict[str, list[str]] = {}
    key: str | None = None
    for cell in (c.strip() for c in cells):
        if cell in MOTIVE_KEYS:
            key = cell
            out[key] = []
        elif key is not None:
            out[key].append(cell)
    return {k: ",".join(v).strip(",") for k, v in out.items()}


def _rate_of(meta: dict[str, str]) -> float | None:
    """The export (else capture) frame rate the metadata states, if it is a positive number."""
    for key in ("Export Frame Rate", "Capture Frame Rate"):
        try:
            rate = float(meta.get(key, "nan"))
        except ValueError:
            continue
        if math.isfinite(rate) and rate > 0:
            return rate
    return None


def _frame_rate(meta: dict[str, str], where: str) -> float:
    rate = _rate_of(meta)
    if rate is None:
        raise InputError("no valid 'Export Frame Rate' or 'Capture Frame Rate' in line 1", where)
    return rate


def _position_columns(
    label_rows: list[list[str]], header: list[str], where: str
) -> dict[str, dict[str, int]]:
    """Column of each (asset name, axis) whose type is a marker or rigid body and property Position."""
    type_row = next((r for r in label_rows if any(c in _TYPES for c in r)), None)
    prop_row = next((r for r in label_rows if "Position" in r), None)
    if type_row is None or prop_row is None:
        raise InputError(
            "no 'Marker'/'Rigid Body' type row or no 'Position' row above the header", where
        )
    name_row = (
        label_rows[label_rows.index(type_row) + 1] if type_row is not label_rows[-1] else None
    )
    named = next((r for r in label_rows if r and r[0] == "Name"), name_row)
    if named is None:
        raise InputError("no marker-name row under the type row", where)
    columns: dict[str, dict[str, int]] = {}
    kinds: dict[tuple[str, str], tuple[str, int]] = {}  # (name, axis) -> (type, column) seen first
    for col in range(2, len(header)):
        kind = type_row[col] if col < len(type_row) else ""
        prop = prop_row[col] if col < len(prop_row) else ""
        axis = header[col].strip().lower()
        name = named[col].strip() if col < len(named) else ""
        if kind in _POSITION_TYPES and prop == "Position" and axis in _AXES and name:
            earlier = kinds.setdefault((name, axis), (kind, col))
            if earlier[0] == kind and earlier[1] != col:
                # Two markers of one name: the later would silently replace the earlier.
                raise InputError(f"two {kind.lower()}s are named {name!r} (columns {earlier[1] + 1} and {col + 1}): "
                                 "rename one in Motive, or export the take with unique names", where)
            columns.setdefault(name, {})[axis] = col
    if not columns:
        raise InputError("no marker or rigid-body position columns", where)
    return columns


def _data(lines: list[str], n_columns: int, where: str) -> tuple[npt.NDArray[np.float64], str]:
    """Data rows as floats (empty or unparsable cells NaN; extra cells beyond the header ignored),
    and a note on the cells that held something other than a number ("" when none did)."""
    body = "\n".join(line for line in lines if line.strip())
    if not body:
        return np.empty((0, n_columns)), ""
    try:
        frame = pd.read_csv(
            io.StringIO(body), header=None, names=range(n_columns), usecols=range(n_columns),
            index_col=False, on_bad_lines="skip", low_memory=False,
        )  # fmt: skip
    except (pd.errors.ParserError, ValueError) as exc:
        raise InputError(f"unreadable data rows ({str(exc).splitlines()[0]})", where) from None
    bad, first = 0, None
    for column in frame.columns:
        if not pd.api.types.is_numeric_dtype(frame[column]):
            raw = frame[column].astype(object)
            numbers = pd.to_numeric(raw, errors="coerce")
            text = raw.notna() & numbers.isna() & ~raw.astype(str).str.strip().str.lower().isin(_GAP_WORDS)
            if text.any():
                bad += int(text.sum())
                row = int(np.flatnonzero(text.to_numpy())[0])
                first = min(first or (row, int(column)), (row, int(column)))
            frame[column] = numbers
    note = (f"{bad} cell(s) are not numbers and are read as gaps (first: data row {first[0] + 1}, column "
            f"{first[1] + 1})" if first is not None else "")
    return frame.to_numpy(dtype=np.float64, na_value=np.nan), note
