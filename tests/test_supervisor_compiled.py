"""The compiled supervisor (controllers.supervisor): properties over random inputs, and the
compiled period as the loop engine composes it against the Python wrapper.

The rules themselves are checked one by one, with hand-worked numbers, in
tests/test_supervisor_rules.py.  Here random sequences (fixed seeds) drive the supervisor
through every mode and fault, and what must hold at every period is checked: the command is
finite, within the driver's supply when the motor's current is one the supply can drive, moves
at most ``slew_v_per_s dt`` a period except where a rule jumps, is 0 V once in ``hold``; a
fault stays latched until a reset; a reset gives the state of a fresh supervisor; a disabled
supervisor is transparent; and the engine's compiled period gives the wrapper's commands bit
for bit.
"""
import math

import numpy as np
import pytest

from ebraille_sim.base.compiled import njit
from controllers import make
from controllers import supervisor as csup
from controllers.compiled import KIND_EXTERNAL
from controllers.supervisor import (CF, EVENT_CAPACITY, MIN_CONTROL_PERIOD_S, SV, Supervisor, SupervisorConfig,
                                    supervise_begin, supervise_end)
from ebraille_sim.plant.engine import command

C = SupervisorConfig()
N_HEADER = len(SV)


def finite(x: float) -> float:
    return x if math.isfinite(x) else 0.0


class Scripted:
    """Inner controller: a PID whose command is replaced by NaN or a scripted value on some calls."""
    name = "scripted"

    def __init__(self, script):
        self.pid = make("pid")
        self.script = script
        self.k = 0
        self.calls = 0

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        self.pid.reset(force_est_n=finite(force_est_n), setpoint_n=finite(setpoint_n), command_v=finite(command_v))

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        self.calls += 1
        # the PID rejects a NaN setpoint or current (its own checks)
        u = self.pid.update(finite(force_est_n), finite(setpoint_n), dt_s,
                            None if motor_current_a is None else finite(motor_current_a))
        s = self.script[self.k % len(self.script)]
        self.k += 1
        return u if s is None else s


class Replay:
    """Inner controller whose command is set from outside before each period (``u``)."""
    name = "replay"

    def __init__(self):
        self.u = 0.0

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        pass

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        return self.u


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


class Checked:
    """Drives a supervisor period by period and checks the properties that hold at every period."""

    def __init__(self, sup):
        self.sup = sup
        self.faults, self.modes, self.texts = set(), set(), set()
        self.jumps = 0

    def reset(self, f, command_v):
        self.sup.reset(force_est_n=finite(f), setpoint_n=1.0, command_v=command_v)

    def step(self, f, sp, dt, cur):
        sup = self.sup
        c = sup.config
        prev, mode0, fault0, calls0 = sup.u_prev, sup.mode, sup.fault, getattr(sup.inner, "calls", None)
        u = sup.update(f, sp, dt, cur)
        mode, fault = sup.mode, sup.fault
        assert math.isfinite(u)
        assert u == sup.u_prev                                   # the next period slews from this command
        du = c.slew_v_per_s * dt
        tol = 1e-12 * (1.0 + abs(prev))
        # a latched fault stays, and its safe state only moves on (retract -> hold)
        if fault0 is not None:
            assert fault == fault0 and mode in ("retract", "hold")
            assert not (mode0 == "hold" and mode == "retract")
        if fault is not None:
            assert mode in ("retract", "hold")
            if calls0 is not None and fault0 is not None:
                assert sup.inner.calls == calls0                 # the inner controller is no longer asked
        # in hold: 0 V, reached at the slew rate from the retract's command
        if mode == "hold":
            assert u == min(max(0.0, prev - du), prev + du)
        # the slew limit: a freeze (back off at -retract_v, then 0 V, and the resume from 0 V)
        # jumps; the current envelope may cut a command further down
        if mode0 == "freeze" or mode == "freeze":
            self.jumps += abs(u - prev) > du + tol
        else:
            assert u <= prev + du + tol, (prev, u, du)
            no_current = cur is None or not math.isfinite(cur)
            if no_current:
                assert u >= prev - du - tol, (prev, u, du)
        self.faults.add(fault)
        self.modes.add(mode)
        return u


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("current", ["none", "float", "mixed"])
def test_properties_over_random_adversarial_sequences(seed, current):
    """Finite, slew-limited, latched, 0 V in hold, at every period of 4,000 adversarial ones."""
    f, sp, dt, cur, script = inputs(seed, 4000, current)
    run = Checked(Supervisor(Scripted(script)))
    run.reset(0.0, 0.0)
    for k in range(len(f)):
        if k % 1500 == 0 and k:
            run.reset(f[k], 0.3 * (k % 3))
        run.step(f[k], sp[k], dt[k], cur[k])


@pytest.mark.parametrize("case", _named_cases(), ids=lambda case: case[0])
def test_properties_along_each_fault(case):
    """The named sequences reach every fault cause; the per-period properties hold along them."""
    _, force, script, current, n, expected = case
    run = Checked(Supervisor(Scripted(script)))
    run.reset(0.0, 0.0)
    for k in range(n):
        run.step(force(k), 1.0, 1e-3, current(run.sup, k))
    assert run.sup.fault == expected and run.sup.mode in ("retract", "hold")


def test_the_sequences_reach_every_mode_and_fault():
    """The properties are not vacuous: the random inputs trip faults, pass through every mode
    and make the freeze's jumps; the named sequences reach every cause."""
    faults, modes, jumps = set(), set(), 0
    for current in ("none", "float", "mixed"):
        for seed in range(6):
            f, sp, dt, cur, script = inputs(seed, 4000, current)
            run = Checked(Supervisor(Scripted(script)))
            run.reset(0.0, 0.0)
            for k in range(len(f)):
                if k % 1500 == 0 and k:
                    run.reset(f[k], 0.0)
                run.step(f[k], sp[k], dt[k], cur[k])
            faults |= run.faults
            modes |= run.modes
            jumps += run.jumps
    assert {"fsr_out_of_range", "fsr_stuck", "controller_nonfinite", "contact_lost"} <= faults
    assert modes == set(csup.MODES) and jumps > 0
    assert {case[5] for case in _named_cases()} == set(csup.FAULTS)


def physical_inputs(seed: int, n: int):
    """Inner commands within the supply (or not finite), currents a motor on that supply can draw:
    ``(u - e) / R`` with the last command ``u`` and a back-EMF ``e`` within the no-load one
    (``V_s - R I_f``), or no measurement."""
    rng = np.random.default_rng(seed)
    f, sp, dt, _, _ = inputs(seed + 1000, n, "none")
    u_in = rng.uniform(-C.driver_supply_v, C.driver_supply_v, n)
    u_in[rng.random(n) < 0.02] = np.nan
    e_max = C.driver_supply_v - C.motor_resistance_ohm * C.friction_current_a
    emf = rng.uniform(-e_max, e_max, n)
    emf[rng.random(n) < 0.5] = 0.0                              # stalled half the time
    has_cur = rng.random(n) < 0.8
    return f, sp, dt, u_in.tolist(), emf.tolist(), has_cur.tolist()


def test_command_stays_within_the_supply_when_the_current_is_physical():
    """With inner commands within +/- V_s and currents the supply can drive, the supervisor's
    command stays within +/- V_s: the envelope's cap is the back-EMF plus R times a current limit
    of at least -I_f, so at least -(V_s - R I_f) - R I_f = -V_s.  Six seeds of 4,000 periods,
    through every mode and several faults."""
    vs, r = C.driver_supply_v, C.motor_resistance_ohm
    faults, modes = set(), set()
    for seed in range(6):
        f, sp, dt, u_in, emf, has_cur = physical_inputs(seed, 4000)
        sup = Supervisor(Replay())
        run = Checked(sup)
        run.reset(0.0, 0.0)
        for k in range(len(f)):
            if k % 1000 == 0 and k:
                run.reset(f[k], float(np.clip(u_in[k], -vs, vs)) if math.isfinite(u_in[k]) else 0.0)
            sup.inner.u = u_in[k]
            cur = (min(max(sup.u_prev, -vs), vs) - emf[k]) / r if has_cur[k] else None
            u = run.step(f[k], sp[k], dt[k], cur)
            assert -vs <= u <= vs, (seed, k, u)
        faults |= run.faults
        modes |= run.modes
    assert len(faults - {None}) >= 3 and modes == set(csup.MODES)


@pytest.mark.parametrize("seed", range(3))
def test_disabled_supervisor_returns_the_inner_command_unchanged(seed):
    rng = np.random.default_rng(seed)
    f, sp, dt, cur, _ = inputs(seed, 1000, "mixed")
    u_in = rng.uniform(-20.0, 20.0, 1000)
    u_in[rng.random(1000) < 0.1] = np.nan
    u_in[rng.random(1000) < 0.05] = np.inf
    sup = Supervisor(Replay(), SupervisorConfig(enabled=False))
    sup.reset(force_est_n=0.0, setpoint_n=1.0)
    before = sup._sv.copy()
    for k in range(1000):
        sup.inner.u = float(u_in[k])
        u = sup.update(f[k], sp[k], dt[k], cur[k])
        assert np.float64(u).tobytes() == np.float64(u_in[k]).tobytes()
    assert sup.compiled() is None and sup.events == [] and sup.fault is None
    np.testing.assert_array_equal(sup._sv, before)


def test_disabled_supervisor_leaves_the_inner_controller_as_it_is_without_it():
    """A PID behind a disabled supervisor gives the bare PID's commands, a reset on a setpoint
    above the cap included (an enabled supervisor resets its inner controller on the clipped
    setpoint, 2.7 N, that it will pass it)."""
    f, sp, dt, _, _ = inputs(3, 1000, "none")
    bare, wrapped = make("pid"), Supervisor(make("pid"), SupervisorConfig(enabled=False))
    for c in (bare, wrapped):
        c.reset(force_est_n=3.0, setpoint_n=3.5)
    for k in range(1000):
        if math.isfinite(f[k]) and math.isfinite(sp[k]):
            assert bare.update(f[k], sp[k], dt[k]) == wrapped.update(f[k], sp[k], dt[k]), k


def _header(sup):
    return sup.compiled()[0][:N_HEADER].copy()


@pytest.mark.parametrize("seed", range(4))
def test_reset_gives_the_state_of_a_fresh_supervisor(seed):
    """After any history, a reset gives the header of a fresh supervisor reset alike, and the
    same commands and states from then on, bit for bit."""
    f, sp, dt, cur, _ = inputs(seed, 3000, "float")
    rng = np.random.default_rng(seed)
    used = Supervisor(Proportional(4.0))
    used.reset(force_est_n=0.0, setpoint_n=1.0)
    cut = int(rng.integers(500, 2500))
    for k in range(cut):
        used.update(f[k], sp[k], dt[k], cur[k])
    assert used.events
    f0, cmd = finite(f[cut]), float(rng.uniform(-2.0, 2.0))
    used.reset(force_est_n=f0, setpoint_n=1.0, command_v=cmd)
    fresh = Supervisor(Proportional(4.0))
    fresh.reset(force_est_n=f0, setpoint_n=1.0, command_v=cmd)
    np.testing.assert_array_equal(_header(used), _header(fresh))
    assert used.events == [] and used.fault is None and used.mode == "run"
    for k in range(cut, len(f)):
        a, b = used.update(f[k], sp[k], dt[k], cur[k]), fresh.update(f[k], sp[k], dt[k], cur[k])
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), k
    np.testing.assert_array_equal(_header(used), _header(fresh))
    assert used.events == fresh.events


@njit(cache=True)
def _engine_periods(sv, cfg, u_ext, f, sp, dt, cur):
    """The supervised period of the loop engine (:func:`ebraille_sim.plant.engine.command`) with
    an external command, for every period."""
    n = f.shape[0]
    out = np.empty(n)
    none = np.empty(0)
    for k in range(n):
        out[k] = command(KIND_EXTERNAL, none, none, u_ext[k], True, sv, cfg, f[k], sp[k], dt[k], cur[k])
    return out


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("current", ["none", "float", "mixed"])
def test_engine_period_gives_the_wrappers_commands_bit_for_bit(seed, current):
    """The compiled period as the engine composes it and :meth:`Supervisor.update` around an inner
    controller that returns the same command: the same commands and state arrays, bit for bit."""
    f, sp, dt, cur, script = inputs(seed, 4000, current)
    rng = np.random.default_rng(seed)
    u_ext = rng.uniform(-8.0, 8.0, len(f))
    u_ext[rng.random(len(f)) < 0.05] = np.nan
    u_ext[1000:1700] = np.nan                                    # the watchdog's timeout
    py = Supervisor(Replay())
    py.reset(force_est_n=0.0, setpoint_n=1.0)
    u_py = np.empty(len(f))
    for k in range(len(f)):
        py.inner.u = float(u_ext[k])
        u_py[k] = py.update(f[k], sp[k], dt[k], cur[k])
    eng = Supervisor(Replay())
    eng.reset(force_est_n=0.0, setpoint_n=1.0)
    sv, cfg = eng.compiled()
    cur_arr = np.array([math.nan if c is None else c for c in cur], dtype=float)
    u_c = _engine_periods(sv, cfg, u_ext, np.array(f), np.array(sp), np.array(dt), cur_arr)
    assert u_c.tobytes() == u_py.tobytes()
    assert sv.tobytes() == py.compiled()[0].tobytes()
    assert eng.events == py.events and eng.events


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
    v_max = c.speed_limit_m_per_s
    speeds = [v_max * k / 32 for k in range(33)] + [1.05 * v_max]
    currents = [c.current_for_force_a(max(c.drive_force_limit_n(v), 0.0)) * (1.0 - c.sense_gain_error_max)
                - c.sense_error_a for v in speeds[:33]]                    # as the board reads them
    currents.append(-c.friction_current_a)
    assert cfg[len(CF):len(CF) + n].tolist() == speeds and cfg[len(CF) + n:].tolist() == currents
    for x, y in zip(speeds, currents):                                      # on the points: the point
        assert csup._interp_envelope(cfg, x) == y
    xs = np.linspace(-0.01, 1.2 * speeds[-1], 997)                          # between them: linear
    got = [csup._interp_envelope(cfg, x) for x in xs.tolist()]
    np.testing.assert_allclose(got, np.interp(xs, speeds, currents), rtol=1e-12, atol=1e-15)
    assert math.isnan(csup._interp_envelope(cfg, math.nan))
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
