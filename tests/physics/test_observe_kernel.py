"""The compiled observation loops give bit for bit what the NumPy forms they replace give."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pianobot.physics._observe_kernel import crossing_times, interp, settled
from pianobot.physics.piano import PianoParams, _crossings, key_events
from pianobot.physics.world import REST_TOL_M, World


def _rest_time(t_s: np.ndarray, x1_m: np.ndarray, x2_m: np.ndarray, t_end_s: float) -> float:
    """The NumPy form of the rest time the compiled pass replaced (the reference it must equal)."""
    moving = np.nonzero((np.abs(x2_m) > REST_TOL_M) | (np.abs(x1_m) > REST_TOL_M))[0]
    last = float(t_s[moving[-1]]) if moving.size else 0.0
    return float(min(max(t_end_s, last + 1e-3), t_s[-1]))

def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and bool(np.all(a.view(np.int64) == b.view(np.int64)))


def _trace(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A key-like trace: rest, a press with noise and plateaus, a release, exact level hits."""
    t = np.arange(n) * 1e-3 + rng.uniform(0, 5)
    x = np.zeros(n)
    a, b = sorted(rng.integers(5, n - 5, 2))
    x[a:b] = np.sin(np.linspace(0, np.pi, b - a)) * rng.uniform(0.002, 0.012)
    x += rng.normal(0, 2e-5, n) * (rng.random(n) < 0.5)
    x[rng.integers(0, n, 3)] = 0.0038  # exactly on a sensor level
    x[b : b + 3] = x[b - 1]  # a plateau
    return t, x


@pytest.mark.parametrize("seed", range(6))
def test_interp_equals_numpy(seed: int) -> None:
    rng = np.random.default_rng(seed)
    xp = np.cumsum(rng.uniform(1e-4, 2e-3, 400))
    fp = rng.normal(size=400)
    fp[50:60] = 1.5  # a flat stretch
    queries = [
        np.arange(xp[0] - 0.01, xp[-1] + 0.01, 1 / 500),  # increasing, beyond both ends
        xp.copy(),  # exactly on the samples
        rng.uniform(xp[0] - 0.1, xp[-1] + 0.1, 300),  # any order
        np.array([np.nan, xp[3], np.nan]),
    ]
    for x in queries:
        assert _same_bits(interp(x, xp, fp), np.interp(x, xp, fp))
    big = fp.copy()
    big[100], big[200] = np.inf, -np.inf  # NumPy's fallbacks for a non-finite interval
    x = np.linspace(xp[95], xp[205], 700)
    assert _same_bits(interp(x, xp, big), np.interp(x, xp, big))


@pytest.mark.parametrize("seed", range(8))
def test_crossing_times_equal_the_array_form(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t, x = _trace(rng, int(rng.integers(200, 3000)))
    x[rng.integers(0, x.size)] = np.nan  # a lost sample crosses nothing
    for level in (0.0018, 0.0038, 0.001):
        for down in (True, False):
            k, frac = _crossings(x, level, down)
            assert _same_bits(crossing_times(t, x, level, down), t[k - 1] + frac * (t[k] - t[k - 1]))


@pytest.mark.parametrize("seed", range(4))
def test_key_events_compiled_and_array_paths_agree(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    import pianobot.physics.piano as piano

    rng = np.random.default_rng(seed)
    params = PianoParams()
    t, x = _trace(rng, 2500)
    t = t + 1000.0  # on a run clock far from zero, as the world reads it
    compiled = key_events(t, x, params, rng=np.random.default_rng(1))
    monkeypatch.setattr(piano, "_COMPILED_FROM", 10**9)
    arrays = key_events(t, x, params, rng=np.random.default_rng(1))
    assert compiled[0] and compiled[0] == arrays[0]
    assert _same_bits(np.array([compiled[1]]), np.array([arrays[1]]))


@pytest.mark.parametrize("seed", range(8))
def test_settled_equals_the_array_forms(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(100, 3000))
    t = np.arange(n) * 1e-3
    _, x2 = _trace(rng, n)
    x1 = x2 * 1.1 + rng.normal(0, 1e-5, n)
    v2 = np.gradient(x2, t)
    if seed == 3:
        x2[:] = 0.0  # never pressed: no speed, rests at once
        x1[:] = 0.0
    if seed == 5:
        x2[n // 3] = np.nan  # a NaN keeps its place in the depth (as np.max)
    lower = 0.0038
    for t_end in (0.0, 0.3 * n * 1e-3, 2.0 * n * 1e-3):
        duration, keep, speed, deepest = settled(t, x1, x2, v2, t_end, REST_TOL_M, lower)
        want = _rest_time(t, x1, x2, t_end)
        want_keep = int(np.searchsorted(t, want + 1e-9, side="right"))
        kx, kv = x2[:want_keep], v2[:want_keep]
        hit = np.nonzero((kx[:-1] < lower) & (kx[1:] >= lower))[0]
        want_speed = math.nan
        if hit.size:
            k = int(hit[0])
            f = (lower - kx[k]) / (kx[k + 1] - kx[k])
            want_speed = float(kv[k] + f * (kv[k + 1] - kv[k]))
        assert _same_bits(np.array([duration, speed, deepest]),
                          np.array([want, want_speed, float(np.max(kx))]))
        assert keep == want_keep


def test_world_keystrokes_observed_alone_and_in_a_batch_are_the_same() -> None:
    """The compiled observation inside the world: a batch and one-at-a-time agree exactly."""
    from pianobot.physics.trajectory import Press

    world = World.default(seed=4)
    presses = [Press(0.01, d, v, v, 0.6, 0.0) for d, v in ((0.02, 0.03), (0.03, 0.05), (0.025, 0.02))]
    batch = world.keystrokes(presses, -20.0, keys=["a", "b", "c"], t0_s=[0.0, 3.0, 6.0])
    for press, key, t0, got in zip(presses, "abc", (0.0, 3.0, 6.0), batch, strict=True):
        alone = World.default(seed=4).keystroke(press, -20.0, key=key, t0_s=t0)
        for name in ("truth_x2_m", "arm_x0_m", "mocap_x0_m", "mocap_x2_m", "mocap_t_s"):
            assert _same_bits(getattr(got, name), getattr(alone, name))
        assert got.midi == alone.midi
        assert _same_bits(np.array([got.key_speed_at_trigger_mps, got.max_key_travel_m]),
                          np.array([alone.key_speed_at_trigger_mps, alone.max_key_travel_m]))


@pytest.mark.parametrize("seed", range(5))
def test_last_beyond_equals_the_array_form(seed: int) -> None:
    from pianobot.physics._observe_kernel import last_beyond

    rng = np.random.default_rng(seed)
    _, x = _trace(rng, 1500)
    x[rng.integers(0, x.size)] = np.nan
    x[-1] = -0.02 if seed == 2 else x[-1]  # the last sample itself beyond (by its size)
    for level in (2e-5, 0.001, 0.0038, 1.0):
        away = np.nonzero(np.abs(x) > level)[0]
        deep = np.nonzero(x >= level)[0]
        assert last_beyond(x, level, True) == (int(away[-1]) if away.size else -1)
        assert last_beyond(x, level, False) == (int(deep[-1]) if deep.size else -1)
