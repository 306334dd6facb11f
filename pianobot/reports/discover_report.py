"""The discovery report: decision line, candidate tables, residual by phase, worst overlays."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from pianobot.analysis.discover.data import SIGNALS
from pianobot.analysis.discover.result import DiscoveryResult
from pianobot.reports.html import Section, figure_html, paragraph, table_html, write_page


def candidate_frame(result: DiscoveryResult, index: int) -> pd.DataFrame:
    """One iteration's candidate table (effect, parameters ± CI, ΔBIC, held-out gap, status)."""
    rows = []
    for c in result.iterations[index].candidates:
        d = c.to_dict()
        params = "; ".join(
            f"{name.split('.', 1)[1]}={v['value']:.4g} [{v['ci95'][0]:.3g}, {v['ci95'][1]:.3g}]"
            for name, v in d["params"].items()
        )
        rows.append(
            {
                "effect": c.effect,
                "family": d["family"],
                "parameters (95 % CI)": params or "(switch)",
                "ΔBIC": c.delta_bic,
                "held-out gap before": c.gap_before,
                "after": c.gap_after,
                "shrink %": 100 * c.gap_reduction,
                "sparse": "yes" if c.proposed_by else "",
                "status": c.status,
                "why not": "; ".join(c.reasons),
            }
        )
    return pd.DataFrame(rows)


def phase_frame(result: DiscoveryResult) -> pd.DataFrame:
    """Held-out systematic error per phase and signal, before (base model) and after (final)."""
    first = result.iterations[0].before
    last = result.iterations[-1].after or result.iterations[-1].before
    after = {(r["phase"], r["signal"]): r for r in last.phases}
    rows = []
    for r in first.phases:
        a = after.get((r["phase"], r["signal"]), {})
        rows.append(
            {
                "phase": r["phase"],
                "signal": r["signal"],
                "n": r["n"],
                "systematic before mm": 1e3 * r["systematic_m"],
                "after mm": 1e3 * a.get("systematic_m", float("nan")),
                "bias before mm": 1e3 * r["bias_m"],
                "lag-1 before": r["lag1"],
                "lag-1 after": a.get("lag1", float("nan")),
            }
        )
    return pd.DataFrame(rows)


def _overlay(result: DiscoveryResult, count: int = 3) -> str:
    """The held-out keystrokes the base model fits worst, measured vs before vs after."""
    ks, before, after = result.held_out, result.predictions_before, result.predictions_after
    scores = [
        float(np.nanmean((k.x_m - p.x_m) ** 2)) if k.has_motion else -1.0
        for k, p in zip(ks, before, strict=True)
    ]
    order = [i for i in np.argsort(scores)[::-1][:count] if scores[i] >= 0]
    if not order:
        return paragraph("No motion capture: overlays need measured trajectories.", note=True)
    fig, axes = plt.subplots(len(order), 1, figsize=(9, 2.8 * len(order)), squeeze=False)
    for ax, i in zip(axes[:, 0], order, strict=True):
        k = ks[i]
        for s, colour in ((0, "tab:grey"), (1, "tab:blue"), (2, "tab:red")):
            ax.plot(k.t_s, 1e3 * k.x_m[s], ".", ms=2, color=colour, label=f"measured {SIGNALS[s]}")
            ax.plot(k.t_s, 1e3 * before[i].x_m[s], "--", lw=1, color=colour)
            ax.plot(k.t_s, 1e3 * after[i].x_m[s], "-", lw=1, color=colour)
        ax.set_title(
            f"{k.key_id}: {k.vacuum_kpa:g} kPa, {1e3 * k.press.down_velocity_mps:.0f} mm/s"
        )
        ax.set_ylabel("mm (down +)")
    axes[-1, 0].set_xlabel("t since motion start (s)")
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=3)
    fig.tight_layout()
    return figure_html(
        fig, "Worst held-out keystrokes: dots measured, dashed base model, solid final model"
    )


def _gap_figure(result: DiscoveryResult) -> str:
    labels = ["base"] + [it.accepted.effect for it in result.iterations if it.accepted]
    gaps = [result.iterations[0].before.gap.primary] + [
        it.after.gap.primary for it in result.iterations if it.accepted and it.after
    ]
    name = result.iterations[0].before.gap.primary_name
    scale, unit = (1e3, "mm") if name == "position_m" else (1.0, "MIDI velocity")
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.bar(range(len(gaps)), [scale * g for g in gaps], color="tab:blue")
    ax.set_xticks(range(len(gaps)), labels, rotation=20)
    ax.set_ylabel(f"held-out systematic ({unit})")
    return figure_html(fig, "Held-out gap after each accepted effect")


def build_discover_report(
    result: DiscoveryResult, path: Path, *, model_path: Path | None = None
) -> Path:
    """Write the HTML report of a discovery run."""
    summary = Section("Decision")
    for line in result.decision_line.splitlines():
        summary.add(paragraph(line))
    summary.add(paragraph(f"Verdict: {result.verdict}"))
    summary.add(
        paragraph(
            f"{result.n_train} training and {result.n_held_out} held-out keystrokes (split by keystroke, "
            "stratified by vacuum and speed). A candidate is accepted when its ΔBIC beats the threshold "
            "(margin, raised by a parametric bootstrap of the fitted model), it shrinks the held-out "
            "systematic error √(RMS² − σ²) by the stated fraction, and a parameter interval excludes 'off'.",
            note=True,
        )
    )
    for note in result.notes:
        summary.add(paragraph(f"Assumed: {note}", note=True))
    if model_path is not None:
        summary.add(paragraph(f"Updated model file: {model_path.name}"))
    sections = [summary, Section("Gap").add(_gap_figure(result))]
    for it in result.iterations:
        sec = Section(
            f"Iteration {it.index + 1}: {it.accepted.effect if it.accepted else 'nothing accepted'}"
        )
        sec.add(
            paragraph(
                f"ΔBIC threshold {it.threshold:.1f} (bootstrap null ΔBIC: {', '.join(f'{x:.1f}' for x in it.bootstrap_delta_bic) or 'not needed'})"
            )
        )
        sec.add(table_html(candidate_frame(result, it.index), caption="Candidates"))
        if it.proposals:
            props = pd.DataFrame(
                [{"term": p.term, "family": p.family, "share": p.share} for p in it.proposals]
            )
            sec.add(
                table_html(
                    props, caption="Sparse regression (STLSQ) on the residual key force: proposals"
                )
            )
        sections.append(sec)
    phases = phase_frame(result)
    if not phases.empty:
        sections.append(Section("Residual by phase (held-out)").add(table_html(phases)))
    regions = pd.DataFrame(result.iterations[0].before.regions)
    if not regions.empty:
        sections.append(
            Section("Residual by region (held-out, base model)").add(table_html(regions))
        )
    sections.append(Section("Worst held-out keystrokes").add(_overlay(result)))
    return write_page(path, "pianobot discover", sections, subtitle=result.verdict)
