"""Fitting discovery's models: the base model, and each candidate = the current model + one effect.

Every model is fitted by the one grey-box fitter on the training keystrokes, judged by one
information criterion (with the current model's effective sample sizes and error levels, so all
candidates of an iteration stand on one scale) and evaluated on the held-out keystrokes.

- Trajectories: the base fit is identification's (`identify.fit.fit_base`: measured-arm drive,
  k1 per level, c1, k2, c2, and k0, c0, m1 when the criterion wants them).
- MIDI only: the commanded drive; the finger and key stiffness, the piano's full-scale speed,
  trigger and release depths, and the arm's acceleration where it was not recorded.

A candidate is first *screened*: its effect's parameters alone, from the best of several
starting points (a stick/slip or an end stop the key never reaches has no gradient to follow),
with the current model fixed; the most promising are then refitted *jointly* with the base
parameters, so a wrong stiffness is never mistaken for missing physics.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from pianobot.analysis.discover.candidates import (
    FAMILIES,
    CandidateSpec,
    candidate_params,
    start_points,
)
from pianobot.analysis.discover.gap import Gap, held_out_gap
from pianobot.analysis.greybox.commanded import Commanded
from pianobot.analysis.greybox.criterion import Criterion
from pianobot.analysis.greybox.fitter import Drive, GreyBoxFit
from pianobot.analysis.greybox.forward import MeasuredArm, Window
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.layout import Layout, base_layout, base_params, model_values
from pianobot.analysis.greybox.pieces import Mapper, serial_map
from pianobot.analysis.identify.fit import fit_base
from pianobot.physics.model import KeystrokeModel

Mode = Literal["trajectories", "midi"]

#: Iteration limits of the screening and joint fits (function evaluations).
SCREEN_NFEV = 40
JOINT_NFEV = 80
#: The second start of a joint fit is first fitted this far (see `joint`).
JOINT_PROBE_NFEV = 15
#: An accepted model is carried on to its optimum with this budget (see `converged`).
CONVERGE_NFEV = 200


@dataclass(frozen=True)
class Setting:
    """The training and held-out keystrokes with their drives."""

    mode: Mode
    train: KeystrokeBatch
    held: KeystrokeBatch
    train_drive: Drive
    held_drive: Drive
    window: Window = "press"  # how far each trajectory is modelled (see `greybox.forward`)

    @classmethod
    def of(cls, train: KeystrokeBatch, held: KeystrokeBatch, window: Window = "press") -> Setting:
        """Trajectories are modelled until lift-off, or through the release (`window`)."""
        if train.has_motion:
            return cls("trajectories", train, held, MeasuredArm.of(train, window), MeasuredArm.of(held, window), window)
        return cls("midi", train, held, Commanded(train), Commanded(held))


@dataclass
class Evaluated:
    """One fitted model: its training fit, criterion, held-out gap and (when asked) intervals."""

    label: str
    spec: CandidateSpec | None
    fit: GreyBoxFit
    ic: float
    gap: Gap
    joint: bool = True  # refitted with the base parameters (False: screened only)
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def model(self) -> KeystrokeModel:
        return self.fit.model_

    @property
    def n_params(self) -> int:
        return int(self.fit.theta_.size)


def base_fit(setting: Setting, start: KeystrokeModel, mapper: Mapper = serial_map) -> GreyBoxFit:
    """The base model fitted on the training keystrokes (see the module docstring); `mapper`
    runs the independent fits (identify's free-coupling fits; a MIDI log's trigger starts)."""
    train = setting.train
    if setting.mode == "trajectories":
        return fit_base(train, start, "auto", mapper)
    commanded = setting.train_drive
    needs = isinstance(commanded, Commanded) and commanded.needs_acceleration
    layout = base_layout(start, train.levels_kpa, trajectories=False, readout=True, fit_acceleration=needs)
    starts = [_scaled_readout(commanded, layout, _with_trigger(layout, f)) for f in (0.2, 0.4, 0.6, 0.8)]

    def fit(theta: np.ndarray) -> GreyBoxFit:
        return GreyBoxFit(commanded, layout).fit(theta)

    # Every start is fitted (a local fit does not cross the trigger's step, and the best start
    # need not lead to the best optimum), and the fits are scored on one judge's error levels:
    # a fit scored on its own levels looks better the worse it fits.
    fits = list(mapper(fit, starts))
    judge = GreyBoxFit(commanded, layout)
    return min(fits, key=lambda f: _cost(judge, f.theta_))


def _scaled_readout(drive: Drive, layout: Layout, theta: np.ndarray) -> np.ndarray:
    """theta with the piano's full-scale speed moved so the median predicted on-velocity of the
    sounded keystrokes matches the measured median (velocity is ∝ 1/full scale for a linear map)."""
    prediction = drive.predict(layout.model(theta), layout.drive(theta))
    both = (drive.observed.sounded == 1.0) & np.isfinite(prediction.on_velocity)
    if both.sum() < 3:
        return theta
    ratio = float(np.median(prediction.on_velocity[both]) / max(np.median(drive.observed.on_velocity[both]), 1.0))
    values = layout.values(theta)
    name = "readout.full_scale_speed_mps"
    param = next(p for p in layout.params if p.name == name)
    values[name] = min(max(values[name] * ratio, param.lower), param.upper)
    return layout.internal(values)


def _with_trigger(layout: Layout, fraction: float) -> np.ndarray:
    """The layout's start with the trigger depth at `fraction` of its range (MIDI: where the
    key must reach to sound decides silence, and a local fit cannot cross that step)."""
    values = {p.name: p.start for p in layout.params}
    trigger = next(p for p in layout.params if p.name == "readout.trigger_depth_m")
    values[trigger.name] = trigger.lower + fraction * (trigger.upper - trigger.lower)
    values["readout.release_m"] = min(values.get("readout.release_m", 1e-3), 0.5 * values[trigger.name])
    return layout.internal(values)


def _cost(fit: GreyBoxFit, theta: np.ndarray) -> float:
    if not fit.sigma:
        fit.sigma = fit.error_levels(fit.raw(fit.predict(theta)))
    return _robust(fit.residuals(theta))


def _fitted_cost(fit: GreyBoxFit) -> float:
    """`_cost` at the fit's own optimum, from the residuals the fit already holds there."""
    return _robust(fit.scaled(fit.residuals_))


def _robust(r: np.ndarray) -> float:
    return float(np.sum(np.log1p(r * r)))  # robust: one diverged start does not dominate


def criterion_of(fit: GreyBoxFit) -> Criterion:
    """The criterion on `fit`'s effective sample sizes and noise levels."""
    res = fit.residuals_
    return Criterion.of(res.values, res.keystroke, res.frame, fit.noise(res))


def evaluate(setting: Setting, fit: GreyBoxFit, criterion: Criterion, noise_m: float, label: str,
             spec: CandidateSpec | None, joint: bool = True) -> Evaluated:
    """The fit's criterion on the training keystrokes and its gap on the held-out ones."""
    held = on_held(setting, fit)
    gap = held_out_gap(held.residuals_, setting.held.n, noise_m, setting.held.sounded, held.prediction_.sounded,
                       np.isfinite(held.prediction_.margin_m))
    return Evaluated(label, spec, fit, criterion.value(fit.channels_, fit.theta_.size), gap, joint)


def on(setting: Setting, fit: GreyBoxFit) -> GreyBoxFit:
    """`fit`'s model evaluated on another setting's training keystrokes (its own error levels)."""
    return GreyBoxFit(setting.train_drive, fit.layout, channels=fit.channels).evaluate(fit.theta_)


def on_held(setting: Setting, fit: GreyBoxFit) -> GreyBoxFit:
    """`fit`'s model evaluated on the setting's held-out keystrokes, on `fit`'s error levels."""
    return GreyBoxFit(setting.held_drive, fit.layout, channels=fit.channels, sigma=fit.sigma).evaluate(fit.theta_)


def held_noise_m(setting: Setting, fit: GreyBoxFit) -> float:
    """Position noise of the held-out residuals under `fit` (NaN with MIDI only)."""
    if setting.mode != "trajectories":
        return float("nan")
    held = on_held(setting, fit)
    noise = held.noise(held.residuals_)
    values = [noise[c] for c in ("x1", "x2") if c in noise]
    return float(np.sqrt(np.mean(np.square(values)))) if values else float("nan")


def screen(setting: Setting, current: GreyBoxFit, spec: CandidateSpec,
           earlier: Mapping[str, float] | None = None) -> GreyBoxFit:
    """The effect's parameters alone, from the best starting point, the current model fixed.

    `earlier` holds the values this candidate reached in the previous iteration (its own and the
    readout's). They are a second fit's start, the better fit kept: an effect that nearly passed
    before another was accepted usually still fits there, while the best generic start may lie in
    a worse basin (on a study log, a velocity curve screened after the arm acceleration was
    accepted stalled at exponent 1.2 from the generic start; alone it had reached 4.0)."""
    full = _candidate_layout(current, spec, setting.train)
    # With MIDI only, an effect on the outcome is seen through the piano's readout, which must be
    # free to follow (a velocity curve's exponent and the full-scale speed trade off). A curve of
    # the piano's own changes the velocities only: its sensor depths stay, or the fit trades the
    # hold for velocity (every candidate is fitted on the base model's error levels, 270 ms of hold
    # where the arm's acceleration was missing), which the criterion then rejects.
    piano = FAMILIES.get(spec.effect) == "piano"
    readout = ["readout.full_scale_speed_mps"] if piano else ["readout"]
    layout = full.restricted([spec.effect, *readout] if setting.mode == "midi" else [spec.effect])
    probe = GreyBoxFit(setting.train_drive, layout, channels=current.channels, sigma=current.sigma)
    starts = [layout.internal(s) for s in start_points(layout, spec, setting.train)] or [layout.start()]
    if setting.mode == "midi" and piano:
        # A start of the piano's curve changes the loudness everywhere: each start is also tried
        # with the full-scale speed matched to it, or its error would say more about the scale
        # than about the shape. (An effect on the finger or the arm keeps the current scale: its
        # starts change a few keystrokes, and on a study log a rescaled start for the arm's
        # acceleration led to another optimum that held out no better.)
        starts += [_scaled_readout(setting.train_drive, layout, th) for th in starts]
    best = min(starts, key=lambda th: _cost(probe, th))

    def fit(start: np.ndarray) -> GreyBoxFit:
        return GreyBoxFit(setting.train_drive, layout, channels=current.channels, sigma=current.sigma,
                          max_nfev=SCREEN_NFEV, tol=1e-5).fit(start)

    fitted = fit(best)
    if not earlier:
        return fitted
    again = fit(layout.internal({k: v for k, v in earlier.items() if k in layout.names}))
    return min((fitted, again), key=_fitted_cost)


def joint(setting: Setting, current: GreyBoxFit, spec: CandidateSpec, screened: GreyBoxFit,
          start_model: KeystrokeModel | None = None, *, from_screened: bool = True) -> GreyBoxFit:
    """The candidate refitted with every parameter of the current model, from the screened fit
    and, when given, also from `start_model`'s base values with the screened effect: a base fit
    that bent its parameters to imitate the missing effect (friction read as key damping) is a
    basin the joint fit may not leave from its own values.

    With `start_model`, the starts race: each is fitted for `JOINT_PROBE_NFEV` evaluations and
    only the best carries on to `JOINT_NFEV`. The starts are the screened fit (the current base
    with the effect's screened values), and on the start model's base: the effect's starting
    point of least error and its screened values (unless `from_screened` is False: the
    screening found no evidence for the effect). Usually they reach the same optimum, and the
    race costs two short fits. Where they do not, the first start is the one that tends to
    stall: on an independent stop take, from a base whose dampers had grown to imitate the stop
    (so small an integration step that each evaluation cost 3-4x the usual), it ran its whole
    budget to 13x the error a start on the prior's base reached in 30 evaluations."""
    layout = _candidate_layout(current, spec, setting.train)

    def fit(start: np.ndarray, nfev: int) -> GreyBoxFit:
        return GreyBoxFit(setting.train_drive, layout, channels=current.channels, sigma=current.sigma,
                          max_nfev=nfev, tol=1e-5).fit(start)

    first = layout.internal({**current.params_, **screened.params_})
    if start_model is None:
        return fit(first, JOINT_NFEV)
    # The start model's base values, with the effect's best starting point for them.
    prior = model_values(start_model, layout.levels_kpa)
    base = {k: v for k, v in prior.items() if k in current.params_ and "." not in k}
    fresh = {**current.params_, **base}
    probe = GreyBoxFit(setting.train_drive, layout, channels=current.channels, sigma=current.sigma)
    # The screened fit is expressed in the full layout (`as_full`): its base values are the
    # current ones this start is meant to leave; the rest (the effect, a MIDI log's readout) it fitted.
    screened_start = layout.internal({**fresh, **{k: v for k, v in screened.params_.items() if k not in base}})
    options = [screened_start, *(layout.internal({**fresh, **point}) for point in start_points(layout, spec, setting.train))]
    cheapest = min(options, key=lambda th: _cost(probe, th))
    # Where the effect's screened values start is raced too, even when its error there is not
    # the least: the screened values already fit the effect's shape (a Stribeck speed, a stop
    # depth), and the error at the start says little about the basin it leads to (an
    # independent Stribeck take: the cheapest start stalled at 13x the screened start's optimum).
    starts = [first, cheapest]
    if from_screened and not np.array_equal(cheapest, screened_start):
        starts.append(screened_start)
    probes = [fit(th, JOINT_PROBE_NFEV) for th in starts]
    best = min(probes, key=_fitted_cost)  # the first start wins a tie
    if best.converged_:
        return best
    return fit(best.theta_, JOINT_NFEV - JOINT_PROBE_NFEV)


def restarted(setting: Setting, fit: GreyBoxFit, spec: CandidateSpec, mapper: Mapper = serial_map) -> GreyBoxFit:
    """An accepted effect of a MIDI log refitted from each of its starting points too, the best
    optimum kept (`fit` itself unless one is better).

    A MIDI log's misfit has many optima (docs/architecture.md), and screening carries only the
    cheapest start on: on an independent 40-keystroke log the tanh curve accepted stopped at an
    optimum 72 in ΔIC worse than the one its start nearest the truth reaches, and the next round
    named a key friction for the difference. The refits are independent pieces (`mapper`)."""
    layout = fit.layout
    points = [point for point in start_points(layout, spec, setting.train) if point]
    if setting.mode != "midi" or not points:  # an effect without parameters has no other start
        return fit
    piano = FAMILIES.get(spec.effect) == "piano"
    starts = [layout.internal({**fit.params_, **point}) for point in points]
    if piano:
        starts = [_scaled_readout(setting.train_drive, layout, th) for th in starts]

    def refit(theta: np.ndarray) -> GreyBoxFit:
        return GreyBoxFit(setting.train_drive, layout, channels=fit.channels, sigma=fit.sigma,
                          max_nfev=JOINT_NFEV, tol=1e-5).fit(theta)

    return min([fit, *mapper(refit, starts)], key=_fitted_cost)  # `fit` wins a tie


def converged(setting: Setting, fit: GreyBoxFit) -> GreyBoxFit:
    """An accepted candidate carried on to its optimum when its joint fit ran out of budget.

    The next iteration judges every candidate against this model: a joint refit that merely
    finished what this fit left undone would gain ΔIC without any new effect.

    With central differences: a joint fit that ran out of budget is usually crawling, and the
    forward difference's error is why. Seen on an independent Hunt–Crossley stop (a fifth base
    set, the finger resting on the key): 400 evaluations with forward differences took the cost
    from 8.61 to 8.42 and still ran out; central ones reached 8.32 in 10."""
    return fit if fit.converged_ else refitted(setting, fit)


def refitted(setting: Setting, fit: GreyBoxFit) -> GreyBoxFit:
    """`fit`'s model carried on to its optimum from its values, with central differences, on
    `setting`'s keystrokes (those it was fitted on, or the same ones read otherwise: a hover
    read again)."""
    return GreyBoxFit(setting.train_drive, fit.layout, channels=fit.channels, sigma=fit.sigma,
                      max_nfev=CONVERGE_NFEV, tol=1e-5, central=True).fit(fit.theta_)


def without(setting: Setting, current: GreyBoxFit, effect: str, base: GreyBoxFit) -> GreyBoxFit:
    """`current` refitted with one of its effects switched off, every other parameter free (the
    backward step of the loop: is an effect accepted earlier still needed now that a later one is
    in the model?). Two starts race as in `joint`: where `current` has the parameters, and on the
    base fit's base values with the other effects' current ones. The effect's share of the model
    may be large (a yielding finger body carrying half of k0), and the base parameters bent
    around it may be a poor start once it is gone; the base fit's values, chosen before any
    effect, are the other start, and the better of the two short fits carries on."""
    layout = current.layout.rebased(current.model_, current.drive_)
    prior = layout.prior.replace(effects=layout.prior.effects.without(effect))
    layout = Layout(prior, tuple(p for p in layout.params if p.group != effect), layout.levels_kpa,
                    {k: form for k, form in layout.forms.items() if k != effect}, layout.fixed_drive)

    def fit(start: np.ndarray, nfev: int) -> GreyBoxFit:
        return GreyBoxFit(setting.train_drive, layout, channels=current.channels, sigma=current.sigma,
                          max_nfev=nfev, tol=1e-5).fit(start)

    on_base = layout.internal({**current.params_, **{k: v for k, v in base.params_.items() if "." not in k}})
    probes = [fit(th, JOINT_PROBE_NFEV) for th in (layout.start(), on_base)]
    best = min(probes, key=_fitted_cost)  # the first start wins a tie
    return best if best.converged_ else fit(best.theta_, JOINT_NFEV - JOINT_PROBE_NFEV)


def as_full(setting: Setting, current: GreyBoxFit, spec: CandidateSpec, screened: GreyBoxFit) -> GreyBoxFit:
    """A screened fit expressed in the full layout (base parameters at the current values), so
    that its parameter count and intervals are those of the whole model."""
    layout = _candidate_layout(current, spec, setting.train)
    start = layout.internal({**current.params_, **screened.params_})
    return GreyBoxFit(setting.train_drive, layout, channels=current.channels, sigma=current.sigma).evaluate(start)


# The arm-fingertip coupling: free in a candidate's fit even where the base model ties it.
_COUPLING = ("k0_over_k1", "c0_over_c1", "m1_kg")


def _candidate_layout(current: GreyBoxFit, spec: CandidateSpec, batch: KeystrokeBatch) -> Layout:
    """The current model's layout plus the candidate effect's parameters (effect switched on).

    Where the trajectories are measured, a candidate's fit also frees the arm-fingertip coupling
    (k0/k1, c0/c1, m1) when the base model ties it. The base fit decides the coupling without the
    missing effect, whose misfit can hide what freeing it gains; with the effect in the model the
    coupling may matter. Seen on an independent weak power-law finger whose body is 1.3x stiffer
    than its pad: with the coupling tied, the power form's exponent went to its bound (4, truth 3)
    and the held-out gap shrank 20 %; with it free, exponent 2.99, scale 222 /m (truth 222) and
    a 94 % shrink. The coupling's parameters count in the candidate's information criterion."""
    layout = current.layout.rebased(current.model_, current.drive_)
    if not layout.free_coupling and "c1_nspm" in layout.names:  # trajectories: damping is free
        free = base_params(current.model_, layout.levels_kpa, free_coupling=True)
        layout = layout.with_params([p for p in free if p.name in _COUPLING])
    return layout.with_params(candidate_params(spec, batch), {spec.effect: spec.form})
