"""The wearer's own motion against the supervisor's setpoint cap: the force a strap slip toward a
held board adds to a relaxed contact (:func:`slip_peak_force_n`) and the largest setpoint that
leaves room for it (:func:`slip_setpoint_cap_n`); derivation and numbers in docs/safety.md,
"Body motion".

A slip completes within tens of milliseconds, before the force estimate shows it (the 100 Hz
firmware lags about 40 ms, the 1 kHz firmware with its hysteresis compensation 20-30 ms), and
the non-back-drivable gearhead holds the board without a change of the motor current: no rule
that reads the board's signals can retract in time.  What keeps the force bound is the room
the standing force leaves: the setpoint is capped so that the slip the configuration allows for
(``slip_headroom_m`` over ``slip_time_s``) brings the design reader to ``safe_force_n`` at most.
"""
from __future__ import annotations

import dataclasses
import functools
import math

from ebraille_sim.physics.fingertip import (compression_at_force_m, contact_force, elastic_force, prony_coefficients,
                                            prony_step, relaxed_elastic_force_n)
from ebraille_sim.physics.params import FINGERS


def slip_peak_force_n(force_n: float, slip_m: float, slip_s: float, finger, mesh_stiffness_n_per_m: float = math.inf,
                      h_s: float = 1e-4) -> float:
    """Largest contact force (N) when the pulp of ``finger`` (a
    :class:`~ebraille_sim.physics.params.FingerParams`), fully relaxed at ``force_n`` against a
    held board, is compressed ``slip_m`` further at a constant speed over ``slip_s``; the board
    gives way on the gear mesh (``mesh_stiffness_n_per_m``, in series with the pulp: the rise of
    the force over it, :func:`~ebraille_sim.physics.drivetrain.mesh_force`'s spring).

    The fully relaxed contact is the worst start: it sits on the largest elastic force for its
    contact force (``Fe = F/c0``, the stiffest tangent ``b + m Fe``) and no Prony state is left to
    decay.  The pulp is advanced with its own laws (:mod:`ebraille_sim.physics.fingertip`) in
    steps of ``h_s``; the force peaks at the end of the slip.

    >>> from ebraille_sim.physics.params import FINGERS
    >>> round(slip_peak_force_n(2.6, 0.1e-3, 0.02, FINGERS["stiff"]), 2)
    3.7
    >>> round(slip_peak_force_n(2.6, 0.1e-3, 0.02, FINGERS["stiff"], 3e4), 2)
    3.41
    """
    b, m = finger.stiffness_b_n_per_m, finger.exponent_m_per_m
    c0 = finger.relax_weight_inf
    weights = (finger.relax_weight_1, finger.relax_weight_2, finger.relax_weight_3)
    a, beta = prony_coefficients(h_s, (finger.relax_tau_1_s, finger.relax_tau_2_s, finger.relax_tau_3_s))
    d0 = compression_at_force_m(relaxed_elastic_force_n(force_n, c0), b, m)
    n = max(1, int(math.ceil(slip_s / h_s)))
    h = [0.0, 0.0, 0.0]
    fe_old = elastic_force(d0, b, m)
    peak = force_n
    # the force rises with the compression at the rate (c0 + sum c_i beta_i)(b + m Fe) within a step
    gain = c0 + sum(w * bt for w, bt in zip(weights, beta))
    d = d0
    for k in range(1, n + 1):
        # the compression at which the pulp's force and the mesh's give balance: Newton on a convex,
        # increasing residual (exact without the mesh)
        x = d0 + slip_m * k / n
        for _ in range(8):
            fe = elastic_force(d, b, m)
            hk = [prony_step(h[i], a[i], weights[i], beta[i], fe - fe_old) for i in range(3)]
            r = c0 * fe + hk[0] + hk[1] + hk[2] - force_n - mesh_stiffness_n_per_m * (x - d)
            d -= r / (gain * (b + m * fe) + mesh_stiffness_n_per_m) if math.isfinite(mesh_stiffness_n_per_m) else 0.0
            if not math.isfinite(mesh_stiffness_n_per_m):
                d = x
        fe = elastic_force(d, b, m)
        h = [prony_step(h[i], a[i], weights[i], beta[i], fe - fe_old) for i in range(3)]
        fe_old = fe
        peak = max(peak, contact_force(d, fe, c0, h[0], h[1], h[2]))
    return peak


def slip_setpoint_cap_n(safe_force_n: float, slip_m: float, slip_s: float, finger,
                        mesh_stiffness_n_per_m: float = math.inf) -> float:
    """Largest standing force (N) whose :func:`slip_peak_force_n` stays at ``safe_force_n``
    (bisection to 1 mN; 0 when even a vanishing force exceeds it)."""
    lo, hi = 0.0, safe_force_n
    if slip_peak_force_n(0.0, slip_m, slip_s, finger, mesh_stiffness_n_per_m) > safe_force_n:
        return 0.0
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        if slip_peak_force_n(mid, slip_m, slip_s, finger, mesh_stiffness_n_per_m) <= safe_force_n:
            lo = mid
        else:
            hi = mid
    return lo


@functools.lru_cache(maxsize=64)
def design_slip_cap_n(safe_force_n: float, slip_m: float, slip_s: float, reader_b_n_per_m: float,
                      reader_m_per_m: float, mesh_stiffness_n_per_m: float) -> float:
    """:func:`slip_setpoint_cap_n` on the design reader: the elastic constants the supervisor's
    impact bound assumes (the stiffer of the device's reader and the stiff preset) with the stiff
    preset's relaxation; computed once per set of arguments (most drawn devices share them)."""
    finger = dataclasses.replace(FINGERS["stiff"], stiffness_b_n_per_m=reader_b_n_per_m,
                                 exponent_m_per_m=reader_m_per_m)
    return slip_setpoint_cap_n(safe_force_n, slip_m, slip_s, finger, mesh_stiffness_n_per_m)
