"""The drive's current and speed envelope: the current limit against rack speed, built once
per configuration (:func:`_envelope_table`, compiled) from the laws of
:mod:`ebraille_sim.physics.limits`, and the re-approach speed's bisection over the same laws
(:func:`reapproach_speed_m_per_s`, compiled: 17 steps of the drive-force bisection in one call,
its bisections memoised as the envelope's)."""
from __future__ import annotations

import functools

import numpy as np

from controllers.compiled import py_max as _pymax
from ebraille_sim.base.compiled import njit
from ebraille_sim.physics import limits


ENVELOPE_POINTS = 34
"""Rows of the speed envelope table: 33 speeds from rest to the speed limit and one beyond it."""

_impact_energy_j = njit(cache=True)(limits.impact_energy_j)
_current_for_push_force_a = njit(cache=True)(limits.current_for_push_force_a)


@njit(cache=True)
def reapproach_speed_m_per_s(speed_limit_m_per_s, pinion_mass_kg, board_mass_kg, gear_efficiency, setpoint_max_n,
                             reader_b_n_per_m, reader_m_per_m, back_emf_v_s_per_m, motor_resistance_ohm,
                             friction_current_a, push_force_per_a_n, weight_n, memo):
    """The bisection of :attr:`SupervisorConfig.reapproach_speed_m_per_s
    <controllers.supervisor.SupervisorConfig.reapproach_speed_m_per_s>` (to 1 um/s) over the laws of
    :mod:`ebraille_sim.physics.limits`: the largest speed whose steady push at the re-approach's
    command plus its impact peaks at most at ``setpoint_max_n`` on the design reader, m/s;
    ``memo`` keeps the drive-force bisections' midpoints (:func:`_envelope_memo` of
    ``setpoint_max_n`` and the design reader)."""
    energies = np.empty(1)
    room = np.empty(1)
    lo, hi = 0.0, speed_limit_m_per_s
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        energies[0] = _impact_energy_j(mid, pinion_mass_kg, board_mass_kg, gear_efficiency)
        limits.drive_forces_for_impacts_n(energies, setpoint_max_n, reader_b_n_per_m, reader_m_per_m, room, memo)
        command_v = back_emf_v_s_per_m * mid + motor_resistance_ohm * friction_current_a
        push = limits.push_force_bound_n(command_v / motor_resistance_ohm, push_force_per_a_n, 1.0, 1.0,
                                         friction_current_a * push_force_per_a_n, weight_n)
        if push - room[0] <= 0.0:
            lo = mid
        else:
            hi = mid
    return lo


ENVELOPE_MEMO_NODES = 1 << 14
"""Midpoints one of the envelope's bisection memos keeps (0.4 MB; :func:`_envelope_memo`)."""


@functools.lru_cache(maxsize=8)
def _envelope_memo(envelope_force_n: float, reader_b_n_per_m: float, reader_m_per_m: float) -> np.ndarray:
    """The bisection memo of the envelopes with this force and design reader, the most recently
    used eight kept: the design reader is the stiff preset, so every device shares one (and
    their envelopes one tree of midpoints)."""
    return limits.new_bisection_memo(ENVELOPE_MEMO_NODES)


@njit(cache=True)
def _envelope_into(out, v_max, pinion_mass_kg, board_mass_kg, gear_efficiency, envelope_force_n, reader_b_n_per_m,
                   reader_m_per_m, push_force_per_a_n, friction_current_a, weight_n, memo):
    """:func:`_envelope` of a configuration's constants written into ``out`` (speeds, then currents):
    the laws of :meth:`SupervisorConfig.drive_force_limit_n` and :meth:`SupervisorConfig.current_for_force_a`
    (:mod:`ebraille_sim.physics.limits`) in one compiled loop; ``memo`` keeps the bisections'
    midpoints (:func:`ebraille_sim.physics.limits.drive_forces_for_impacts_n`)."""
    n = ENVELOPE_POINTS
    energies = np.empty(n - 1)
    for k in range(n - 1):
        v = v_max * k / 32
        out[k] = v
        energies[k] = _impact_energy_j(_pymax(v, 0.0), pinion_mass_kg, board_mass_kg, gear_efficiency)
    forces = np.empty(n - 1)
    limits.drive_forces_for_impacts_n(energies, envelope_force_n, reader_b_n_per_m, reader_m_per_m, forces, memo)
    for k in range(n - 1):
        out[n + k] = _current_for_push_force_a(_pymax(forces[k], 0.0), push_force_per_a_n, 1.0, 1.0,
                                               friction_current_a * push_force_per_a_n, weight_n)
    out[n - 1] = 1.05 * v_max
    out[2 * n - 1] = -friction_current_a


def _envelope_table(c, out: np.ndarray) -> None:
    """Write the envelope of ``c`` into ``out`` (length ``2 * ENVELOPE_POINTS``): speeds, then the
    current limits as the board reads them (:meth:`SupervisorConfig.sensed_limit_a` of the true
    limits :func:`_envelope_into` computes in one compiled call)."""
    _envelope_into(out, c.speed_limit_m_per_s, c.pinion_mass_kg, c.board_mass_kg, c.gear_efficiency,
                   c.envelope_force_n, c.reader_b_n_per_m, c.reader_m_per_m, c.push_force_per_a_n,
                   c.friction_current_a, c.weight_n,
                   _envelope_memo(c.envelope_force_n, c.reader_b_n_per_m, c.reader_m_per_m))
    n = ENVELOPE_POINTS
    out[n:2 * n - 1] = out[n:2 * n - 1] * (1.0 - c.sense_gain_error_max) - c.sense_error_a
