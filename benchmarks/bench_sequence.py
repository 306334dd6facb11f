"""Sequence models: does context help? `python benchmarks/bench_sequence.py` (JSON).

1. The study's sequential rigid-finger log (`seq_data.txt`, 1,151 strokes in 99 sequences, from
   the shared fixture folder; skipped when absent), imported with `pianobot import
   keystroke-log`: cross-validation grouped by sequence (5 folds), the per-note models (GP)
   and the sequence model with k = 0, 1, 2, 3 previous strokes, on the same folds. Errors:
   on-velocity RMSE/MAE (MIDI), inter-onset interval RMSE (previous note-on → this note-on, s),
   MIDI hold RMSE (s); with PyTorch installed (extra `[rnn]`) also the recurrent model (row
   `rnn gru`) on the same folds. `chosen_k` is what `fit` saves (`choose_k`); `context_gain_vs_k0` is its relative
   change against k = 0, per error.
2. The simulated world where context matters (own-world suite, reported apart): sequence-mode
   strokes on a `World` whose finger stiffness drifts by up to 30 % between sequences and stays
   within one; per-note GP against the sequence model (and the GRU, with PyTorch) on held-out
   sequences.
3. Fit cost: wall time of fitting the sequence model (k = 2) and the per-note GP on all strokes of
   the log in the same run, as a ratio.

Results: benchmarks/results/sequence.json. `--quick`: k = 0, 2 only, fewer simulated sequences.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
SEQ_LOG = ROOT.parent / "shared" / "fixtures" / "zhang2022" / "experiments" / "rigid" / "data" / "seq_data.txt"
RESULTS = Path(__file__).resolve().parent / "results" / "sequence.json"


def _records(cv: Any) -> list[dict[str, Any]]:
    return [{k: (None if isinstance(v, float) and v != v else v) for k, v in row.items()}
            for row in cv.to_dict(orient="records")]


def _has_torch() -> bool:
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def study_log(ks: tuple[int, ...]) -> dict[str, Any]:
    from pianobot.analysis.learn.run import load_trials
    from pianobot.analysis.sequence.evaluate import _per_note, cross_validate_sequence
    from pianobot.analysis.sequence.fit import choose_k
    from pianobot.analysis.sequence.model import SequenceModel
    from pianobot.analysis.sequence.strokes import stroke_sequences

    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-m", "pianobot", "import", "keystroke-log", str(SEQ_LOG),
                              "--data", tmp, "--json"], check=True, capture_output=True, text=True).stdout
        run_id = json.loads(out)["run_id"]
        table = stroke_sequences(load_trials([run_id], Path(tmp)))
    cv = cross_validate_sequence(table, ks=ks, per_note=("gp",), folds=5, workers=2, rnn=_has_torch())
    rows = cv.set_index("model")
    chosen = choose_k(cv)
    best = rows.loc[f"sequence k={chosen}"]
    k0, gp = rows.loc["sequence k=0"], rows.loc["per-note gp"]
    t0 = time.perf_counter()
    SequenceModel(2).fit(table)
    seq_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    _per_note("gp", table, table, 0)
    gp_s = time.perf_counter() - t0
    return {
        "strokes": table.n, "sequences": table.n_sequences, "cv": _records(cv), "chosen_k": chosen,
        "context_gain_vs_k0": {m: float(best[m] / k0[m] - 1.0) for m in ("on_velocity_rmse", "ioi_rmse_s", "hold_rmse_s")},
        "best_vs_per_note_gp": {m: float(best[m] / gp[m] - 1.0) for m in ("on_velocity_rmse", "ioi_rmse_s")},
        "fit_s": {"sequence_k2": seq_s, "per_note_gp": gp_s, "ratio_sequence_over_gp": seq_s / gp_s},
    }


def sim_world(n_sequences: int, ks: tuple[int, ...]) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT))
    from pianobot.analysis.sequence.evaluate import cross_validate_sequence
    from pianobot.analysis.sequence.strokes import stroke_sequences
    from tests.sequence.sim_world import context_world_trials

    out: dict[str, Any] = {}
    for per_sequence in (False, True):
        trials = context_world_trials(n_sequences, stiffness_per_sequence=per_sequence)
        cv = cross_validate_sequence(stroke_sequences(trials), ks=ks, per_note=("gp",), folds=4, workers=1,
                                     rnn=_has_torch())
        out["context world" if per_sequence else "default (no state between strokes)"] = _records(cv)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    ks = (0, 2) if args.quick else (0, 1, 2, 3)
    result: dict[str, Any] = {"benchmark": "sequence"}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    result["seq_data"] = study_log(ks) if SEQ_LOG.is_file() else {"skipped": "fixture seq_data.txt absent"}
    RESULTS.write_text(json.dumps(result, indent=2))  # written after each part: the log's figures first
    result["sim_world"] = sim_world(24 if args.quick else 36, ks)
    RESULTS.write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
