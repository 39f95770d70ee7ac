"""Brushed DC motor: armature circuit and torque.

Armature: ``L di/dt = V - R i - kE w`` (:func:`current_rate_a_per_s`, the form the loop
analysis linearises).  Its time constant L/R (10 us for the Faulhaber
0816 006 SR) is far below any practical physics step, so the current is advanced with
the exact solution for a step ``h`` during which the voltage ``V`` and the speed ``w``
are held::

    i(t+h) = i_ss + (i(t) - i_ss) exp(-h R/L),   i_ss = (V - kE w)/R

which is stable for every ``h`` and tends to the quasi-static ``i_ss`` when h >> L/R.
Shaft torque ``kM i``; brush/bearing friction is applied by :mod:`ebraille_sim.physics.drivetrain`.

Examples
--------
>>> from ebraille_sim.physics.params import MOTORS
>>> m = MOTORS["faulhaber_0816_006sr"]
>>> round(m.stall_torque_at(6.0) * 1e3, 2)     # mN m, datasheet 1.13
1.13
>>> round(m.no_load_speed_at(6.0) * 60 / (2 * 3.141592653589793))   # rpm, datasheet 13 500
13514
"""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit

STATE_SLOTS = ("current_a",)
"""State slots of the armature (see :mod:`ebraille_sim.plant.layout`)."""

ENERGY_SLOTS = ("energy_j",)
"""State slot of the electrical energy drawn from the driver."""

OWNED_STATE_SLOTS = STATE_SLOTS + ENERGY_SLOTS
"""Every state slot this module declares."""


@njit(cache=True, inline="always")
def driver_voltage(command_v, supply_v):
    """Terminal voltage of the H-bridge: the command clipped to +/- the supply (V)."""
    if command_v > supply_v:
        return supply_v
    if command_v < -supply_v:
        return -supply_v
    return command_v


@njit(cache=True, inline="always")
def current_step(i_a, v_v, omega_rad_s, g_s, ke_v_s, decay):
    """Advance the armature current over one step, exactly for held V and w.

    Parameters
    ----------
    i_a : float
        Current at the start of the step, A.
    v_v : float
        Terminal voltage, V.
    omega_rad_s : float
        Shaft speed, rad/s.
    g_s, ke_v_s : float
        Armature conductance ``1/R`` (S) and back-EMF constant: the kernel forms ``1/R`` once
        per call, so the step multiplies where a division would sit on its critical path.
    decay : float
        ``exp(-h R / L)`` for the step ``h``.
    """
    i_ss = (v_v - ke_v_s * omega_rad_s) * g_s
    return i_ss + (i_a - i_ss) * decay


@njit(cache=True, inline="always")
def rack_force_n(i_a, kt_nm_per_a, shaft_to_rack_per_m):
    """Motor force at the rack line, ``kM i N/r`` (N), before any friction or gear loss."""
    return kt_nm_per_a * i_a * shaft_to_rack_per_m


@njit(cache=True, inline="always")
def electrical_power_w(v_v, i_a):
    """Power drawn from the driver, ``V i`` (W)."""
    return v_v * i_a


def current_rate_a_per_s(i_a, v_v, omega_rad_s, r_ohm, l_h, ke_v_s):
    """The armature ODE in continuous time, ``di/dt = (V - R i - kE w)/L`` (A/s).

    :func:`current_step` is its exact solution over a step with ``V`` and ``w`` held.  The
    law is linear in ``(i, V, w)``: its partial derivatives are its values on unit inputs
    (``-R/L``, ``1/L``, ``-kE/L``), which is how the loop analysis's Jacobian takes them.
    A speed at the rack line works as well with ``ke_v_s`` the rack-line constant ``kE N/r``.
    """
    return (v_v - r_ohm * i_a - ke_v_s * omega_rad_s) / l_h


def current_decay(h_s: float, r_ohm: float, l_h: float) -> float:
    """``exp(-h R/L)``: the per-step decay of the armature transient."""
    return math.exp(-h_s * r_ohm / l_h)
