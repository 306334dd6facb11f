"""Commands `pianobot import keystroke-log | force-log | mocap`: old data into new runs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from pianobot.cli.common import (
    DEFAULT_DATA,
    DataDir,
    JsonFlag,
    NoProgressFlag,
    command_progress,
    emit_json,
    figure_path,
    print_fields,
    print_warning,
    say,
    say_written,
)
from pianobot.errors import InputError
from pianobot.io.force_log import (
    DEFAULT_GAIN_N,
    DEFAULT_OFFSET_N,
    DEFAULT_RATE_HZ,
    ForceCalibration,
)
from pianobot.io.importers import ImportResult, import_force_log, import_keystroke_log, import_mocap
from pianobot.io.keystroke_layouts import LAYOUT_CHOICES
from pianobot.io.named_keys import DEFAULT_NOTE_OCTAVE

imports = typer.Typer(
    help="Import old data (keystroke logs, force logs, Motive mocap CSV) as runs.",
    no_args_is_help=True,
)
SHOWN_SKIPPED = 20  # skipped lines listed on screen; all of them are in the run's meta
SourceFile = Annotated[Path, typer.Argument(help="The file to import.", show_default=False)]


def register(app: typer.Typer) -> None:
    app.add_typer(imports, name="import")


@imports.command("keystroke-log")
def keystroke_log(
    file: SourceFile,
    layout: Annotated[
        str, typer.Option(help=f"Control-list layout of positional logs: {', '.join(LAYOUT_CHOICES)}.")
    ] = "auto",
    columns: Annotated[
        str | None,
        typer.Option("--columns", help="Declare the control-list columns in order, e.g. "
                     "vacuum_kpa,velocity_mps,skip,hold_s "
                     "(skip ignores a value; a unit-less name keeps it as an extra column)."),
    ] = None,
    layout_file: Annotated[
        Path | None, typer.Option("--layout-file", help="A YAML file declaring the columns (name, finger, columns).")
    ] = None,
    finger: Annotated[
        str | None, typer.Option("--finger", help="soft or rigid, when the log does not say.")
    ] = None,
    note_octave: Annotated[
        int, typer.Option("--note-octave", help="Octave of note letters without one (4: C = MIDI 60, middle C).")
    ] = DEFAULT_NOTE_OCTAVE,
    data: DataDir = DEFAULT_DATA,
    json: JsonFlag = False,
    no_progress: NoProgressFlag = False,
) -> None:
    """Import a dict-per-line keystroke log (control lists or named keys).

    MIDI events stay on the line that printed them unless the read backlog
    and the predicted stroke timing show they belong to an earlier
    keystroke; each moved event's evidence is kept.
    """
    declared = columns.split(",") if columns is not None else None
    result = import_keystroke_log(file, data, layout=layout, columns=declared, layout_file=layout_file,
                                  finger=finger, note_octave=note_octave,
                                  progress=command_progress(json, no_progress))  # fmt: skip
    _show(result, json, data)


@imports.command("force-log")
def force_log(
    file: SourceFile,
    rate_hz: Annotated[
        float, typer.Option("--rate-hz", help="Sample rate of the capture.")
    ] = DEFAULT_RATE_HZ,
    gain_n: Annotated[
        float, typer.Option("--gain-n", help="Newtons per reading.")
    ] = DEFAULT_GAIN_N,
    offset_n: Annotated[
        float, typer.Option("--offset-n", help="Force at reading 0, N.")
    ] = DEFAULT_OFFSET_N,
    align_run: Annotated[
        str | None, typer.Option("--align-run", help="Fit rate and clock to this run's note-ons.")
    ] = None,
    data: DataDir = DEFAULT_DATA,
    json: JsonFlag = False,
    no_progress: NoProgressFlag = False,
) -> None:
    """Import an `Analog reading = N` force capture; one trial per press (burst)."""
    calibration = ForceCalibration(gain_n=gain_n, offset_n=offset_n, rate_hz=rate_hz)
    _show(import_force_log(file, data, calibration=calibration, align_run=align_run,
                           progress=command_progress(json, no_progress)), json, data)


@imports.command("mocap")
def mocap(
    file: SourceFile,
    run: Annotated[
        str | None, typer.Option("--run", help="Align the take to this run (new derived run).")
    ] = None,
    marker: Annotated[
        list[str] | None,
        typer.Option("--marker", help="ROLE=NAME (arm, fingertip, key): NAME may be any piece of a "
                     "split track, or none (not in view); repeatable."),
    ] = None,
    rig: Annotated[
        Path | None, typer.Option("--rig", help="Rig file whose mocap.markers name the roles.")
    ] = None,
    min_coverage: Annotated[
        float, typer.Option(help="Drop markers present on fewer frames (ghosts).")
    ] = 0.5,
    up_axis: Annotated[
        str, typer.Option("--up-axis", help="Vertical axis of the export (x|y|z); auto: y, or the axis the "
                          "markers move along when they do not move along y (an export made Z-up).")
    ] = "auto",
    vacuum_kpa: Annotated[
        float | None,
        typer.Option("--vacuum-kpa", help="Finger vacuum during the take (gauge kPa, <= 0; 40 reads as -40)."),
    ] = None,
    plot: Annotated[
        Path | None, typer.Option("--plot", help="Also write a figure of the take (PNG).")
    ] = None,
    arm_log: Annotated[
        Path | None,
        typer.Option("--arm-log", help="The UR arm log recorded with the take (ur_rtde's file recording, "
                     "CSV with timestamp and actual_TCP_pose_0..5): drives the model and times the mocap clock."),
    ] = None,
    arm_log_start: Annotated[
        float | None,
        typer.Option("--arm-log-start", help="The arm log's timestamp (s) at the take's time 0 (its first frame, unless exported from a later one) "
                     "[default: its first row: the recordings started together]."),
    ] = None,
    data: DataDir = DEFAULT_DATA,
    json: JsonFlag = False,
    no_progress: NoProgressFlag = False,
) -> None:
    """Import a Motive CSV take: keystrokes segmented from the arm marker, or aligned to a run.

    Marker tracks Motive split after an occlusion are joined first; roles
    are inferred only when the evidence is clear, otherwise the candidates
    are named.
    """
    figure_path(plot, "--plot")
    markers = _rig_markers(rig) if rig is not None else {}
    markers.update(_marker_options(marker or []))
    result = import_mocap(
        file,
        data,
        run_id=run,
        markers=markers or None,
        min_coverage=min_coverage,
        up_axis=up_axis,
        vacuum_kpa=vacuum_kpa,
        progress=command_progress(json, no_progress),
        arm_log=arm_log,
        arm_log_start_s=arm_log_start,
    )
    if plot is not None:
        from pianobot.reports.command_figures import plot_mocap_run

        plot_mocap_run(result.run_id, data, plot)
    _show(result, json, data)
    if plot is not None and not json:
        say_written("figure", plot)


def _marker_options(items: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        role, sep, name = item.partition("=")
        if not sep or not role.strip() or not name.strip():
            raise InputError(f"expected ROLE=NAME, got {item!r}", "--marker")
        out[role.strip()] = name.strip()
    return out


def _rig_markers(path: Path) -> dict[str, str]:
    from pianobot.spec.loader import load_rig

    rig = load_rig(path)
    names = rig.mocap.markers
    if names is None:
        raise InputError("the rig file names no mocap markers (mocap.markers)", str(path))
    return {"arm": names.arm, "fingertip": names.fingertip, "key": names.key}


_UNITS = {"_hz": "Hz", "_kpa": "kPa", "_s": "s", "_mm": "mm"}


def _label(key: str) -> str:
    """`rate_hz` as "rate (Hz)": the unit suffix of a summary key in words."""
    for suffix, unit in _UNITS.items():
        if key.endswith(suffix):
            return f"{key.removesuffix(suffix).replace('_', ' ')} ({unit})"
    return key.replace("_", " ")


def _shown(value: object) -> str:
    """A summary value as a person reads it: no Python dict or list syntax."""
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_shown(v)}" for k, v in value.items()) or "none"
    if isinstance(value, list | tuple):
        return ", ".join(_shown(v) for v in value) or "none"
    return str(value)


def _show(result: ImportResult, json: bool, data: Path) -> None:
    if json:
        emit_json(result.to_dict())
        return
    fields = [(_label(key), _shown(value))
              for key, value in result.to_dict().items() if key not in ("skipped_lines", "run_dir", "warnings")]
    fields.append(("skipped lines", str(len(result.skipped_lines))))
    print_fields(fields, title=f"imported {result.kind}")
    for line, reason in result.skipped_lines[:SHOWN_SKIPPED]:
        say(f"  line {line}: {reason}")
    if len(result.skipped_lines) > SHOWN_SKIPPED:
        say(f"  ... {len(result.skipped_lines) - SHOWN_SKIPPED} more in the run's meta (skipped_lines)")
    say_written("run", data / "runs" / result.run_id)
    for line in result.extra.get("warnings", ()):
        print_warning(line)
