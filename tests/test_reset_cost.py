"""Cheap resets: the caches behind ``ContactForceEnv.reset`` change no trajectory and are hit,
shared read-only and keyed on what they depend on.

The trajectories are compared within this process, bit for bit: every configuration's episodes
from caches emptied as a fresh process starts, and again from emptied caches that episodes of
other seeds have filled first with other devices, specs and excerpts (observations, rewards, ends, infos, the
drawn specs and packed parameters of the scalar env at 200 Hz and 1 kHz, with and without the
safety layer, device randomisation, disturbances and reset options, and of the vector env with
autoresets).  Across machines the goldens of ``tests/test_backends.py`` and the scenario
baselines compare at tolerances instead (docs/architecture.md, Determinism).
"""
import dataclasses
import functools
import math
import sys

import numpy as np
import pytest

from controllers.supervisor import (ENVELOPE_POINTS, SupervisorConfig, _envelope_table,
                                    _pack, _packed_config)
from ebraille_sim.base.validation import check_number
from ebraille_sim.physics.params import DeviceParams, FSRParams, MotorParams, check_finite
from ebraille_sim.rl.env import ContactForceEnv
from ebraille_sim.scenarios.inputs import _cells_of
from ebraille_sim.scenarios.population import PopulationSpec, sample_devices

CASES = [("default", {}, None), ("1khz", {"control_rate_hz": 1000.0}, None),
         ("nominal", {"randomize_device": False}, None), ("nosafety", {"safety": False}, None),
         ("nosafety_1khz", {"safety": False, "control_rate_hz": 1000.0}, None),
         ("options", {}, {"wpm": 300.0, "gap_m": 0.8e-3, "tremor_amplitude_m": 3e-5, "setpoint_n": 1.0}),
         ("options2", {}, {"passage": "garden", "first_character": 0, "supply_fraction": 0.8}),
         ("nodist", {"disturbances": False}, {"device": DeviceParams()})]
"""Configurations of the scalar env (keyword arguments, reset options) whose trajectories the
caches must not change."""


def clear_caches() -> None:
    """Empty every ``functools`` cache of the package and the controllers, as in a fresh process."""
    for name, module in list(sys.modules.items()):
        if name.split(".")[0] in ("ebraille_sim", "controllers"):
            for obj in list(vars(module).values()):
                if isinstance(obj, functools._lru_cache_wrapper):
                    obj.cache_clear()
    from controllers.supervisor import config
    from ebraille_sim.plant import lumped
    lumped._LAST_ROWS.clear()                                # the rows of the device packed last
    config._LAST_CHAIN.clear()                               # the datasheet chain made last
    config._LAST_CONSTANTS.clear()                           # the firmware limits' datasheet constants


def episodes(kw: dict, options, seeds, steps: int = 600) -> dict:
    """Per seed: the scalar env's observations, rewards, ends, infos, drawn specs and packed
    parameters over ``steps`` steps of a fixed action law, with the resets they need and
    three more."""
    env = ContactForceEnv(**kw)
    out = {}
    for seed in seeds:
        obs, info = env.reset(seed=seed, options=options)
        rows, rews, flags, infos = [obs], [], [], [sorted(info.items())]
        specs, params = [repr(env.episode.spec)], [env.plant.params.copy()]
        for k in range(steps):
            obs, r, te, tr, info = env.step(np.array([0.9 * np.sin(0.013 * k) + 0.2], dtype=np.float32))
            rows.append(obs); rews.append(r); flags.append((te, tr)); infos.append(sorted(info.items()))
            if te or tr:
                obs, info = env.reset()
                rows.append(obs); infos.append(sorted(info.items()))
                specs.append(repr(env.episode.spec)); params.append(env.plant.params.copy())
        for _ in range(3):
            obs, info = env.reset()
            rows.append(obs); infos.append(sorted(info.items()))
            specs.append(repr(env.episode.spec)); params.append(env.plant.params.copy())
        out[seed] = {"obs": np.array(rows), "rew": np.array(rews), "flags": np.array(flags),
                     "info": repr(infos), "spec": "\n".join(specs), "params": np.array(params)}
    return out


def vector_episodes(kw: dict, seed: int, steps: int) -> dict:
    """The vector env's (6 sub-envs, autoresets) observations, rewards and ends over ``steps`` steps."""
    from ebraille_sim.rl.vector_env import ContactForceVectorEnv
    venv = ContactForceVectorEnv(num_envs=6, parallel=False, **kw)
    obs, _ = venv.reset(seed=seed)
    rows, rews, flags = [obs], [], []
    for _ in range(steps):
        a = np.clip(0.05 + 0.6 * obs[:, 2:3] + 0.2 * obs[:, 4:5], -1, 1).astype(np.float32)
        obs, r, te, tr, _ = venv.step(a)
        rows.append(obs); rews.append(r); flags.append(np.stack([te, tr]))
    venv.close()
    return {"obs": np.array(rows), "rew": np.array(rews), "flags": np.array(flags)}


def _assert_same(a: dict, b: dict, label: str) -> None:
    assert sorted(a) == sorted(b), label
    for key in a:
        if isinstance(a[key], str):
            assert a[key] == b[key], f"{label}: {key}"
        else:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{label}: {key}")


def test_caches_change_no_trajectory():
    clear_caches()
    cold = {name: episodes(kw, opts, (0, 11)) for name, kw, opts in CASES}
    cold_vec = {name: vector_episodes(kw, 3, steps) for name, kw, steps in
                (("vec", {}, 1500), ("vec1k", {"control_rate_hz": 1000.0}, 600))}
    clear_caches()
    for name, kw, opts in CASES:                           # other devices, specs and excerpts first
        episodes(kw, opts, (5, 23), steps=200)
    vector_episodes({}, 8, 300)
    for name, kw, opts in CASES:
        warm = episodes(kw, opts, (0, 11))
        for seed in (0, 11):
            _assert_same(cold[name][seed], warm[seed], f"{name}, seed {seed}")
    assert any(flags.any() for flags in (cold[name][s]["flags"] for name in cold for s in (0, 11)))   # episodes ended
    for name, kw, steps in (("vec", {}, 1500), ("vec1k", {"control_rate_hz": 1000.0}, 600)):
        warm = vector_episodes(kw, 3, steps)
        _assert_same(cold_vec[name], warm, name)
    assert cold_vec["vec"]["flags"].any()                  # the sub-envs reset themselves


def test_same_seed_gives_the_same_first_observation_and_trajectory():
    env = ContactForceEnv()
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=42)
        rows, rews = [obs], []
        for k in range(300):
            obs, r, te, tr, _ = env.step(np.array([0.3 * math.sin(0.02 * k)], np.float32))
            rows.append(obs)
            rews.append(r)
        runs.append((np.array(rows), np.array(rews), info))
        env.reset()                                         # an episode in between
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


def test_compiled_envelope_equals_the_configs_laws_bit_for_bit():
    """The compiled envelope table (33 speeds from rest to the speed limit, then a braking
    current beyond it) holds, at every speed, the current :meth:`SupervisorConfig.current_for_force_a`
    gives for the drive force :meth:`SupervisorConfig.drive_force_limit_n` allows there."""
    devices = sample_devices(3, 300, dataclasses.replace(PopulationSpec(), calibrate=False))
    devices += [dataclasses.replace(d, driver_supply_v=d.driver_supply_v * 0.85) for d in devices[:50]]
    devices += [DeviceParams(), dataclasses.replace(DeviceParams(), driver_supply_v=5.0)]
    for dev in devices:
        c = SupervisorConfig.for_device(dev)
        v_max = c.speed_limit_m_per_s
        speeds = [v_max * k / 32 for k in range(33)] + [1.05 * v_max]
        currents = [c.current_for_force_a(max(c.drive_force_limit_n(v), 0.0)) * (1.0 - c.sense_gain_error_max)
                    - c.sense_error_a for v in speeds[:33]]
        currents.append(-c.friction_current_a)
        out = np.empty(2 * ENVELOPE_POINTS)
        _envelope_table(c, out)
        assert out.tolist() == speeds + currents


def test_packed_supervisor_config_is_cached_read_only_and_not_changed_by_an_episode():
    _packed_config.cache_clear()
    env = ContactForceEnv(randomize_device=False, disturbances=False)
    env.reset(seed=1)
    cfg = env._sup.config
    shared = cfg.pack()
    assert not shared.flags.writeable
    with pytest.raises(ValueError):
        shared[0] = 1.0
    before = shared.copy()
    hits = _packed_config.cache_info().hits
    for _ in range(3):
        env.reset()
        for _ in range(50):
            env.step(np.array([1.0], np.float32))
    assert _packed_config.cache_info().hits >= hits + 3        # the nominal device packs once
    np.testing.assert_array_equal(shared, before)
    assert env._svcfg is not shared and env._svcfg.flags.writeable   # the live array is the supervisor's copy
    np.testing.assert_array_equal(_pack(cfg), shared)


def test_a_changed_supervisor_config_is_packed_afresh():
    _packed_config.cache_clear()
    a = SupervisorConfig()
    b = dataclasses.replace(a, finger_motion_m=30e-6)
    c = SupervisorConfig.for_device(dataclasses.replace(DeviceParams(), motor=MotorParams(resistance_ohm=25.0)))
    pa, pb, pc = a.pack(), b.pack(), c.pack()
    assert _packed_config.cache_info().misses == 3
    assert not np.array_equal(pa, pb) and not np.array_equal(pa, pc)
    for cfg, packed in ((a, pa), (b, pb), (c, pc)):
        np.testing.assert_array_equal(_pack(cfg), packed)
    assert SupervisorConfig().pack() is pa                    # an equal config shares the packed array
    assert _packed_config.cache_info().hits == 1


def test_transcriptions_of_excerpts_are_cached_and_shared():
    env = ContactForceEnv()
    env.reset(seed=9)
    text = env.episode.spec.reading.text
    hits = _cells_of.cache_info().hits
    env.reset(seed=9)                                         # the same excerpt again
    assert _cells_of.cache_info().hits > hits
    cells = _cells_of(text)
    assert isinstance(cells, tuple) and cells is _cells_of(text)
    assert _cells_of.cache_info().maxsize >= 432              # every word start of the shipped passages


def test_disturbance_generators_are_the_children_of_the_inputs_generator():
    from ebraille_sim.scenarios import disturbances as dist
    from ebraille_sim.scenarios.draws import child_generator
    t = np.arange(1500) * 5e-3
    section = dist.validate_section("test", {"tremor": {"rms_m": 1e-5}, "pressing": {"rms_m": 1e-4},
                                             "battery": {"soc_start": 0.5}})
    rng = np.random.default_rng(77)
    before = rng.bit_generator.state
    got = dist.build_inputs(section, t, rng, DeviceParams())
    assert rng.bit_generator.state == before                  # the parent is left as it was
    children = {k: child_generator(np.random.default_rng(77), i) for i, k in enumerate(dist.KINDS)}
    want_x = (section["tremor"].inputs(t, children["tremor"], DeviceParams())["finger_pos_m"][1]
              + section["pressing"].inputs(t, children["pressing"], DeviceParams())["finger_pos_m"][1])
    np.testing.assert_array_equal(got["finger_pos_m"][1], want_x)


@pytest.mark.parametrize("args", [(1.5, 0.0, 2.0), (0.0, 0.0, None, True), (2.0, None, 2.0, False, True),
                                  (3.0, 0, 3), (7.25, None, None), (-1e300, None, None)])
def test_check_number_fast_path_returns_what_the_full_check_returns(args):
    value, lo, hi, *flags = args + (False,) * (5 - len(args))
    lo_open, hi_open = flags[0], flags[1]
    ok = (lo is None or (value > lo if lo_open else value >= lo)) and \
         (hi is None or (value < hi if hi_open else value <= hi))
    if ok:
        out = check_number("x", value, lo, hi, lo_open, hi_open)
        assert out == value and type(out) is float
    else:
        with pytest.raises(ValueError, match="^x "):
            check_number("x", value, lo, hi, lo_open, hi_open)


@pytest.mark.parametrize("value, message", [(math.nan, "must be finite"), (math.inf, "must be finite"),
                                            (-math.inf, "must be finite"), (0.0, "must be > 0"),
                                            (-1.0, "must be > 0")])
def test_parameter_checks_still_reject_bad_values(value, message):
    with pytest.raises(ValueError, match=f"^FSRParams.resistance_at_1n_ohm {message}"):
        FSRParams(resistance_at_1n_ohm=value)
    with pytest.raises(ValueError, match="must be finite"):
        check_number("x", value if not math.isfinite(value) else math.nan)
    check_finite(FSRParams())


def test_reset_header_is_shared_read_only_and_each_supervisor_gets_a_copy():
    from controllers.supervisor import SV, _initial_state, _reset_header
    _reset_header.cache_clear()
    a = SupervisorConfig()
    b = SupervisorConfig.for_device(dataclasses.replace(DeviceParams(), motor=MotorParams(resistance_ohm=25.0)))
    ha, hb = _initial_state(a), _initial_state(b)
    assert _reset_header.cache_info().misses == 1 and _reset_header.cache_info().hits == 1
    template = _reset_header()
    assert not template.flags.writeable
    with pytest.raises(ValueError):
        template[SV.cut_t] = 0.0
    assert ha is not template and ha.flags.writeable
    assert ha[SV.current_limit_a] == a.sensed_limit_a(a.current_limit_a)
    assert hb[SV.current_limit_a] == b.sensed_limit_a(b.current_limit_a)
    assert ha[SV.cut_t] == -math.inf and math.isnan(ha[SV.stuck_ref_n])
    ha[:] = 7.0                                               # a caller's copy, not the template
    assert _initial_state(a)[SV.cut_t] == -math.inf


def test_a_reused_workspace_starts_each_episode_with_a_clear_supervisor_state():
    from controllers.supervisor import _initial_state
    env = ContactForceEnv()
    env.reset(seed=4)
    for _ in range(400):                                      # fill the supervisor's ring buffers
        _, _, te, tr, _ = env.step(np.array([0.8], np.float32))
        if te or tr:
            break
    buffer = env._buffer
    env.reset()
    assert env._ws.base is buffer                              # the same buffer, reused
    sv, cfg = env._sup.compiled()
    header = _initial_state(env._sup.config)
    np.testing.assert_array_equal(sv[:header.size], header)
    assert not np.any(sv[header.size:])
    np.testing.assert_array_equal(cfg, env._sup.config.pack())
    from ebraille_sim.plant.layout import U
    from ebraille_sim.rl.env import P_PROF, P_ROWS, workspace_part
    profiles = env.episode.run.profiles
    assert profiles                                           # the default episodes vary the finger
    np.testing.assert_array_equal(workspace_part(env._ws, P_PROF), np.concatenate(list(profiles.values())))
    assert workspace_part(env._ws, P_ROWS).tolist() == [U[name] for name in profiles]


def test_estimator_steady_state_is_cached_per_parameters_and_input_and_read_only():
    from ebraille_sim.plant import lumped
    from ebraille_sim.plant.layout import N_STATE, P
    lumped._steady_state_slots.cache_clear()
    devices = sample_devices(8, 3)
    params = [lumped.pack_params(d, 1.0) for d in devices]
    for p in params:
        for u0 in (0.0, -0.0, 0.37):
            want, got = np.full(N_STATE, 5.0), np.full(N_STATE, 5.0)
            lumped._fill_estimator_steady_state(want, p, u0)
            lumped._estimator_steady_state(got, p, u0)
            assert want.tobytes() == got.tobytes()            # -0.0 kept apart from 0.0
    info = lumped._steady_state_slots.cache_info()
    assert info.misses == 3 and info.hits == 6                # one estimator and filter for every unit
    slots, values = lumped._steady_state_slots(params[0][lumped._STEADY_HEAD].tobytes(),
                                               params[0][lumped._STEADY_MODEL].tobytes(), (0.0).hex())
    assert not slots.flags.writeable and not values.flags.writeable
    with pytest.raises(ValueError):
        values[0] = 1.0
    other = params[0].copy()
    other[P.aa_b0] *= 1.5                                     # another filter: computed afresh
    a, b = np.zeros(N_STATE), np.zeros(N_STATE)
    lumped._estimator_steady_state(a, other, 0.37)
    lumped._fill_estimator_steady_state(b, other, 0.37)
    assert a.tobytes() == b.tobytes()
    assert lumped._steady_state_slots.cache_info().misses == 4


def test_a_device_sharing_the_last_ones_parts_copies_its_rows_and_no_other_does():
    """The plant rows of the device packed last are reused only for a device of the same part
    objects (the nominal device with its supply sagged); a drawn device packs afresh; the
    copies equal fresh packing and a user changing a returned row changes no later plant."""
    from ebraille_sim.base.validation import replace_fields
    from ebraille_sim.plant import lumped
    base = DeviceParams()
    lumped._LAST_ROWS.clear()
    first = lumped.Plant.from_devices([base], [3.0])
    first.params[0, lumped.P.motor_r_ohm] = 99.0                 # not the cache's row
    sagged = replace_fields(base, driver_supply_v=5.1)
    again = lumped.Plant.from_devices([sagged], [7.0])
    fresh_p = lumped.pack_params(sagged, 7.0)
    np.testing.assert_array_equal(again.params[0], fresh_p)
    np.testing.assert_array_equal(again.state[0], lumped.initial_state(sagged, fresh_p))
    assert lumped._LAST_ROWS[0][0] is base.motor
    drawn = sample_devices(4, 1)[0]
    other = lumped.Plant.from_devices([drawn], [7.0])
    np.testing.assert_array_equal(other.params[0], lumped.pack_params(drawn, 7.0))
    assert other.params[0, lumped.P.finger_b_n_per_m] != again.params[0, lumped.P.finger_b_n_per_m]
    assert lumped._LAST_ROWS[0][2] is drawn.finger


def test_compiled_cell_index_equals_the_searchsorted_lookup():
    from ebraille_sim.scenarios.reading import build_schedule
    rng = np.random.default_rng(2)
    for text, wpm, jitter in (("hello world, a line\nand more", 90.0, 0.0), ("abc def", 300.0, 0.3), ("x", 60.0, 0.0)):
        sched = build_schedule(text, wpm, start_s=0.7, jitter_fraction=jitter, word_pause_s=0.05,
                               rng=np.random.default_rng(1))
        t = np.concatenate([np.arange(0.0, sched.t_end_s + 0.5, 0.005), sched.start_s, [sched.t_end_s, math.nan,
                            -math.inf, math.inf], rng.uniform(-1, sched.t_end_s + 1, 500)])
        want = np.searchsorted(sched.start_s, t, side="right") - 1
        want = np.where((t >= sched.start_s[0]) & (t < sched.t_end_s), want, -1).astype(np.int64)
        got = sched.index_at(t)
        assert got.dtype == np.int64 and got.tolist() == want.tolist()
        assert [sched.index_at(float(x)) for x in t[:50]] == want[:50].tolist()
        np.testing.assert_array_equal(sched.index_at(t[:40].reshape(8, 5)), want[:40].reshape(8, 5))


def test_replaced_dataclass_does_not_inherit_what_was_cached_on_the_original():
    from ebraille_sim.base.validation import replace_checked, replace_fields
    cfg = SupervisorConfig()
    packed = cfg.pack()
    assert cfg.envelope_force_n > 0 and "_packed" in cfg.__dict__ and "envelope_force_n" in cfg.__dict__
    for new in (replace_fields(cfg, finger_motion_m=30e-6), replace_checked(cfg, finger_motion_m=30e-6)):
        fresh = dataclasses.replace(cfg, finger_motion_m=30e-6)
        assert "_packed" not in new.__dict__ and new == fresh
        assert new.envelope_force_n == fresh.envelope_force_n != cfg.envelope_force_n     # found anew
        assert not np.array_equal(new.pack(), packed)
    fsr = FSRParams()
    new = replace_fields(fsr, exponent=0.9)
    assert new == dataclasses.replace(fsr, exponent=0.9) and new.__dict__.keys() == fsr.__dict__.keys()
    with pytest.raises(ValueError, match="^unknown key 'exponnt' in FSRParams; allowed: "):
        replace_checked(fsr, exponnt=0.9)
    with pytest.raises(ValueError, match="^FSRParams.exponent must be finite"):
        replace_checked(fsr, exponent=math.nan)


def test_config_for_a_device_is_the_constructors_and_leaves_the_shared_defaults_alone():
    from controllers.supervisor import _default_config, device_limits
    defaults = _default_config()
    before = dataclasses.asdict(defaults)
    devices = sample_devices(4, 20) + [DeviceParams()]
    for i, dev in enumerate(devices):
        overrides = {"finger_motion_m": 25e-6} if i % 3 == 0 else {}
        got = SupervisorConfig.for_device(dev, **overrides)
        want = SupervisorConfig(**{**device_limits(dev), **overrides})
        assert repr(got) == repr(want) and got == want
        assert got.envelope_force_n == want.envelope_force_n
        np.testing.assert_array_equal(_pack(got), _pack(want))
    assert _default_config() is defaults and dataclasses.asdict(defaults) == before
    for bad, message in (({"finger_motion_m": math.nan}, "^finger_motion_m must be finite"),
                         ({"slew_v_per_s": -1.0}, "^slew_v_per_s must be > 0"),
                         ({"stall_time_s": True}, "^stall_time_s must be a number"),
                         ({"finger_motoin_m": 1e-5}, "^unknown key 'finger_motoin_m' in SupervisorConfig")):
        with pytest.raises(ValueError, match=message):
            SupervisorConfig.for_device(devices[0], **bad)
    assert SupervisorConfig.for_device(devices[0], stall_time_s=2).stall_time_s == 2.0


def test_drawn_disturbance_sections_equal_validate_section_and_share_only_their_constant_part():
    from ebraille_sim.scenarios import episodes
    from ebraille_sim.scenarios.disturbances import validate_section
    from ebraille_sim.scenarios.spec import ScenarioError
    episodes._validated_kind.cache_clear()
    rng = np.random.default_rng(3)
    for _ in range(200):
        table = {}
        if rng.random() < 0.8:
            table["tremor"] = {"rms_m": float(rng.uniform(0, 2e-5)) + 1e-9, "band_hz": [8.0, 12.0]}
        if rng.random() < 0.8:
            table["pressing"] = {"rms_m": float(rng.uniform(0, 1e-4)) + 1e-9, "band_hz": [0.1, 1.0]}
        if rng.random() < 0.3:
            table["battery"] = {"cells_series": 1, "soc_start": float(rng.uniform(0.05, 1.0))}
        got, want = episodes._validated_section(table), validate_section("episode", table)
        assert got == want and repr(got) == repr(want) and list(got) == list(want)
    info = episodes._validated_kind.cache_info()
    assert info.misses == 3 and info.hits > 300                # one validation per kind and band
    for bad in ({"tremor": {"rms_m": 2e-3, "band_hz": [8.0, 12.0]}},
                {"tremor": {"rms_m": math.nan, "band_hz": [8.0, 12.0]}},
                {"tremor": {"rms_m": 1e-5, "band_hz": [8.0, 8.001]}},
                {"tremor": {"rms_m": 1e-5, "band_hz": [8.0, 12.0]}, "pressing": {"rms_m": 1e-5, "band_hz": [0.1, 30.0]}},
                {"battery": {"cells_series": 1, "soc_start": 1.5}}):
        with pytest.raises(ScenarioError) as want:
            validate_section("episode", bad)
        with pytest.raises(ScenarioError) as got:
            episodes._validated_section(bad)
        assert str(got.value) == str(want.value)
    shared = episodes._validated_kind("tremor", (("band_hz", (8.0, 12.0)),))
    with pytest.raises(dataclasses.FrozenInstanceError):
        shared.rms_m = 1.0


def _compensations_written_one_slot_at_a_time(p, e, dt_sensor_s, adc_lsb_v, h, sensor_rate_hz):
    """The creep and hysteresis compensations of ``e`` written slot by slot from the firmware's laws."""
    from ebraille_sim.estimation.firmware import firmware_fsr
    from ebraille_sim.physics.fsr import creep_decay, creep_gain, creep_taus_s, creep_term_weight, play_loop_widths
    from ebraille_sim.plant.layout import N_PLAYS, P
    nominal = firmware_fsr(e)
    p[P.est_creep_comp] = 1.0 if e.creep_compensation else 0.0
    p[P.comp_creep_weight] = creep_term_weight(nominal.creep_per_decade, nominal.creep_tau_min_s,
                                               nominal.creep_tau_max_s)
    for j, tau in enumerate(creep_taus_s(nominal.creep_tau_min_s, nominal.creep_tau_max_s)):
        p[P[f"comp_creep_a{j}"]] = creep_decay(dt_sensor_s, tau)
    p[P.comp_fsr_n] = nominal.exponent
    p[P.comp_g_standoff_s] = 1.0 / nominal.standoff_resistance_ohm
    p[P.comp_load_threshold_n] = nominal.load_threshold_n
    p[P.comp_reference_gain] = creep_gain(e.creep_reference_hold_s, nominal)
    p[P.est_hyst_comp] = 1.0 if e.hysteresis_compensation else 0.0
    widths, weights = play_loop_widths(h, nominal.exponent)
    for j in range(N_PLAYS):
        p[P[f"comp_play_w{j}"]] = widths[j]
        p[P[f"comp_play_weight{j}"]] = weights[j]
    p[P.comp_hyst_halfwidth] = sum(w * x for w, x in zip(weights, widths))
    p[P.comp_fsr_k_ohm] = nominal.resistance_at_1n_ohm
    p[P.comp_hyst_deadband_v] = e.hysteresis_deadband_lsb * adc_lsb_v
    p[P.comp_hyst_turn_v] = e.hysteresis_turn_lsb * adc_lsb_v
    p[P.comp_hyst_follow_v] = e.hysteresis_follow_lsb * adc_lsb_v
    p[P.comp_centre_alpha] = -math.expm1(-1.0 / (e.hysteresis_centre_time_s * sensor_rate_hz)) \
        if e.hysteresis_centre_time_s > 0.0 else 0.0
    p[P.comp_turn_alpha] = -math.expm1(-1.0 / (e.hysteresis_turn_time_s * sensor_rate_hz))


def test_compensation_values_fill_exactly_their_slots_as_slot_by_slot_writes_do():
    """The creep and hysteresis compensations packed as one values row into fixed slots write the
    same slots with the same numbers as the firmware's laws written one slot at a time, on drawn
    units (each with its bench's creep and loop), the nominal device and the 1 kHz presets."""
    from ebraille_sim.estimation.presets import get_firmware
    from ebraille_sim.physics.fsr import play_loop_fraction
    from ebraille_sim.plant import lumped
    from ebraille_sim.plant.layout import N_PARAM
    from ebraille_sim.estimation.firmware import firmware_fsr
    from ebraille_sim.physics.params import EstimatorParams
    devices = sample_devices(17, 6) + [DeviceParams()] + [
        DeviceParams(estimator=dataclasses.replace(EstimatorParams(), **get_firmware(name).estimator))
        for name in ("fast_1khz", "fast_1khz_centred", "paper_100hz")]
    for dev in devices:
        e, c, s = dev.estimator, dev.circuit, dev.fsr
        for rate in (dev.rates.sensor_rate_hz, 1000.0):
            h = (play_loop_fraction(dataclasses.replace(firmware_fsr(e), hysteresis_fraction=e.hysteresis_fraction))
                 if e.hysteresis_fraction is not None else lumped.measured_hysteresis_fraction(s)
                 if e.hysteresis_compensation else play_loop_fraction(lumped.FIRMWARE_FSR))
            fast, plain = np.full(N_PARAM, np.nan), np.full(N_PARAM, np.nan)
            lumped._pack_creep_compensation(fast, e, 1.0 / rate)
            lumped._pack_hysteresis_compensation(fast, e, c, s, rate)
            _compensations_written_one_slot_at_a_time(plain, e, 1.0 / rate, float(c.adc_lsb_v), h, rate)
            np.testing.assert_array_equal(fast, plain)
            written = np.flatnonzero(~np.isnan(fast))
            assert sorted(written) == sorted(np.concatenate([lumped.CREEP_COMPENSATION_SLOTS,
                                                             lumped.HYSTERESIS_COMPENSATION_SLOTS]))
    assert not lumped.creep_compensation_values(devices[0].estimator, 1e-3).flags.writeable


def test_calibration_table_through_the_compiled_steady_map_equals_the_models_own_map():
    """The bench's table read through the compiled steady map and one mean per load equals the
    readings of :func:`table_reading_n` (the model's ``steady_state``) averaged row by row with
    ``np.mean``, to the last bit, on drawn units with their load errors and on the presets."""
    from ebraille_sim.estimation import calibration as cal
    from ebraille_sim.estimation.presets import get_firmware
    from ebraille_sim.physics.params import EstimatorParams
    from ebraille_sim.base.seeds import default_rng
    devices = sample_devices(29, 40) + [cal.calibrate_device(DeviceParams(estimator=dataclasses.replace(
        EstimatorParams(), **get_firmware(name).estimator))) for name in ("fast_1khz", "fast_1khz_centred", "paper_100hz")]
    for k, dev in enumerate(devices):
        errors = tuple(0.02 * math.sin(k + j) for j in range(4))
        fsr, circuit = dev.fsr, dev.circuit
        draws = default_rng(cal._fsr_unit_seed(fsr, circuit)).standard_normal((4, cal.TABLE_PRESSES, 2))
        carried = np.array([[load * (1.0 + e)] for load, e in zip(cal.TABLE_LOADS_N, errors)])
        presses = cal.table_reading_n(cal.cached_model(dev.estimator.model), carried, fsr, circuit, cal.TABLE_HOLD_S,
                                      press_z=draws[..., 0], noise_v=fsr.noise_v_rms / math.sqrt(256) * draws[..., 1])
        plain = [float(np.mean(row)) for row in presses]
        level = 1.0 / plain[1]
        table = cal.calibration_table(dev, cal.TABLE_LOADS_N, errors)
        assert table is not None and table[1] == tuple(r * level for r in plain), dev
        assert cal.calibration_table(dev, cal.TABLE_LOADS_N, errors, anchor_n=None)[1] == tuple(plain)


def test_zero_and_mean_readings_in_one_call_equal_the_zero_and_each_mean_reading():
    """The drive calibration's zeroing and four mean readings in one compiled call give what
    :func:`zero_code` and :func:`mean_reading_a` give one by one, on drawn current chains."""
    from ebraille_sim.physics.current_sense import mean_reading_a, zero_and_mean_readings_a, zero_code
    for k, dev in enumerate(sample_devices(31, 40)):
        cs = dev.current_sense
        seed = 1000003 * k + 17
        currents = (-1.0 / dev.motor.resistance_ohm, 0.01, 0.05, 0.004 + 1e-4 * k)
        seeds = (float(seed), seed + 2.0, seed + 4.0, seed + 7.0)
        zero, reads = zero_and_mean_readings_a(cs, seed, currents, seeds, 256)
        plain_zero = zero_code(cs, seed, cs.adc_lsb_v, cs.adc_max_code)
        assert zero == plain_zero
        assert reads == [mean_reading_a(cs, i, s, 256, plain_zero) for i, s in zip(currents, seeds)]
        assert reads[1] != reads[2]


@pytest.mark.parametrize("force_n, peak_n, ramp_s", [(1.0, 2.0, 1.0), (0.5, 2.0, 1.0), (1.9, 2.0, 0.3),
                                                     (2.5, 2.0, 1.0), (1e-4, 2.0, 1.0)])
def test_compiled_loop_of_a_cycle_equals_numpys_argmax_searchsorted_and_interp(force_n, peak_n, ramp_s):
    """The datasheet cycle's loop read by the compiled peak search and two-sample interpolations
    equals NumPy's ``argmax``, ``searchsorted`` and ``interp`` of the same samples to the last bit,
    on drawn units and the presets; a force the branches do not pass between two samples (above
    the peak, below the first sample) falls back to NumPy's reading."""
    from ebraille_sim.physics import fsr as F
    from ebraille_sim.physics.params import FSRS
    units = [d.fsr for d in sample_devices(37, 30)] + list(FSRS.values())
    seen_fallback = False
    for unit in units:
        widths, weights = F.play_widths(unit)
        p = np.array(list(widths) + list(weights) + [F.creep_decay(1e-3, tau) for tau in
                                                     F.creep_taus_s(unit.creep_tau_min_s, unit.creep_tau_max_s)])
        s = np.zeros(F.N_PLAYS + F.N_CREEP)
        s[:F.N_PLAYS] = F.log_force(0.0)
        w = F.creep_term_weight(unit.creep_per_decade, unit.creep_tau_min_s, unit.creep_tau_max_s)
        seen, lagged = F._cycle_forces(F._load_cycle(ramp_s, 1e-3, peak_n), F.lag_alpha(1e-3, unit.mechanical_lag_s),
                                       s, p, w, unit.load_threshold_n)
        plain = F._loop_of_samples(seen, lagged, force_n, unit)
        fast = F._loop_fraction(seen, lagged, force_n, unit.resistance_at_1n_ohm, unit.exponent,
                                unit.actuation_force_n, unit.turn_on_steepness)
        if fast == fast:
            assert fast == plain, unit.name
        else:
            seen_fallback = True
        got = F.datasheet_hysteresis(unit, ramp_s=ramp_s, force_n=force_n, peak_n=peak_n)
        assert got == plain or (got != got and plain != plain)
    assert seen_fallback == (force_n > peak_n or force_n < 1e-3)


def test_static_conductance_in_one_call_equals_its_laws_called_one_by_one():
    """The film's static conductance in one compiled call equals :func:`conductance_s` of the force
    grown by :func:`creep_gain` above the load threshold and scaled by :func:`temperature_factor`,
    each called on its own, on drawn units and the presets, at and below the threshold, warm and cold."""
    from ebraille_sim.physics import fsr as F
    from ebraille_sim.physics.params import FSRS
    units = [d.fsr for d in sample_devices(41, 25)] + list(FSRS.values())
    for unit in units:
        for force in (0.0, 0.5 * unit.load_threshold_n, unit.load_threshold_n, 0.3, 1.0, 2.7):
            for hold in (0.0, 2.0, 20.0):
                for temp in (-12.0, 0.0, 7.5):
                    f = force * F.creep_gain(hold, unit) if force > unit.load_threshold_n else force
                    scale = F.temperature_factor(temp, unit.temperature_coeff_per_k, unit.temperature_coeff_cold_per_k)
                    plain = F.conductance_s(f, unit.resistance_at_1n_ohm, unit.exponent,
                                            1.0 / unit.standoff_resistance_ohm, scale, unit.actuation_force_n,
                                            unit.turn_on_steepness)
                    assert F.static_conductance(force, unit, load_time_s=hold, temp_offset_k=temp) == plain


def _bench_creep_through_numpy(device, load_n, load_error):
    """The bench's creep per decade with every step a NumPy broadcast (the protocol as written)."""
    from ebraille_sim.base.seeds import default_rng
    from ebraille_sim.estimation import calibration as cal
    from ebraille_sim.estimation.firmware import FIRMWARE_FSR as nom
    from ebraille_sim.physics.fsr import (N_CREEP, divider_conductance_s, divider_voltage, held_creep_gain,
                                          static_conductance)
    fsr, circuit = device.fsr, device.circuit
    rng = default_rng(cal._fsr_unit_seed(fsr, circuit) + 1)
    sd_v = fsr.noise_v_rms / math.sqrt(cal.TABLE_CONVERSIONS)
    f_eff = load_n * (1.0 + load_error) * cal.loading_branch_factor(fsr)
    held = np.array([static_conductance(f_eff, fsr, load_time_s=t) for t in cal.CREEP_READ_S])
    draws = rng.standard_normal((cal.TABLE_PRESSES, 3))
    scale = np.exp(fsr.press_repeatability * draws[:, :1])
    g = 1.0 / fsr.standoff_resistance_ohm + (held - 1.0 / fsr.standoff_resistance_ohm) / scale
    v = divider_voltage(g, circuit.r2_ohm, circuit.supply_v) + sd_v * draws[:, 1:]
    g_path = divider_conductance_s(v, circuit.r2_ohm, circuit.supply_v) - 1.0 / nom.standoff_resistance_ohm
    ratio = float(np.mean((g_path[:, 1] / g_path[:, 0]) ** (1.0 / nom.exponent)))
    a = [held_creep_gain(t, 1.0, nom.creep_tau_min_s, nom.creep_tau_max_s, N_CREEP) - 1.0 for t in cal.CREEP_READ_S]
    w = (ratio - 1.0) / (a[1] - ratio * a[0])
    return float(min(max(w * (N_CREEP - 1) / math.log10(nom.creep_tau_max_s / nom.creep_tau_min_s), 0.0), 0.2))


def test_bench_creep_reads_in_one_call_equal_numpys_broadcasts():
    """The bench's creep reads turned into conductance ratios in one compiled call give the creep
    per decade of the same protocol written as NumPy broadcasts, to the last bit, on drawn units
    (their own load errors) and the presets' films."""
    from ebraille_sim.estimation import calibration as cal
    from ebraille_sim.physics.params import FSRS
    from ebraille_sim.base.validation import replace_fields
    devices = sample_devices(43, 40) + [cal.calibrate_device(replace_fields(DeviceParams(), fsr=f))
                                        for f in FSRS.values()]
    values = set()
    for k, dev in enumerate(devices):
        for load_error in (0.0, 0.015 * math.cos(k)):
            got = cal.bench_creep_per_decade(dev, 1.0, load_error)
            assert got == _bench_creep_through_numpy(dev, 1.0, load_error), dev.fsr
            values.add(got)
    assert len(values) > 40                                    # the units read differently


def test_drive_calibration_is_remembered_per_drive_and_chain_and_reads_nothing_else():
    """The drive's calibration is keyed on the parts it reads (motor, drive train, current chain,
    driver supply): a device that differs in its reader, FSR unit or divider shares the stored
    calibration, one that differs in any of the four parts gets its own, and each equals a
    calibration computed afresh (its seed is the CRC of those parts' ``repr``, as it was)."""
    import zlib
    from ebraille_sim.base.validation import replace_fields
    from ebraille_sim.estimation import calibration as cal
    from ebraille_sim.physics.params import FINGERS, FSRS
    a, b = sample_devices(57, 2)
    twin = replace_fields(a, finger=FINGERS["stiff"], fsr=FSRS["nominal"],
                          circuit=replace_fields(a.circuit, r2_ohm=a.circuit.r2_ohm * 1.1))
    assert cal.calibrate_drive(twin) is cal.calibrate_drive(a)
    for other in (replace_fields(a, motor=b.motor), replace_fields(a, drivetrain=b.drivetrain),
                  replace_fields(a, current_sense=b.current_sense), replace_fields(a, driver_supply_v=5.5)):
        assert cal.calibrate_drive(other) != cal.calibrate_drive(a)
        fresh = cal._calibrate_drive.__wrapped__(other.motor, other.drivetrain, other.current_sense,
                                                 other.driver_supply_v)
        assert fresh == cal.calibrate_drive(other)
    key = repr((a.motor, a.drivetrain, a.current_sense, a.driver_supply_v))
    assert cal._unit_seed(a.motor, a.drivetrain, a.current_sense, a.driver_supply_v) == \
        zlib.crc32(key.encode()) % (1 << 31)


def test_datasheet_chain_and_constants_are_reused_only_for_the_same_parts():
    """The supervisor's datasheet current chain is shared by boards that differ only in their unit
    errors, and the firmware limits' datasheet constants by datasheet devices of the same parts
    and gravity; what either reuse gives equals what is made afresh (the caches emptied), keys in
    their order, and a device with another chain, drive train or gravity gets its own."""
    from controllers.supervisor import config as C
    from ebraille_sim.base.validation import replace_fields
    from ebraille_sim.physics.params import DRIVETRAINS

    def fresh(d):
        C._LAST_CHAIN.clear()
        C._LAST_CONSTANTS.clear()
        return C.datasheet_device(d), C.device_limits(d)

    a, b, c = sample_devices(61, 3)
    variants = [a, b, c, replace_fields(a, current_sense=replace_fields(a.current_sense, adc_bits=12)),
                replace_fields(b, drivetrain=DRIVETRAINS["planetary_16"]), replace_fields(c, gravity_m_per_s2=0.0),
                b]
    for d in variants:
        sheet, lim = C.datasheet_device(d), C.device_limits(d)
        sheet0, lim0 = fresh(d)
        C.device_limits(variants[0])                            # the caches hold another device now
        assert sheet == sheet0 and lim == lim0 and list(lim) == list(lim0)
        assert sheet.current_sense.shunt_error == sheet.current_sense.gain_error == sheet.current_sense.offset_v == 0.0
    assert C.datasheet_device(a).current_sense is C.datasheet_device(b).current_sense
    assert C.device_limits(variants[3])["sense_error_a"] != C.device_limits(a)["sense_error_a"]
    assert C.device_limits(variants[5])["weight_n"] != C.device_limits(c)["weight_n"]
