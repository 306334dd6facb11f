"""`pianobot rig calibrate`: teach the arm where the reference key is.

The arm goes into teach (freedrive) mode, the operator rests the fingertip on the reference key
(the study used the B left of middle C, fingertip 1.5 cm from the key's front edge, finger level),
confirms, and the TCP pose is read and written into the rig file with a UTC timestamp. Every
other key is found from this pose and the keyboard geometry, so the pose must be taken with
the finger level and just touching (the key must not be pressed down).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pianobot.rig.errors import DeviceUnavailable, RigError
from pianobot.rig.ur5_session import open_links
from pianobot.rig.ur5_status import failure, read_status
from pianobot.spec.loader import load_rig, write_rig_calibration

NOTE_NAMES = ("C", "C#", "D", "D#", "E", "F", "F#", "G", "G#", "A", "A#", "B")


def note_name(note: int) -> str:
    """Scientific pitch name of a MIDI note (59 → B3)."""
    return f"{NOTE_NAMES[note % 12]}{note // 12 - 1}"


@dataclass(frozen=True)
class Calibration:
    """The pose written into the rig file."""

    rig_path: str
    reference_note: int
    pose: tuple[float, ...]
    calibrated_utc: str
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-able."""
        return {
            "rig": self.rig_path,
            "reference_note": self.reference_note,
            "reference_pose": list(self.pose),
            "calibrated_utc": self.calibrated_utc,
            "warnings": list(self.warnings),
        }


def _stdin_is_tty() -> bool:
    return sys.stdin is not None and sys.stdin.isatty()


def _utc_now() -> datetime:
    return datetime.now(UTC)


def calibrate_reference_pose(
    rig_path: str | Path,
    *,
    ask: Callable[[str], str] = input,
    interactive: Callable[[], bool] = _stdin_is_tty,
    now: Callable[[], datetime] = _utc_now,
    receive_factory: Any = None,
    control_factory: Any = None,
    dashboard_factory: Any = None,
) -> Calibration:
    """Freedrive, let the operator place the fingertip, write the TCP pose into the rig file.

    Raises InputError for a bad rig file, DeviceUnavailable without a terminal or an arm, a
    RigError when the arm refuses teach mode or the operator aborts; the file is then untouched.
    """
    rig = load_rig(rig_path)
    if rig.kind != "ur5" or rig.ur5 is None:
        raise DeviceUnavailable(f"{rig_path}: calibration needs a lab rig file (kind: ur5)")
    if not interactive():
        raise DeviceUnavailable(
            "calibration needs an operator at a terminal to place the finger (stdin is not a TTY)"
        )
    ur5 = rig.ur5
    links = open_links(ur5, receive_factory=receive_factory, control_factory=control_factory,
                       dashboard_factory=dashboard_factory)
    receive, control = links.receive, links.control
    try:
        status = read_status(receive, control)
        if status.stopped or status.link_down:
            raise failure("calibration", status)
        if not control.teachMode():
            raise failure("teachMode", read_status(receive, control))
        try:
            key = note_name(ur5.reference_note)
            answer = ask(
                f"Freedrive is on. Rest the fingertip on {key} (MIDI {ur5.reference_note}), "
                "1.5 cm from the key's front edge, finger level, touching without pressing; "
                "then press Enter (q to abort): "
            ).strip().lower()
            if answer in ("q", "quit", "abort"):
                raise RigError("calibration aborted by the operator; the rig file is unchanged")
            pose = tuple(float(v) for v in receive.getActualTCPPose())
        except EOFError as exc:
            raise DeviceUnavailable("the operator's terminal closed (end of input)") from exc
        finally:
            control.endTeachMode()
    finally:
        for link in (control, receive, links.dashboard):
            _close(link)
    when = now()
    warnings = []
    outside = [
        axis for axis, v, lo, hi in zip("xyz", pose[:3], ur5.workspace_min_m, ur5.workspace_max_m,
                                        strict=True)
        if not lo <= v <= hi
    ]
    if outside:
        warnings.append(
            f"the pose is outside the workspace box on {', '.join(outside)}: every move will be "
            "refused until workspace_min_m/workspace_max_m include it"
        )
    updated = write_rig_calibration(rig_path, pose, when)
    assert updated.ur5 is not None
    return Calibration(
        rig_path=str(rig_path),
        reference_note=ur5.reference_note,
        pose=pose,
        calibrated_utc=updated.ur5.calibrated_utc or when.isoformat(),
        warnings=tuple(warnings),
    )


def _close(link: Any) -> None:
    if link is None:
        return
    for method in ("stopScript", "disconnect"):
        try:
            getattr(link, method)()
        except Exception:  # the receive interface has no stopScript; closing must not fail
            pass
