"""The learned maps from press parameters to MIDI outcome: one regressor/classifier pair per kind.

Kinds (`MODEL_KINDS`):

- `gp`: Gaussian process, ARD Matern-5/2 times a constant plus a white-noise term, inputs scaled,
  targets normalised; silent probability from logistic regression on degree-2 terms (a GP
  classifier took minutes per fold on the study's logs for no better accuracy). Fast by design:
  one optimiser start (no restarts), at most `GP_MAX_POINTS` training points (an exact GP costs
  O(n³) per likelihood evaluation; a few hundred points pin a smooth map of 2–6 inputs), and a
  warm start from given hyperparameters (cross-validation folds start from the full-data fit).
- `poly`: the study's cubic surface in x = vacuum and y = down velocity,
  f = a + bx + cy + dx² + exy + fy² + gx²y + hxy² + iy³, generalised to more varying inputs z by
  adding z, z·y and z² for each (a ridge penalty keeps the larger design stable).
- `spline`: a smoothing spline in the down velocity, one per group of the other inputs (unseen
  groups use the nearest group in scaled units).
- `mlp`: a small multilayer perceptron (two layers of 16, L-BFGS, which suits a few hundred
  samples), stopped early at `MLP_MAX_ITER` iterations with an L2 penalty: on the study's logs
  this generalises as well as a 32×32 network run to convergence, at a tenth of the cost.
- `mean`: predicts the training mean — the baseline every model must beat.

Each `make_regressor(kind, inputs)` returns a scikit-learn-style estimator (`fit(X, y) -> self`,
`predict(X)`) over the columns `inputs` (X is a 2-D array in that column order).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import UnivariateSpline
from sklearn.base import BaseEstimator, ClassifierMixin, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessClassifier, GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel
from sklearn.linear_model import LogisticRegression, Ridge
from sklearn.neural_network import MLPClassifier, MLPRegressor
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import PolynomialFeatures, StandardScaler

FloatArray = npt.NDArray[np.float64]

MODEL_KINDS: tuple[str, ...] = ("gp", "poly", "spline", "mlp", "physics")
SPEED = "down_velocity_mps"
VACUUM = "vacuum_kpa"
#: Largest training set an exact GP is fitted on (a seeded subsample beyond it).
GP_MAX_POINTS = 400
#: L-BFGS iterations of the MLP (early stopping; the L2 penalty keeps it smooth).
MLP_MAX_ITER = 200


class StudyPolynomial(RegressorMixin, BaseEstimator):  # type: ignore[misc]
    """The study's cubic in (vacuum, speed), plus z, z·y, z² for other varying inputs."""

    def __init__(self, inputs: tuple[str, ...] = (), alpha: float = 1e-6) -> None:
        self.inputs = inputs
        self.alpha = alpha

    def _design(self, X: FloatArray) -> FloatArray:
        Z = (X - self.mean_) / self.scale_
        cols = list(self.inputs)
        y = Z[:, cols.index(SPEED)] if SPEED in cols else np.zeros(len(Z))
        x = Z[:, cols.index(VACUUM)] if VACUUM in cols else np.zeros(len(Z))
        terms = [x, y, x**2, x * y, y**2, x**2 * y, x * y**2, y**3]
        for j, name in enumerate(cols):
            if name not in (SPEED, VACUUM):
                z = Z[:, j]
                terms += [z, z * y, z**2]
        return np.column_stack(terms)

    def fit(self, X: FloatArray, y: FloatArray) -> StudyPolynomial:
        X = np.asarray(X, dtype=np.float64)
        self.mean_ = X.mean(axis=0)
        self.scale_ = np.where(X.std(axis=0) > 0, X.std(axis=0), 1.0)
        self.ridge_ = Ridge(alpha=self.alpha).fit(self._design(X), y)
        return self

    def predict(self, X: FloatArray) -> FloatArray:
        return np.asarray(self.ridge_.predict(self._design(np.asarray(X, dtype=np.float64))), dtype=np.float64)


class GroupedSpline(RegressorMixin, BaseEstimator):  # type: ignore[misc]
    """Smoothing spline in the down velocity, one per setting of the other inputs."""

    def __init__(self, inputs: tuple[str, ...] = (), smoothing: float = 1.0) -> None:
        self.inputs = inputs
        self.smoothing = smoothing

    def fit(self, X: FloatArray, y: FloatArray) -> GroupedSpline:
        X = np.asarray(X, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        cols = list(self.inputs)
        self.speed_col_ = cols.index(SPEED)
        self.other_cols_ = [j for j in range(len(cols)) if j != self.speed_col_]
        others = X[:, self.other_cols_]
        self.scale_ = np.where(others.std(axis=0) > 0, others.std(axis=0), 1.0) if others.size else np.ones(0)
        self.keys_: list[FloatArray] = []
        self.fns_: list[Any] = []
        keys = np.round(others, 9)
        for key in np.unique(keys, axis=0) if others.size else [np.zeros(0)]:
            rows = np.all(keys == key, axis=1) if others.size else np.ones(len(X), bool)
            s, v = X[rows, self.speed_col_], y[rows]
            order = np.argsort(s)
            s, v = s[order], v[order]
            us, inv = np.unique(s, return_inverse=True)
            vm = np.bincount(inv, weights=v) / np.bincount(inv)
            if us.size >= 4:
                resid = np.std(v - vm[inv]) if v.size > us.size else np.std(vm) * 0.1
                s_factor = self.smoothing * us.size * max(resid, 1e-6) ** 2
                fn: Any = UnivariateSpline(us, vm, k=3, s=s_factor, ext=3)
            elif us.size >= 2:
                fn = _Linear(us, vm)
            else:
                fn = _Const(float(vm[0]))
            self.keys_.append(key)
            self.fns_.append(fn)
        return self

    def predict(self, X: FloatArray) -> FloatArray:
        X = np.asarray(X, dtype=np.float64)
        out = np.empty(len(X))
        others = X[:, self.other_cols_]
        keys = np.array(self.keys_)
        for i in range(len(X)):
            if others.size:
                d = np.sum(((keys - others[i]) / self.scale_) ** 2, axis=1)
                fn = self.fns_[int(np.argmin(d))]
            else:
                fn = self.fns_[0]
            out[i] = float(fn(X[i, self.speed_col_]))
        return out


class _Linear:
    def __init__(self, x: FloatArray, y: FloatArray) -> None:
        self.coef = np.polyfit(x, y, 1)

    def __call__(self, x: float) -> float:
        return float(np.polyval(self.coef, x))


class _Const:
    def __init__(self, value: float) -> None:
        self.value = value

    def __call__(self, x: float) -> float:
        return self.value


class MeanRegressor(RegressorMixin, BaseEstimator):  # type: ignore[misc]
    """Predicts the training mean (the baseline)."""

    def fit(self, X: FloatArray, y: FloatArray) -> MeanRegressor:
        self.mean_ = float(np.mean(y))
        return self

    def predict(self, X: FloatArray) -> FloatArray:
        return np.full(len(X), self.mean_)


class ConstantClassifier(ClassifierMixin, BaseEstimator):  # type: ignore[misc]
    """P(silent) = training frequency; used when a fold holds only one class."""

    def fit(self, X: FloatArray, y: npt.NDArray[np.bool_]) -> ConstantClassifier:
        self.p_ = float(np.mean(y))
        return self

    def predict_proba(self, X: FloatArray) -> FloatArray:
        p = np.full(len(X), self.p_)
        return np.column_stack([1 - p, p])


class CappedGP(RegressorMixin, BaseEstimator):  # type: ignore[misc]
    """Exact GP regression on scaled inputs, on at most `max_points` rows, warm-startable.

    `kernel` (a fitted GP's `kernel_`) sets the optimiser's starting hyperparameters; the
    optimiser still runs, so a warm-started fold is fitted on its own data only.
    """

    def __init__(self, n_inputs: int = 1, seed: int = 0, max_points: int = GP_MAX_POINTS,
                 kernel: Any = None) -> None:
        self.n_inputs = n_inputs
        self.seed = seed
        self.max_points = max_points
        self.kernel = kernel

    def _initial_kernel(self) -> Any:
        if self.kernel is not None:
            return self.kernel
        return ConstantKernel(1.0, (1e-3, 1e3)) * Matern(
            length_scale=np.ones(self.n_inputs), length_scale_bounds=(1e-2, 1e3), nu=2.5
        ) + WhiteKernel(0.1, (1e-6, 1e1))

    def fit(self, X: FloatArray, y: FloatArray) -> CappedGP:
        X = np.asarray(X, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if len(X) > self.max_points:
            rows = np.sort(np.random.default_rng(self.seed).choice(len(X), self.max_points, replace=False))
            X, y = X[rows], y[rows]
        gpr = GaussianProcessRegressor(self._initial_kernel(), normalize_y=True,
                                       n_restarts_optimizer=0, random_state=self.seed)
        self.pipeline_ = make_pipeline(StandardScaler(), gpr)
        with warnings.catch_warnings():
            # A length scale at its bound means "this input barely matters": an answer, not a fault.
            warnings.simplefilter("ignore", ConvergenceWarning)
            self.pipeline_.fit(X, y)
        self.kernel_ = gpr.kernel_
        return self

    def predict(self, X: FloatArray) -> FloatArray:
        return np.asarray(self.pipeline_.predict(np.asarray(X, dtype=np.float64)), dtype=np.float64)


class EarlyStoppedMLP(RegressorMixin, BaseEstimator):  # type: ignore[misc]
    """Scaled inputs → small MLP, L-BFGS capped at `max_iter` (iteration cap = early stopping)."""

    def __init__(self, seed: int = 0, max_iter: int = MLP_MAX_ITER) -> None:
        self.seed = seed
        self.max_iter = max_iter

    def fit(self, X: FloatArray, y: FloatArray) -> EarlyStoppedMLP:
        mlp = MLPRegressor(hidden_layer_sizes=(16, 16), solver="lbfgs", alpha=1e-2,
                           max_iter=self.max_iter, random_state=self.seed)
        self.pipeline_ = make_pipeline(StandardScaler(), mlp)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # stopping early is the intent
            self.pipeline_.fit(np.asarray(X, dtype=np.float64), np.asarray(y, dtype=np.float64))
        return self

    def predict(self, X: FloatArray) -> FloatArray:
        return np.asarray(self.pipeline_.predict(np.asarray(X, dtype=np.float64)), dtype=np.float64)


def make_regressor(kind: str, inputs: tuple[str, ...], seed: int = 0, warm: Any = None) -> Any:
    """A fresh, unfitted regressor of `kind` over the columns `inputs`.

    `warm`: a fitted regressor of the same kind whose hyperparameters start the optimiser
    (used by cross-validation; ignored by kinds without hyperparameters to optimise).
    """
    d = len(inputs)
    if kind == "gp":
        return CappedGP(d, seed, kernel=getattr(warm, "kernel_", None))
    if kind == "poly":
        return StudyPolynomial(inputs)
    if kind == "spline":
        if SPEED not in inputs:
            return StudyPolynomial(inputs)
        return GroupedSpline(inputs)
    if kind == "mlp":
        return EarlyStoppedMLP(seed)
    if kind == "mean":
        return MeanRegressor()
    raise ValueError(f"unknown model kind {kind!r}; valid: {MODEL_KINDS}")


def make_classifier(kind: str, inputs: tuple[str, ...], seed: int = 0) -> Any:
    """A fresh classifier for P(silent) that goes with regressor `kind`."""
    d = len(inputs)
    if kind == "gp-classifier":  # exact but slow (minutes for a few hundred keystrokes per fold)
        kernel = ConstantKernel(1.0, (1e-2, 1e2)) * RBF(np.ones(d), (1e-2, 1e3))
        return make_pipeline(StandardScaler(), GaussianProcessClassifier(kernel, random_state=seed))
    if kind == "mlp":
        mlp = MLPClassifier(hidden_layer_sizes=(16,), solver="lbfgs", alpha=1e-2, max_iter=MLP_MAX_ITER,
                            random_state=seed)
        return make_pipeline(StandardScaler(), mlp)
    if kind == "mean":
        return ConstantClassifier()
    # poly / spline: logistic regression on degree-2 terms of the scaled inputs.
    return Pipeline([
        ("scale", StandardScaler()),
        ("poly", PolynomialFeatures(2, include_bias=False)),
        ("logit", LogisticRegression(C=10.0, max_iter=2000)),
    ])


def fit_classifier(kind: str, inputs: tuple[str, ...], X: FloatArray, silent: npt.NDArray[np.bool_], seed: int = 0) -> Any:
    """Fit the silent classifier (a constant one when only one class is present)."""
    if silent.all() or not silent.any():
        return ConstantClassifier().fit(X, silent)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # the MLP's iteration cap is intended
        return make_classifier(kind, inputs, seed).fit(X, silent.astype(int))


def p_silent(classifier: Any, X: FloatArray) -> FloatArray:
    """Probability of the silent class."""
    proba = np.asarray(classifier.predict_proba(X), dtype=np.float64)
    return proba[:, -1] if proba.shape[1] > 1 else proba[:, 0]
