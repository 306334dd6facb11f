"""The simulated lab: reproducible keystrokes, instruments, and the real data's behaviour."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from pianobot.physics.effects import Effects
from pianobot.physics.trajectory import Press, press_duration_s
from pianobot.physics.world import World, WorldConfig

PRESS = Press(0.05, 0.03, 0.06, 0.06, 1.0, 0.1)


def test_a_keystroke_is_a_pure_function_of_its_inputs() -> None:
    w = World.default(seed=3)
    a = w.keystroke(PRESS, -60.0, key="trial-1", t0_s=10.0)
    World.default(seed=3).keystroke(PRESS, -40.0, key="other")  # unrelated work in between
    b = World.default(seed=3).keystroke(PRESS, -60.0, key="trial-1", t0_s=10.0)
    assert a.midi == b.midi
    assert np.array_equal(a.mocap_x2_m, b.mocap_x2_m, equal_nan=True)
    c = w.keystroke(PRESS, -60.0, key="trial-2", t0_s=10.0)
    assert not np.array_equal(a.mocap_x2_m, c.mocap_x2_m, equal_nan=True)
    assert np.array_equal(a.truth_x2_m, c.truth_x2_m)  # noise differs, physics does not
    batch = w.keystrokes([PRESS, PRESS], -60.0, t0_s=[10.0, 20.0], keys=["trial-1", "x"])
    assert batch[0].midi == a.midi and np.allclose(batch[0].truth_x2_m, a.truth_x2_m)


def test_observations_have_the_configured_form() -> None:
    cfg = WorldConfig(mocap={"drop_prob": 0.2, "clock_offset_s": 0.01}, arm_rate_hz=125)
    w = World(cfg, seed=1)
    k = w.keystroke(PRESS, -80.0, t0_s=5.0, key="k")
    assert k.duration_s >= press_duration_s(PRESS)
    assert k.truth_t_s[0] == 5.0 and k.arm_t_s[0] == 5.0
    assert np.allclose(np.diff(k.arm_t_s), 1 / 125)
    assert np.allclose(np.diff(k.mocap_t_s), 1 / 120)
    lost = np.isnan(k.mocap_x2_m)
    assert 0 < lost.sum() < lost.size and np.array_equal(lost, np.isnan(k.mocap_x0_m))
    # mocap stamps = true time + clock offset + the world's mocap delay
    offset = 0.01 + w.model.mocap_delay_s
    tau = k.mocap_t_s[~lost] - offset
    truth = np.interp(tau, k.truth_t_s, k.truth_x2_m)
    assert np.max(np.abs(k.mocap_x2_m[~lost] - truth)) < 2e-5
    ons = [e for e in k.midi if e.type == "note_on"]
    assert len(ons) == 1 and 5.0 < ons[0].t_s < 5.0 + k.duration_s
    assert [e.type for e in k.midi] == ["note_on", "note_off"]
    assert 0.0038 < k.max_key_travel_m < 0.011
    assert k.key_speed_at_trigger_mps > 0


def test_config_is_yaml_able() -> None:
    cfg = WorldConfig(effects=Effects.default_world().to_dict(), mocap={"noise_m": 1e-5})
    again = WorldConfig.model_validate(yaml.safe_load(yaml.safe_dump(cfg.model_dump())))
    assert again == cfg
    assert World(again).model == World(cfg).model


def test_midi_times_sit_on_the_run_clock_ticks() -> None:
    k = World.default().keystroke(PRESS, -60.0, t0_s=3.0004, key="tick")
    assert k.midi
    for e in k.midi:
        assert abs(e.t_s * 1000 - round(e.t_s * 1000)) < 1e-6


def test_linear_world_and_config_validation() -> None:
    w = World.linear()
    assert w.model.effects == Effects.none()
    assert "contact" in World.default().model.effects
    with pytest.raises(ValidationError):
        WorldConfig(unknown=1)  # type: ignore[call-arg]
    with pytest.raises(ValidationError):
        WorldConfig(arm_rate_hz=100)  # type: ignore[arg-type]
    w2 = World(WorldConfig(effects={"keybed": {"form": "linear", "bed_depth_m": 0.009}}))
    assert w2.model.effects.names == ("keybed",)
    assert w.vacuum_settle_s(-60, -60) == 0.0
    assert w.vacuum_settle_s(0, -80) > w.vacuum_settle_s(0, -20) > 0.0


def test_default_world_shows_the_real_soft_finger_trends() -> None:
    """Silence falls with vacuum and depth; velocity rises with speed except at 0.1 m/s²."""
    w = World.default(seed=0)
    vacua, depths, vels, accs = (0.0, -40.0, -80.0), (0.02, 0.03, 0.04), (0.01, 0.04, 0.06, 0.08), (0.1, 1.0)
    grid = [(p, d, v, a) for p in vacua for d in depths for v in vels for a in accs]
    presses = [Press(0.05, d, v, v, a, 0.0) for _, d, v, a in grid]
    ks = w.keystrokes(presses, [g[0] for g in grid])
    vel = {g: (k.on_velocity or 0) for g, k in zip(grid, ks, strict=True)}

    def silent(**fix: float) -> float:
        keys = [g for g in grid if all(g[("p", "d", "v", "a").index(n)] == x for n, x in fix.items())]
        return float(np.mean([vel[g] == 0 for g in keys]))

    by_vacuum = [silent(p=p) for p in vacua]
    assert by_vacuum[0] > by_vacuum[1] >= by_vacuum[2]
    assert by_vacuum[0] == 1.0 and by_vacuum[2] < 0.5
    by_depth = [silent(d=d) for d in depths]
    assert by_depth[0] > by_depth[1] >= by_depth[2]
    for p in (-40.0, -80.0):
        rising = [vel[(p, 0.04, v, 1.0)] for v in vels]
        assert rising[-1] > rising[0] + 3 and all(b >= a for a, b in zip(rising, rising[1:], strict=False))
        # at 0.1 m/s² the arm never reaches the commanded speed within the distance
        assert vel[(p, 0.04, 0.08, 0.1)] <= vel[(p, 0.04, 0.06, 0.1)] + 1
        assert vel[(p, 0.04, 0.08, 0.1)] < vel[(p, 0.04, 0.08, 1.0)]
    sounded = [v for v in vel.values() if v > 0]
    assert max(sounded) <= 60 and np.median(sounded) <= 25
    assert all(math.isfinite(k.max_key_travel_m) for k in ks)
