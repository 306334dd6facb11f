"""How a grey-box fit ends: where it has stalled, and, asked to finish, on central differences.

A base fit that bends the model to imitate an effect it lacks crawls along a flat valley: on an
independent rest-stop take (tests/truth: a simulator sharing no code with pianobot) its error
fell by hundredths of a percent over a hundred evaluations, each a simulation of every
keystroke. `Stall` ends the crawl; the fit's error stays where it was.

A joint fit that ran out of budget crawls for another reason: the forward differences' error.
Discovery finishes it (`search.converged`) on central differences.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from scipy.optimize import OptimizeResult

from pianobot.analysis.discover import search
from pianobot.analysis.discover.search import Setting
from pianobot.analysis.greybox import fitter
from pianobot.analysis.greybox.fitter import FloatArray, GreyBoxFit, Stall
from pianobot.analysis.greybox.layout import Layout


def _costs(stall: Stall, costs: list[float]) -> int:
    """How many iterations `stall` lets run (all of them: len(costs))."""
    for i, cost in enumerate(costs):
        try:
            stall(OptimizeResult(cost=cost))
        except StopIteration:
            return i + 1
    return len(costs)


def test_a_fit_that_keeps_improving_runs_on() -> None:
    progress = [1000.0 * 0.99**i for i in range(300)]  # 1 % per iteration
    assert _costs(Stall(10, 1e-4), progress) == 300


def test_a_crawl_stops_after_its_window() -> None:
    crawl = [1000.0 * (1 - 1e-6 * i) for i in range(300)]  # 1e-5 of the cost per 10 iterations
    assert _costs(Stall(10, 1e-4), crawl) == 11
    # A quick descent (3 iterations), then the crawl: stopped once a whole window has crawled.
    assert _costs(Stall(10, 1e-4), [2000.0, 1500.0, 1200.0, *crawl]) == 3 + 10 + 1


def test_a_slow_but_real_descent_is_not_a_stall() -> None:
    descent = [1000.0 * (1 - 2e-5 * i) for i in range(300)]  # 2e-4 of the cost per 10 iterations
    assert _costs(Stall(10, 1e-4), descent) == 300


def _rest_stop_take(tmp_path: Path) -> tuple[Setting, Layout]:
    """The independent weak rest-stop take (its arm from the UR arm log), split as discovery
    splits it, and the tied base layout."""
    from pianobot.analysis.greybox.layout import base_layout
    from pianobot.analysis.greybox.load import load_keystrokes, read_schedule
    from pianobot.analysis.greybox.split import holdout_indices
    from pianobot.io.importers import import_mocap
    from pianobot.physics.model import KeystrokeModel
    from tests.truth import materialise, scenario

    made = materialise(scenario("mocap-key_preload-rest_stop-weak"), tmp_path / "files")
    run_id = import_mocap(made.files["take"], tmp_path / "data", vacuum_kpa=float(made.truth["vacuum_kpa"]),
                          arm_log=made.files["arm_log"]).run_id
    batch = load_keystrokes([run_id], tmp_path / "data", schedule=read_schedule(made.files["presses"])).batch
    train_rows, held_rows = holdout_indices(batch, 3, 0)
    setting = Setting.of(batch.subset(train_rows), batch.subset(held_rows))
    return setting, base_layout(KeystrokeModel.study(), setting.train.levels_kpa)


def test_a_crawling_base_fit_stops_at_the_same_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The tied base fit: a stiff, heavily damped key imitating the stop, reached in a few
    evaluations and then crawled."""
    setting, layout = _rest_stop_take(tmp_path)
    drive = setting.train_drive

    stalled = fitter.GreyBoxFit(drive, layout).fit()
    monkeypatch.setattr(fitter, "STALL_ITERATIONS", 10**9)  # the tolerances alone
    crawled = fitter.GreyBoxFit(drive, layout).fit()

    assert stalled.converged_ and crawled.converged_
    assert stalled.nfev_ <= 0.7 * crawled.nfev_
    assert stalled.rms_m_ == pytest.approx(crawled.rms_m_, rel=5e-3)


def test_a_fit_asked_to_finish_steps_on_central_differences(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A fit steps on forward differences; discovery carries a fit that ran out of budget on to
    its optimum on central ones, and gets no worse for it."""
    setting, layout = _rest_stop_take(tmp_path)
    kinds: list[bool] = []
    jacobian = GreyBoxFit.jacobian

    def spy(self: GreyBoxFit, theta: FloatArray, *, central: bool = True) -> FloatArray:
        kinds.append(central)
        return jacobian(self, theta, central=central)

    monkeypatch.setattr(GreyBoxFit, "jacobian", spy)
    cut_short = GreyBoxFit(setting.train_drive, layout, max_nfev=3).fit()
    assert not cut_short.converged_
    assert kinds and not any(kinds)

    kinds.clear()
    finished = search.converged(setting, cut_short)
    assert kinds and all(kinds)
    assert finished.converged_
    assert finished.rms_m_ <= cut_short.rms_m_
    assert search.converged(setting, finished) is finished  # a finished fit is left as it is
