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
