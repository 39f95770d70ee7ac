"""The supervisor as a Python controller wrapper (:class:`Supervisor`): the per-period shim's
composition of :func:`~controllers.supervisor.period.supervise_begin`, the inner controller and
:func:`~controllers.supervisor.period.supervise_end`."""
from __future__ import annotations

import math

import numpy as np

from controllers.base import check_dt
from controllers.compiled import resume_controller
from controllers.supervisor.config import SupervisorConfig
from controllers.supervisor.layout import CF, EVENT, FAULTS, MODES, SV, _EVENT_TEXTS, _N_HEADER, _initial_state
from controllers.supervisor.period import supervise_begin, supervise_end

def _scalar(name: str) -> property:
    k = getattr(SV, name)

    def get(self) -> float:
        return float(self._sv[k])

    def set_(self, value: float) -> None:
        self._sv[k] = value

    return property(get, set_, doc=f"``{name}`` of the state array (see :func:`supervise_begin`).")


class Supervisor:
    """Safety wrapper around a :class:`~controllers.base.Controller` (see the module docstring).

    The state lives in a float64 array (:meth:`compiled`); the attributes below decode it.

    Attributes
    ----------
    mode : str
        ``"run"``, ``"freeze"`` (contact lost: back off, hold, re-approach), ``"retract"`` or ``"hold"``.
    fault : str or None
        Cause of the latched fault, if any.
    events : list of (float, str)
        Time since reset (s) and a short description of every mode change.
    """

    def __init__(self, inner, config: SupervisorConfig = SupervisorConfig(), *, state_out: np.ndarray | None = None,
                 config_out: np.ndarray | None = None):
        """``state_out`` and ``config_out`` (both or neither): arrays to hold the state and the
        configuration from the start, as :meth:`bind` would move them there (the state is
        zeroed, the configuration copied in)."""
        if not isinstance(config, SupervisorConfig):
            raise TypeError(f"config must be a SupervisorConfig, got {type(config).__name__}")
        self.inner = inner
        self.config = config
        self.name = f"supervised({getattr(inner, 'name', type(inner).__name__)})"
        packed = config.pack()
        if (state_out is None) != (config_out is None):
            raise ValueError("state_out and config_out go together")
        if state_out is None:
            self._cfg = packed.copy()
            self._sv = np.zeros(int(self._cfg[CF.state_len]))
        else:
            n = int(packed[CF.state_len])
            if np.shape(state_out) != (n,) or np.shape(config_out) != packed.shape:
                raise ValueError(f"the supervisor needs arrays of lengths {n} and {packed.size}, got "
                                 f"{np.shape(state_out)} and {np.shape(config_out)}")
            config_out[:] = packed
            state_out[:] = 0.0
            self._cfg, self._sv = config_out, state_out
        self._sv0 = _initial_state(config)
        self._min_dt = float(self._cfg[CF.min_dt_s])
        self._clear()

    def compiled(self):
        """The live ``(state, config)`` float64 arrays of the compiled period, or None when disabled.

        :func:`supervise_begin` and :func:`supervise_end` advance ``state`` in place; the
        attributes of this object read it, before and after.  ``config`` holds the derived
        constants, the buffer layout and the speed envelope (:meth:`SupervisorConfig.pack`);
        the events are rows ``(time, code, value)`` inside ``state``.
        """
        if not self.config.enabled:
            return None
        return self._sv, self._cfg

    @property
    def min_control_period_s(self) -> float:
        """Shortest control period (s) the supervisor's window buffers are sized for."""
        return self._min_dt

    def bind(self, state_out: np.ndarray, config_out: np.ndarray) -> None:
        """Move the live arrays into ``state_out`` and ``config_out`` (e.g. one row each of a
        batch's 2-D arrays, stepped by the loop engine, :mod:`ebraille_sim.plant.engine`); this object then reads and
        resets those.

        Raises
        ------
        ValueError
            The arrays do not have the lengths of :meth:`compiled`'s.
        """
        if np.shape(state_out) != self._sv.shape or np.shape(config_out) != self._cfg.shape:
            raise ValueError(f"bind needs arrays of lengths {self._sv.size} and {self._cfg.size}, got "
                             f"{np.shape(state_out)} and {np.shape(config_out)}")
        state_out[:] = self._sv
        config_out[:] = self._cfg
        self._sv, self._cfg = state_out, config_out

    def _clear(self):
        self._sv[:_N_HEADER] = self._sv0

    def reset(self, *, force_est_n: float, setpoint_n: float, command_v: float = 0.0) -> None:
        """Clear faults and detectors and reset the inner controller bumplessly (on the setpoint it
        will be given: clipped to :attr:`SupervisorConfig.setpoint_max_n`, unchanged when disabled)."""
        self._clear()
        self._sv[SV.u_prev] = float(command_v) if math.isfinite(command_v) else 0.0
        sp = min(setpoint_n, self._sp_max) if self.config.enabled else setpoint_n
        self.inner.reset(force_est_n=force_est_n, setpoint_n=sp, command_v=command_v)

    @property
    def _sp_max(self) -> float:
        return self.config.setpoint_max_n

    @property
    def mode(self) -> str:
        return MODES[int(self._sv[SV.mode])]

    @mode.setter
    def mode(self, value: str) -> None:
        self._sv[SV.mode] = MODES.index(value)

    @property
    def fault(self) -> str | None:
        k = int(self._sv[SV.fault])
        return None if k == 0 else FAULTS[k - 1]

    @fault.setter
    def fault(self, value: str | None) -> None:
        self._sv[SV.fault] = 0 if value is None else FAULTS.index(value) + 1

    @property
    def in_contact(self) -> bool:
        return bool(self._sv[SV.in_contact])

    @in_contact.setter
    def in_contact(self, value: bool) -> None:
        self._sv[SV.in_contact] = bool(value)

    @property
    def contact_travel_m(self) -> float | None:
        return float(self._sv[SV.contact_travel_m]) if self._sv[SV.contact_travel_set] else None

    @property
    def events(self) -> list[tuple[float, str]]:
        sv = self._sv
        n = int(sv[SV.event_count])
        base = int(self._cfg[CF.events_base])
        out = []
        for t, code, value in sv[base:base + 3 * n].reshape(n, 3).tolist():
            text = _EVENT_TEXTS[int(code)]
            out.append((round(t, 6), text.format(FAULTS[int(value) - 1]) if code == EVENT.fault else text))
        dropped = int(sv[SV.events_dropped])
        if dropped:
            out.append((round(float(sv[SV.first_dropped_t]), 6),
                        f"event log full: {dropped} events from here on not recorded"))
        return out

    t = _scalar("t")
    u_prev = _scalar("u_prev")
    theta = _scalar("theta")
    nan_s = _scalar("nan_s")
    freeze_t0 = _scalar("freeze_t0")
    retract_t0 = _scalar("retract_t0")
    moving_s = _scalar("moving_s")
    speed = _scalar("speed")
    accel = _scalar("accel")
    travel_m = _scalar("travel_m")
    stuck_ref_n = _scalar("stuck_ref_n")
    stuck_travel_m = _scalar("stuck_travel_m")
    cut_t = _scalar("cut_t")
    sp_last = _scalar("sp_last")
    fall_t = _scalar("fall_t")
    stall_s = _scalar("stall_s")
    implausible_s = _scalar("implausible_s")
    current_limit_a = _scalar("current_limit_a")
    last_f = _scalar("last_f")

    def update(self, force_est_n: float, setpoint_n: float, dt_s: float, motor_current_a: float | None = None) -> float:
        """One period: run the detectors, then pass, shape or replace the inner command.

        An inner controller with an ``applied(command_v)`` method is told the command that
        left the supervisor, every period (a learned policy observes it, as it did in the
        env's safety layer)."""
        c = self.config
        if not 0.0 < dt_s < math.inf:
            check_dt(dt_s)
        if not c.enabled:
            return self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        if dt_s < self._min_dt:
            raise ValueError(f"dt_s = {dt_s:g} s is below the {self._min_dt:g} s shortest control period the "
                             f"supervisor's windows are sized for (MIN_CONTROL_PERIOD_S, MAX_WINDOW_SAMPLES)")
        f = float(force_est_n)
        sp = float(setpoint_n)
        dt = float(dt_s)
        cur = math.nan if motor_current_a is None or not math.isfinite(motor_current_a) else float(motor_current_a)
        code, u, sp_inner = supervise_begin(self._sv, self._cfg, f, sp, dt, cur)
        if code == 1:
            u_inner = self.inner.update(f, sp_inner, dt_s, motor_current_a)
            code, u, reset_cmd = supervise_end(self._sv, self._cfg, float(u_inner), f, sp, dt, cur)
            if code == 1:
                self.inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=reset_cmd)
            elif code == 2:
                self.inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=0.0)
        elif code == 2:
            resume_controller(self.inner, force_est_n=f, setpoint_n=sp_inner)
        applied = getattr(self.inner, "applied", None)
        if applied is not None:
            applied(u)
        return u


