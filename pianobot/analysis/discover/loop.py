"""`pianobot discover`: find where simulation and measurement disagree, name the missing effect.

The loop (DESIGN.md, "Discovery"):

1. split the keystrokes into training and held-out ones (`greybox.split`);
2. check what is measured directly (`measured.py`): the arm's acceleration and lag against the
   arm trace, the mocap clock against the arm log, the piano's velocity map against the key;
3. fit the base model on the training keystrokes as identification does (`search.base_fit`),
   so that a wrong stiffness is never mistaken for missing physics;
4. localise the disagreement on the held-out keystrokes (`localise.py`);
5. fit every candidate effect the model lacks (`candidates.py`, `search.py`), judge each with
   the calibrated rule (`decide.py`), accept the best that passes (on a MIDI log refitted from
   each of its starting points, `search.restarted`), and repeat with it in the model until
   nothing passes; after each acceptance, an effect accepted in an earlier round is refitted out
   of the model and dropped where it would no longer be accepted on top of the others (the
   backward step, `_pruned`: an early effect that imitated a later one's misfit);
6. when nothing passes but the held-out error is above the noise, the sparse residual search
   names the best-supported term and the discrepancy is reported as unexplained;
7. when the fingertips were tracked off the key, the release is judged too (`_release`): the
   model window is extended past lift-off, where unilateral `contact` (reported with the
   measured checks) and a sticking pad (`adhesion`, a candidate) show.

Candidate fits are independent pieces of work, run through `mapper` (default: one after the
other), which is what a parallel executor replaces.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from threadpoolctl import threadpool_limits

from pianobot.analysis.discover import search
from pianobot.analysis.discover.candidates import CandidateSpec, candidates, size_params
from pianobot.analysis.discover.decide import (
    Rule,
    Verdict,
    choose,
    judge,
    something_to_explain,
    verdict,
)
from pianobot.analysis.discover.localise import localise
from pianobot.analysis.discover.measured import (
    MeasuredCheck,
    arm_checks,
    clock_check,
    readout_check,
)
from pianobot.analysis.discover.result import (
    DiscoveryResult,
    Iteration,
    ReleaseView,
    in_model,
    verdict_text,
)
from pianobot.analysis.discover.search import Evaluated, Setting
from pianobot.analysis.discover.sparse import Proposal, outcome_proposals, trajectory_proposals
from pianobot.analysis.greybox.covariance import Z95
from pianobot.analysis.greybox.fitter import GreyBoxFit
from pianobot.analysis.greybox.forward import lifts_off
from pianobot.analysis.greybox.hover import (
    HOVER_NOTE_START,
    HoverCorrection,
    corrected_hover,
    read_hover,
)
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.pieces import Mapper, serial_map
from pianobot.analysis.greybox.split import holdout_indices
from pianobot.analysis.identify.fit import rms_x2_m
from pianobot.physics.model import KeystrokeModel
from pianobot.progress import NO_PROGRESS, Progress

#: A candidate's label -> the values (its own and the readout's) it reached in the last round.
Starts = dict[str, dict[str, float]]


@dataclass(frozen=True)
class Settings:
    """Knobs of the discovery loop; the defaults are what the benchmark suites run."""

    rule: Rule = field(default_factory=Rule)
    holdout_every: int = 3  # every 3rd keystroke (per level, by speed) is held out
    max_iterations: int = 3
    joint_refits: int = 3  # candidates refitted jointly with the base after screening
    seed: int = 0


def _intervals(fit: GreyBoxFit, names: Sequence[str]) -> dict[str, tuple[float, float]]:
    """95 % intervals of named parameters from the fitter's covariance, within each parameter's
    physical range: a force or a stiffness never reaches below 0 (an interval "[-0.028, 0.039] N"
    for a friction force said nothing the clipped "[0, 0.039] N" does not, and read as nonsense;
    an interval that reaches "off" still includes it)."""
    cov = fit.covariance()
    out = {}
    for name in names:
        j = fit.layout.names.index(name)
        p = fit.layout.params[j]
        sd = math.sqrt(max(float(cov[j, j]), 0.0))
        u = float(fit.theta_[j])
        if sd < 50:
            lo, hi = p.from_internal(u - Z95 * sd), p.from_internal(u + Z95 * sd)
            out[name] = (max(lo, p.lower), min(hi, p.upper))
        else:
            out[name] = (-math.inf, math.inf)
    return out


def _verdict(e: Evaluated, current: Evaluated, rule: Rule, with_intervals: bool) -> Verdict:
    spec = e.spec
    assert spec is not None
    names = [p.name for p in e.fit.layout.params if p.group == spec.effect]
    intervals = _intervals(e.fit, names) if with_intervals and names else {}
    sizes = size_params(e.fit.layout, spec.effect)
    excludes = True
    if sizes and intervals:
        excludes = any(not (intervals[p.name][0] <= (p.off or 0.0) <= intervals[p.name][1]) for p in sizes)
    elif sizes:
        excludes = False  # not computed: judged only when the other conditions hold
    return verdict(spec.label, spec.effect, spec.form, {n: e.fit.params_[n] for n in names}, intervals,
                   tuple(n for n in e.fit.on_bounds_ if n in names), current.ic - e.ic, current.gap, e.gap,
                   excludes, e.joint)


def _evidence(v: Verdict, rule: Rule) -> bool:
    """The candidate improved the criterion and the held-out gap by the rule's margins."""
    return v.delta_ic > rule.ic_margin and v.shrink >= rule.min_shrink


def _bent_base(setting: Setting, reference: Evaluated, fits: Sequence[Evaluated], index: int, rule: Rule) -> bool:
    """The first round of a take's trajectories, a base misfit over `BENT_BASE_SIGMAS` of the
    noise, and no candidate with evidence of its own."""
    gap = reference.gap
    return (index == 0 and setting.mode == "trajectories" and gap.position_m > BENT_BASE_SIGMAS * gap.sigma_m
            and not any(_evidence(_verdict(e, reference, rule, False), rule) for e in fits))


def _promising(v: Verdict, rule: Rule) -> bool:
    return _evidence(v, rule) and v.consistency >= rule.min_consistency


def _iterate(setting: Setting, current: GreyBoxFit, start: KeystrokeModel, settings: Settings, sigma_m: float,
             index: int, progress: Progress, mapper: Mapper,
             earlier: Mapping[str, Mapping[str, float]],
             only: tuple[str, ...] | None = None) -> tuple[Iteration, GreyBoxFit | None, Starts]:
    """One round of candidates against `current`, and the starts it leaves for the next round.

    `earlier` maps a candidate's label to the values it reached in the previous round when it
    had evidence there (a second start for it in this one); `only` restricts the candidates to
    these effects."""
    rule = settings.rule
    criterion = search.criterion_of(current)
    reference = search.evaluate(setting, current, criterion, sigma_m, "current", None)
    explainable = something_to_explain(reference.gap, rule)
    before = localise(search.on_held(setting, current), sigma_m)
    if not explainable:
        # No candidate can pass (condition 2 of the rule fails for all alike): fitting them
        # would cost most of a clean take's discovery and decide nothing.
        return Iteration(index, reference.gap, before, (), None, None, explainable, window=setting.window), None, {}
    specs = [c for c in candidates(current.model_, setting.train) if only is None or c.effect in only]
    total = len(specs) + min(settings.joint_refits, len(specs))
    with progress.task(f"discover, iteration {index + 1}: candidate fits", total=total) as task:
        def screen_one(spec: CandidateSpec) -> Evaluated:
            screened = search.screen(setting, current, spec, earlier.get(spec.label))
            full = search.as_full(setting, current, spec, screened)
            return search.evaluate(setting, full, criterion, sigma_m, spec.label, spec, joint=False)

        evaluated = []
        for e in mapper(screen_one, specs):  # progress advances here, as results come back
            evaluated.append(e)
            task.advance(note=e.label)
        order = [e.label for e in sorted(evaluated, key=lambda e: e.ic)]
        by_label = {e.label: e for e in evaluated}

        # The screened fits travel inside the function (sent to each worker once), the tasks
        # carry only their labels: a fit holds the keystrokes (tens of MB).
        def refit(label: str) -> Evaluated:
            e = by_label[label]
            assert e.spec is not None
            # The screened values are a start of their own only where screening saw the effect,
            # in trajectories (a base fit bent to imitate friction there); on MIDI logs they
            # changed no finding (20 independent and 3 study logs).
            fit = search.joint(setting, current, e.spec, e.fit, start, from_screened=(
                setting.mode == "trajectories" and reference.ic - e.ic > rule.ic_margin))
            joint = search.evaluate(setting, fit, criterion, sigma_m, e.label, e.spec)
            return joint if joint.ic <= e.ic else e

        refitted: dict[str, Evaluated] = {}

        def refit_all(labels: list[str]) -> None:
            """Refit `labels` jointly with the base, the progress bar's total grown to hold them."""
            if labels:
                task.update(total=max(total, len(specs) + len(refitted) + len(labels)))
            for e in mapper(refit, labels):
                refitted[e.label] = e
                task.advance(note=f"{e.label} (joint)")

        refit_all(order[: settings.joint_refits])
        # Refitted with the base too: the other forms of an effect refitted with evidence, and the
        # candidates that had evidence in the last round. Screened on a fixed base, the forms of
        # one effect rank poorly from a base that bent to imitate one of them (the truth lab's
        # exponential finger was named as a power law, the form refitted), and a candidate that
        # lost a round may help only once the base moves with it (an independent take's yielding
        # finger body: ΔIC -21 screened after the stiffening was accepted, yield share 0.0008
        # against 0.60 a round before; refitted, it was named and the gap fell 0.11 mm → 0.006 mm).
        # Where nothing refitted has evidence, as on a clean take, the forms cost nothing.
        effects = {e.spec.effect for e in refitted.values()
                   if e.spec is not None and _evidence(_verdict(e, reference, rule, False), rule)}
        also = [k for k in order[settings.joint_refits :]
                if ((s := by_label[k].spec) is not None and s.effect in effects) or k in earlier]
        refit_all(also)
        rest = [k for k in order[settings.joint_refits :] if k not in also]
        if rest and _bent_base(setting, reference, list(refitted.values()) + [by_label[k] for k in rest], index, rule):
            # A misfit well above the noise, and no candidate has evidence of its own, screened or
            # refitted: the base fit may have bent to imitate the missing effect, so far that no
            # effect helps on top of it (a rest stop read as a finger 9x softer than it is, where
            # the preload screened last). The other candidates are then refitted too.
            refit_all(rest)
    final = [refitted.get(e.label, e) for e in evaluated]
    verdicts = [_verdict(e, reference, rule, False) for e in final]
    # A candidate with evidence of its own (ΔIC and held-out shrink) that was not accepted keeps
    # its values as a start for the next round; one without evidence starts afresh there.
    starts: Starts = {e.label: {k: x for k, x in e.fit.params_.items() if k.split(".", 1)[0] in (e.spec.effect, "readout")}
                      for e, v in zip(final, verdicts, strict=True)
                      if e.spec is not None and _evidence(v, rule)}
    # Intervals (a central Jacobian and noise draws each) only where the rest of the rule holds,
    # and only at an optimum: away from it the residuals still hold the misfit the fit was about
    # to remove, and the sandwich covariance reads it as uncertainty of the effect's size.
    for i, (e, v) in enumerate(zip(final, verdicts, strict=True)):
        if not _promising(v, rule):
            continue
        if not e.fit.converged_:
            assert e.spec is not None
            with progress.task(f"discover, iteration {index + 1}: {e.label} fitted to its optimum", total=None):
                done = search.converged(setting, e.fit)
            e = search.evaluate(setting, done, criterion, sigma_m, e.label, e.spec, e.joint)
            final[i] = e
        verdicts[i] = _verdict(e, reference, rule, True)
    accepted, judged = choose(verdicts, rule, explainable)
    chosen = next((e.fit for e in final if accepted is not None and e.label == accepted.label), None)
    after = None
    if chosen is not None:
        after = localise(search.on_held(setting, chosen), sigma_m)
    return Iteration(index, reference.gap, before, tuple(judged), accepted, after, explainable,
                     window=setting.window), chosen, starts


#: The base fit's held-out systematic error, in noise σ, above which a first round in which no
#: candidate has evidence after the usual joint refits refits the others too (`_bent_base`). Smaller
#: misfits (clean deep takes of the independent suite: 1.6-3.2 σ) cannot hide an effect that
#: bent the base far, and every joint fit costs a fit of the whole model.
BENT_BASE_SIGMAS = 5.0


#: Training keystrokes whose fingertip must have left the key for the release to be judged.
MIN_RELEASES = 3


def _pruned(setting: Setting, current: GreyBoxFit, base: GreyBoxFit, kept: Sequence[Verdict], settings: Settings,
            sigma_m: float, progress: Progress) -> tuple[GreyBoxFit, tuple[Verdict, ...]]:
    """The backward step: each effect accepted before the latest one (`kept[:-1]`) is refitted out
    of the model, and judged as a candidate added back to that refit. The one with the least ΔIC
    among those that would not pass (no ΔIC, no held-out shrink, or nothing left to explain) is
    dropped: the model and the verdict that dropped it are returned.

    Forward selection alone keeps whatever an early round accepted for part of a misfit a later
    effect explains. On an independent take whose finger stiffens as a tangent of its compression
    (capped), a yielding finger body was accepted first and the power form second; refitted
    without the body, the held-out gap grew 19x, so it stays: the candidates need it for that
    form. A test on truth takes drops a key friction accepted before a stop on a clean take."""
    rule = settings.rule
    criterion = search.criterion_of(current)
    with_all = search.evaluate(setting, current, criterion, sigma_m, "current", None)
    weak: list[tuple[Verdict, GreyBoxFit]] = []
    with progress.task("discover: is each earlier effect still needed?", total=len(kept) - 1) as task:
        for v in kept[:-1]:
            spec = CandidateSpec(v.effect, v.form)
            fit = search.without(setting, current, v.effect, base)
            out = search.evaluate(setting, fit, criterion, sigma_m, v.label, None)
            back = _verdict(Evaluated(v.label, spec, current, with_all.ic, with_all.gap), out, rule, False)
            if not (_evidence(back, rule) and something_to_explain(out.gap, rule)):
                weak.append((judge(back, rule, something_to_explain(out.gap, rule)), fit))
            task.advance(note=v.label)
    if not weak:
        return current, ()
    verdict_, fit = min(weak, key=lambda w: w[0].delta_ic)
    return search.converged(setting, fit), (replace(verdict_, status="dropped"),)


def _release(setting: Setting, current: GreyBoxFit, start: KeystrokeModel, settings: Settings, index: int,
             progress: Progress, mapper: Mapper) -> tuple[MeasuredCheck | None, list[Iteration], GreyBoxFit,
                                                          ReleaseView | None]:
    """The release judged past lift-off (step 7 of the module docstring): the contact check, the
    adhesion round, the model after them, and the held-out release before and after.

    That the finger leaves the key is a property of every real finger and key (the study's
    bilateral coupling lacks it), so it is reported with the measured checks, not as a
    discovery (`_contact`). A pad that sticks (`adhesion`) is then a candidate like those before
    lift-off. Each round re-reads the current model's error levels on the longer window, so its
    candidates stand on one scale with it."""
    if setting.mode != "trajectories":
        return None, [], current, None
    off_train, off_held = lifts_off(setting.train), lifts_off(setting.held)
    if off_train.sum() < MIN_RELEASES or not off_held.any():
        return None, [], current, None
    release = Setting.of(setting.train, setting.held, "release")
    before = search.on_held(release, current).prediction_
    check = None
    rounds: list[Iteration] = []
    if "contact" not in current.model_.effects:
        with progress.task("discover: the release, past lift-off: contact", total=None):
            check, fit = _contact(release, current, start, settings.rule, int(off_train.sum()))
        current = fit or current
    if "contact" in current.model_.effects:
        here = search.on(release, current)
        iteration, chosen, _ = _iterate(release, here, start, settings, search.held_noise_m(release, here), index,
                                        progress, mapper, {}, only=("adhesion",))
        rounds.append(iteration)
        if chosen is not None:
            with progress.task(f"discover, {iteration.heading}: adhesion fitted to its optimum", total=None):
                current = search.converged(release, chosen)
    return check, rounds, current, ReleaseView(before, search.on_held(release, current).prediction_)


def _contact(release: Setting, current: GreyBoxFit, start: KeystrokeModel, rule: Rule,
             n_off: int) -> tuple[MeasuredCheck, GreyBoxFit | None]:
    """Unilateral contact against the bilateral coupling, through the release; with the fitted
    model when the evidence holds.

    Only the evidence (ΔIC) decides: a fingertip measured clear of the key is the observation,
    and a pad that sticks makes the bilateral coupling look partly right (it also pulls the key
    up), so the held-out shrink of contact alone is no test of it."""
    here = search.on(release, current)
    criterion = search.criterion_of(here)
    noise_m = search.held_noise_m(release, here)
    reference = search.evaluate(release, here, criterion, noise_m, "current", None)
    spec = CandidateSpec("contact", "default")
    screened = search.screen(release, here, spec)
    fit = search.converged(release, search.joint(release, here, spec, search.as_full(release, here, spec, screened),
                                                 start))
    e = search.evaluate(release, fit, criterion, noise_m, spec.label, spec)
    delta = reference.ic - e.ic
    left = f"the fingertip leaves the key in {n_off} of {release.train.n} training keystrokes"
    if not delta > rule.ic_margin:
        return MeasuredCheck("contact", float(n_off), (math.nan, math.nan), delta, False,
                             f"{left}; past lift-off the study's bilateral coupling fits as well (ΔIC {delta:.0f})",
                             {}), None
    return MeasuredCheck("contact", float(n_off), (math.nan, math.nan), delta, True,
                         f"{left}: past lift-off a unilateral contact fits the release better than the study's "
                         f"bilateral coupling, which pulls the key up with the finger (held-out "
                         f"{reference.gap.text()} → {e.gap.text()}, ΔIC {delta:.0f})", {}), fit


def _residual_search(setting: Setting, fit: GreyBoxFit) -> tuple[Proposal, ...]:
    """The sparse search over what the current model leaves in the training keystrokes."""
    batch, pred = fit.batch, fit.prediction_
    if setting.mode == "trajectories":
        times = batch.t_s[None, :] + batch.t_offset_s[:, None]
        return trajectory_proposals(times, batch.x0_m, batch.x1_m, batch.x2_m, batch.start_gap_m, pred.x1_m, pred.x2_m,
                                    pred.v2_mps, pred.force_n, fit.model_.msd.m2_kg)
    residual = np.full(batch.n, np.nan)
    res = fit.residuals_
    if "on_velocity" in res.values:
        residual[res.keystroke["on_velocity"]] = res.values["on_velocity"]
    return outcome_proposals(batch.down_velocity_mps, batch.acceleration_mps2, batch.depth_m, batch.vacuum_kpa, residual)


def _with_findings(model: KeystrokeModel, findings: Sequence[MeasuredCheck]) -> KeystrokeModel:
    """The model with the effects measured on the set-up switched on (they do not change what the
    measured-arm drive predicts, but a commanded press, as `play` sends, needs them)."""
    for f in findings:
        if f.accepted and f.effect not in model.effects:
            model = model.replace(effects=model.effects.with_effect(f.effect, form=None, **f.params))
    return model


#: A hover re-read through the current model that moves by less than this keeps the model as fitted.
HOVER_REREAD_M = 5e-5


def _hover_reread(batch: KeystrokeBatch, setting: Setting, hover: HoverCorrection, current: GreyBoxFit,
                  train_idx: np.ndarray, held_idx: np.ndarray, iterations: Sequence[Iteration],
                  progress: Progress) -> tuple[KeystrokeBatch, Setting, HoverCorrection, GreyBoxFit]:
    """The hover read from the take, read again through the model with the effects accepted so far
    (`greybox.hover`), and the current model refitted there where it moved by `HOVER_REREAD_M`.

    The base model's reading leaves out what an effect adds to the bias: a friction or a preload
    that holds the key back lets the pad compress further before the key is seen to move. On an
    independent weak-friction take (5.0 mm hover, read as 5.50 mm) the base model's correction
    left 5.38 mm; read through the model with the friction, 5.05 mm. The hover is a value the model reads, so each round
    judges its candidates on the current model's hover, and its gaps are those of that hover."""
    again = corrected_hover(batch, current.model_)
    if again is None or abs(again.corrected_m - hover.corrected_m) < HOVER_REREAD_M:
        return batch, setting, hover, current
    found = ", ".join(v.label for v in in_model(iterations))
    first = hover.why or f"read the same way on the fitted model: {1e3 * hover.corrected_m:.2f} mm"
    moved = HoverCorrection(again.batch, hover.read_m, again.corrected_m,
                            f"{first}, {1e3 * again.corrected_m:.2f} mm read through the model with {found}")
    setting = Setting.of(moved.batch.subset(train_idx), moved.batch.subset(held_idx))
    with progress.task(f"discover: the model refitted at the hover read through it ({1e3 * moved.corrected_m:.2f} mm)",
                       total=None):
        current = search.refitted(setting, current)
    return moved.batch, setting, moved, current


def discover(batch: KeystrokeBatch, start: KeystrokeModel | None = None, settings: Settings | None = None, *,
             notes: Sequence[str] = (), progress: Progress = NO_PROGRESS, mapper: Mapper | None = None) -> DiscoveryResult:
    """Run discovery on a batch (trajectories or MIDI only) from `start` (default: the study's
    linear model). Linear algebra runs on one BLAS thread (see `greybox.fitter`)."""
    with threadpool_limits(1, user_api="blas"):
        return _discover(batch, start, settings, notes, progress, mapper)


def _discover(batch: KeystrokeBatch, start: KeystrokeModel | None, settings: Settings | None, notes: Sequence[str],
              progress: Progress, mapper: Mapper | None) -> DiscoveryResult:
    t0 = time.perf_counter()
    settings = settings or Settings()
    start = start or KeystrokeModel.study()
    mapper = mapper or serial_map
    train_idx, held_idx = holdout_indices(batch, settings.holdout_every, settings.seed)
    if held_idx.size == 0:
        raise ValueError(f"cannot split {batch.n} keystrokes into training and held-out ones")
    setting = Setting.of(batch.subset(train_idx), batch.subset(held_idx))
    findings: list[MeasuredCheck] = []
    if setting.mode == "trajectories":
        findings += arm_checks(batch)
        findings += [f for f in (clock_check(batch), readout_check(batch)) if f is not None]
    timings: dict[str, float] = {}
    with progress.task("discover: base fit", total=None):
        base = search.base_fit(setting, start, mapper)
        # A hover read from the take reads long: corrected by reading the fitted model the same way.
        hover = corrected_hover(batch, base.model_) if setting.mode == "trajectories" and read_hover(batch) else None
        if hover is not None:
            batch = hover.batch
            notes = [*notes, hover.note()]
            setting = Setting.of(batch.subset(train_idx), batch.subset(held_idx))
            base = search.base_fit(setting, start, mapper)
    timings["base_fit_s"] = time.perf_counter() - t0
    sigma_m = search.held_noise_m(setting, base)
    held_base = search.on_held(setting, base)
    base_setting = setting
    current = base
    iterations: list[Iteration] = []
    unexplained: Proposal | None = None
    starts: Starts = {}
    for index in range(settings.max_iterations):
        if hover is not None and index > 0:
            batch, setting, hover, current = _hover_reread(batch, setting, hover, current, train_idx, held_idx,
                                                           iterations, progress)
        iteration, chosen, starts = _iterate(setting, current, start, settings, sigma_m, index, progress, mapper,
                                             starts)
        if chosen is None:
            proposals = _residual_search(setting, current) if iteration.explainable else ()
            iteration = Iteration(iteration.index, iteration.gap_before, iteration.before, iteration.verdicts,
                                  None, None, iteration.explainable, proposals)
            unexplained = next((p for p in proposals if p.family is not None), proposals[0] if proposals else None)
        iterations.append(iteration)
        if chosen is None:
            break
        label = iteration.accepted.label if iteration.accepted else "the accepted model"
        with progress.task(f"discover, iteration {index + 1}: {label} fitted to its optimum", total=None):
            if iteration.accepted is not None:
                accepted = CandidateSpec(iteration.accepted.effect, iteration.accepted.form)
                chosen = search.restarted(setting, chosen, accepted, mapper)
            current = search.converged(setting, chosen)
        if iteration.accepted is not None and len(kept := in_model(iterations)) > 1:
            current, dropped = _pruned(setting, current, base, kept, settings, sigma_m, progress)
            if dropped:
                iterations[-1] = replace(iteration, dropped=dropped,
                                         after=localise(search.on_held(setting, current), sigma_m))
    last = iterations[-1]
    press = current
    contact, release, current, release_view = _release(setting, current, start, settings, len(iterations),
                                                       progress, mapper)
    if contact is not None:
        findings.append(contact)
    # The model reported and written is the press-window fit with the effects the release found
    # (contact, a sticking pad): the release's own refit of the base parameters, over a window the
    # tables never show, went where nothing judged it (a simulated quickstart run: m1 at its lower
    # limit, k1 at a tenth of the shown value, written to --model-out).
    final = press.model_.replace(effects=current.model_.effects)
    timings["candidates_s"] = time.perf_counter() - t0 - timings["base_fit_s"]
    held_final = search.on_held(setting, press)
    final_gap = last.gap_after
    explainable = something_to_explain(final_gap, settings.rule)
    final_loc = last.after if last.accepted and last.after is not None else last.before
    iterations += release
    text, explained = verdict_text(iterations, findings, final_gap, unexplained if explainable else None,
                                   explainable, final_loc.worst_stages())
    if not explainable:
        unexplained = None
    base_rms = rms_x2_m(base_setting.held, base.model_) if setting.mode == "trajectories" else math.nan
    if hover is not None:
        notes = [n for n in notes if not n.startswith(HOVER_NOTE_START)] + [hover.note()]
    return DiscoveryResult(
        mode=setting.mode, iterations=tuple(iterations), findings=tuple(findings), start_model=start,
        base_model=base.model_, final_model=_with_findings(final, findings), base_params=dict(base.params_),
        base_on_bounds=base.on_bounds_, verdict=text, explained=explained, rule=settings.rule,
        n_train=setting.train.n, n_held_out=setting.held.n, held_out=setting.held,
        predictions_before=held_base.prediction_, predictions_after=held_final.prediction_,
        base_holdout_rms_x2_m=base_rms, unexplained=unexplained, notes=tuple(notes), release=release_view,
        seconds=time.perf_counter() - t0, timings=timings)
