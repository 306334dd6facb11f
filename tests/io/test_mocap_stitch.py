"""Split marker tracks are joined before roles are assigned; unclear roles are refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from motive_synth import motive_csv

from pianobot.errors import InputError
from pianobot.io.importers import import_mocap
from pianobot.io.mocap import read_mocap
from pianobot.io.mocap_segment import segment_take
from pianobot.io.mocap_tracks import Track, stitch
from pianobot.store import load_run

SPEEDS = [0.01, 0.02, 0.03, 0.04, 0.05, 0.06]
STARTS = [1.0 + 3.0 * i for i in range(6)]
ROLES = {"arm": "Unlabeled:100", "fingertip": "Unlabeled:102", "key": "Unlabeled:103"}


def take(tmp_path: Path, **kwargs: object) -> Path:
    return motive_csv(
        tmp_path / "take.csv", duration_s=20.0, starts_s=STARTS, speeds_mps=SPEEDS, **kwargs
    )  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "split",
    [
        {"Unlabeled:103": (0.4, 0.7)},
        {"Unlabeled:103": (0.4, 0.7), "Unlabeled:102": (0.5,)},
        {
            "Unlabeled:100": (0.3, 0.6),
            "Unlabeled:101": (0.45,),
            "Unlabeled:102": (0.2, 0.8),
            "Unlabeled:103": (0.4, 0.7),
        },
    ],
)
def test_split_tracks_are_joined_and_roles_are_right(
    tmp_path: Path, split: dict[str, tuple[float, ...]]
) -> None:
    mocap = read_mocap(take(tmp_path, split=split))
    assert mocap.roles == ROLES
    assert set(mocap.stitched) == set(split)
    for name, cuts in split.items():
        assert len(mocap.stitched[name]) == len(cuts) + 1 and mocap.coverage[name] > 0.95
    strokes = segment_take(mocap)
    assert len(strokes) == 6
    assert strokes["key_travel_m"].to_numpy() == pytest.approx(0.0036, abs=2e-4)


def test_split_take_imports_with_full_keystroke_count(tmp_path: Path, data_dir: Path) -> None:
    result = import_mocap(take(tmp_path, split={"Unlabeled:103": (0.4, 0.7)}), data_dir)
    out = result.to_dict()
    assert out["keystrokes"] == 6 and out["roles"] == ROLES
    assert out["stitched"] == {"Unlabeled:103": ["Unlabeled:103", "Unlabeled:531", "Unlabeled:532"]}
    run = load_run(result.run_id, data_dir)
    assert run.meta["stitched"] == out["stitched"] and len(run.meta["joins"]) == 2
    key = run.samples[run.samples["trial_id"] == run.trials["trial_id"].iloc[5]]["x2_m"]
    assert key.max() == pytest.approx(0.0036, abs=2e-4)  # the last press is seen on the last piece


def test_a_marker_option_may_name_any_piece(tmp_path: Path) -> None:
    path = take(tmp_path, split={"Unlabeled:103": (0.4, 0.7)})
    assert read_mocap(path, markers={"key": "Unlabeled:532"}).roles["key"] == "Unlabeled:103"


def test_unclear_roles_are_refused_naming_the_candidates(tmp_path: Path) -> None:
    # no key in view: the finger's two markers move alike, so neither is clearly the key
    path = take(tmp_path, markers=("Unlabeled:100", "Unlabeled:101", "Unlabeled:102"))
    with pytest.raises(InputError) as error:
        read_mocap(path)
    message = str(error.value)
    assert "cannot tell which marker is the key" in message
    assert "Unlabeled:101" in message and "Unlabeled:102" in message and "--marker key=" in message
    roles = read_mocap(path, markers={"key": "none"}).roles
    assert roles == {"arm": "Unlabeled:100", "fingertip": "Unlabeled:102"}


def test_pieces_that_overlap_or_jump_are_different_markers() -> None:
    t = np.arange(300) / 120.0
    still = np.tile([0.1, 0.2, 0.3], (100, 1))
    first = Track("A", np.arange(0, 100), still)
    overlapping = Track("B", np.arange(90, 200), np.tile([0.1, 0.2, 0.3], (110, 1)))
    jumped = Track("C", np.arange(210, 300), np.tile([0.1, 0.25, 0.3], (90, 1)))  # 5 cm away
    follows = Track("D", np.arange(205, 300), np.tile([0.1, 0.2, 0.3], (95, 1)))
    result = stitch([first, overlapping, jumped], t)
    assert len(result.chains) == 3 and not result.joins
    result = stitch([first, follows], t)
    assert result.pieces == {"A": ["A", "D"]}


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.dictionaries(
    st.sampled_from(list(ROLES.values()) + ["Unlabeled:101"]),
    st.lists(st.floats(0.1, 0.9), min_size=1, max_size=3, unique=True).map(lambda c: tuple(sorted(c))),
    min_size=1, max_size=4,
))  # fmt: skip
def test_any_split_of_any_marker(tmp_path_factory: pytest.TempPathFactory, split: dict[str, tuple[float, ...]]) -> None:
    """Random occlusions split random markers into 2-4 pieces: roles and keystrokes stay right."""
    cuts = {name: tuple(c for i, c in enumerate(cs) if i == 0 or c - cs[i - 1] > 0.05) for name, cs in split.items()}
    mocap = read_mocap(take(tmp_path_factory.mktemp("split"), split=cuts))
    assert mocap.roles == ROLES
    assert len(segment_take(mocap)) == 6
