"""The recurrent sequence model (optional extra `[rnn]`: PyTorch, CPU): a GRU over each sequence.

The study trained recurrent networks on its sequence data; this is the forward form of one, so
that it is scored exactly as the windowed model is (`evaluate`, same grouped folds): per stroke
the input is its own controls (`OWN_INPUTS`), the pitch step from the previous stroke and the previous
stroke's outcomes (on-velocity, silent, MIDI hold — observed, as `SequenceModel.predict`
sees them; zeros and a start flag at a sequence's start); the GRU's state carries everything
before. Outputs: on-velocity, MIDI hold, lead and inter-onset interval, each standardised, with
a squared error over the known values only. A fifth of the training sequences are held out of
the gradient steps, and each target keeps the weights of the epoch that predicted them best
(early stopping per target). P(silent) is the training frequency (silent strokes are too rare
in the lab's data to learn).

Without PyTorch every other command works; `fit --model sequence --model rnn` says in one line
how to install it (`require_torch`).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.learn.predictors import INPUT_COLUMNS
from pianobot.analysis.sequence.strokes import TARGETS, StrokeSequences
from pianobot.errors import InputError

FloatArray = npt.NDArray[np.float64]

INSTALL_HINT = ("the recurrent sequence model needs PyTorch, an optional extra: "
                "pip install 'pianobot[rnn]' (CPU build: pip install torch==2.13.0)")
HIDDEN = 16
#: Most full-batch epochs; training stops earlier when the held-out sequences stop improving
#: for `PATIENCE` epochs.
EPOCHS = 1000
PATIENCE = 100
LEARNING_RATE = 0.01
WEIGHT_DECAY = 1e-2
DROPOUT = 0.2
#: Share of the training sequences held out of the gradient steps to decide when to stop.
VALIDATION_FRACTION = 0.2


def require_torch() -> Any:
    """The torch module, or InputError naming the one-line install (exit 2 from the CLI)."""
    try:
        import torch
    except ImportError:
        raise InputError(INSTALL_HINT, "--model rnn") from None
    return torch


def _inputs(frame: pd.DataFrame, controls: tuple[str, ...]) -> FloatArray:
    """Per stroke: own controls, pitch step, previous outcomes and a sequence-start flag."""
    seq = frame["sequence"].to_numpy()
    start = np.r_[True, seq[1:] != seq[:-1]]

    def previous(values: FloatArray) -> FloatArray:
        out = np.asarray(np.r_[np.nan, values[:-1]], dtype=np.float64)
        out[start] = np.nan
        return out

    note = frame["note"].to_numpy(float)
    on = frame["on_velocity"].to_numpy(float)
    hold = frame["midi_hold_s"].to_numpy(float)
    silent = frame["silent"].to_numpy(float)
    own = [c for c in controls if c in OWN_INPUTS]
    columns = [frame[own].to_numpy(float), (note - previous(note))[:, None],
               previous(on)[:, None], previous(silent)[:, None], previous(hold)[:, None], start[:, None].astype(float)]
    return np.asarray(np.column_stack(columns), dtype=np.float64)


#: A stroke's own controls the network sees: the per-note model's inputs and the sideways move's
#: speed. On the study's 1,149 strokes a dense network given every logged control (the pitch,
#: the sideways acceleration, the upward acceleration) overfits them: +1 to +2.5 MIDI of
#: held-out on-velocity error for the same network (measured with an MLP on grouped folds).
OWN_INPUTS: frozenset[str] = frozenset((*INPUT_COLUMNS, "move_velocity_mps"))


class RnnSequenceModel:
    """A GRU forward model of each stroke given the strokes before it in its sequence."""

    def __init__(self, seed: int = 0, hidden: int = HIDDEN, epochs: int = EPOCHS) -> None:
        self.seed, self.hidden, self.epochs = seed, hidden, epochs

    def _tensor(self, table: StrokeSequences, values: FloatArray) -> tuple[Any, FloatArray]:
        """Pad per sequence: (n_sequences, longest, features) and each stroke's (sequence, step)."""
        torch = require_torch()
        seq = table.frame["sequence"].to_numpy()
        codes, position = np.unique(seq, return_inverse=True)
        step = table.frame.groupby(seq).cumcount().to_numpy()
        out = np.zeros((len(codes), int(step.max()) + 1, values.shape[1]), dtype=np.float32)
        out[position, step] = values
        return torch.from_numpy(out), np.column_stack([position, step])

    def fit(self, table: StrokeSequences) -> RnnSequenceModel:
        """Train on `table`'s sequences, stopping where held-out sequences stop improving.

        A tenth to a fifth of the sequences (at least one) are held out of the gradient steps;
        the weights kept are those of the epoch with the lowest error on them, so the network
        stops before it memorises its training sequences (a few hundred strokes are few for a
        GRU: unchecked, it fits the training strokes to ~2 MIDI and misses new ones by ~20).
        """
        torch = require_torch()
        torch.manual_seed(self.seed)
        torch.set_num_threads(1)  # a shared machine; a few thousand strokes gain nothing from more
        self.controls_ = table.controls
        X = _inputs(table.frame, self.controls_)
        self.x_mean_, self.x_std_ = np.nanmean(X, axis=0), np.nanstd(X, axis=0) + 1e-9
        Y = table.frame[list(TARGETS)].to_numpy(float)
        with warnings.catch_warnings():  # a target never measured (the lead of an old log): all NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            self.y_mean_, self.y_std_ = np.nanmean(Y, axis=0), np.nanstd(Y, axis=0) + 1e-9
        self.p_silent_ = float(table.frame["silent"].mean())
        xs, _ = self._tensor(table, np.nan_to_num((X - self.x_mean_) / self.x_std_))
        y = (Y - self.y_mean_) / self.y_std_
        ys, _ = self._tensor(table, np.nan_to_num(y))
        known, _ = self._tensor(table, np.isfinite(y).astype(float))
        n_seq = xs.shape[0]
        rng = np.random.default_rng(self.seed)
        held = np.zeros(n_seq, bool)
        if n_seq >= 4:
            held[rng.choice(n_seq, size=max(1, round(VALIDATION_FRACTION * n_seq)), replace=False)] = True
        fit_rows, val_rows = torch.from_numpy(~held), torch.from_numpy(held)
        self.net_ = _Net(torch, xs.shape[-1], self.hidden, len(TARGETS), DROPOUT)
        optimiser = torch.optim.Adam(self.net_.parameters(), lr=LEARNING_RATE, weight_decay=WEIGHT_DECAY)

        def errors(rows: Any) -> Any:
            """Per target: mean squared error over the known values of `rows`."""
            w = known[rows]
            return (((self.net_(xs[rows]) - ys[rows]) ** 2) * w).sum(dim=(0, 1)) / w.sum(dim=(0, 1)).clamp(min=1.0)

        # Each target keeps the weights of its own best epoch: the inter-onset interval (which
        # the state carries) and the on-velocity (which the stroke's own controls set) stop
        # improving on held-out sequences at different epochs.
        best = np.full(len(TARGETS), np.inf)
        self.states_: list[dict[str, Any] | None] = [None] * len(TARGETS)
        since = 0
        for _ in range(self.epochs):
            self.net_.train()
            optimiser.zero_grad()
            errors(fit_rows).sum().backward()
            optimiser.step()
            if not held.any():
                continue
            self.net_.eval()
            with torch.no_grad():
                val = errors(val_rows).numpy().astype(float)
            better = np.isfinite(val) & (val < best - 1e-6)
            if better.any():
                state = {k: v.detach().clone() for k, v in self.net_.state_dict().items()}
                for i in np.flatnonzero(better):
                    best[i], self.states_[i] = val[i], state
                since = 0
            else:
                since += 1
                if since >= PATIENCE:
                    break
        self.net_.eval()
        return self

    def predict(self, table: StrokeSequences) -> pd.DataFrame:
        """Each stroke's predicted outcome given its observed predecessors (`TARGETS`, p_silent)."""
        torch = require_torch()
        if not hasattr(self, "net_"):
            raise RuntimeError("RnnSequenceModel is not fitted; call fit first")
        X = _inputs(table.frame, self.controls_)
        xs, where = self._tensor(table, np.nan_to_num((X - self.x_mean_) / self.x_std_))
        last = {k: v.detach().clone() for k, v in self.net_.state_dict().items()}
        out = np.zeros((len(where), len(TARGETS)))
        with torch.no_grad():
            for i, state in enumerate(getattr(self, "states_", [None] * len(TARGETS))):
                self.net_.load_state_dict(last if state is None else state)
                out[:, i] = self.net_(xs).numpy().astype(float)[where[:, 0], where[:, 1], i]
        self.net_.load_state_dict(last)
        pred = pd.DataFrame(out * self.y_std_ + self.y_mean_, columns=list(TARGETS))
        pred["on_velocity"] = np.clip(pred["on_velocity"], 1.0, 127.0)
        pred["p_silent"] = self.p_silent_
        return pred


def _Net(torch: Any, n_in: int, hidden: int, n_out: int, dropout: float) -> Any:
    """GRU → head over the GRU state and the stroke's own inputs (a stroke's own controls matter
    most; the state adds what came before), built here so that torch is imported only when the
    model is used."""

    class Net(torch.nn.Module):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.gru = torch.nn.GRU(n_in, hidden, batch_first=True)
            self.drop = torch.nn.Dropout(dropout)
            self.head = torch.nn.Sequential(torch.nn.Linear(hidden + n_in, hidden), torch.nn.Tanh(),
                                            torch.nn.Linear(hidden, n_out))

        def forward(self, x: Any) -> Any:
            states, _ = self.gru(x)
            return self.head(torch.cat([self.drop(states), x], dim=-1))

    return Net()
