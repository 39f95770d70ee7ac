"""The pymunk plant (ebraille_sim.plant.pymunk.plant): cross-validation with the lumped plant,
determinism, the off-centre scenario, checked options and inputs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.backends import PLANT_BACKENDS
from ebraille_sim.plant.pymunk.plant import PymunkPlant
from ebraille_sim.plant.pymunk.recording import Recorder
from ebraille_sim.scenarios.mechanism_section import load_mechanism_scenario
from ebraille_sim.scenarios.runner import run_scenario

STANDARD = ["steady_60wpm", "steady_90wpm", "steady_120wpm", "setpoint_steps", "contact_onset"]
BOUND = 0.05          # true-force RMS difference between the backends, fraction of the setpoint

def test_the_pymunk_backend_is_this_plant():
    from ebraille_sim.plant.backends import make_plant
    assert PLANT_BACKENDS["pymunk"] == "ebraille_sim.plant.pymunk.plant:PymunkPlant"
    assert type(make_plant([DeviceParams()], seeds=[1], backend="pymunk")) is PymunkPlant

def _rms_difference(scenario, duration_s, **kw):
    a = run_scenario(scenario, duration_s=duration_s)
    b = run_scenario(scenario, duration_s=duration_s, backend="pymunk", **kw)
    d = a.trace["force_true_n"] - b.trace["force_true_n"]
    return math.sqrt(float(np.mean(d ** 2))) / float(np.mean(a.trace["setpoint_n"])), a, b

@pytest.mark.parametrize("scenario", STANDARD)
def test_backends_agree_on_standard_scenarios_short(scenario):
    """First 4.5 s of every standard scenario (onset, reading and the first setpoint step)."""
    rel, _, b = _rms_difference(scenario, 4.5)
    assert rel <= BOUND, f"{scenario}: true-force RMS difference {rel:.1%} of the setpoint"
    assert b.metrics["peak_force_n"] < 3.0

@pytest.mark.slow
@pytest.mark.parametrize("scenario", STANDARD)
def test_backends_agree_on_standard_scenarios_full_length(scenario):
    """Full length.  Where the friction-limited loop is chaotic (the 2 N stretch of
    setpoint_steps: stick-slip events at different instants), the lumped plant differs from
    itself by about 6 % between its 10 kHz and 20 kHz steps; there the mechanism must
    stay within that reproducibility of the reference model."""
    import dataclasses

    from ebraille_sim.scenarios.spec import load_scenario
    rel, a, _ = _rms_difference(scenario, None)
    spec = load_scenario(scenario)
    fine = dataclasses.replace(spec.device, rates=dataclasses.replace(spec.device.rates, physics_rate_hz=20000.0))
    a20 = run_scenario(dataclasses.replace(spec, device=fine))
    d = a.trace["force_true_n"] - a20.trace["force_true_n"]
    own = math.sqrt(float(np.mean(d ** 2))) / float(np.mean(a.trace["setpoint_n"]))
    assert rel <= max(BOUND, 1.1 * own), (f"{scenario}: true-force RMS difference {rel:.1%} of the setpoint "
                                          f"(lumped 10 vs 20 kHz: {own:.1%})")

def test_without_2d_effects_the_mechanism_reproduces_the_lumped_plant_closely(monkeypatch):
    """No mesh offset (no binding): what remains is the step size and the rack/board split."""
    import ebraille_sim.plant.backends as backends
    import ebraille_sim.plant.pymunk.plant as pymunk_plant

    class NoOffsetPlant(PymunkPlant):
        @classmethod
        def from_devices(cls, devices, seeds, board_pos_m=None, models=None):
            return super().from_devices(devices, seeds, board_pos_m, models, mesh_offset_m=0.0)

    monkeypatch.setattr(pymunk_plant, "NoOffsetPlant", NoOffsetPlant, raising=False)
    monkeypatch.setitem(backends.PLANT_BACKENDS, "pymunk_no_offset", "ebraille_sim.plant.pymunk.plant:NoOffsetPlant")
    a = run_scenario("setpoint_steps", duration_s=4.5)
    b = run_scenario("setpoint_steps", duration_s=4.5, backend="pymunk_no_offset")
    d = a.trace["force_true_n"] - b.trace["force_true_n"]
    assert math.sqrt(float(np.mean(d ** 2))) / float(np.mean(a.trace["setpoint_n"])) <= 0.01

def test_same_seed_gives_the_same_trajectory_exactly():
    a = run_scenario("contact_onset", duration_s=1.0, backend="pymunk", seed=5)
    b = run_scenario("contact_onset", duration_s=1.0, backend="pymunk", seed=5)
    for col in ("force_true_n", "force_est_n", "fsr_voltage_v", "command_v", "board_pos_m", "energy_j"):
        assert np.array_equal(a.trace[col], b.trace[col]), col
    c = run_scenario("contact_onset", duration_s=1.0, backend="pymunk", seed=6)
    assert not np.array_equal(a.trace["fsr_voltage_v"], c.trace["fsr_voltage_v"])

def test_offcentre_scenario_runs_on_both_backends_and_shows_tilt():
    spec = load_mechanism_scenario("offcentre_press")
    rec = Recorder(every_s=0.05)
    b = run_scenario(spec, backend="pymunk", duration_s=8.0, recorder=rec)
    t = np.array([f["t_s"] for f in rec.frames])
    tilt = np.array([f["tilt_rad"] for f in rec.frames])
    assert abs(np.mean(tilt[(t > 2.0) & (t < 3.0)])) < 1e-4
    assert np.mean(tilt[(t > 7.0) & (t < 8.0)]) < -5e-4
    a = run_scenario(spec, duration_s=8.0)
    assert np.isfinite(a.trace["force_true_n"]).all() and b.metrics["in_band_fraction"] > 0.8

def test_bad_options_and_inputs_give_one_line_errors():
    with pytest.raises(ValueError, match="unknown key 'rod_gap_m'.*allowed: .*rod_spacing_m"):
        PymunkPlant.from_devices([DeviceParams()], seeds=[1], rod_gap_m=1.0)
    with pytest.raises(ValueError, match="n_contacts"):
        PymunkPlant.from_devices([DeviceParams()], seeds=[1], n_contacts=1)
    with pytest.raises(ValueError, match="whole multiple"):
        PymunkPlant.from_devices([DeviceParams()], seeds=[1], physics_rate_hz=3000.0)
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_pose(finger_tilt_rad=float("nan"))
    with pytest.raises(ValueError, match="finger pose must be finite"):
        plant.advance(0.0)
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    with pytest.raises(ValueError, match="command_v must be finite"):
        plant.advance(float("inf"))
