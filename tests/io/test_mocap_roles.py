"""Which marker is the key: the least moving of the rest, by a margin that a finger chain relaxes."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from pianobot.errors import InputError
from pianobot.io.mocap_roles import assign_roles

T = np.linspace(0.0, 1.0, 400)


def _markers(travel_mm: dict[str, float], height_m: dict[str, float]) -> Callable[[str], np.ndarray]:
    """Each marker presses down by its travel once, at its own height."""
    press = np.clip(np.sin(np.pi * T), 0.0, None)

    def up_m(name: str) -> np.ndarray:
        return height_m[name] - 1e-3 * travel_mm[name] * press

    return up_m


HEIGHT = {"arm": 0.23, "middle": 0.016, "tip": -0.012, "key": 0.008}  # the study's rig (zzz40)


def _roles(travel_mm: dict[str, float]) -> dict[str, str]:
    names = list(travel_mm)
    return assign_roles(names, _markers(travel_mm, HEIGHT), {}, lambda n: n if n in names else None, "take.csv")


def test_a_key_that_travels_nearly_as_far_as_the_fingertip_is_the_least_moving_of_the_chain() -> None:
    # A stiffer finger or a softer key than the study's (zzz40: 0.67): 0.8 of the fingertip.
    roles = _roles({"arm": 8.0, "middle": 7.0, "tip": 6.0, "key": 4.8})
    assert roles == {"arm": "arm", "fingertip": "tip", "key": "key"}


def test_without_a_finger_marker_of_its_own_the_margin_stays_strict() -> None:
    # Two moving markers besides the arm: they may be two finger markers and no key in view.
    with pytest.raises(InputError, match="cannot tell which marker is the key"):
        _roles({"arm": 8.0, "tip": 6.0, "key": 4.8})
    assert _roles({"arm": 8.0, "tip": 6.3, "key": 4.0})["key"] == "key"  # zzz40's 0.67: clear


def test_a_chain_whose_two_least_moving_markers_travel_alike_is_refused() -> None:
    with pytest.raises(InputError, match="cannot tell which marker is the key") as error:
        _roles({"arm": 8.0, "middle": 7.0, "tip": 6.3, "key": 6.0})
    assert "tip" in str(error.value) and "key" in str(error.value) and "--marker key=" in str(error.value)


def _roles_with(travel_mm: dict[str, float], still: dict[str, tuple[float, float]]) -> dict[str, str]:
    """`still` markers barely move: (travel in mm with the presses, drift in mm of their own)."""
    press = np.clip(np.sin(np.pi * T), 0.0, None)
    drift = np.cos(2 * np.pi * 3.0 * T)
    heights = {**HEIGHT, "piano": -0.05, "room": 0.4}

    def up_m(name: str) -> np.ndarray:
        if name in still:
            locked, own = still[name]
            return heights[name] - 1e-3 * (locked * press + own * drift)
        return heights[name] - 1e-3 * travel_mm[name] * press

    names = [*travel_mm, *still]
    return assign_roles(names, up_m, {}, lambda n: n if n in names else None, "take.csv")


def test_a_key_a_preload_holds_up_against_a_resting_finger_is_found_though_it_barely_moves() -> None:
    # An independent take: a 0.3 N rest stop under a light finger lets the key move 0.46 mm, with
    # the presses; the finger's two markers travel alike (5.0 and 6.4 mm). Before: refused.
    roles = _roles_with({"arm": 8.1, "middle": 6.4, "tip": 5.0}, {"key": (0.4, 0.05), "room": (0.0, 0.1)})
    assert roles == {"arm": "arm", "fingertip": "tip", "key": "key"}


def test_markers_that_barely_move_without_the_arm_are_never_the_key() -> None:
    roles = _roles_with({"arm": 8.1, "tip": 5.0}, {"piano": (0.0, 0.1), "room": (0.0, 0.2)})
    assert roles == {"arm": "arm", "fingertip": "tip"}  # no piano in view: no key
    assert _roles_with({"arm": 8.1, "tip": 5.0}, {"piano": (0.02, 0.0)}) == roles  # 20 µm: too little to be a press


def test_two_markers_that_barely_move_with_the_arm_leave_the_key_unclear() -> None:
    with pytest.raises(InputError, match="cannot tell which marker is the key"):
        _roles_with({"arm": 8.1, "middle": 6.4, "tip": 5.0}, {"key": (0.4, 0.05), "piano": (0.2, 0.0)})


def test_a_key_that_moves_only_at_the_bottom_of_each_press_is_found_through_the_drift() -> None:
    # An independent take: a 0.4 N rest stop holds the key still but at the bottom of each press
    # (0.14 mm), while the whole capture volume drifts by 0.1 mm. Before: refused.
    t = np.linspace(0.0, 80.0, 9600)
    press = np.clip(np.sin(2 * np.pi * t / 3.3), 0.0, None)  # 24 presses
    drift = 1e-4 * np.sin(2 * np.pi * t / 70.0 + 0.4)
    travel = {"arm": 8.1e-3 * press, "middle": 6.3e-3 * press, "tip": 4.8e-3 * press,
              "key": 1.4e-4 * np.clip(press - 0.8, 0.0, None) / 0.2}
    names = list(travel)
    roles = assign_roles(names, lambda n: HEIGHT[n] + drift - travel[n], {}, lambda n: n if n in names else None,
                         "take.csv")
    assert roles == {"arm": "arm", "fingertip": "tip", "key": "key"}


def test_a_key_that_barely_moves_is_not_mistaken_for_the_fingertip_of_a_two_marker_finger() -> None:
    # An independent take: a 0.4 N rest stop on a stiff key, the finger resting on it. The key
    # moves 0.26 mm; the finger's two markers (5.6 and 3.7 mm) pass the travel rule on their own,
    # and the fingertip was silently taken for the key (the finger's middle for the fingertip).
    roles = _roles_with({"arm": 8.0, "middle": 5.6, "tip": 3.7}, {"key": (0.26, 0.05), "room": (0.0, 0.1)})
    assert roles == {"arm": "arm", "fingertip": "tip", "key": "key"}
