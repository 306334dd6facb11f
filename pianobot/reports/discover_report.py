"""The discovery report: decision, measured checks, candidate tables, localisation, overlays.

Every length in text and tables is in mm; every information criterion is the one of
`greybox.criterion` (a ΔIC above 10 is strong evidence); parameters that ended on a bound are
flagged; overlay legends name what each line is.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from pianobot.analysis.discover.decide import percent_text
from pianobot.analysis.discover.gap import Gap
from pianobot.analysis.discover.result import DiscoveryResult, dropped_text, params_text
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.prediction import Prediction
from pianobot.reports.html import Section, figure_html, paragraph, table_html, write_page


def gap_cell(gap: Gap) -> str:
    """A held-out gap in a table cell (mm, or MIDI outcomes)."""
    return gap.text(short=True)


def candidate_frame(result: DiscoveryResult, index: int) -> pd.DataFrame:
    """One iteration's candidate table."""
    rows = []
    rule = result.rule
    for v in result.iterations[index].verdicts:
        params = params_text(v)
        rows.append({"candidate": v.label, "family": v.family, "parameters (95 % CI)": params or "(switch)",
                     "ΔIC": round(v.delta_ic, 1), "held-out gap before": gap_cell(v.gap_before),
                     "after": gap_cell(v.gap_after), "shrink %": percent_text(100 * v.shrink, 100 * rule.min_shrink),
                     "consistent %": percent_text(100 * v.consistency, 100 * rule.min_consistency), "joint fit": "yes" if v.joint else "screened",
                     "status": v.status, "why not": "; ".join(v.reasons)})
    return pd.DataFrame(rows)


def stage_frame(result: DiscoveryResult) -> pd.DataFrame:
    """Held-out systematic error per stage and signal, base model and final model (mm)."""
    first = result.iterations[0].before
    last = result.press_iterations[-1]
    final = last.after if last.accepted and last.after is not None else last.before
    after = {(r["stage"], r["signal"]): r for r in final.stages}
    rows = []
    for r in first.stages:
        a = after.get((r["stage"], r["signal"]), {})
        rows.append({"stage": r["stage"], "signal": r["signal"], "frames": r["n"],
                     "systematic mm (base)": round(r["systematic_mm"], 4),
                     "systematic mm (final)": round(a.get("systematic_mm", math.nan), 4),
                     "bias mm (base)": round(r["bias_mm"], 4), "lag-1 (base)": round(r["lag1"], 2),
                     "lag-1 (final)": round(a.get("lag1", math.nan), 2)})
    return pd.DataFrame(rows)


def params_frame(result: DiscoveryResult) -> pd.DataFrame:
    """The base model's fitted parameters (SI units), bounds flagged."""
    return pd.DataFrame([{"parameter": k, "value": f"{v:.4g}", "on bound": "yes" if k in result.base_on_bounds else ""}
                         for k, v in result.base_params.items()])


def _overlay(result: DiscoveryResult, count: int = 3) -> str:
    """The held-out keystrokes the base model fits worst: measured, base model, final model."""
    held, before, after = result.held_out, result.predictions_before, result.predictions_after
    if not held.has_motion:
        return _outcome_overlay(result)
    final_name = "final model (" + (", ".join(v.label for v in result.accepted) or "= base") + ")"
    return _trajectory_overlay(held, before, after, ("base model", final_name), count,
                               "Worst held-out keystrokes of the base model: dots measured, dashed base model, "
                               "solid final model (each trace relative to its own rest level)")


def _release_overlay(result: DiscoveryResult, count: int = 2) -> str:
    """The held-out keystrokes through their release: the model entering the release rounds (the
    study's bilateral coupling) against the one leaving them."""
    assert result.release is not None
    effects = [f.effect for f in result.findings if f.effect == "contact" and f.accepted]
    effects += [it.accepted.label for it in result.iterations if it.window == "release" and it.accepted]
    final_name = "with " + (", ".join(effects) or "nothing added")
    return _trajectory_overlay(result.held_out, result.release.before, result.release.after,
                               ("model before the release rounds", final_name), count,
                               "The release, past lift-off (held-out keystrokes the earlier model fits worst): "
                               "dots measured, dashed the model before the release rounds, solid after them")


def _trajectory_overlay(held: KeystrokeBatch, before: Prediction, after: Prediction, names: tuple[str, str],
                        count: int, caption: str) -> str:
    """Measured fingertip and key against two models, on the `count` keystrokes `before` fits worst."""
    err = np.nanmean((before.x2_m - held.x2_m) ** 2, axis=1)
    order = [int(i) for i in np.argsort(np.where(np.isfinite(err), err, -1.0))[::-1][:count] if np.isfinite(err[i])]
    if not order:
        return paragraph("No modelled frames to overlay.", note=True)
    fig, axes = plt.subplots(len(order), 1, figsize=(9, 2.8 * len(order)), squeeze=False)
    for ax, i in zip(axes[:, 0], order, strict=True):
        t = held.row_times_s(i)
        for signal, measured, base_pred, final_pred, colour in (
                ("fingertip x1", held.x1_m[i], before.x1_m[i], after.x1_m[i], "tab:blue"),
                ("key x2", held.x2_m[i], before.x2_m[i], after.x2_m[i], "tab:red")):
            # Each trace with its rest offset removed, as the fit compares them.
            ok = np.isfinite(base_pred) & np.isfinite(measured)
            if not ok.any():
                continue
            off_b = float(np.mean(base_pred[ok] - measured[ok]))
            off_f = float(np.nanmean(final_pred[ok] - measured[ok]))
            ax.plot(t, 1e3 * measured, ".", ms=2, color=colour, label=f"measured {signal}")
            ax.plot(t, 1e3 * (base_pred - off_b), "--", lw=1, color=colour, label=f"{names[0]} {signal}")
            ax.plot(t, 1e3 * (final_pred - off_f), "-", lw=1, color=colour, label=f"{names[1]} {signal}")
        ax.set_title(f"{held.trial_id[i]}: {held.vacuum_kpa[i]:g} kPa, {1e3 * held.down_velocity_mps[i]:.0f} mm/s")
        ax.set_ylabel("displacement, mm (down +)")
    axes[-1, 0].set_xlabel("time since motion start (s)")
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=2)
    fig.tight_layout()
    return figure_html(fig, caption)


def _outcome_overlay(result: DiscoveryResult) -> str:
    """MIDI only: on-velocity and hold against commanded speed, measured vs base vs final."""
    held, before, after = result.held_out, result.predictions_before, result.predictions_after
    speed = 1e3 * held.down_velocity_mps
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    final_name = "final model (" + (", ".join(v.label for v in result.accepted) or "= base") + ")"
    for ax, measured, b, a, label in ((axes[0], held.on_velocity, before.on_velocity, after.on_velocity, "on-velocity (MIDI)"),
                                      (axes[1], 1e3 * held.hold_midi_s, 1e3 * before.hold_s, 1e3 * after.hold_s, "hold (ms)")):
        ax.plot(speed, measured, "o", ms=4, color="black", label="measured")
        ax.plot(speed, b, "x", ms=4, color="tab:grey", label="base model")
        ax.plot(speed, a, "+", ms=5, color="tab:red", label=final_name)
        ax.set_xlabel("commanded down speed (mm/s)")
        ax.set_ylabel(label)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return figure_html(fig, "Held-out keystrokes: measured MIDI outcome against the base and final models")


def _gap_figure(result: DiscoveryResult) -> str:
    """Held-out gap of the base model and after each accepted effect; the release rounds (a longer
    window, so not comparable with the rest) in a panel of their own."""
    press = [v for it in result.press_iterations if (v := it.accepted) is not None]
    labels = ["base"] + [v.label for v in press]
    gaps = [result.gap_before] + [v.gap_after for v in press]
    release = [it for it in result.iterations if it.window == "release"]
    position = math.isfinite(result.gap_before.position_m)
    unit = "mm" if position else "MIDI velocity"
    fig, axes = plt.subplots(1, 2 if release else 1, figsize=(9 if release else 6, 3), squeeze=False)
    panels = [(axes[0, 0], labels, gaps, "until lift-off")]
    if release:
        rel_labels = ["with contact"] + [it.accepted.label for it in release if it.accepted]
        rel_gaps = [release[0].gap_before] + [it.accepted.gap_after for it in release if it.accepted]
        panels.append((axes[0, 1], rel_labels, rel_gaps, "through the release"))
    for ax, names, values_gap, title in panels:
        values = [1e3 * g.position_m if position else g.on_velocity for g in values_gap]
        ax.bar(range(len(values)), values, color="tab:blue", label="held-out systematic error")
        if position:
            ax.axhline(1e3 * values_gap[0].sigma_m, color="tab:grey", ls=":", label="noise σ")
        ax.set_xticks(range(len(values)), names, rotation=20)
        ax.set_ylabel(f"held-out systematic error ({unit})")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return figure_html(fig, "Held-out gap of the base model and after each accepted effect"
                       + ("; right: the release, modelled past lift-off (a longer window)" if release else ""))


def build_discover_report(result: DiscoveryResult, path: Path, *, model_path: Path | None = None) -> Path:
    """Write the HTML report of a discovery run."""
    summary = Section("Decision")
    for line in result.decision_line.splitlines():
        summary.add(paragraph(line))
    summary.add(paragraph(f"Verdict: {result.verdict}"))
    drive = ("the measured arm trace drives the model" if result.mode == "trajectories"
             else "the commanded presses drive the model (MIDI only)")
    summary.add(paragraph(
        f"{result.n_train} training and {result.n_held_out} held-out keystrokes (whole keystrokes, every third of "
        f"each vacuum level by speed); {drive}. Acceptance: {result.rule.describe()}. ΔIC: Gaussian likelihood "
        "with each channel's systematic-plus-noise error, on the effective number of independent samples "
        "(residuals along a keystroke are correlated); above 10 is strong evidence.", note=True))
    for finding in result.findings:
        summary.add(paragraph(f"Measured: {finding.text}" + (" (in the model)" if finding.accepted else "")))
    for note in result.notes:
        summary.add(paragraph(f"Data: {note}", note=True))
    if model_path is not None:
        summary.add(paragraph(f"Updated model file: {model_path.name}"))
    base = Section("Base model (fitted on the training keystrokes)").add(table_html(params_frame(result)))
    if result.base_on_bounds:
        base.add(paragraph("Parameters on a bound are not pinned by these data: " + ", ".join(result.base_on_bounds),
                           note=True))
    sections = [summary, base, Section("Held-out gap").add(_gap_figure(result))]
    for it in result.iterations:
        title = it.accepted.label if it.accepted else "nothing accepted"
        sec = Section(f"{it.heading}: {title}")
        sec.add(paragraph(f"Held-out gap of the current model: {it.gap_before.text()}."))
        if it.verdicts:
            sec.add(table_html(candidate_frame(result, it.index), caption="Candidates (best ΔIC first)"))
        else:
            sec.add(paragraph("The held-out error is at the noise level: no effect can be judged, so no candidate "
                              "was fitted.", note=True))
        for v in it.dropped:
            sec.add(paragraph(f"Then {dropped_text(v)}."))
        if it.proposals:
            props = pd.DataFrame([{"term": p.term, "family": p.family or "", "share": round(p.share, 3)}
                                  for p in it.proposals])
            sec.add(table_html(props, caption="Residual search (sparse regression): best-supported terms"))
        sections.append(sec)
    stages = stage_frame(result)
    if not stages.empty:
        sections.append(Section("Residual by keystroke stage (held-out)").add(table_html(stages)))
    regions = pd.DataFrame(result.iterations[0].before.regions)
    if not regions.empty:
        sections.append(Section("Residual by parameter region (held-out, base model)").add(table_html(regions)))
    outcomes = result.iterations[0].before.outcomes
    if outcomes:
        sections.append(Section("MIDI outcomes (held-out, base model)").add(
            table_html(pd.DataFrame([{"measure": k, "value": v} for k, v in outcomes.items()]))))
    sections.append(Section("Held-out keystrokes").add(_overlay(result)))
    if result.release is not None:
        sections.append(Section("The release, past lift-off").add(_release_overlay(result)))
    return write_page(path, "pianobot discover", sections, subtitle=result.verdict)
