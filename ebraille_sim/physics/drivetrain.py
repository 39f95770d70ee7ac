"""Gearhead, pinion-rack mesh with backlash, guide friction and end stops.

Forces are written at the rack line.  The motor's shaft quantities are reflected through
``N/r`` (gear ratio over pinion pitch radius): a shaft torque ``T`` pushes the rack with
``T N/r``, the rotor inertia ``J`` weighs ``J (N/r)^2`` and the back-EMF acts as a damper
``kM kE/R (N/r)^2`` (525 N s/m for the default 0816 006 SR with 64:1 and r = 2.5 mm).

Friction (brush and bearing, gear teeth, guide rods) follows the Stribeck curve
``F(v) = Fc + (Fs - Fc) exp(-(v/vs)^2) + sigma v`` (Armstrong-Helouvry 1994; Olsson et al.
1998).  It is applied at the velocity level: within one step friction can remove at most
``h F/m`` of velocity and never reverse it, and a body at rest stays at rest while the
other forces stay below the break-away level ``Fs``.  This is the event-free form of
Karnopp's stick band: no chatter, no stiff friction ODE.

The gearhead loses power in proportion to the load it carries: a Coulomb friction
``mu |F_mesh|`` with ``mu = 1/eta - 1`` reproduces the forward efficiency ``eta`` at steady
speed, and makes back-driving by the finger much weaker than driving.

Backlash is a dead zone of width ``2 b`` between the pinion (rack-line position
``x_p``) and the rack ``x_b``, with a stiff damped mesh contact outside it that can only
push.  End stops limit the rack travel and absorb the impact (inelastic projection).
"""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit

STATE_SLOTS = ("pinion_pos_m", "pinion_vel_m_per_s", "board_pos_m", "board_vel_m_per_s")
"""State slots of the drive train, all at the rack line (see :mod:`ebraille_sim.plant.layout`)."""

OWNED_STATE_SLOTS = STATE_SLOTS
"""Every state slot this module declares."""


@njit(cache=True, inline="always")
def shaft_to_rack_per_m(gear_ratio, pinion_radius_m):
    """Gear reflection ``N/r`` (1/m): rack force per shaft torque, shaft speed per rack speed.

    A shaft torque ``T`` pushes the rack with ``T N/r``; a rack speed ``v`` turns the shaft
    at ``v N/r``; an inertia ``J`` weighs ``J (N/r)^2`` at the rack line.
    """
    return gear_ratio / pinion_radius_m


@njit(cache=True, inline="always")
def shaft_speed_rad_per_s(rack_velocity_m_per_s, shaft_to_rack):
    """Motor shaft speed (rad/s) for a rack-line speed, ``v N/r``."""
    return rack_velocity_m_per_s * shaft_to_rack


@njit(cache=True, inline="always")
def reflected_inertia_kg(inertia_kg_m2, shaft_to_rack):
    """A shaft inertia (or rotary damping) seen at the rack line, ``J (N/r)^2``."""
    return inertia_kg_m2 * shaft_to_rack * shaft_to_rack


@njit(cache=True, inline="always")
def reflected_force_n(torque_nm, shaft_to_rack):
    """A shaft torque seen at the rack line, ``T N/r`` (N)."""
    return torque_nm * shaft_to_rack


@njit(cache=True, inline="always")
def mesh_damping_n_s_per_m(damping_ratio, stiffness_n_per_m, mass_kg):
    """Mesh damping coefficient ``2 zeta sqrt(k m)`` for a damping ratio ``zeta``."""
    return 2.0 * damping_ratio * math.sqrt(stiffness_n_per_m * mass_kg)


@njit(cache=True, inline="always")
def gear_loss_n(gear_mu, mesh_force_n):
    """Load-dependent Coulomb friction of the gearhead, ``mu |F_mesh|`` (N)."""
    return gear_mu * abs(mesh_force_n)


@njit(cache=True, inline="always")
def viscous_force_n(c_n_s_per_m, v_m_per_s):
    """Viscous friction ``sigma v`` (N), opposing the motion when subtracted."""
    return c_n_s_per_m * v_m_per_s


@njit(cache=True, inline="always")
def weight_along_n(mass_kg, gravity_along_m_per_s2):
    """Weight of a body along the travel axis, ``m g_along`` (N)."""
    return mass_kg * gravity_along_m_per_s2


@njit(cache=True, inline="always")
def stribeck(v_abs, f_coulomb, f_static, v_stribeck):
    """Kinetic friction magnitude at speed ``v_abs`` (N), without the viscous term.

    At rest the curve is ``Fs`` (``exp(0) = 1``), returned without calling ``exp``: a stuck body
    is the common case in a loop that holds a force."""
    if v_abs == 0.0:
        return f_coulomb + (f_static - f_coulomb)
    r = v_abs / v_stribeck
    return f_coulomb + (f_static - f_coulomb) * math.exp(-r * r)


@njit(cache=True, inline="always")
def loaded_friction_n(v_abs, f_coulomb, f_static, v_stribeck, load_n):
    """Kinetic and break-away friction (N) of a contact whose friction grows by ``load_n``.

    The gear loss adds to both the Coulomb and the break-away level of the pinion side.

    Returns
    -------
    (float, float)
        Kinetic friction at ``v_abs`` and the break-away level.
    """
    fs = f_static + load_n
    return stribeck(v_abs, f_coulomb + load_n, fs, v_stribeck), fs


@njit(cache=True, inline="always")
def friction_velocity_update(v, f_applied, h_per_mass, f_kinetic, f_static):
    """New velocity of a body with dry friction after one step.

    Parameters
    ----------
    v : float
        Velocity at the start of the step, m/s (exactly 0.0 while stuck).
    f_applied : float
        Sum of all forces except dry friction, N.
    h_per_mass : float
        Step over mass ``h/m`` (s/kg): a force ``F`` changes the velocity by ``F h/m``.
    f_kinetic, f_static : float
        Kinetic friction at ``|v|`` and the break-away level, N.
    """
    if v == 0.0:
        if abs(f_applied) <= f_static:
            return 0.0
        s = 1.0 if f_applied > 0.0 else -1.0
        return (f_applied - s * f_kinetic) * h_per_mass
    v_free = v + f_applied * h_per_mass
    dv = f_kinetic * h_per_mass
    if abs(v_free) <= dv:
        return 0.0
    if v_free > 0.0:
        return v_free - dv
    return v_free + dv


@njit(cache=True, inline="always")
def mesh_force(dx, dv, half_gap, k, c):
    """Force the pinion exerts on the rack (N, positive pushes the rack toward the finger).

    ``dx = x_pinion - x_rack`` and ``dv`` its rate; zero inside the backlash gap, a
    damped spring outside it that can push but never pull.
    """
    if dx > half_gap:
        f = k * (dx - half_gap) + c * dv
        return f if f > 0.0 else 0.0
    if dx < -half_gap:
        f = k * (dx + half_gap) + c * dv
        return f if f < 0.0 else 0.0
    return 0.0


@njit(cache=True, inline="always")
def end_stop(x_m, v_m_per_s, x_min_m, x_max_m):
    """Inelastic end stops: position clipped to the travel, velocity into the stop removed.

    Returns
    -------
    (float, float)
        Position and velocity after the stops.
    """
    if x_m < x_min_m:
        return x_min_m, (0.0 if v_m_per_s < 0.0 else v_m_per_s)
    if x_m > x_max_m:
        return x_max_m, (0.0 if v_m_per_s > 0.0 else v_m_per_s)
    return x_m, v_m_per_s


def reflected(motor, drivetrain) -> dict:
    """Motor quantities seen at the rack line (for analysis and docs).

    Returns
    -------
    dict
        ``mass_kg`` J (N/r)^2, ``back_emf_damping_n_s_per_m`` kM kE/R (N/r)^2,
        ``coulomb_n`` T_f N/r, ``stall_force_n`` (at the nominal voltage, through the
        gear efficiency), ``no_load_speed_m_per_s``, ``force_per_volt_n_per_v``.
    """
    g = shaft_to_rack_per_m(drivetrain.gear_ratio, drivetrain.pinion_radius_m)
    kt, ke, r = motor.torque_constant_nm_per_a, motor.back_emf_v_s_per_rad, motor.resistance_ohm
    v = motor.nominal_voltage_v
    return {
        "mass_kg": reflected_inertia_kg(motor.rotor_inertia_kg_m2, g),
        "back_emf_damping_n_s_per_m": reflected_inertia_kg(kt * ke / r, g),
        "coulomb_n": reflected_force_n(motor.friction_torque_nm, g),
        "stall_force_n": reflected_force_n(motor.stall_torque_at(v), g) * drivetrain.gear_efficiency,
        "no_load_speed_m_per_s": motor.no_load_speed_at(v) / g,
        "force_per_volt_n_per_v": reflected_force_n(kt / r, g) * drivetrain.gear_efficiency,
    }
