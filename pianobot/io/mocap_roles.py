"""Which marker of a take is the arm, the fingertip and the key — or a clear "cannot tell".

Roles given by the user (`--marker ROLE=NAME`, a rig file's `mocap.markers`) are used as they
are; a NAME may be any piece of a stitched track, and `none` says the role is not in view (e.g.
`--marker key=none` for a take without the piano). The missing roles are inferred from the
persistent markers, each only when the evidence is clear (otherwise InputError names the
candidates and how to settle it):

- markers that barely move (< STATIC_MOTION_M) are fixed to the piano body or the room: no role;
- the arm marker sits on the end effector above the finger: the highest, by at least
  ARM_SEPARATION_M;
- the key is the one marker that barely moves but does so with the arm (at least
  HELD_KEY_MOTION_M, its height, drift removed, correlated with the arm's by PRESS_LOCKED or
  more), if there is one: a key that a break-away preload holds up against a resting finger
  moves a fraction of a millimetre, with every press, while a marker on the piano body or the
  room moves with none. Such a key is looked for first: the finger's own two markers would
  otherwise pass the travel rule below, and the fingertip was taken for the key (an independent
  take, a 0.4 N rest stop on a stiff key: key 0.26 mm, fingertip 3.7 mm, finger 5.6 mm);
- otherwise the key moves least of the rest (its travel stops at the key bed, ≤
  KEY_MAX_TRAVEL_M), by a clear margin (at most KEY_MOTION_RATIO of the next); inferred only
  when at least two moving markers remain besides the arm (with one, there is no piano in view).
  Where three or more remain, the finger is in view with a marker of its own besides the
  fingertip, and the margin is KEY_CHAIN_RATIO: the markers of a finger that presses a key travel
  at least as far as the key does, so the least moving of a chain is the key unless the two
  travel alike (the study's zzz40: 0.67 of the fingertip; a stiffer finger or a softer key comes
  closer to 1);
- the fingertip is the lowest of the rest (markers higher up the finger are ignored), by at least
  TIP_SEPARATION_M.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NoReturn

import numpy as np
import numpy.typing as npt

from pianobot.errors import InputError

FloatArray = npt.NDArray[np.float64]
ROLES = ("arm", "fingertip", "key")
STATIC_MOTION_M = 0.0005
ARM_SEPARATION_M = 0.02
KEY_MOTION_RATIO = 0.75
KEY_CHAIN_RATIO = 0.9
KEY_MAX_TRAVEL_M = 0.015
TIP_SEPARATION_M = 0.004
HELD_KEY_MOTION_M = 5e-5
PRESS_LOCKED = 0.5
ARM_UP_SHARE = 0.2
NOT_IN_VIEW = "none"


def assign_roles(
    names: list[str],
    up_m: Callable[[str], FloatArray],
    given: dict[str, str],
    resolve: Callable[[str], str | None],
    where: str,
) -> dict[str, str]:
    """Roles of the persistent markers `names` (module docstring).

    Args:
        names: persistent markers (chain names after stitching).
        up_m: a marker's coordinate along the up axis on every frame (NaN when unseen).
        given: role -> marker name chosen by the user.
        resolve: the persistent marker a given name stands for (a piece -> its chain), or None.
        where: the take's file, for messages.
    """
    roles: dict[str, str] = {}
    absent = set()
    for role, name in given.items():
        if role not in ROLES:
            raise InputError(f"marker role should be one of {ROLES}, got {role!r}", "--marker")
        if name.lower() == NOT_IN_VIEW:
            absent.add(role)
            continue
        chain = resolve(name)
        if chain is None or chain not in names:
            known = ", ".join(names[:8])
            raise InputError(
                f"marker {name!r} is not a persistent marker of the take ({known})", "--marker"
            )
        twice = next((other for other, named in roles.items() if named == chain), None)
        if twice is not None:
            raise InputError(f"marker {name!r} is given as both the {twice} and the {role}: each role is its own "
                             "marker", "--marker")
        roles[role] = chain
    free = [n for n in names if n not in roles.values()]
    height = {n: float(np.nanmedian(up_m(n))) for n in free}
    motion = {n: float(np.subtract(*np.nanpercentile(up_m(n), [99, 1]))) for n in free}
    moving = [n for n in free if motion[n] >= STATIC_MOTION_M]
    if "arm" not in roles and "arm" not in absent and moving:
        ranked = sorted(moving, key=lambda n: height[n], reverse=True)
        if len(ranked) > 1 and height[ranked[0]] - height[ranked[1]] < ARM_SEPARATION_M:
            _unclear("arm", "highest", ranked[:2], height, where)
        roles["arm"] = ranked[0]
    rest = [n for n in moving if n not in roles.values()]
    if "key" not in roles and "key" not in absent:
        # A key a preload holds nearly still first: the travel rule would take a two-marker
        # finger's fingertip for it.
        key = _held_key(free, motion, up_m, roles.get("arm")) or _least_moving(rest, motion, where)
        if key is not None:
            roles["key"] = key
    rest = [n for n in moving if n not in roles.values()]
    if "fingertip" not in roles and "fingertip" not in absent and rest:
        ranked = sorted(rest, key=lambda n: height[n])
        if len(ranked) > 1 and height[ranked[1]] - height[ranked[0]] < TIP_SEPARATION_M:
            _unclear("fingertip", "lowest", ranked[:2], height, where)
        roles["fingertip"] = ranked[0]
    return {role: roles[role] for role in ROLES if role in roles}


def _least_moving(rest: list[str], motion: dict[str, float], where: str) -> str | None:
    """The travel rule: the key is the moving marker that travels clearly least (None: fewer
    than two markers left to tell apart)."""
    ranked = sorted(rest, key=lambda n: motion[n])
    if len(ranked) < 2:
        return None
    margin = KEY_CHAIN_RATIO if len(rest) >= 3 else KEY_MOTION_RATIO
    if motion[ranked[0]] <= margin * motion[ranked[1]] and motion[ranked[0]] <= KEY_MAX_TRAVEL_M:
        return ranked[0]
    _unclear("key", "least moving", ranked[:2], motion, where)


def _held_key(free: list[str], motion: dict[str, float], up_m: Callable[[str], FloatArray],
              arm: str | None) -> str | None:
    """The one marker that barely moves but moves with the arm (module docstring), or None."""
    if arm is None:
        return None
    a = up_m(arm)
    locked = []
    for n in free:
        if not HELD_KEY_MOTION_M <= motion[n] < STATIC_MOTION_M:
            continue
        if _locked_to_arm(up_m(n), a) >= PRESS_LOCKED:
            locked.append(n)
    return locked[0] if len(locked) == 1 else None


def _locked_to_arm(y: FloatArray, arm: FloatArray) -> float:
    """How closely a marker's height follows the arm's: their correlation, with the marker's
    drift taken out. The capture volume drifts by a tenth of a millimetre or more, as much as a
    held key moves; where the arm is up (within `ARM_UP_SHARE` of its range from the top, between
    presses) the key is at rest, so the marker's height there, interpolated in time, is its
    drift (measured on an independent take: a 0.4 N rest stop under a resting finger, the key
    moving 0.14 mm only at the bottom of each press: 0.19 with the drift, 0.67 without)."""
    both = np.flatnonzero(np.isfinite(y) & np.isfinite(arm))
    if both.size < 3:
        return 0.0
    y, a = y[both], arm[both]
    lo, hi = np.percentile(a, [1, 99])
    up = a >= hi - ARM_UP_SHARE * (hi - lo)
    if up.sum() < 2 or up.all():
        return 0.0
    pressed = y - np.interp(both, both[up], y[up])
    if not np.std(pressed) > 0:
        return 0.0
    return float(np.corrcoef(pressed, a)[0, 1])


def _unclear(
    role: str, rule: str, candidates: list[str], value: dict[str, float], where: str
) -> NoReturn:
    what = "height" if rule != "least moving" else "travel"
    listed = " or ".join(f"{n} ({what} {value[n] * 1000:.1f} mm)" for n in candidates)
    raise InputError(
        f"cannot tell which marker is the {role} (the {rule} one): {listed}; "
        f"name it with --marker {role}=NAME (or --marker {role}=none if it is not in view)",
        where,
    )
