"""`pianobot discover`: find where simulation and measurement disagree, name the missing effect.

The loop (DESIGN.md, "Discovery"):

1. fit the starting model's base parameters on the training keystrokes, so that a wrong
   stiffness is never mistaken for missing physics;
2. localise the disagreement on the held-out keystrokes (by phase, region, state, outcome);
3. fit every effect of the vocabulary that the model lacks, jointly with the base parameters,
   by simulation error on the training keystrokes; STLSQ on the residual key force proposes
   which families to look at first (it never decides);
4. accept the best candidate only if it passes the calibrated rule (`discover_decide`); repeat
   until nothing passes, then say whether what is left looks like noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from pianobot.analysis.discover import model as dm
from pianobot.analysis.discover import params as dp
from pianobot.analysis.discover.data import Keystroke, stratified_split
from pianobot.analysis.discover.decide import Candidate, DecisionRule, choose
from pianobot.analysis.discover.fit import FitResult, bic, fit
from pianobot.analysis.discover.load import load_keystrokes, resolve_model
from pianobot.analysis.discover.localise import Localisation, localise
from pianobot.analysis.discover.result import DiscoveryResult, Iteration, decision_line, verdict
from pianobot.errors import InputError
from pianobot.physics.model import KeystrokeModel, save_model


@dataclass(frozen=True)
class DiscoverySettings:
    """Knobs of the discovery loop; the defaults are what the scenario suite is tested with."""

    held_out_fraction: float = 0.33
    rule: DecisionRule = field(default_factory=DecisionRule)
    max_iterations: int = 6
    bootstrap_samples: int = 2
    max_nfev: int = 20
    screen_nfev: int = 12  # screening fits (effect parameters only) stop earlier
    joint_refits: int = 2  # candidates refit jointly with the base after screening
    seed: int = 0
    # Lag-1 autocorrelation of the held-out residual below which it "looks like noise".
    noise_lag1: float = 0.5
    # ... and a systematic error below this fraction of the noise level counts as explained.
    noise_fraction: float = 1.0


def _chi2(model: KeystrokeModel, keystrokes: Sequence[Keystroke], weights: dm.Weights) -> float:
    r = dm.residual_vector(keystrokes, dm.predict(model, keystrokes, states=False), weights)
    return float(r @ r)


def _fit_model(
    model: KeystrokeModel,
    effect: str | None,
    keystrokes: Sequence[Keystroke],
    weights: dm.Weights,
    max_nfev: int,
    *,
    base: bool = True,
) -> tuple[KeystrokeModel, FitResult]:
    """Fit base parameters and/or one effect's parameters by simulation error.

    `effect` must already be on in `model` (its current values are the start); `base=False`
    keeps the base parameters fixed (the screening fit), but the information criterion still
    counts them, so screened and joint fits compare on one scale.
    """
    base_specs = dp.base_specs(model, keystrokes)
    specs = list(base_specs) if base else []
    if effect is not None:
        specs += dp.effect_specs(model, effect)

    def residuals(values: dict[str, float]) -> np.ndarray:
        trial = dp.apply_values(model, values)
        return dm.residual_vector(keystrokes, dm.predict(trial, keystrokes, states=False), weights)

    result = (
        fit(specs, residuals, max_nfev=max_nfev) if max_nfev or not specs else fit([], residuals)
    )
    if not base:
        result = replace(result, bic=bic(result.chi2, len(specs) + len(base_specs), result.n))
    return dp.apply_values(model, result.as_dict()), result


def _screen(
    current: KeystrokeModel,
    effect: str,
    keystrokes: Sequence[Keystroke],
    weights: dm.Weights,
    max_nfev: int,
) -> tuple[KeystrokeModel, FitResult]:
    """Fit one effect with the base fixed, from the best of a few starting points."""
    candidate = dp.with_effect(current, effect)
    starts = [
        dp.apply_values(candidate, start)
        for start in dp.start_points(candidate, effect, keystrokes)
    ]
    best = min(starts, key=lambda m: _chi2(m, keystrokes, weights))
    return _fit_model(best, effect, keystrokes, weights, max_nfev, base=False)


def _bootstrap(
    base: KeystrokeModel,
    effect: str,
    train: Sequence[Keystroke],
    weights: dm.Weights,
    settings: DiscoverySettings,
    rng: np.random.Generator,
) -> tuple[float, ...]:
    """ΔBIC the candidate wins on data simulated from the base model (no effect): the null."""
    out = []
    predictions = dm.predict(base, train)
    for _ in range(settings.bootstrap_samples):
        synthetic = dm.synthesise(train, predictions, weights, rng)
        _, null_base = _fit_model(base, None, synthetic, weights, settings.max_nfev)
        screened, _ = _screen(base, effect, synthetic, weights, settings.screen_nfev)
        _, null_cand = _fit_model(screened, effect, synthetic, weights, settings.max_nfev)
        out.append(null_base.bic - null_cand.bic)
    return tuple(out)


# Below these a held-out measure is at its noise floor and its ratio means nothing.
_POSITION_FLOOR_SIGMAS = 0.3
_VELOCITY_FLOOR = 0.3


def _primary_or_nan(before: Localisation, weights: dm.Weights) -> float:
    """The primary gap, or NaN when it is at the noise floor (then other measures decide)."""
    g = before.gap
    floor = (
        _POSITION_FLOOR_SIGMAS * weights.sigma_m
        if g.primary_name == "position_m"
        else _VELOCITY_FLOOR
    )
    return g.primary if g.primary > floor else float("nan")


def _other_gaps(before: Localisation, after: Localisation) -> tuple[tuple[str, float, float], ...]:
    """On-velocity gap before/after when it is not the primary and above its floor."""
    b, a = before.gap, after.gap
    if (
        b.primary_name == "on_velocity"
        or not np.isfinite(b.on_velocity)
        or b.on_velocity <= _VELOCITY_FLOOR
    ):
        return ()
    return (("on_velocity", b.on_velocity, a.on_velocity),)


def discover(
    keystrokes: Sequence[Keystroke],
    model: KeystrokeModel,
    settings: DiscoverySettings | None = None,
) -> DiscoveryResult:
    """Run the discovery loop on measured keystrokes, starting from `model`."""
    settings = settings or DiscoverySettings()
    keystrokes = list(keystrokes)
    train_idx, held_idx = stratified_split(keystrokes, settings.held_out_fraction, settings.seed)
    train = [keystrokes[i] for i in train_idx]
    held = [keystrokes[i] for i in held_idx]
    rng = np.random.default_rng(settings.seed)

    weights = dm.estimate_weights(train, dm.predict(model, train))
    base, _ = _fit_model(model, None, train, weights, settings.max_nfev)
    weights = dm.estimate_weights(train, dm.predict(base, train))
    current, current_fit = base, None
    held_before = tuple(dm.predict(base, held))
    iterations: list[Iteration] = []
    for index in range(settings.max_iterations):
        # The current model is already fitted (base first, then jointly with each accepted
        # effect): its χ² with the base parameters counted is the reference for ΔBIC.
        _, current_fit = _fit_model(current, None, train, weights, 0, base=False)
        predictions_held = dm.predict(current, held)
        before = localise(held, predictions_held, sigma_m=weights.sigma_m)
        proposals = dm.sparse_proposals(current, train, dm.predict(current, train))
        pending: list[Candidate] = []
        fitted: dict[str, KeystrokeModel] = {}
        screened: dict[str, tuple[KeystrokeModel, FitResult]] = {}
        for effect in dp.candidate_effects(current, train, proposals):
            screened[effect] = _screen(current, effect, train, weights, settings.screen_nfev)
        # Joint refits (base + effect) for the most promising candidates only: screening with
        # the base fixed already ranks them, and the decision uses the joint fit.
        ranked = sorted(screened, key=lambda e: screened[e][1].bic)
        for effect in ranked:
            cand_model, cand_fit = screened[effect]
            if effect in ranked[: settings.joint_refits] and current_fit.bic - cand_fit.bic > 0:
                cand_model, cand_fit = _fit_model(
                    cand_model, effect, train, weights, settings.max_nfev
                )
            after = localise(held, dm.predict(cand_model, held), sigma_m=weights.sigma_m)
            names = tuple(n for n in cand_fit.names if n.startswith(effect + "."))
            pending.append(
                Candidate(
                    effect=effect,
                    fit=cand_fit,
                    effect_params=names,
                    off_values=dp.off_values(names),
                    delta_bic=current_fit.bic - cand_fit.bic,
                    gap_before=_primary_or_nan(before, weights),
                    gap_after=after.gap.primary,
                    other_gaps=_other_gaps(before, after),
                    proposed_by=("sparse",) if any(p.family == effect for p in proposals) else (),
                )
            )
            fitted[effect] = cand_model
        best = max(pending, key=lambda c: c.delta_bic, default=None)
        null: tuple[float, ...] = ()
        if (
            best is not None
            and best.delta_bic > settings.rule.bic_margin
            and settings.bootstrap_samples
        ):
            null = _bootstrap(current, best.effect, train, weights, settings, rng)
        threshold = settings.rule.threshold(null)
        accepted, judged = choose(pending, settings.rule, threshold)
        after_loc = None
        if accepted is not None:
            current = fitted[accepted.effect]
            after_loc = localise(held, dm.predict(current, held), sigma_m=weights.sigma_m)
        iterations.append(
            Iteration(index, before, after_loc, tuple(judged), accepted, threshold, null, proposals)
        )
        if accepted is None:
            break
    held_after = tuple(dm.predict(current, held))
    final = localise(held, list(held_after), sigma_m=weights.sigma_m)
    text, explained = verdict(iterations, final, settings.noise_lag1, settings.noise_fraction)
    return DiscoveryResult(
        iterations=tuple(iterations),
        start_model=model,
        base_model=base,
        final_model=current,
        verdict=text,
        explained=explained,
        decision_line=decision_line(iterations),
        n_train=len(train),
        n_held_out=len(held),
        held_out_ids=tuple(k.key_id for k in held),
        predictions_before=held_before,
        predictions_after=held_after,
        held_out=tuple(held),
    )


def discover_runs(
    run_ids: Sequence[str],
    data_dir: Path,
    model: str = "study",
    *,
    seed: int = 0,
    model_out: Path | None = None,
    vacuum_kpa: float | None = None,
) -> DiscoveryResult:
    """Load runs, run discovery from `model` ("study" or a model file), save the final model.

    Raises:
        InputError: unknown runs, runs without mocap or MIDI, a bad model file.
    """
    notes: set[str] = set()
    keystrokes = load_keystrokes(run_ids, data_dir, vacuum_kpa, notes)
    if len(keystrokes) < 6:
        raise InputError(f"discovery needs at least 6 keystrokes, got {len(keystrokes)}", "RUN_ID")
    result = discover(keystrokes, resolve_model(model), DiscoverySettings(seed=seed))
    result = replace(result, notes=tuple(sorted(notes)))
    if model_out is not None:
        intervals = {
            name: [lo, hi]
            for it in result.iterations
            if it.accepted
            for name, lo, hi in zip(
                it.accepted.fit.names,
                it.accepted.fit.lower_ci,
                it.accepted.fit.upper_ci,
                strict=True,
            )
        }
        save_model(
            result.final_model,
            model_out,
            intervals=intervals,
            provenance={
                "command": "discover",
                "runs": list(run_ids),
                "start_model": model,
                "accepted_effects": list(result.accepted_effects),
                "verdict": result.verdict,
            },
        )
    return result
