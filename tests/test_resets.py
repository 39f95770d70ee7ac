"""Cheap resets: the cached calibration and packing give the numbers of the uncached path
(the env's trajectories from empty and from filled caches: ``tests/test_reset_cost.py``)."""
import dataclasses

import numpy as np
import pytest

from ebraille_sim.estimation import calibration
from ebraille_sim.physics.params import DeviceParams, EstimatorParams
from ebraille_sim.scenarios.population import PopulationSpec, sample_device


@pytest.mark.parametrize("model", ["paper:wiener:5", "paper:hammerstein:3", "paper:linear:2"])
def test_cached_calibration_is_bit_identical_to_the_protocol(model):
    base = dataclasses.replace(DeviceParams(), estimator=EstimatorParams(model=model))
    spec = dataclasses.replace(PopulationSpec(), calibrate=False)
    devices = [sample_device(s, spec, base) for s in range(12)]
    for dev in devices:
        fast = calibration.calibrate_device(dev)
        slow = calibration.calibrate_device_reference(dev)
        assert fast.circuit.r2_ohm == slow.circuit.r2_ohm      # exact, not approximate
        assert fast == slow
    assert len({d.fsr for d in devices}) == len(devices)       # the units really differ


def test_calibration_moves_r2_and_reads_the_calibration_force():
    dev = DeviceParams()
    cal = calibration.calibrate_device(dev, force_n=1.0, hold_s=20.0)
    assert cal.circuit.r2_ohm != dev.circuit.r2_ohm
    model = calibration.cached_model(dev.estimator.model)
    est = calibration.steady_estimate(model, 1.0, cal.fsr, cal.circuit, 20.0)
    assert est == pytest.approx(1.0, abs=1e-5)
    # a different calibration force gives a different R2 (the cache key includes it)
    assert calibration.calibrate_device(dev, force_n=2.0).circuit.r2_ohm != cal.circuit.r2_ohm


def test_resets_reuse_the_caches_and_the_next_episode_differs():
    import gymnasium as gym
    import ebraille_sim  # noqa: F401
    env = gym.make("EBraille/ContactForce-v0", randomize_device=False, safety=False)
    o1, _ = env.reset(seed=5)
    p1 = env.unwrapped.plant.params.copy()
    seed1 = env.unwrapped.episode.sensor_seed
    o2, _ = env.reset(seed=5)
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(env.unwrapped.plant.params, p1)
    env.reset()
    assert env.unwrapped.episode.sensor_seed != seed1
