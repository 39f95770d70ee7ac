"""Cheap resets: the caches behind ``ContactForceEnv.reset`` change no trajectory and are hit,
shared read-only and keyed on what they depend on.

``REFERENCE`` holds hashes of trajectories recorded by the env before its resets were made
cheaper (observations, rewards, ends, infos, the drawn specs and packed parameters of the
scalar env at 200 Hz and 1 kHz, with and without the safety layer, device randomisation,
disturbances and reset options, and of the vector env with autoresets): the same seeds must
give the same bits.  The hashes of packed parameters, specs and plant states were recorded again
when the estimator's hysteresis compensation added parameters and state slots (off by
default: observations, rewards, ends and infos kept their hashes, and the states' earlier
slots theirs) and again when its turn test did (off by default, the same hashes kept), and the
supervisor's configuration arrays when the slot ``powered_current_a``
replaced ``half_friction_current_a`` (every trajectory kept its hashes).
"""
import dataclasses
import hashlib
import math

import numpy as np
import pytest

from controllers.supervisor import (ENVELOPE_POINTS, SupervisorConfig, _envelope, _envelope_table,
                                    _pack, _packed_config)
from ebraille_sim.base.validation import check_number
from ebraille_sim.physics.params import DeviceParams, FSRParams, MotorParams, check_finite
from ebraille_sim.rl.env import ContactForceEnv
from ebraille_sim.scenarios.inputs import _cells_of
from ebraille_sim.scenarios.population import PopulationSpec, sample_devices


def h(x):
    """A short digest of an array's dtype, shape and bytes."""
    a = np.ascontiguousarray(np.asarray(x))
    return hashlib.sha256(a.dtype.str.encode() + str(a.shape).encode() + a.tobytes()).hexdigest()[:16]


def record() -> dict:
    """Digests of a few episodes of the scalar env (seeds 0 and 11 in seven configurations,
    900 steps with the resets they need and three more) and of the vector env (6 sub-envs,
    autoresets), keyed by configuration and quantity."""
    from ebraille_sim.rl.vector_env import ContactForceVectorEnv
    out = {}
    cases = [("default", {}, None), ("1khz", {"control_rate_hz": 1000.0}, None),
             ("nominal", {"randomize_device": False}, None), ("nosafety", {"safety": False}, None),
             ("options", {}, {"wpm": 300.0, "gap_m": 0.8e-3, "tremor_amplitude_m": 3e-5, "setpoint_n": 1.0}),
             ("options2", {}, {"passage": "garden", "first_character": 0, "supply_fraction": 0.8}),
             ("nodist", {"disturbances": False}, {"device": DeviceParams()})]
    for name, kw, opts in cases:
        env = ContactForceEnv(**kw)
        for seed in (0, 11):
            obs, info = env.reset(seed=seed, options=opts)
            rows, rews, flags, infos = [obs], [], [], [sorted(info.items())]
            specs = [repr(env.episode.spec)]
            params = [env.plant.params.copy()]
            for k in range(900):
                a = np.array([0.9 * np.sin(0.013 * k) + 0.2], dtype=np.float32)
                obs, r, te, tr, info = env.step(a)
                rows.append(obs); rews.append(r); flags.append((te, tr)); infos.append(sorted(info.items()))
                if te or tr:
                    obs, info = env.reset()
                    rows.append(obs); infos.append(sorted(info.items()))
                    specs.append(repr(env.episode.spec)); params.append(env.plant.params.copy())
            for _ in range(3):
                obs, info = env.reset()
                rows.append(obs); infos.append(sorted(info.items()))
                specs.append(repr(env.episode.spec)); params.append(env.plant.params.copy())
            out[f"{name}_{seed}_obs"] = h(np.array(rows))
            out[f"{name}_{seed}_rew"] = h(np.array(rews))
            out[f"{name}_{seed}_flags"] = h(np.array(flags))
            out[f"{name}_{seed}_info"] = hashlib.sha256(repr(infos).encode()).hexdigest()[:16]
            out[f"{name}_{seed}_spec"] = hashlib.sha256("\n".join(specs).encode()).hexdigest()[:16]
            out[f"{name}_{seed}_params"] = h(np.array(params))
    for name, kw in (("vec", {}), ("vec1k", {"control_rate_hz": 1000.0})):
        venv = ContactForceVectorEnv(num_envs=6, parallel=False, **kw)
        obs, _ = venv.reset(seed=3)
        rows, rews, flags = [obs], [], []
        for k in range(2000 if not kw else 600):
            a = np.clip(0.05 + 0.6 * obs[:, 2:3] + 0.2 * obs[:, 4:5], -1, 1).astype(np.float32)
            obs, r, te, tr, _ = venv.step(a)
            rows.append(obs); rews.append(r); flags.append(np.stack([te, tr]))
        venv._load_rows(range(6), {})
        out[f"{name}_obs"] = h(np.array(rows)); out[f"{name}_rew"] = h(np.array(rews))
        out[f"{name}_flags"] = h(np.array(flags)); out[f"{name}_params"] = h(venv.params)
        out[f"{name}_svcfg"] = h(venv._svcfg2); out[f"{name}_state"] = h(venv.state)
    return out


REFERENCE = {
    '1khz_0_flags': '7742b24394aabe5b',
    '1khz_0_info': '1023f1f8307f18e6',
    '1khz_0_obs': 'ceeacedd4c5dd719',
    '1khz_0_params': 'f31ed5835e367703',
    '1khz_0_rew': '7486f617ca19a4a4',
    '1khz_0_spec': '0e06eb836ee5ccd6',
    '1khz_11_flags': '7742b24394aabe5b',
    '1khz_11_info': 'a7f603cfa39d1634',
    '1khz_11_obs': '66c1af6ae5cc37d3',
    '1khz_11_params': '0ca39c56b93c7927',
    '1khz_11_rew': '1cb76bae969c3787',
    '1khz_11_spec': '5e6f423e1ce93de2',
    'default_0_flags': '4d6fecb70fdc32bb',
    'default_0_info': '22c81f8a53531880',
    'default_0_obs': 'ae7c513f4afdcdfb',
    'default_0_params': 'e81cf015800fe9d2',
    'default_0_rew': 'e9b7200f7c6230f3',
    'default_0_spec': '423f5d69dd76cd55',
    'default_11_flags': '7742b24394aabe5b',
    'default_11_info': '839928915b2787b4',
    'default_11_obs': '18741485438d4a35',
    'default_11_params': '0ca39c56b93c7927',
    'default_11_rew': '5994dfb1f74535c8',
    'default_11_spec': 'b15e49de2d082dbf',
    'nodist_0_flags': '7742b24394aabe5b',
    'nodist_0_info': '3580fa1387ab65a9',
    'nodist_0_obs': 'da1163ffdf0ff6d8',
    'nodist_0_params': '5811340f1fc2f778',
    'nodist_0_rew': 'd932b22a7f49d2d5',
    'nodist_0_spec': '15ec2349a3098c48',
    'nodist_11_flags': '7742b24394aabe5b',
    'nodist_11_info': 'ad77fbe157601a24',
    'nodist_11_obs': '51260cf5a8776b7e',
    'nodist_11_params': 'f1d08d2f9f8266c6',
    'nodist_11_rew': '5daea90fdb1f1ae5',
    'nodist_11_spec': '243ea632241d4191',
    'nominal_0_flags': '347c259d485164d9',
    'nominal_0_info': '111b5e029066ee2d',
    'nominal_0_obs': 'ac5c94fed50cbd5d',
    'nominal_0_params': '2e7dbe1ef7c009c2',
    'nominal_0_rew': '3eafaf51e3528b33',
    'nominal_0_spec': '4f8cad8641b4f3c4',
    'nominal_11_flags': 'c378addf0057cba0',
    'nominal_11_info': '2b376f2e1850dad0',
    'nominal_11_obs': 'd1b5fe1d1c79a694',
    'nominal_11_params': 'c6eba6cd97a1afa0',
    'nominal_11_rew': '0b1f3baf3ef5bb7c',
    'nominal_11_spec': '768ff4e26abb9bfa',
    'nosafety_0_flags': 'ef16aa4cb0fe90b2',
    'nosafety_0_info': 'c8e3d4ce9f555b8c',
    'nosafety_0_obs': '408cc929a67cc5f4',
    'nosafety_0_params': '898048ef955e3b43',
    'nosafety_0_rew': 'bf04165d6a362af5',
    'nosafety_0_spec': 'dd13acd7fe90df49',
    'nosafety_11_flags': '09b9b429346f06e9',
    'nosafety_11_info': 'fcd7be493f61676d',
    'nosafety_11_obs': '98f0382333c13e7c',
    'nosafety_11_params': '4e731fefeff1bd6b',
    'nosafety_11_rew': '9c04f78f0351ad21',
    'nosafety_11_spec': '48644fd92434df40',
    'options2_0_flags': '4d6fecb70fdc32bb',
    'options2_0_info': '22c81f8a53531880',
    'options2_0_obs': 'ae7c513f4afdcdfb',
    'options2_0_params': 'e81cf015800fe9d2',
    'options2_0_rew': 'e9b7200f7c6230f3',
    'options2_0_spec': 'd6801dd0b1a9976f',
    'options2_11_flags': '7742b24394aabe5b',
    'options2_11_info': '839928915b2787b4',
    'options2_11_obs': '18741485438d4a35',
    'options2_11_params': '0ca39c56b93c7927',
    'options2_11_rew': '5994dfb1f74535c8',
    'options2_11_spec': 'af489a95ed28d7c2',
    'options_0_flags': 'f8d7b15de3876b8e',
    'options_0_info': 'ed3e0bab633d69d4',
    'options_0_obs': '4350be315cf1589a',
    'options_0_params': 'e81cf015800fe9d2',
    'options_0_rew': '4370e237b44a3e07',
    'options_0_spec': 'aaa1c1d74fe918b0',
    'options_11_flags': '8a4f19618e4ef227',
    'options_11_info': 'cbeef072dbaabb9b',
    'options_11_obs': '4dfedcd6c809755f',
    'options_11_params': 'c259bd8874b85283',
    'options_11_rew': '3045fd8dd254e4bd',
    'options_11_spec': 'b4734ab8b75989c4',
    'vec1k_flags': '11a404f9edd760cb',
    'vec1k_obs': '4aa58c587e4a1094',
    'vec1k_params': 'c5b8f044755330e9',
    'vec1k_rew': 'e43d4131ab353b63',
    'vec1k_state': 'd3e9f799bf48dd3b',
    'vec1k_svcfg': 'fba240eeb34e9918',
    'vec_flags': '5f892664e193d856',
    'vec_obs': '1f2f090425c662d9',
    'vec_params': 'e5a717b8918d41f2',
    'vec_rew': '0b68ffcf8f675ff8',
    'vec_state': 'd3e9f799bf48dd3b',
    'vec_svcfg': 'a0d5f8eb60bf7877',
}


def test_trajectories_are_bit_identical_to_the_record_made_before_the_faster_resets():
    now = record()
    assert sorted(now) == sorted(REFERENCE)
    assert {k: v for k, v in now.items() if v != REFERENCE[k]} == {}


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


def test_compiled_envelope_equals_the_python_envelope_bit_for_bit():
    devices = sample_devices(3, 300, dataclasses.replace(PopulationSpec(), calibrate=False))
    devices += [dataclasses.replace(d, driver_supply_v=d.driver_supply_v * 0.85) for d in devices[:50]]
    devices += [DeviceParams(), dataclasses.replace(DeviceParams(), driver_supply_v=5.0)]
    for dev in devices:
        c = SupervisorConfig.for_device(dev)
        speeds, currents = _envelope(c)
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


def test_disturbance_generators_are_the_children_of_spawn():
    from ebraille_sim.scenarios import disturbances as dist
    t = np.arange(1500) * 5e-3
    section = dist.validate_section("test", {"tremor": {"rms_m": 1e-5}, "pressing": {"rms_m": 1e-4},
                                             "battery": {"soc_start": 0.5}})
    got = dist.build_inputs(section, t, np.random.default_rng(77), DeviceParams())
    children = dict(zip(dist.KINDS, np.random.default_rng(77).spawn(len(dist.KINDS))))
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


def test_compiled_std_equals_numpy_std_bit_for_bit():
    from ebraille_sim.base.reductions import pairwise_sum, std
    rng = np.random.default_rng(5)
    lengths = list(range(1, 300)) + [1000, 1023, 1024, 1025, 8000, 8191, 8192, 8193, 40000] + \
        rng.integers(300, 20000, 40).tolist()
    for n in lengths:
        for scale, offset in ((1.0, 0.0), (1e-5, 3e-5), (1e3, -2e4)):
            x = rng.standard_normal(n) * scale + offset
            assert pairwise_sum(x, 0, n) == np.add.reduce(x), n
            assert std(x) == np.std(x), n
    x = np.fft.irfft(np.r_[0, rng.standard_normal(40) + 1j * rng.standard_normal(40), np.zeros(3960)], 8000)
    assert std(x) == np.std(x)


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
    assert ha[SV.current_limit_a] == a.current_limit_a and hb[SV.current_limit_a] == b.current_limit_a
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
    from ebraille_sim.plant import loop
    from ebraille_sim.plant.layout import N_STATE, P
    loop._steady_state_slots.cache_clear()
    devices = sample_devices(8, 3)
    params = [loop.pack_params(d, 1.0) for d in devices]
    for p in params:
        for u0 in (0.0, -0.0, 0.37):
            want, got = np.full(N_STATE, 5.0), np.full(N_STATE, 5.0)
            loop._fill_estimator_steady_state(want, p, u0)
            loop._estimator_steady_state(got, p, u0)
            assert want.tobytes() == got.tobytes()            # -0.0 kept apart from 0.0
    info = loop._steady_state_slots.cache_info()
    assert info.misses == 3 and info.hits == 6                # one estimator and filter for every unit
    slots, values = loop._steady_state_slots(params[0][loop._STEADY_HEAD].tobytes(),
                                             params[0][loop._STEADY_MODEL].tobytes(), (0.0).hex())
    assert not slots.flags.writeable and not values.flags.writeable
    with pytest.raises(ValueError):
        values[0] = 1.0
    other = params[0].copy()
    other[P.aa_b0] *= 1.5                                     # another filter: computed afresh
    a, b = np.zeros(N_STATE), np.zeros(N_STATE)
    loop._estimator_steady_state(a, other, 0.37)
    loop._fill_estimator_steady_state(b, other, 0.37)
    assert a.tobytes() == b.tobytes()
    assert loop._steady_state_slots.cache_info().misses == 4


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
