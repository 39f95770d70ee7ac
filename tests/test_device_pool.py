"""The env's device pool: episodes that share N drawn units instead of drawing one each."""
from __future__ import annotations

import numpy as np
import pytest

from ebraille_sim.rl.env import ContactForceEnv
from ebraille_sim.rl.vector_env import ContactForceVectorEnv
from ebraille_sim.scenarios.episodes import EpisodeDistribution
from ebraille_sim.scenarios.population import PopulationSpec, sample_devices


def _unit(device):
    """What makes a device's unit and reader (not the episode's supply, which sags per episode)."""
    return (device.finger, device.fsr, device.motor, device.drivetrain, device.current_sense, device.circuit,
            device.estimator)


def test_pool_units_are_the_population_draws_of_the_pool_seed_and_every_unit_is_used():
    env = ContactForceEnv(device_pool=5, device_pool_seed=11)
    expected = [_unit(d) for d in sample_devices(11, 5, PopulationSpec(), env.config.base_device)]
    env.reset(seed=2)
    seen = []
    for _ in range(60):
        env.reset()
        k = [j for j, u in enumerate(expected) if u == _unit(env.episode.device)]
        assert len(k) == 1
        seen.append(k[0])
    assert set(seen) == set(range(5))
    counts = np.bincount(seen, minlength=5)
    assert counts.max() < 30                      # uniform over the pool: 12 expected each


def test_a_pool_unit_is_drawn_once_and_kept():
    dist = EpisodeDistribution(device_pool=3, device_pool_seed=4)
    a = dist.pool_device(2)
    assert dist.pool_device(2) is a
    assert _unit(a) == _unit(sample_devices(4, 3)[2])
    with pytest.raises(ValueError, match="pool unit 3 is out of range"):
        dist.pool_device(3)


def test_the_pool_keeps_the_other_draws_and_the_same_seed_gives_the_same_trajectory():
    def run(**kw):
        env = ContactForceEnv(**kw)
        obs, _ = env.reset(seed=7)
        out = [obs]
        for k in range(150):
            obs, r, term, trunc, _ = env.step(np.array([0.3 * np.sin(0.05 * k)], np.float32))
            out.append(obs)
        return env.episode, np.array(out)

    ep_a, tr_a = run(device_pool=4)
    ep_b, tr_b = run(device_pool=4)
    assert np.array_equal(tr_a, tr_b)
    ep_fresh, _ = run()
    # the pool changes the device only: the reading, setpoint and gap are the episode's own draws
    assert ep_a.passage == ep_fresh.passage and ep_a.wpm == ep_fresh.wpm and ep_a.gap_m == ep_fresh.gap_m
    assert np.array_equal(ep_a.setpoint_n, ep_fresh.setpoint_n)
    assert _unit(ep_a.device) != _unit(ep_fresh.device)


def test_an_episode_of_the_pool_is_its_spec_again():
    from ebraille_sim.rl.episode import episode_from_spec
    env = ContactForceEnv(device_pool=2)
    env.reset(seed=5)
    ep = env.episode
    again = episode_from_spec(ep.spec)             # what run_scenario(ep.spec) runs
    assert _unit(again.device) == _unit(ep.device)
    assert _unit(ep.device) in [_unit(d) for d in sample_devices(0, 2, PopulationSpec(), env.config.base_device)]
    assert np.array_equal(again.setpoint_n, ep.setpoint_n) and np.array_equal(again.finger_m, ep.finger_m)
    assert again.sensor_seed == ep.sensor_seed


def test_vector_env_sub_envs_take_their_units_from_the_pool():
    venv = ContactForceVectorEnv(num_envs=4, device_pool=2, device_pool_seed=9)
    venv.reset(seed=1)
    units = [_unit(d) for d in sample_devices(9, 2, PopulationSpec(), venv.config.base_device)]
    assert all(_unit(ep.device) in units for ep in venv.episodes)


@pytest.mark.parametrize("kwargs, message", [
    ({"device_pool": -1}, "device_pool"),
    ({"device_pool": 2.5}, "device_pool"),
    ({"device_pool": 10 ** 6}, "device_pool"),
    ({"device_pool_seed": -3}, "device_pool_seed"),
    ({"device_pool": 3, "randomize_device": False}, "needs randomize_device=True"),
])
def test_bad_pool_arguments_are_one_line_errors(kwargs, message):
    with pytest.raises(ValueError, match=message) as exc:
        ContactForceEnv(**kwargs)
    assert "\n" not in str(exc.value)
