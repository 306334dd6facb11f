"""Commands `pianobot rig check | calibrate`: the lab rig's devices and the arm's reference pose."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text

from pianobot.cli.common import (
    DEFAULT_DATA,
    Column,
    DataDir,
    JsonFlag,
    emit_json,
    fail,
    print_error,
    print_table,
)
from pianobot.errors import InputError
from pianobot.rig.calibrate import calibrate_reference_pose
from pianobot.rig.check import check_rig
from pianobot.rig.errors import RigError
from pianobot.spec import load_rig

rig_app = typer.Typer(
    help="The lab rig: reach every device (`check`), teach the reference pose (`calibrate`).",
    no_args_is_help=True,
)
RigFile = Annotated[
    Path, typer.Argument(help="A lab rig file (kind: ur5), e.g. experiments/rigs/ur5-lab.yaml.",
                         show_default=False)
]


def register(app: typer.Typer) -> None:
    app.add_typer(rig_app, name="rig")


@rig_app.command("check")
def check(rigfile: RigFile, data: DataDir = DEFAULT_DATA, json: JsonFlag = False) -> None:
    """Connect to the arm, dashboard, vacuum I/O and MIDI port; move nothing; report each.

    Exits 2 with one line per device that cannot be reached or used.
    """
    rig = load_rig(rigfile)
    if rig.kind != "ur5":
        raise InputError(f"rig check needs a lab rig file (kind: ur5), got kind: {rig.kind}",
                         str(rigfile))
    report = check_rig(rig)
    if json:
        emit_json(report.to_dict())
    else:
        rows: list[list[str | Text]] = [
            [d.device, Text("ok", "green") if d.ok else Text("FAIL", "red"), d.summary]
            for d in report.devices
        ]
        print_table([Column("device"), Column("status"), Column("details", wrap=True)], rows,
                    title=f"rig {rigfile} ({report.host})")
    if not report.ok:
        for device in report.failures:
            print_error(f"{device.device}: {device.summary}")
        raise typer.Exit(code=2)


@rig_app.command("calibrate")
def calibrate(rigfile: RigFile, data: DataDir = DEFAULT_DATA, json: JsonFlag = False) -> None:
    """Freedrive the arm onto the reference key and write its TCP pose into the rig file.

    Needs an operator at a terminal: the arm goes into teach mode and you rest the fingertip on
    the reference key (the B left of middle C, 1.5 cm from the key's front edge, finger level).
    """
    try:
        result = calibrate_reference_pose(rigfile)
    except RigError as exc:
        fail(f"{rigfile}: {exc}")
    if json:
        emit_json(result.to_dict())
        return
    pose = ", ".join(f"{v:.5f}" for v in result.pose)
    print(f"reference pose [{pose}] written to {result.rig_path} at {result.calibrated_utc}")
    for warning in result.warnings:
        print(f"warning: {warning}")
