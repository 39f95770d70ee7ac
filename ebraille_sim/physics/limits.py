"""Force, current and speed bounds of the drive: what a motor current can do to the finger.

These laws bound the contact force from quantities the microcontroller measures without
the force sensor: the motor current ``i``, the terminal voltage ``u`` and, through the
back-EMF ``u - R i``, the motor speed.  They compose the laws of
:mod:`~ebraille_sim.physics.motor` (``kM i N/r``), :mod:`~ebraille_sim.physics.drivetrain`
(gear reflection, reflected inertia and torque) and :mod:`~ebraille_sim.physics.fingertip`
(the exponential pulp).

Steady push.  Moving the board toward the finger, the pinion side obeys
``kM i N/r = F_mesh / eta + T_f N/r + M_p a`` (gear loss ``mu |F_mesh|`` with
``mu = 1/eta - 1``, brush friction ``T_f``) and the board ``F_contact = F_mesh - F_guide +
m g_along - m_b a``.  Friction only ever opposes the push, so the largest force a current
can push with at constant speed is::

    F_push(i) = eta (kM i - T_f) N/r + m_b g                           (1)

(guide friction dropped, gravity counted as if the hand were upside down).  The
efficiency ``eta`` is the bound in the pushing direction; the larger factor ``1/(1 - mu)``
of the non-back-drivable gearhead only holds a force that is already there, it cannot
raise it.

Impact.  A board that arrives at speed ``v`` brings the kinetic energy of the rotor
reflected through the gearhead (transmitted with ``eta``) and of the board::

    E(v) = (eta M_p + m_b) v^2 / 2,      M_p = J (N/r)^2                (2)

With a drive force ``F_d`` held from the compression where the pulp pushes back with
``F_d``, the pulp's instantaneous elastic law absorbs ``E`` above ``F_d`` until the peak
``F_pk``::

    U(d(F_pk)) - U(d(F_d)) - F_d (d(F_pk) - d(F_d)) = E(v),
    U(d) = (b/m) ((exp(m d) - 1)/m - d)                                  (3)

Friction and the pulp's relaxation only lower the peak.

Examples
--------
>>> from ebraille_sim.physics.params import DeviceParams
>>> d = DeviceParams()
>>> round(drive_bounds(d)["push_force_per_a_n"], 2)       # eta kM N/r, N/A
63.28
"""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.physics.drivetrain import reflected_force_n, reflected_inertia_kg, shaft_to_rack_per_m
from ebraille_sim.physics.fingertip import compression_at_force_m, elastic_force
from ebraille_sim.physics.motor import rack_force_n

__all__ = ["push_force_bound_n", "current_for_push_force_a", "rack_speed_from_emf_m_per_s", "impact_energy_j",
           "elastic_energy_j", "absorbed_energy_j", "drive_force_for_impact_n", "drive_forces_for_impacts_n",
           "speed_for_energy_m_per_s",
           "drive_bounds"]


@njit(cache=True, inline="always")
def push_force_bound_n(current_a, kt_nm_per_a, shaft_to_rack, gear_efficiency, friction_torque_nm, weight_n):
    """Largest steady force (N) the drive pushes the finger with at motor current ``current_a``: eq. (1)."""
    return gear_efficiency * (rack_force_n(current_a, kt_nm_per_a, shaft_to_rack)
                              - reflected_force_n(friction_torque_nm, shaft_to_rack)) + weight_n


def current_for_push_force_a(force_n, kt_nm_per_a, shaft_to_rack, gear_efficiency, friction_torque_nm, weight_n):
    """Motor current (A) at which :func:`push_force_bound_n` equals ``force_n`` (its inverse)."""
    return ((force_n - weight_n) / gear_efficiency / shaft_to_rack + friction_torque_nm) / kt_nm_per_a


@njit(cache=True, inline="always")
def rack_speed_from_emf_m_per_s(voltage_v, current_a, resistance_ohm, back_emf_v_s_per_rad, shaft_to_rack):
    """Rack speed (m/s) read from the back-EMF: ``(u - R i) / kE / (N/r)``."""
    return (voltage_v - resistance_ohm * current_a) / back_emf_v_s_per_rad / shaft_to_rack


def impact_energy_j(speed_m_per_s, pinion_mass_kg, board_mass_kg, gear_efficiency):
    """Kinetic energy (J) a board arriving at ``speed_m_per_s`` can put into the finger: eq. (2)."""
    return 0.5 * (gear_efficiency * pinion_mass_kg + board_mass_kg) * speed_m_per_s * speed_m_per_s


def speed_for_energy_m_per_s(energy_j, pinion_mass_kg, board_mass_kg, gear_efficiency):
    """Speed (m/s) at which :func:`impact_energy_j` equals ``energy_j`` (its inverse)."""
    return math.sqrt(2.0 * max(energy_j, 0.0) / (gear_efficiency * pinion_mass_kg + board_mass_kg))


@njit(cache=True)
def elastic_energy_j(d_m, b_n_per_m, m_per_m):
    """Energy (J) stored in the pulp's instantaneous elastic law at compression ``d_m``: ``U(d)`` of eq. (3)."""
    if d_m <= 0.0:
        return 0.0
    return (elastic_force(d_m, b_n_per_m, m_per_m) - b_n_per_m * d_m) / m_per_m


@njit(cache=True)
def absorbed_energy_j(drive_force_n, peak_force_n, b_n_per_m, m_per_m):
    """Energy (J) the pulp absorbs above a constant drive ``F_d`` from ``d(F_d)`` to ``d(F_pk)``: eq. (3)."""
    d1 = compression_at_force_m(peak_force_n, b_n_per_m, m_per_m)
    return _absorbed_below_j(drive_force_n, d1, elastic_energy_j(d1, b_n_per_m, m_per_m), b_n_per_m, m_per_m)


@njit(cache=True, inline="always")
def _absorbed_below_j(drive_force_n, peak_d_m, peak_energy_j, b_n_per_m, m_per_m):
    """:func:`absorbed_energy_j` given the peak's compression ``d(F_pk)`` and energy ``U(d(F_pk))``
    (a bisection over the drive force computes them once)."""
    d0 = compression_at_force_m(drive_force_n, b_n_per_m, m_per_m)
    return peak_energy_j - elastic_energy_j(d0, b_n_per_m, m_per_m) - drive_force_n * (peak_d_m - d0)


@njit(cache=True)
def drive_force_for_impact_n(energy_j, peak_force_n, b_n_per_m, m_per_m):
    """Largest constant drive force (N) with which an impact of ``energy_j`` peaks at most at ``peak_force_n``.

    Bisection on :func:`absorbed_energy_j`, which falls monotonically as the drive force rises
    (0 at ``F_d = F_pk``).  Returns a negative value when even a zero drive force lets the
    impact exceed the peak: the board must then be braked.  (:func:`drive_forces_for_impacts_n`
    with one energy.)
    """
    energies = np.empty(1)
    energies[0] = energy_j
    out = np.empty(1)
    drive_forces_for_impacts_n(energies, peak_force_n, b_n_per_m, m_per_m, out, np.empty(0))
    return out[0]


BISECTION_MEMO_HEADER = 5
"""Slots before the nodes of a bisection memo (:func:`drive_forces_for_impacts_n`): the peak
force, b and m it holds the absorbed energies of, the nodes used and the nodes it has room for."""


def new_bisection_memo(nodes: int) -> np.ndarray:
    """An empty memo for :func:`drive_forces_for_impacts_n` with room for ``nodes`` midpoints
    (three slots each)."""
    memo = np.zeros(BISECTION_MEMO_HEADER + 3 * nodes)
    memo[4] = nodes
    return memo


@njit(cache=True)
def drive_forces_for_impacts_n(energies_j, peak_force_n, b_n_per_m, m_per_m, out, memo):
    """:func:`drive_force_for_impact_n` of every energy in ``energies_j``, written into ``out``.

    Every bisection starts from ``[0, F_pk]`` and halves it 50 times, so its midpoints form a
    binary tree shared by all energies and all calls with the same ``F_pk``, ``b`` and ``m``:
    ``memo`` (:func:`new_bisection_memo`; an empty array for none) keeps the absorbed energy
    at each midpoint a bisection has reached (three slots a node: the energy, then the nodes
    of the lower and the upper half, -1 for none), and a later bisection that walks the same
    path reads it instead of computing it again.  The memo is taken over by the first call
    and serves only calls with its ``F_pk``, ``b`` and ``m`` (others compute every midpoint);
    when it is full, new midpoints are computed and not kept.  Each midpoint's energy is the
    number the bisection would compute, so the results are those of one bisection after the
    other without a memo.  What it buys (``python benchmarks/bench_replicas.py``, 2-core
    machine, load average 7): the supervisor's envelope of a new device in 16 us against 134 us;
    with the re-approach speed's bisection, which shares the memo, 141 us of a 685 us reset of
    the default env.
    """
    n = energies_j.shape[0]
    d1 = compression_at_force_m(peak_force_n, b_n_per_m, m_per_m)
    u1 = elastic_energy_j(d1, b_n_per_m, m_per_m)
    at_zero = _absorbed_below_j(0.0, d1, u1, b_n_per_m, m_per_m)
    h = BISECTION_MEMO_HEADER
    usable = False
    if memo.shape[0] > h:
        if memo[3] == 0.0:
            memo[0], memo[1], memo[2] = peak_force_n, b_n_per_m, m_per_m
        usable = memo[0] == peak_force_n and memo[1] == b_n_per_m and memo[2] == m_per_m
    for i in range(n):
        e = energies_j[i]
        if e <= 0.0:
            out[i] = peak_force_n
            continue
        if at_zero < e:
            out[i] = -1.0
            continue
        lo, hi = 0.0, peak_force_n
        node = 0 if usable and memo[3] > 0.0 else -1
        parent = -1
        side = 0
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            if node >= 0:
                g = memo[h + 3 * node]
            else:
                g = _absorbed_below_j(mid, d1, u1, b_n_per_m, m_per_m)
                if usable and memo[3] < memo[4]:
                    node = int(memo[3])
                    memo[3] += 1.0
                    memo[h + 3 * node] = g
                    memo[h + 3 * node + 1] = -1.0
                    memo[h + 3 * node + 2] = -1.0
                    if parent >= 0:
                        memo[h + 3 * parent + side] = node
            if g >= e:
                lo = mid
                side = 2
            else:
                hi = mid
                side = 1
            parent = node
            node = int(memo[h + 3 * parent + side]) if parent >= 0 else -1
        out[i] = lo


def drive_bounds(device) -> dict:
    """Rack-line constants of ``device`` (a :class:`~ebraille_sim.physics.params.DeviceParams`) for the bounds.

    Returns
    -------
    dict
        ``push_force_per_a_n`` (eta kM N/r), ``friction_current_a`` (T_f/kM),
        ``weight_n`` (m_b g), ``back_emf_v_s_per_m`` (kE N/r), ``pinion_mass_kg``
        (J (N/r)^2), ``board_mass_kg``, ``impact_mass_kg`` (eta M_p + m_b),
        ``gear_efficiency``, ``shaft_to_rack_per_m``.
    """
    m, dt = device.motor, device.drivetrain
    g = shaft_to_rack_per_m(dt.gear_ratio, dt.pinion_radius_m)
    eta = dt.gear_efficiency
    mp = reflected_inertia_kg(m.rotor_inertia_kg_m2, g)
    return {
        "push_force_per_a_n": eta * rack_force_n(1.0, m.torque_constant_nm_per_a, g),
        "friction_current_a": m.friction_torque_nm / m.torque_constant_nm_per_a,
        "weight_n": dt.moving_mass_kg * device.gravity_m_per_s2,
        "back_emf_v_s_per_m": m.back_emf_v_s_per_rad * g,
        "pinion_mass_kg": mp,
        "board_mass_kg": dt.moving_mass_kg,
        "impact_mass_kg": eta * mp + dt.moving_mass_kg,
        "gear_efficiency": eta,
        "shaft_to_rack_per_m": g,
    }
