"""`pianobot model bode | simulate`: the keystroke model's resonance and one simulated keystroke."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from pianobot.cli.common import (
    DEFAULT_DATA,
    DataDir,
    JsonFlag,
    check_vacuum_option,
    emit_json,
    figure_path,
    print_fields,
    say,
    say_written,
)
from pianobot.errors import InputError, check_seed
from pianobot.physics.linear import peak_response
from pianobot.physics.model import KeystrokeModel, load_model
from pianobot.physics.trajectory import Press, press_timing
from pianobot.physics.world import World, WorldKeystroke
from pianobot.plan.trial import press_from
from pianobot.spec.parameters import PARAMETERS, format_value

model_app = typer.Typer(help="Inspect the keystroke model: resonance, one simulated keystroke.",
                        no_args_is_help=True)

VacuumOpt = Annotated[float, typer.Option("--vacuum-kpa", help="Vacuum, gauge kPa (<= 0).")]
PlotOpt = Annotated[Path | None, typer.Option("--plot", help="Write a PNG figure here.")]


def register(app: typer.Typer) -> None:
    app.add_typer(model_app, name="model")


def _vacuum(vacuum_kpa: float) -> float:
    """As every command reads `--vacuum-kpa`: a gauge pressure in [-100, 0] kPa, a magnitude (40)
    read as −40 (this command took −200 and refused 40)."""
    check_vacuum_option(vacuum_kpa)
    return -abs(vacuum_kpa) or 0.0


@model_app.command("bode")
def bode_command(
    vacuum_kpa: VacuumOpt = -60.0,
    model_file: Annotated[Path | None, typer.Option("--model", help="A model file (default: the study's).")] = None,
    plot: PlotOpt = None,
    data: DataDir = DEFAULT_DATA,
    json: JsonFlag = False,
) -> None:
    """Peak frequency and gain of the key's response to the arm, |X2/X0|."""
    figure_path(plot)
    model = load_model(model_file) if model_file is not None else KeystrokeModel.study()
    vacuum_kpa = _vacuum(vacuum_kpa)
    lp = model.msd.at(vacuum_kpa)
    peak_hz, gain = peak_response(lp)
    if plot is not None:
        from pianobot.reports.command_figures import save_png
        from pianobot.reports.figures import bode

        save_png(bode(model.msd, [vacuum_kpa], fingertip=True, title=f"Arm-to-key response at {vacuum_kpa:g} kPa"),
                 plot)
    payload = {"vacuum_kpa": vacuum_kpa, "peak_hz": peak_hz, "peak_gain": gain,
               "model": str(model_file) if model_file else "study", "plot": str(plot) if plot else None}
    if json:
        emit_json(payload)
        return
    say(f"|X2/X0| at {vacuum_kpa:g} kPa: peak {peak_hz:.2f} Hz, gain {gain:.3f}")
    if plot is not None:
        say_written("figure", plot)


def _default_help(name: str) -> str:
    """`Default: 0.5 m/s².` from the parameter table (what a spec's trial gets when unset)."""
    p = PARAMETERS[name]
    if p.follows is not None:
        return f"Default: the {PARAMETERS[p.follows].label.removeprefix('arm ')}."
    return f"Default: {format_value(p.default or 0.0)} {p.unit}."


@model_app.command("simulate")
def simulate(
    vacuum_kpa: VacuumOpt = -60.0,
    down_velocity_mps: Annotated[float, typer.Option("--down-velocity-mps")] = 0.04,
    depth_m: Annotated[float, typer.Option("--depth-m")] = 0.03,
    acceleration_mps2: Annotated[float | None, typer.Option("--acceleration-mps2", help=_default_help("acceleration_mps2"))] = None,
    up_velocity_mps: Annotated[float | None, typer.Option("--up-velocity-mps", help=_default_help("up_velocity_mps"))] = None,
    distance_m: Annotated[float | None, typer.Option("--distance-m", help=_default_help("distance_m"))] = None,
    hold_s: Annotated[float | None, typer.Option("--hold-s", help=_default_help("hold_s"))] = None,
    world: Annotated[str, typer.Option("--world", help="default | linear")] = "default",
    seed: Annotated[int, typer.Option("--seed")] = 0,
    plot: PlotOpt = None,
    data: DataDir = DEFAULT_DATA,
    json: JsonFlag = False,
) -> None:
    """Simulate one keystroke in the simulated world; print its MIDI outcome, optionally plot it."""
    figure_path(plot)
    check_seed(seed)
    if world not in ("default", "linear"):
        raise InputError(f"expected 'default' or 'linear', got {world!r}", "--world")
    press = press_from({"distance_m": distance_m, "depth_m": depth_m, "down_velocity_mps": down_velocity_mps,
                        "up_velocity_mps": up_velocity_mps, "acceleration_mps2": acceleration_mps2,
                        "hold_s": hold_s})
    try:
        press_timing(press)
    except ValueError as exc:
        raise InputError(str(exc), "press") from None
    sim = World.default(seed) if world == "default" else World.linear(seed)
    vacuum_kpa = _vacuum(vacuum_kpa)
    k = sim.keystroke(press, vacuum_kpa, key="cli")
    if plot is not None:
        from pianobot.reports.command_figures import save_png, simulated_keystroke

        save_png(simulated_keystroke(k, press, vacuum_kpa), plot)
    payload = _summary(k, world, vacuum_kpa, press)
    payload["plot"] = str(plot) if plot else None
    if json:
        emit_json(payload)
        return
    fields = [(label, _quantity(payload[name], scale, fmt)) for name, label, scale, fmt in SIMULATE_FIELDS]
    print_fields(fields, title=f"{world} world, {vacuum_kpa:g} kPa, {1e3 * down_velocity_mps:g} mm/s, "
                               f"depth {1e3 * depth_m:g} mm")
    if plot is not None:
        say_written("figure", plot)


# (payload key, label with unit, scale, format): lengths in mm, times in ms.
SIMULATE_FIELDS = (
    ("silent", "silent", 1.0, ""),
    ("on_velocity", "note-on velocity (MIDI)", 1.0, "d"),
    ("t_on_s", "note-on after motion start (ms)", 1e3, ".1f"),
    ("t_off_s", "note-off after motion start (ms)", 1e3, ".1f"),
    ("key_speed_at_trigger_mps", "key speed at trigger (mm/s)", 1e3, ".1f"),
    ("max_key_travel_m", "max key travel (mm)", 1e3, ".2f"),
    ("duration_s", "keystroke duration (ms)", 1e3, ".0f"),
)


def _quantity(value: Any, scale: float, fmt: str) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool) or not fmt:
        return str(value)
    return str(int(value)) if fmt == "d" else format(float(value) * scale, fmt)


def _summary(k: WorldKeystroke, world: str, vacuum_kpa: float, press: Press) -> dict[str, Any]:
    ons = [e for e in k.midi if e.type == "note_on"]
    offs = [e for e in k.midi if e.type == "note_off"]
    return {
        "world": world,
        "vacuum_kpa": vacuum_kpa,
        "press": press.__dict__,
        "silent": not ons,
        "on_velocity": ons[0].velocity if ons else None,
        "off_velocity": offs[0].velocity if offs else None,
        "t_on_s": ons[0].t_s - k.t0_s if ons else None,
        "t_off_s": offs[0].t_s - k.t0_s if offs else None,
        "key_speed_at_trigger_mps": k.key_speed_at_trigger_mps,
        "max_key_travel_m": k.max_key_travel_m,
        "duration_s": k.duration_s,
        "midi": [e.__dict__ for e in k.midi],
    }
