"""The compiled supervisor (controllers.supervisor) against the pure-Python reference copy.

tests/supervisor_reference.py keeps the Python implementation the compiled one replaced.
Both are driven with the same inputs around inner controllers of the same type, and every
command, mode, fault, event and detector state must agree exactly (not approximately).
"""
import math
import pathlib
import sys

import numpy as np
import pytest

from ebraille_sim.base.compiled import njit
from controllers import make
from controllers import supervisor as csup
from controllers.supervisor import (CF, EVENT_CAPACITY, MIN_CONTROL_PERIOD_S, SV, Supervisor, SupervisorConfig,
                                    supervise_begin, supervise_end)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import supervisor_reference as ref  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
STATE = ("t", "u_prev", "theta", "nan_s", "in_contact", "freeze_t0", "retract_t0", "moving_s", "speed", "accel",
         "travel_m", "stuck_ref_n", "stuck_travel_m", "contact_travel_m", "cut_t", "sp_last", "fall_t", "stall_s",
         "implausible_s", "current_limit_a", "mode", "fault")


def same(a, b) -> bool:
    """Exactly equal, NaN equal to NaN, None to None."""
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def finite(x: float) -> float:
    return x if math.isfinite(x) else 0.0


def same_log(a, b) -> bool:
    """The inner controllers' call logs agree call by call (NaN arguments equal)."""
    return len(a) == len(b) and all(len(x) == len(y) and all(same(p, q) for p, q in zip(x, y)) for x, y in zip(a, b))


class Scripted:
    """Inner controller: a PID whose command is replaced by NaN or a scripted value on some calls.

    Records every call, so that the two supervisors can be checked to call it identically.
    """
    name = "scripted"

    def __init__(self, script):
        self.pid = make("pid")
        self.script = script
        self.k = 0
        self.log = []

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        self.log.append(("reset", force_est_n, setpoint_n, command_v))
        self.pid.reset(force_est_n=force_est_n, setpoint_n=finite(setpoint_n), command_v=command_v)

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        self.log.append(("update", force_est_n, setpoint_n, dt_s, motor_current_a))
        # the PID rejects a NaN setpoint or current (its own checks): the log keeps what it was given
        u = self.pid.update(force_est_n, finite(setpoint_n), dt_s,
                            None if motor_current_a is None else finite(motor_current_a))
        s = self.script[self.k % len(self.script)]
        self.k += 1
        return u if s is None else s


def inputs(seed: int, n: int, current: str):
    """An adversarial input sequence: (force, setpoint, dt, current) per period and the inner's script."""
    rng = np.random.default_rng(seed)
    f = np.empty(n)
    level = 0.0
    k = 0
    while k < n:
        seg = int(rng.integers(5, 400))
        kind = rng.choice(["ramp", "hold", "stuck", "drop", "nan", "over", "zero", "noise", "cap"],
                          p=[0.2, 0.15, 0.15, 0.1, 0.05, 0.05, 0.1, 0.1, 0.1])
        idx = slice(k, min(k + seg, n))
        m = idx.stop - idx.start
        if kind == "ramp":
            target = rng.uniform(0.0, 3.2)
            f[idx] = np.linspace(level, target, m)
            level = target
        elif kind == "hold":
            f[idx] = level + rng.normal(0.0, 2e-3, m)
        elif kind == "stuck":
            f[idx] = level
        elif kind == "drop":
            f[idx] = max(level - rng.uniform(0.2, 1.5), 0.0)
            level = f[idx.start]
        elif kind == "nan":
            f[idx] = np.nan
        elif kind == "over":
            f[idx] = rng.uniform(3.5, 15.0)
        elif kind == "zero":
            f[idx] = 0.05
            level = 0.05
        elif kind == "cap":
            f[idx] = rng.uniform(2.6, 3.1, m)
        else:
            f[idx] = np.abs(level + rng.normal(0.0, 0.3, m))
        k = idx.stop
    sp = np.empty(n)
    k = 0
    while k < n:
        seg = int(rng.integers(20, 600))
        sp[k:k + seg] = rng.choice([0.0, 0.5, 1.0, 1.5, 2.5, 3.5, np.nan], p=[0.15, 0.2, 0.25, 0.15, 0.1, 0.1, 0.05])
        k += seg
    dt = np.where(rng.random(n) < 0.1, rng.uniform(2e-4, 3e-3, n), 1e-3)
    if current == "none":
        cur = [None] * n
    else:
        c = rng.normal(0.05, 0.1, n)
        c[rng.random(n) < 0.05] = rng.uniform(0.3, 1.0)              # overcurrent bursts
        c = c.tolist()
        if current == "mixed":
            for j in np.flatnonzero(rng.random(n) < 0.2):
                c[j] = rng.choice([None, math.nan, math.inf])
        cur = c
    script = [None] * 200 + [math.nan] * int(rng.integers(1, 700)) + [None] * 300 + [math.inf] * 5 + \
        [float(x) for x in rng.uniform(-6.0, 6.0, 50)]
    return f.tolist(), sp.tolist(), dt.tolist(), cur, script


def compare(new, old, f, sp, dt, cur, *, reset_every=None):
    """Drive both supervisors with the same inputs; every output and state must agree at every period."""
    for k in range(len(f)):
        if reset_every and k % reset_every == 0:
            for s in (new, old):
                s.reset(force_est_n=0.0 if math.isnan(f[k]) else f[k], setpoint_n=1.0, command_v=0.3 * (k % 3))
        u_new = new.update(f[k], sp[k], dt[k], cur[k])
        u_old = old.update(f[k], sp[k], dt[k], cur[k])
        assert same(float(u_new), float(u_old)), (k, u_new, u_old)
        for name in STATE:
            assert same(getattr(new, name), getattr(old, name)), (k, name, getattr(new, name), getattr(old, name))
        assert new.events == old.events, k
    assert same_log(new.inner.log, old.inner.log)


def pair(script, config=SupervisorConfig()):
    new, old = Supervisor(Scripted(script), config), ref.Supervisor(Scripted(script), config)
    for s in (new, old):
        s.reset(force_est_n=0.0, setpoint_n=1.0)
    return new, old


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("current", ["none", "float", "mixed"])
def test_random_adversarial_sequences_match_the_reference(seed, current):
    f, sp, dt, cur, script = inputs(seed, 4000, current)
    new, old = pair(script)
    compare(new, old, f, sp, dt, cur, reset_every=1500)
    assert new.events or new.fault is None


@pytest.mark.parametrize("seed", range(4))
def test_plausible_sequences_with_a_following_current_match_the_reference(seed):
    """A current that follows the command (``u / R`` plus noise) reaches the travel, stall and plausibility rules."""
    rng = np.random.default_rng(100 + seed)
    f, sp, dt, _, script = inputs(seed + 50, 3000, "none")
    script = [None] * len(script)
    new, old = pair(script, SupervisorConfig(implausible_s=0.02, stall_time_s=0.05))
    r = new.config.motor_resistance_ohm
    for k in range(len(f)):
        i = (new.u_prev - rng.uniform(-0.2, 1.5) * 0.05) / r if k % 500 < 450 else 0.4
        u_new = new.update(f[k], sp[k], dt[k], i)
        u_old = old.update(f[k], sp[k], dt[k], i)
        assert same(u_new, u_old), k
        for name in STATE:
            assert same(getattr(new, name), getattr(old, name)), (k, name)
        assert new.events == old.events
    assert same_log(new.inner.log, old.inner.log)


def test_the_sequences_reach_every_branch():
    """The random inputs trip faults and pass through every mode (the comparison is not vacuous)."""
    faults, texts = set(), set()
    for current in ("none", "float", "mixed"):
        for seed in range(6):
            f, sp, dt, cur, script = inputs(seed, 4000, current)
            s = ref.Supervisor(Scripted(script))
            for k in range(len(f)):
                if k % 1500 == 0:
                    faults.add(s.fault)
                    texts.update(text.split(":")[1] for _, text in s.events)
                    s.reset(force_est_n=0.0, setpoint_n=1.0)
                s.update(f[k], sp[k], dt[k], cur[k])
            faults.add(s.fault)
            texts.update(text.split(":")[1] for _, text in s.events)
    assert {"fsr_out_of_range", "fsr_stuck", "controller_nonfinite", "contact_lost"} <= faults
    assert {" retract", " freeze", " resume", " hold"} <= texts
    assert {case[5] for case in _named_cases()} == set(csup.FAULTS)      # the named sequences reach the rest


def _named_cases():
    """(name, force(k), script, current(sup, k), periods, expected fault): the rules random inputs rarely reach."""
    c = SupervisorConfig()
    k_e, r = c.back_emf_v_s_per_m, c.motor_resistance_ohm
    jitter = lambda k: 0.0 if k < 20 else 0.5 + 3e-3 * (k % 2)              # noqa: E731 (in contact, not stuck)
    return [
        ("stuck estimate, command moves (no current)", lambda k: 0.0 if k < 50 else 1.0,
         [None] * 60 + [3.0] * 300, lambda s, k: None, 400, "fsr_stuck"),
        ("contact lost, regained, lost for good",
         lambda k: 0.0 if k < 20 else (1.0 + 3e-3 * (k % 2) if k < 220 or 250 <= k < 350 else 0.02),
         [None], lambda s, k: None, 1200, "contact_lost"),
        ("I^2 t at a high current", lambda k: 1.0 + 3e-3 * (k % 2), [None], lambda s, k: 0.28, 3000, "motor_overcurrent"),
        ("non-finite, finite again, non-finite for good", lambda k: 1.0 + 3e-3 * (k % 2),
         [None] * 100 + [math.nan] * 100 + [None] * 100 + [math.nan] * 1200, lambda s, k: 0.01, 1500,
         "controller_nonfinite"),
        ("no contact within the travel", lambda k: 0.0, [1.0], lambda s, k: 0.005, 1000, "fsr_no_contact"),
        ("pushing without moving, no contact", lambda k: 0.05, [1.0], lambda s, k: s.u_prev / r, 1000,
         "motor_stalled"),
        ("travel beyond the compression the estimate allows", jitter, [1.0],
         lambda s, k: (s.u_prev - k_e * 5e-3) / r if k > 100 else s.u_prev / r, 1000, "fsr_implausible"),
        ("estimate above the range", lambda k: 0.5 if k < 100 else 12.0, [None], lambda s, k: s.u_prev / r, 300,
         "fsr_out_of_range"),
    ]


@pytest.mark.parametrize("case", _named_cases(), ids=lambda case: case[0])
def test_named_fault_sequences_match_the_reference(case):
    """Every fault cause, reached on purpose; the current may follow the supervisor's own command."""
    _, force, script, current, n, expected = case
    new, old = pair(script)
    for k in range(n):
        i = current(new, k)
        assert same(i, current(old, k))
        u_new, u_old = new.update(force(k), 1.0, 1e-3, i), old.update(force(k), 1.0, 1e-3, i)
        assert same(u_new, u_old), k
        for name in STATE:
            assert same(getattr(new, name), getattr(old, name)), (k, name)
        assert new.events == old.events, k
    assert same_log(new.inner.log, old.inner.log)
    assert new.fault == expected and new.mode in ("retract", "hold")


@pytest.mark.parametrize("name", sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml")))
def test_scenario_runs_match_the_reference(name, monkeypatch):
    """run_scenario (supervised, default) gives the same trace, metrics and supervisor record.

    Short runs: 2.5 s, and 6 s for the fault scenarios (their faults begin at 4 s).
    """
    from ebraille_sim.scenarios import runner, supervision

    duration = 6.0 if name.startswith("fault_") else 2.5
    new = runner.run_scenario(name, duration_s=duration)
    made = []

    class Reference(ref.Supervisor):
        def __init__(self, *args):
            super().__init__(*args)
            made.append(self)

    monkeypatch.setattr(csup, "Supervisor", Reference)
    monkeypatch.setattr(supervision, "Supervisor", Reference)
    old = runner.run_scenario(name, duration_s=duration)
    assert len(made) == 1 and made[0].t > 0.0                     # the reference did run
    assert new.supervisor == old.supervisor
    assert new.supervisor["events"] or not name.startswith("fault_")     # the fault reached the supervisor
    assert _same_metrics(new.metrics, old.metrics)
    assert new.trace.keys() == old.trace.keys()
    for key in new.trace:
        np.testing.assert_array_equal(np.asarray(new.trace[key]), np.asarray(old.trace[key]), err_msg=key)


def _same_metrics(a, b) -> bool:
    """Every metric but the wall-clock one (``real_time_factor``) agrees exactly."""
    return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a if k != "real_time_factor")


@njit(cache=True)
def _proportional_loop(sv, cfg, inner_state, f, sp, dt, cur, kp):
    """A compiled loop around a proportional inner controller (``u = kp (sp - f)``), as a whole-scenario loop calls it."""
    n = f.shape[0]
    u_out = np.empty(n)
    for k in range(n):
        code, u, sp_inner = supervise_begin(sv, cfg, f[k], sp[k], dt, cur[k])
        if code == 1:
            u_inner = kp * (sp_inner - f[k]) + inner_state[0]
            code2, u, reset_cmd = supervise_end(sv, cfg, u_inner, f[k], sp[k], dt, cur[k])
            if code2 == 1:
                inner_state[0] = reset_cmd - kp * (sp_inner - f[k])     # bumpless: the next command starts there
        elif code == 2:
            inner_state[0] = 0.0 - kp * (sp_inner - f[k])
        u_out[k] = u
    return u_out


class Proportional:
    """The Python twin of the compiled loop's inner controller."""
    name = "p"

    def __init__(self, kp):
        self.kp = kp
        self.offset = 0.0

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        self.offset = command_v - self.kp * (setpoint_n - force_est_n)

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        return self.kp * (setpoint_n - force_est_n) + self.offset


@pytest.mark.parametrize("current", ["none", "float"])
def test_supervise_begin_end_from_a_compiled_loop_match_the_python_path(current):
    f, sp, _, cur, _ = inputs(7, 4000, current)
    cur_arr = np.array([math.nan if c is None else c for c in cur])
    kp = 4.0
    py = Supervisor(Proportional(kp))
    py.reset(force_est_n=0.0, setpoint_n=1.0)
    u_py = np.array([py.update(f[k], sp[k], 1e-3, cur[k]) for k in range(len(f))])
    sup = Supervisor(Proportional(kp))
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    sv, cfg = sup.compiled()
    inner_state = np.array([sup.inner.offset])
    u_c = _proportional_loop(sv, cfg, inner_state, np.array(f), np.array(sp), 1e-3, cur_arr, kp)
    np.testing.assert_array_equal(u_c, u_py)
    assert (sup.mode, sup.fault, sup.events, sup.u_prev) == (py.mode, py.fault, py.events, py.u_prev)
    assert sup.events                                     # the sequence did reach the supervisor's rules


def test_compiled_arrays_are_live_and_reset_in_place():
    sup = Supervisor(make("pid"))
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    sv, cfg = sup.compiled()
    code, u, _ = supervise_begin(sv, cfg, math.nan, 1.0, 1e-3, math.nan)
    assert (code, sup.fault, sup.mode) == (0, "fsr_out_of_range", "retract")
    assert sup.events == [(0.001, "fault fsr_out_of_range: retract")]
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    assert sup.compiled()[0] is sv and sup.fault is None and sup.events == [] and sup.mode == "run"
    assert sv[SV.sp_last] == math.inf and sv[SV.cut_t] == -math.inf
    assert Supervisor(make("pid"), SupervisorConfig(enabled=False)).compiled() is None


def test_config_pack_is_cached_and_holds_the_envelope():
    c = SupervisorConfig()
    cfg = c.pack()
    assert c.pack() is cfg
    n = int(cfg[CF.envelope_n])
    speeds, currents = ref._envelope(c)
    assert cfg[len(CF):len(CF) + n].tolist() == speeds and cfg[len(CF) + n:].tolist() == currents
    for x in np.linspace(-0.01, 1.2 * speeds[-1], 997).tolist() + speeds:      # between and on the points
        assert csup._interp_envelope(cfg, x) == ref._interp((speeds, currents), x)
    assert cfg[CF.min_dt_s] == MIN_CONTROL_PERIOD_S
    assert cfg[CF.state_len] * 8 < 200_000          # bytes of one supervisor's state: sane for a vector env


def test_period_below_the_sized_minimum_is_a_one_line_error():
    sup = Supervisor(make("pid"))
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    with pytest.raises(ValueError, match=r"dt_s = 5e-05 s is below the 0.0001 s shortest control period"):
        sup.update(0.0, 1.0, 5e-5)
    sup.update(0.0, 1.0, 1e-4)


def test_event_log_overflow_is_counted_not_a_crash():
    sup = Supervisor(Proportional(4.0), SupervisorConfig(backoff_s=1e-3))
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    for _ in range(EVENT_CAPACITY):                     # contact lost, regained: two events per cycle
        for f in [1.0] * 5 + [0.02] * 3:
            sup.update(f, 1.0, 1e-3)
    ev = sup.events
    assert len(ev) == EVENT_CAPACITY + 1 and sup.fault is None
    assert ev[-1][1].startswith("event log full: ") and int(ev[-1][1].split()[3]) > 100


def test_bisection_memo_gives_the_bisections_numbers_and_serves_only_its_reader():
    from ebraille_sim.physics import limits
    rng = np.random.default_rng(4)
    memo = limits.new_bisection_memo(4000)
    for b, m in ((540.0, 1448.0), (700.0, 1500.0), (540.0, 1448.0)):
        e_max = limits.absorbed_energy_j(0.0, 3.2, b, m)
        energies = np.concatenate([[0.0, 2 * e_max], rng.uniform(0.0, e_max, 40)])
        for _ in range(2):
            got, plain = np.empty(energies.size), np.empty(energies.size)
            limits.drive_forces_for_impacts_n(energies, 3.2, b, m, got, memo)
            limits.drive_forces_for_impacts_n(energies, 3.2, b, m, plain, np.empty(0))
            assert got.tolist() == plain.tolist()
            assert got.tolist() == [limits.drive_force_for_impact_n(e, 3.2, b, m) for e in energies]
    assert memo[:3].tolist() == [3.2, 540.0, 1448.0] and 0 < memo[3] <= memo[4]
    small = limits.new_bisection_memo(10)                 # full: the rest is computed, not kept
    out = np.empty(energies.size)
    limits.drive_forces_for_impacts_n(energies, 3.2, b, m, out, small)
    assert small[3] == 10 and out.tolist() == plain.tolist()
