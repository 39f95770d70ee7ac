"""Every plant backend: golden trajectories and one conformance suite.

Golden trajectories
-------------------
``tests/data/golden/<backend>.npz`` holds, for every backend of
:data:`ebraille_sim.plant.backends.PLANT_BACKENDS`, the first 3 s of the ``contact_onset``
scenario with seed 3 in closed loop (true force, estimate, FSR voltage, command, motor
current, board position, one sample per control period).  A fresh run must reproduce every
column within the absolute tolerance of ``make_golden.TOLERANCES``, each named by the
physics it guards (the true force within 1 mN, the FSR voltage on the same ADC code, the
current within the 16 uA that push 1 mN, ...): round-off that differs between machines stays
inside them, a change of the physics, the sensor chain, the estimator, the controller or the
scenario shows (0.1 % stiffer pulp fails, tested below).

After an *intended* change of any of those, rewrite the stored references and commit them
with the change, saying in the commit message why the trajectories moved::

    python tests/make_golden.py              # every golden trajectory and scenario baseline
    python tests/make_golden.py pymunk       # one backend

A new backend in ``PLANT_BACKENDS`` fails :func:`test_golden_trajectory` until its file
is written the same way.

Conformance
-----------
Every backend is built by ``from_devices`` and driven through the same interface
(``advance``, ``set_finger``, ``set_input``, the state views); the tests below hold each of
them to the same behaviour.  The lumped and the pymunk backends model the same device
(the pymunk one adds the rack/board split, the bushing side loads and a 2 kHz step), so
they must also agree on a centred press in closed loop: measured true-force RMS
difference 1.7 % of the 1 N setpoint over 2 s, contact within one control period of each
other, the mean of the last second 0.5 % apart.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import controllers
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.layout import N_INPUT, N_PARAM, N_STATE, S, U
from ebraille_sim.plant.backends import PLANT_BACKENDS, make_plant
from make_golden import (COLUMNS, CONTROLLER, DURATION_S, FIRMWARE, SCENARIO, SEED, TOLERANCES, golden_path, golden_run,
                         read_golden)

BACKENDS = list(PLANT_BACKENDS)
GAP_M = 1e-3            # pulp surface 1 mm above the retracted board


def _plant(backend, n=1, seeds=None, **kw):
    return make_plant([DeviceParams()] * n, seeds or list(range(1, n + 1)), backend=backend, **kw)


def _assert_matches_golden(fresh: dict, golden: dict, label: str) -> None:
    for c in COLUMNS:
        atol, guards = TOLERANCES[c]
        np.testing.assert_allclose(fresh[c], golden[c], rtol=0.0, atol=atol, err_msg=f"{label}: {c} ({guards})")


# ---------------------------------------------------------------- golden trajectories

@pytest.mark.parametrize("backend", BACKENDS)
def test_golden_trajectory(backend):
    path = golden_path(backend)
    assert path.exists(), f"no golden trajectory for backend {backend!r}: run python tests/make_golden.py {backend}"
    assert path.stat().st_size < 200 * 1024
    golden = read_golden(backend)
    assert (str(golden["scenario"]), int(golden["seed"]), float(golden["duration_s"]), str(golden["backend"])) \
        == (SCENARIO, SEED, DURATION_S, backend)
    n = round(DURATION_S * DeviceParams().rates.control_rate_hz)
    assert all(golden[c].shape == (n,) for c in COLUMNS)
    # the stored run makes contact and regulates: a trajectory worth guarding
    assert golden["force_true_n"][0] == 0.0 and 1.0 < golden["force_true_n"][-500:].mean() < 2.0
    _assert_matches_golden(golden_run(backend), golden, backend)


def test_golden_tolerances_name_every_column():
    assert sorted(TOLERANCES) == sorted(COLUMNS)
    assert all(atol > 0 and guards for atol, guards in TOLERANCES.values())


@pytest.mark.parametrize("backend, relative, caught", [("lumped", 1e-3, True), ("lumped", 1e-12, False),
                                                       ("pymunk", 1e-12, False)])
def test_golden_comparison_sees_a_small_physics_change_and_not_round_off(backend, relative, caught):
    """0.1 % stiffer pulp moves the trajectory far beyond the golden tolerance; a change of
    1e-12 relative, round-off that another machine may do differently, stays inside it."""
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.scenarios.spec import load_scenario
    dev = load_scenario(SCENARIO).device
    stiffer = dataclasses.replace(dev, finger=dataclasses.replace(
        dev.finger, stiffness_b_n_per_m=(1.0 + relative) * dev.finger.stiffness_b_n_per_m))
    res = run_scenario(SCENARIO, controller=CONTROLLER, seed=SEED, duration_s=DURATION_S, device=stiffer,
                       backend=backend, firmware=FIRMWARE)
    fresh = {c: np.asarray(res.trace[c], float) for c in COLUMNS}
    golden = read_golden(backend)
    if caught:
        with pytest.raises(AssertionError, match="force_true_n"):
            _assert_matches_golden(fresh, golden, backend)
    else:
        assert any(not np.array_equal(fresh[c], golden[c]) for c in COLUMNS)      # it did move
        _assert_matches_golden(fresh, golden, backend)


# ---------------------------------------------------------------- conformance

@pytest.mark.parametrize("backend", BACKENDS)
def test_from_devices_builds_n_devices(backend):
    dev = DeviceParams()
    plant = _plant(backend, n=3, board_pos_m=2e-3)
    assert plant.n == 3 and len(plant.devices) == 3
    assert plant.state.shape == (3, N_STATE)
    assert plant.params.shape == (3, N_PARAM)
    assert plant.inputs.shape == (3, N_INPUT)
    assert plant.control_dt_s == pytest.approx(1.0 / dev.rates.control_rate_hz)
    for view in (plant.contact_force_n, plant.force_est_n, plant.fsr_voltage_v, plant.motor_current_a,
                 plant.board_pos_m, plant.energy_j, plant.time_s):
        assert view.shape == (3,)
    assert np.all(plant.board_pos_m == 2e-3)
    assert np.all(plant.inputs[:, U.gravity_along_m_per_s2] == -dev.gravity_m_per_s2)
    assert np.all(plant.inputs[:, U.driver_supply_v] == dev.driver_supply_v)
    plant.advance(np.zeros(3))
    assert np.allclose(plant.time_s, plant.control_dt_s, rtol=1e-12)
    with pytest.raises(ValueError, match="at least one device"):
        make_plant([], [], backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_advance_accepts_scalars_and_arrays_and_rejects_non_finite_commands(backend):
    one = _plant(backend)
    for cmd in (0.5, 1, np.float64(0.5), np.array(0.5), np.array([0.5])):
        one.advance(cmd)
    for bad in (math.nan, math.inf, -math.inf, np.array([math.nan])):
        with pytest.raises(ValueError, match="command_v must be finite"):
            one.advance(bad)
    two = _plant(backend, n=2)
    two.advance(0.5)
    two.advance(np.array([0.5, 1.0]))
    assert list(two.inputs[:, U.command_v]) == [0.5, 1.0]
    with pytest.raises(ValueError, match="command_v must be finite for every device"):
        two.advance(np.array([0.5, math.nan]))
    with pytest.raises(ValueError):
        two.advance(np.zeros(3))           # one command per device


@pytest.mark.parametrize("backend", BACKENDS)
def test_set_finger_and_set_input(backend):
    plant = _plant(backend, n=2)
    plant.set_finger(np.array([1e-3, 2e-3]))
    assert list(plant.inputs[:, U.finger_pos_m]) == [1e-3, 2e-3]
    plant.set_finger(1.5e-3)
    assert list(plant.inputs[:, U.finger_pos_m]) == [1.5e-3, 1.5e-3]
    plant.set_input("fsr_temp_offset_k", 5.0)
    assert np.all(plant.inputs[:, U.fsr_temp_offset_k] == 5.0)
    with pytest.raises(KeyError, match="unknown plant input 'finger_speed'.*allowed: .*finger_pos_m"):
        plant.set_input("finger_speed", 1.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_zero_command_at_rest_keeps_zero_force(backend):
    plant = _plant(backend)
    plant.set_finger(GAP_M)
    x0 = float(plant.board_pos_m[0])
    for _ in range(300):
        plant.advance(0.0)
    assert plant.contact_force_n[0] == 0.0
    assert plant.motor_current_a[0] == 0.0
    assert abs(plant.board_pos_m[0] - x0) < 1e-6        # gravity holds it on the lower stop
    assert plant.state[0, S.elastic_force_n] == 0.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_positive_command_makes_contact_and_the_force_rises(backend):
    plant = _plant(backend)
    plant.set_finger(GAP_M)
    force = []
    for _ in range(400):
        plant.advance(1.5)
        force.append(float(plant.contact_force_n[0]))
    force = np.array(force)
    onset = int(np.argmax(force > 0.0))
    assert 0 < onset < 200, "no contact within 0.2 s at 1.5 V"
    assert np.all(force[:onset] == 0.0)
    assert plant.board_pos_m[0] > GAP_M
    # a press against the pulp: the force builds up after contact
    assert 0.0 < force[onset + 20] < force[onset + 100] < force[-1]
    assert plant.motor_current_a[0] > 0.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_batch_of_two_equals_single_runs_exactly(backend):
    soft = dataclasses.replace(DeviceParams(), finger=dataclasses.replace(
        DeviceParams().finger, stiffness_b_n_per_m=0.8 * DeviceParams().finger.stiffness_b_n_per_m))
    devices, seeds, gaps = [DeviceParams(), soft], [4, 9], [1e-3, 0.5e-3]
    cmds = np.array([[1.2, 2.0]] * 150 + [[0.8, -0.5]] * 50)
    batch = make_plant(devices, seeds, backend=backend)
    batch.set_finger(np.array(gaps))
    for c in cmds:
        batch.advance(c)
    for k in range(2):
        single = make_plant([devices[k]], [seeds[k]], backend=backend)
        single.set_finger(gaps[k])
        for c in cmds:
            single.advance(float(c[k]))
        assert np.array_equal(single.state[0], batch.state[k]), f"device {k}"
    assert batch.contact_force_n[0] > 0.0 and batch.contact_force_n[1] > 0.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_seed_gives_the_same_trajectory(backend):
    def run(seed):
        plant = _plant(backend, seeds=[seed])
        plant.set_finger(GAP_M)
        out = []
        for k in range(300):
            plant.advance(1.5 if k < 200 else 0.3)
            out.append(plant.state[0].copy())
        return np.array(out)
    a, b, c = run(7), run(7), run(8)
    assert np.array_equal(a, b)
    assert not np.array_equal(a[:, S.fsr_voltage_v], c[:, S.fsr_voltage_v])     # the sensor noise
    assert np.array_equal(a[:, S.board_pos_m], c[:, S.board_pos_m])                # open loop: same physics


def _centred_press(backend, setpoint_n=1.0, steps=2000):
    plant = _plant(backend)
    plant.set_finger(GAP_M)
    ctrl = controllers.make("pid")
    ctrl.reset(force_est_n=float(plant.force_est_n[0]), setpoint_n=setpoint_n, command_v=0.0)
    force, est = np.empty(steps), np.empty(steps)
    for k in range(steps):
        plant.advance(ctrl.update(float(plant.force_est_n[0]), setpoint_n, plant.control_dt_s,
                                  float(plant.motor_current_a[0])))
        force[k], est[k] = plant.contact_force_n[0], plant.force_est_n[0]
    return force, est, plant.state[0].copy()


def _hysteresis_log_offset(s):
    """Weighted play outputs less ln(F + F_eps): the log-force offset of the branch the sensor is on."""
    from ebraille_sim.physics.fsr import F_EPS_N, N_PLAYS
    lf = math.log(s[S.fsr_force_lagged_n] + F_EPS_N)
    return sum(s[S[f"play_{j}"]] - lf for j in range(N_PLAYS)) / N_PLAYS


def test_lumped_and_pymunk_agree_on_a_centred_press():
    """PID at 1 N from a 1 mm gap, 2 s.  Measured: RMS difference 2.8 % of the setpoint,
    onsets one control period apart; last-second means of the estimate 0.2 % apart
    (1.0024 / 1.0003 N) and of the true force 3.8 % (0.963 / 1.000 N).  Both backends
    feed the same sensor laws (kernel.sensor_substep) and end with the same creep states;
    the true forces differ by the branch of the rate-independent hysteresis each ends on
    after the onset overshoot and the friction-limited wiggles (weighted play outputs
    +0.016 above ln F in the lumped plant, -0.017 in the mechanism): the loop holds the
    estimate, so the true forces' ratio is the ratio of the branch factors exp(offset),
    and it stays inside the 10 % hysteresis band."""
    (lum, lum_est, s_lum), (mec, mec_est, s_mec) = _centred_press("lumped"), _centred_press("pymunk")
    rms = math.sqrt(float(np.mean((lum - mec) ** 2))) / 1.0
    assert rms < 0.03
    assert abs(int(np.argmax(lum > 0)) - int(np.argmax(mec > 0))) <= 2
    assert mec_est[-1000:].mean() == pytest.approx(lum_est[-1000:].mean(), rel=0.005)
    branch = math.exp(_hysteresis_log_offset(s_lum) - _hysteresis_log_offset(s_mec))
    assert s_mec[S.fsr_force_lagged_n] / s_lum[S.fsr_force_lagged_n] == pytest.approx(branch, rel=0.005)
    assert mec[-1000:].mean() == pytest.approx(lum[-1000:].mean(), rel=0.05)
