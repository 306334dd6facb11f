"""Commands `identify`, `fit` and `report`: thin wrappers over pianobot.analysis and pianobot.reports."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, cast

import pandas as pd
import typer

from pianobot.analysis.identify.static_stiffness import (
    STUDY_COMPRESSION_M,
    force_log_levels,
    static_stiffness_from_logs,
)
from pianobot.cli.common import (
    DEFAULT_DATA,
    Column,
    DataDir,
    JsonFlag,
    NoProgressFlag,
    PressesOption,
    RunIds,
    check_vacuum_option,
    command_progress,
    emit_json,
    figure_path,
    output_console,
    print_table,
    print_warning,
    say,
    say_written,
    warn_unfinished,
    writable_folder,
)
from pianobot.errors import InputError
from pianobot.executor import ExecutorSettings
from pianobot.output import check_output_path
from pianobot.store import load_runs

# The analysis and report modules load scikit-learn, scipy.optimize and matplotlib (seconds on a
# busy machine): each command imports only what it uses, after its progress line is up.

PlotOption = Annotated[Path | None, typer.Option("--plot", help="Also write a figure here (PNG).")]


#: Where identify's arm trace may come from (`greybox.trajectories.keystroke_batch`).
X0_SOURCES = ("auto", "arm", "mocap", "sim-truth")


def keystrokes_per_level(runs: list[str], data: Path, vacuum_kpa: float | None, fitted: int) -> dict[float, int]:
    """Keystrokes per vacuum level (kPa) of the runs' usable trials; a single level gets the
    number the fit actually used."""
    trials = pd.concat([run.trials for run in load_runs(runs, data)], ignore_index=True)
    if "status" in trials:
        trials = trials[trials["status"].isin(["ok", "silent"])]
    fallback = 0.0 if vacuum_kpa is None else -abs(vacuum_kpa)
    levels = trials["vacuum_kpa"].fillna(fallback) if "vacuum_kpa" in trials else pd.Series(fallback, trials.index)
    tally = levels.value_counts()
    counts = {float(level): int(n) for level, n in zip(tally.index.to_numpy(float), tally.to_numpy(int), strict=True)}
    return {next(iter(counts)): fitted} if len(counts) == 1 else counts


def register(app: typer.Typer) -> None:
    """Add identify, fit and report to the app."""

    @app.command()
    def identify(
        runs: RunIds,
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
        out: Annotated[Path, typer.Option("--out", help="Model file to write.")] = Path("model.json"),
        coupling: Annotated[str, typer.Option(help="tied | free | auto (BIC).")] = "auto",
        bootstrap: Annotated[int, typer.Option(min=0, help="Bootstrap refits over keystrokes.")] = 20,
        seed: Annotated[int, typer.Option(min=0, help="Bootstrap seed.")] = 0,
        x0_source: Annotated[str, typer.Option(help="arm | mocap | sim-truth | auto.")] = "auto",
        vacuum_kpa: Annotated[float | None, typer.Option(help="Vacuum of runs that do not record it.")] = None,
        force_log: Annotated[list[str] | None, typer.Option(help="P=FILE or a folder of P.txt force logs.")] = None,
        compression_m: Annotated[float, typer.Option(help="Compression of the force-log presses.")] = STUDY_COMPRESSION_M,
        plot: PlotOption = None,
        presses: PressesOption = None,
        workers: Annotated[int | None, typer.Option(
            "--workers", min=1, help="Processes for the bootstrap refits (default: the machine's cores; "
                                     "small work stays in this process).")] = None,
        scheduler: Annotated[str | None, typer.Option(
            "--scheduler", help="Dask scheduler address (tcp://HOST:PORT) for the bootstrap refits.")] = None,
        no_progress: NoProgressFlag = False,
    ) -> None:
        """Identify the keystroke model from mocap trajectories; write a model file with intervals."""
        if coupling not in ("tied", "free", "auto"):
            raise InputError(f"expected tied, free or auto, got {coupling!r}", "--coupling")
        if x0_source not in X0_SOURCES:
            raise InputError(f"expected {', '.join(X0_SOURCES)}, got {x0_source!r}", "--x0-source")
        check_vacuum_option(vacuum_kpa)
        check_output_path(out, "--out")  # before minutes of fitting, not after
        figure_path(plot, "--plot")
        warn_unfinished(runs, data)
        levels = force_log_levels(force_log or [])
        static = static_stiffness_from_logs(levels, compression_m=compression_m) if levels else None
        from pianobot.analysis.identify.fit import Coupling
        from pianobot.analysis.identify.run import identify_runs
        from pianobot.analysis.plausibility import (
            Interval,
            as_dicts,
            identify_findings,
            store_findings,
        )
        from pianobot.reports.command_figures import identified_model, k1_by_level, save_png

        # identify_runs reports its own steps (held-out fit, full fit, bootstrap refits).
        result = identify_runs(runs, data, out=out, coupling=cast(Coupling, coupling), bootstrap=bootstrap, seed=seed,
                               x0_source=x0_source, vacuum_kpa=vacuum_kpa, static=static,
                               progress=command_progress(json_out, no_progress),
                               executor=ExecutorSettings.resolve(workers=workers, scheduler=scheduler),
                               schedule=presses)
        findings = identify_findings(result.fit.params, [Interval(e.name, e.value, e.unit, e.ci95, at_limit=e.on_bound)
                                                         for e in result.fit.estimates],
                                     keystrokes_per_level(runs, data, vacuum_kpa, result.fit.n_keystrokes))
        for note in result.notes:
            if "left out" in note:  # a MIDI-only run beside a take: said, not silently dropped
                print_warning(note)
        if result.model_path is not None:
            store_findings(result.model_path, findings)
        if plot is not None:
            save_png(identified_model(result.fit.params, k1_by_level(result.fit.estimates),
                                      title=f"Identified model ({result.fit.n_keystrokes} keystrokes)"), plot)
        if json_out:
            for finding in findings:
                print_warning(finding.text())
            emit_json({**result.to_dict(), "warnings": as_dicts(findings),
                       "plot": None if plot is None else str(plot)})
            return
        print_table(ESTIMATE_COLUMNS, [[e.name, f"{e.value:.4g}", e.unit, f"{e.ci95[0]:.4g}", f"{e.ci95[1]:.4g}"]
                                       for e in result.fit.estimates], title="identified parameters")
        if result.model_path is not None:
            say_written("model", result.model_path)
        console = output_console()
        console.print(f"held-out RMS x2: identified {1e3 * result.holdout_rms_identified_m:.4f} mm, "
                      f"published {1e3 * result.holdout_rms_published_m:.4f} mm")
        peaks = ", ".join((f"{hz:.2f} Hz" if hz > 0 else "none (largest at 0 Hz)") + f" at {level} kPa"
                          for level, hz in result.peak_hz.items())
        console.print(f"x2/x0 resonance peak: {peaks}")
        if result.damping is not None:
            d = result.damping
            console.print(f"damping cross-check (log decrement, {len(d.ringing)} keystrokes): "
                          f"{d.frequency_hz:.2f} Hz, zeta {d.zeta:.3f} [{d.zeta_ci95[0]:.3f}, {d.zeta_ci95[1]:.3f}]; "
                          f"identified model's mode {d.model_frequency_hz:.2f} Hz, zeta {d.model_zeta:.3f}")
        if result.readout is not None:
            r = result.readout
            console.print(f"readout: trigger depth {1e3 * r.trigger_depth_m:.2f} mm, velocity = 127 (s / "
                          f"{r.full_scale_speed_mps:.4f} m/s)^{r.curve_exponent:.2f}, RMSE {r.rmse_velocity:.2f} "
                          f"MIDI ({r.n_trials} keystrokes)")
        if result.static is not None:
            st = result.static
            console.print(f"static stiffness: k1 = {st.k1_a_npm:.2f} + {st.k1_b_npm_per_kpa:.3f}|p| N/m "
                          f"(compression {1e3 * st.compression_m:.1f} mm)")
        if plot is not None:
            say_written("figure", plot)
        for finding in findings:  # last, beside the numbers they qualify
            print_warning(finding.text())

    @app.command()
    def fit(
        runs: RunIds,
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
        model: Annotated[list[str] | None, typer.Option("--model", help="gp | poly | spline | mlp | physics | sequence | rnn (repeatable; with sequence, the others are its per-note baselines; rnn adds the recurrent model: pip extra 'rnn').")] = None,
        out_dir: Annotated[Path, typer.Option("--out-dir", help="Folder for the saved predictors.")] = Path("models"),
        folds: Annotated[int, typer.Option(min=2, help="Grouped CV folds.")] = 5,
        physics_model: Annotated[Path | None, typer.Option(help="Model file for --model physics.")] = None,
        plot: PlotOption = None,
        no_progress: NoProgressFlag = False,
        context: Annotated[str, typer.Option("--context", help="With --model sequence: previous strokes k to compare, e.g. 0,1,2,3.")] = "0,1,2,3",
        workers: Annotated[int | None, typer.Option(
            "--workers", min=1, help="Processes for the cross-validation folds (default: the machine's cores; "
                                     "small work stays in this process).")] = None,
        scheduler: Annotated[str | None, typer.Option(
            "--scheduler", help="Dask scheduler address (tcp://HOST:PORT) for the cross-validation folds.")] = None,
    ) -> None:
        """Cross-validate learned maps to on-velocity, hold and silence; save each as a predictor."""
        kinds = model or ["gp"]
        writable_folder(out_dir, "--out-dir")
        warn_unfinished(runs, data)
        if "sequence" in kinds or "rnn" in kinds:
            from pianobot.cli.sequence_fit import fit_sequence_command

            if plot is not None:
                raise InputError("--plot draws per-note maps; it is not available with --model sequence", "--plot")

            fit_sequence_command(runs, data, kinds, out_dir, folds, context, json_out, no_progress)
            return
        figure_path(plot, "--plot")
        progress = command_progress(json_out, no_progress)
        with progress.task("fit: loading scikit-learn"):
            from pianobot.analysis.learn.files import load_predictor
            from pianobot.analysis.learn.physical import PhysicsPredictor
            from pianobot.analysis.learn.run import fit_runs, load_trials
            from pianobot.analysis.plausibility import as_dicts
            from pianobot.reports.command_figures import learned_maps, save_png
        result = fit_runs(runs, data, kinds=kinds, out_dir=out_dir, folds=folds,
                          physics_model=physics_model, progress=progress,
                          executor=ExecutorSettings.resolve(workers=workers, scheduler=scheduler))
        table, saved = result.cv, result.saved
        if plot is not None:
            predictors = {kind: load_predictor(path) for kind, path in saved.items()}
            if "physics" in kinds:
                predictors["physics"] = (load_predictor(physics_model) if physics_model
                                         else PhysicsPredictor.published())
            save_png(learned_maps(load_trials(runs, data), predictors), plot)
        if json_out:
            for finding in result.findings:
                print_warning(finding.text())
            emit_json({"cv": table.to_dict(orient="records"), "saved": {k: str(v) for k, v in saved.items()},
                       "warnings": as_dicts(result.findings), "plot": None if plot is None else str(plot)})
            return
        print_cv(table, saved)
        if plot is not None:
            say_written("figure", plot)
        for finding in result.findings:  # last, beside the numbers they qualify
            print_warning(finding.text())

    @app.command()
    def report(
        runs: RunIds,
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
        model: Annotated[Path | None, typer.Option("--model", help="Model file (identify output).")] = None,
        out: Annotated[Path, typer.Option("--out", help="HTML file to write.")] = Path("report.html"),
        compare: Annotated[bool, typer.Option(help="Also run a quick grouped CV (poly, spline).")] = False,
        no_progress: NoProgressFlag = False,
    ) -> None:
        """Write one self-contained HTML report (figures embedded, no network)."""
        check_output_path(out, "--out")
        warn_unfinished(runs, data)
        progress = command_progress(json_out, no_progress)
        with progress.task("report: loading matplotlib" + (" and scikit-learn" if compare else "")):
            from pianobot.reports.run_report import build_run_report

            if compare:
                from pianobot.analysis.learn.run import fit_runs
        cv = None
        if compare:
            try:
                cv = fit_runs(runs, data, kinds=["poly", "spline"], out_dir=None, progress=progress).cv
            except InputError as exc:  # nothing to learn from (every keystroke silent): the rest still tells
                print_warning(f"--compare: no model comparison ({exc.message}); the report is written without it")
        path = build_run_report(runs, data, out, model_file=model, cv_table=cv, progress=progress)
        if json_out:
            emit_json({"report": str(path)})
        else:
            say_written("report", path)


ESTIMATE_COLUMNS = (
    Column("parameter"), Column("value", justify="right"), Column("unit"),
    Column("95 % low", justify="right"), Column("95 % high", justify="right"),
)
CV_COLUMNS = (
    Column("model"),
    Column("velocity RMSE (MIDI)", justify="right"),
    Column("R²", justify="right"),
    Column("hold RMSE (ms)", 1, "right"),
    Column("silence right (%)", 1, "right"),
    Column("velocity MAE (MIDI)", 2, "right"),
    Column("predict (ms)", 3, "right"),
    Column("fit (s)", 3, "right"),
)


def _number(value: object, fmt: str, scale: float = 1.0) -> str:
    if not isinstance(value, int | float) or value != value:
        return "-"
    return format(float(value) * scale, fmt)


def print_cv(table: pd.DataFrame, saved: dict[str, Path]) -> None:
    """The CV table (units in the headings, the `mean` row named a baseline) and where files went."""
    first = table.iloc[0] if len(table) else None
    title = "grouped cross-validation of on-velocity (sounded keystrokes)"
    if first is not None:
        title += f": {int(first['n_trials'])} keystrokes, {int(table['folds'].max())} folds by setting"
    rows = []
    for r in table.to_dict(orient="records"):
        name = "mean (baseline)" if r["model"] == "mean" else str(r["model"])
        rows.append([name, _number(r["rmse"], ".2f"), _number(r["r2"], ".3f"),
                     _number(r["hold_rmse_s"], ".0f", 1e3), _number(r["silent_accuracy"], ".0f", 100.0),
                     _number(r["mae"], ".2f"), _number(r["latency_ms"], ".2f"), _number(r["fit_s"], ".2f")])
    print_table(CV_COLUMNS, rows, title=title)
    for kind, path in saved.items():
        say_written(f"predictor {kind}", f"{path} (+ {path.with_suffix('.joblib').name})")
    if not saved:
        say("no predictor saved (only the baseline and --model physics were evaluated)")
