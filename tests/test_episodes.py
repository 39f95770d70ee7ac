"""Episodes are scenarios: the env's draw is a ScenarioSpec, run by the runner's input builder."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controllers import make
from ebraille_sim.rl.env import ContactForceEnv
from ebraille_sim.scenarios.disturbances import Battery, Pressing, Tremor
from ebraille_sim.scenarios.episodes import EpisodeDistribution
from ebraille_sim.scenarios.inputs import SCHEDULE_CELL_MARGIN, build_run_inputs
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import ScenarioSpec, load_scenario


class PwmPid:
    """The scenario PID with its command quantised to 2^-16 of the driver supply (a PWM duty).

    A duty ``d = m / 2^16`` times the supply is computed by the env from the action ``d`` with
    the same floating-point product, so replaying the duties reproduces the volts exactly.  The
    duties are the whole run's: a reset (the supervisor resumes the controller after its search
    for the first contact) does not clear them.
    """

    name = "pwm_pid"

    def __init__(self, supply_v: float):
        self.pid = make("pid")
        self.supply_v = supply_v
        self.duties: list[float] = []

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        self.pid.reset(force_est_n=force_est_n, setpoint_n=setpoint_n, command_v=command_v)

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        u = self.pid.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        d = float(np.clip(np.round(u / self.supply_v * 2**16) / 2**16, -1.0, 1.0))
        self.duties.append(d)
        return d * self.supply_v


def _battery_seed(env, want: bool, start: int = 0) -> int:
    for seed in range(start, start + 60):
        env.reset(seed=seed)
        if ("battery" in env.episode.spec.sections.get("disturbances", {})) == want:
            return seed
    raise AssertionError("no such episode in 60 seeds")


@pytest.mark.parametrize("rate_hz, battery", [(1000.0, False), (200.0, True)])
def test_runner_and_env_give_the_same_trajectory_for_the_same_spec(rate_hz, battery):
    env = ContactForceEnv(control_rate_hz=rate_hz)
    seed = _battery_seed(env, battery)
    env.reset(seed=seed)
    spec = env.episode.spec
    assert isinstance(spec, ScenarioSpec) and spec.device.rates.control_rate_hz == rate_hz
    assert "tremor" in spec.sections["disturbances"]

    ctrl = PwmPid(env.config.base_device.driver_supply_v)
    res = run_scenario(spec, controller=ctrl)
    duties = list(ctrl.duties)
    n = len(res.trace["force_true_n"])
    assert n == env.episode.n_steps == len(duties)

    env.reset(seed=seed)
    assert env.episode.spec == spec
    f_true, f_est, cmd = [], [], []
    for k, d in enumerate(duties):
        _, _, term, trunc, info = env.step(np.array([d]))
        f_true.append(info["force_true_n"])
        f_est.append(info["force_est_n"])
        cmd.append(info["command_v"])
        assert not term and trunc == (k == n - 1)
    # bit for bit: same spec, same input arrays, same kernel, same volts
    assert np.array_equal(np.array(cmd), res.trace["command_v"])
    assert np.array_equal(np.array(f_true), res.trace["force_true_n"])
    assert np.array_equal(np.array(f_est), res.trace["force_est_n"])
    assert np.max(res.trace["force_true_n"]) > 0.2            # the episode did press the finger
    if battery:
        supply = env.episode.run.profiles["driver_supply_v"]
        assert 3.0 < supply.min() < supply.max() < 4.2       # one Li-ion cell, not the 6 V supply


def test_env_episodes_carry_band_limited_tremor():
    env = ContactForceEnv(control_rate_hz=200.0)
    env.reset(seed=4, options={"wpm": 60.0, "drift_amplitude_m": 0.0, "tremor_amplitude_m": 20e-6,
                               "gap_m": 1e-3})
    x = env.episode.finger_m - 1e-3
    assert np.std(x) == pytest.approx(20e-6 / np.sqrt(2), rel=0.15)
    p = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(len(x), env.config.dt_s)
    band = (f >= 7.5) & (f <= 12.5)
    assert p[band].sum() / p.sum() > 0.95                       # energy in the tremor band
    share = np.sort(p[band])[::-1] / p[band].sum()
    assert share[0] < 0.3                                        # not one spectral line
    assert np.searchsorted(np.cumsum(share), 0.9) + 1 >= 10      # 90 % needs many bins


def test_same_seed_same_episode_and_other_seeds_differ():
    a, b, c = ContactForceEnv(), ContactForceEnv(), ContactForceEnv()
    a.reset(seed=21)
    b.reset(seed=21)
    c.reset(seed=22)
    assert a.episode.spec == b.episode.spec
    assert np.array_equal(a.episode.finger_m, b.episode.finger_m)
    assert np.array_equal(a.episode.setpoint_n, b.episode.setpoint_n)
    assert a.episode.spec != c.episode.spec
    assert not np.array_equal(a.episode.finger_m[:100], c.episode.finger_m[:100])


def test_draws_are_scenario_sections_in_their_ranges():
    dist = EpisodeDistribution()
    batteries = 0
    for seed in range(40):
        spec = dist.draw(np.random.SeedSequence(seed))
        assert spec.duration_s is None and spec.reading.max_characters == 30 and spec.reading.start_s == 1.0
        assert 60.0 <= spec.reading.wpm <= 120.0
        levels = [spec.setpoint.force_n] + [f for _, f in spec.setpoint.steps]
        assert 1 <= len(levels) <= 3 and all(0.3 <= f <= 1.5 for f in levels)
        assert all(1.0 <= t for t, _ in spec.setpoint.steps)
        assert 0.5e-3 <= spec.finger.gap_m <= 1.5e-3
        dist_sec = spec.sections.get("disturbances", {})
        assert isinstance(dist_sec["tremor"], Tremor) and dist_sec["tremor"].band_hz == (8.0, 12.0)
        assert 0.0 < dist_sec["tremor"].rms_m <= 20e-6
        assert isinstance(dist_sec["pressing"], Pressing) and dist_sec["pressing"].rms_m <= 0.1e-3
        if "battery" in dist_sec:
            batteries += 1
            assert isinstance(dist_sec["battery"], Battery) and 0.05 <= dist_sec["battery"].soc_start <= 1.0
            assert spec.device.driver_supply_v == 6.0
        else:
            assert 0.85 * 6.0 <= spec.device.driver_supply_v <= 6.0
        run = build_run_inputs(spec)
        assert len(run.schedule) == 30 and run.setpoint_n.shape == (run.n_steps + 1,)
    assert 3 <= batteries <= 20                               # p = 0.25 over 40 draws


def test_no_disturbances_gives_a_still_finger_and_a_full_supply():
    spec = EpisodeDistribution(disturbances=False, population=None).draw(np.random.SeedSequence(0))
    run = build_run_inputs(spec)
    assert spec.sections == {} and run.profiles == {} and spec.device.driver_supply_v == 6.0


def test_fixed_components_do_not_shift_the_others():
    dist = EpisodeDistribution()
    free = dist.draw(np.random.SeedSequence(5))
    fixed = dist.draw(np.random.SeedSequence(5), {"wpm": 90.0, "passage": "market", "first_character": 0})
    from ebraille_sim.scenarios.passages import load_passage
    assert fixed.reading.wpm == 90.0 and load_passage("market").startswith(fixed.reading.text)
    assert fixed.device == free.device and fixed.seed == free.seed and fixed.finger == free.finger
    assert fixed.setpoint.force_n == free.setpoint.force_n
    with pytest.raises(ValueError, match="unknown fixed component 'speed'"):
        dist.draw(np.random.SeedSequence(5), {"speed": 1.0})


def test_each_drawn_value_follows_its_own_variate():
    """Widening one range moves that value only, for a device and for an episode; the
    episode's device is the population's draw of the episode's seed."""
    from ebraille_sim.scenarios.population import PopulationSpec, device_from_variates, device_variates, sample_device
    u, z = device_variates(np.random.SeedSequence(4))
    a = device_from_variates(u, z, PopulationSpec(calibrate=False))
    b = device_from_variates(u, z, PopulationSpec(calibrate=False, gear_efficiency=(0.6, 0.9)))
    assert b.drivetrain.gear_efficiency == pytest.approx(0.6 + 0.3 * u[6], rel=1e-12)
    assert a.drivetrain.gear_efficiency == pytest.approx(0.5 + 0.2 * u[6], rel=1e-12)
    assert dataclasses.replace(b.drivetrain, gear_efficiency=a.drivetrain.gear_efficiency) == a.drivetrain
    assert (a.finger, a.fsr, a.motor) == (b.finger, b.fsr, b.motor)
    free = EpisodeDistribution().draw(np.random.SeedSequence(9))
    wide = EpisodeDistribution(wpm_range=(30.0, 300.0), gap_range_m=(0.1e-3, 2e-3)).draw(np.random.SeedSequence(9))
    assert wide.device == free.device and wide.seed == free.seed and wide.sections == free.sections
    assert [f for _, f in wide.setpoint.steps] == [f for _, f in free.setpoint.steps]   # times follow the length
    assert wide.reading.wpm != free.reading.wpm and wide.finger != free.finger
    drawn = sample_device(np.random.SeedSequence(9))
    assert free.device == dataclasses.replace(drawn, driver_supply_v=free.device.driver_supply_v)
    assert free.device.driver_supply_v <= drawn.driver_supply_v        # a sag or the full supply


def test_bad_distributions_are_one_line_errors():
    for kwargs, text in [({"wpm_range": (120.0, 60.0)}, "low <= high"),
                         ({"passages": ("nope",)}, "not one of"),
                         ({"battery_probability": 1.5}, "out of range"),
                         ({"setpoint_range_n": (0.3, 5.0)}, "out of range"),
                         ({"episode_characters": 0}, "integer")]:
        with pytest.raises(ValueError, match=text) as exc:
            EpisodeDistribution(**kwargs)
        assert "\n" not in str(exc.value)
    with pytest.raises(ValueError, match="Nyquist"):
        ContactForceEnv(control_rate_hz=20.0)                  # 8-12 Hz tremor needs > 24 Hz


def test_schedule_margin_covers_a_jittered_duration():
    spec = load_scenario("jittered_reading")
    spec = dataclasses.replace(spec, duration_s=20.0)
    run = build_run_inputs(spec)
    assert run.schedule.t_end_s >= 20.0
    need = (20.0 - spec.reading.start_s) / (60.0 / (5 * spec.reading.wpm))
    assert len(run.schedule) == int(np.ceil(need * SCHEDULE_CELL_MARGIN)) + 1
