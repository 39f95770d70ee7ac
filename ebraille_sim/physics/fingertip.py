"""Fingertip pulp under a flat board: exponential elasticity with QLV relaxation.

Instantaneous elastic law (Serina et al. 1997; Pawluk & Howe 1999)::

    Fe(d) = (b/m) (exp(m d) - 1),   d > 0 (compression), else 0
    dFe/dd = b + m Fe          (stiffness grows linearly with force)

Quasi-linear viscoelasticity (Fung; Pawluk & Howe 1999) with the reduced relaxation
function ``G(t) = c0 + sum_i c_i exp(-t/tau_i)`` (tau = 4 ms, 70 ms, 1.4 s)::

    F(t) = c0 Fe(t) + sum_i h_i(t),     dh_i/dt = -h_i/tau_i + c_i dFe/dt

(:func:`prony_rate_n_per_s`, the form the loop analysis linearises).

Small-signal stiffness about a relaxed contact force ``F`` (Fe = F/c0, all h_i = 0)::

    K(jw) = (b + m F/c0) G*(jw),   G*(jw) = c0 + sum_i c_i jw tau_i / (1 + jw tau_i)

(:func:`dynamic_stiffness_n_per_m`): ``c0 (b + m F/c0)`` slowly, ``b + m F/c0`` for an
instant change; a loop sees ``|K|`` at its crossover.
Each Prony state is advanced exactly for ``Fe`` varying linearly over a step ``h``::

    h_i <- a_i h_i + c_i beta_i (Fe_new - Fe_old),  a_i = exp(-h/tau_i),
    beta_i = (tau_i/h)(1 - a_i)

A step in compression gives the full instantaneous force ``Fe`` that relaxes to
``c0 Fe``.  Contact can only push: the force is clipped at zero and is zero whenever the
board is below the pulp surface (the pulp then recovers through the decaying h_i).
"""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit

STATE_SLOTS = ("prony_1_n", "prony_2_n", "prony_3_n", "elastic_force_n", "contact_force_n")
"""State slots of the pulp: the three Prony states, the instantaneous elastic force and the
contact force (see :mod:`ebraille_sim.plant.layout`)."""

OWNED_STATE_SLOTS = STATE_SLOTS
"""Every state slot this module declares."""


@njit(cache=True, inline="always")
def compression_m(board_pos_m, finger_pos_m):
    """Pulp compression (m): how far the board has risen past the pulp surface."""
    return board_pos_m - finger_pos_m


_LN2 = math.log(2.0)


@njit(cache=True, inline="always")
def exp_minus_one(x):
    """``exp(x) - 1`` within 2 ulp: ``math.exp(x) - 1`` where ``exp(x) >= 2`` (the subtraction is
    exact there, and the result at least half of ``exp(x)``), ``math.expm1`` below, where the
    subtraction would cancel.  The C library's ``exp`` takes a third to a half of the time of its
    ``expm1`` (glibc, 2.9-3.2 against 7.8-10.5 ns a call: ``python benchmarks/bench_kernel.py``),
    and the pulp law runs at every physics step."""
    if x >= _LN2:
        return math.exp(x) - 1.0
    return math.expm1(x)


@njit(cache=True, inline="always")
def elastic_force(d_m, b_n_per_m, m_per_m):
    """Instantaneous elastic force (N) at compression ``d_m`` (m)."""
    if d_m <= 0.0:
        return 0.0
    return b_n_per_m / m_per_m * exp_minus_one(m_per_m * d_m)


@njit(cache=True, inline="always")
def compression_at_force_m(elastic_force_n, b_n_per_m, m_per_m):
    """Inverse of :func:`elastic_force`: compression (m) at which the elastic force is ``Fe``."""
    return math.log1p(m_per_m * elastic_force_n / b_n_per_m) / m_per_m


@njit(cache=True, inline="always")
def relaxed_elastic_force_n(contact_force_n, c0):
    """Elastic force ``Fe = F/c0`` under which a fully relaxed contact pushes with ``F``."""
    return contact_force_n / c0


@njit(cache=True, inline="always")
def prony_step(h_n, a, c, beta, d_elastic_force_n):
    """One exact step of a Prony state: ``h <- a h + c beta (Fe_new - Fe_old)`` (N)."""
    return a * h_n + c * beta * d_elastic_force_n


def prony_rate_n_per_s(h_n, tau_s, c, elastic_force_rate_n_per_s):
    """The Prony ODE in continuous time, ``dh/dt = -h/tau + c dFe/dt`` (N/s).

    :func:`prony_step` is its exact solution over a step with ``Fe`` varying linearly.  The
    law is linear in ``(h, dFe/dt)``: its partial derivatives are its values on unit inputs
    (``-1/tau`` and ``c``), which is how the loop analysis's Jacobian takes them.
    """
    return -h_n / tau_s + c * elastic_force_rate_n_per_s


@njit(cache=True, inline="always")
def contact_force(d_m, elastic_force_n, c0, h1_n, h2_n, h3_n):
    """QLV contact force ``c0 Fe + h1 + h2 + h3`` (N), zero off the pulp or when it would pull."""
    f = c0 * elastic_force_n + h1_n + h2_n + h3_n
    if d_m <= 0.0 or f < 0.0:
        return 0.0
    return f


@njit(cache=True, inline="always")
def tangent_stiffness_n_per_m(elastic_force_n, b_n_per_m, m_per_m):
    """Tangent stiffness ``dFe/dd = b + m Fe`` (N/m) of the elastic law at force ``Fe``.

    At a relaxed contact force ``F`` the pulp sits on ``Fe = F/c0``; pass that force to get
    the stiffness a slow force change sees through the instantaneous law.
    """
    return b_n_per_m + m_per_m * elastic_force_n


def prony_coefficients(h_s: float, taus_s) -> tuple[list[float], list[float]]:
    """Exact ramp-invariant decay ``a_i`` and input weights ``beta_i`` for step ``h_s``."""
    a = [math.exp(-h_s / t) for t in taus_s]
    beta = [t / h_s * (1.0 - ai) for t, ai in zip(taus_s, a)]
    return a, beta


def relaxation_function(t_s, finger) -> "numpy.ndarray":
    """Reduced relaxation function G(t) of a :class:`~ebraille_sim.physics.params.FingerParams`."""
    import numpy as np
    t = np.asarray(t_s, dtype=float)
    return (finger.relax_weight_inf
            + finger.relax_weight_1 * np.exp(-t / finger.relax_tau_1_s)
            + finger.relax_weight_2 * np.exp(-t / finger.relax_tau_2_s)
            + finger.relax_weight_3 * np.exp(-t / finger.relax_tau_3_s))


def tap_dissipated_fraction(finger, duration_s: float = 0.1, peak_force_n: float = 2.0, h_s: float = 1e-4) -> float:
    """Fraction of the work done on the pulp that a tap dissipates (-).

    The tap is a half-sine compression lasting ``duration_s`` whose peak gives the
    instantaneous elastic force ``peak_force_n``; the pulp is advanced with the loop's own
    laws (:func:`elastic_force`, :func:`prony_step`, :func:`contact_force`).  The work put
    in while compressing is ``W_in = int F dd`` over the loading half, the work returned
    ``W_out`` over the unloading half; the result is ``1 - W_out/W_in`` (Jindrich et al.
    2003 measured 81 % for voluntary taps).
    """
    b, m = finger.stiffness_b_n_per_m, finger.exponent_m_per_m
    d_peak = compression_at_force_m(peak_force_n, b, m)
    taus = (finger.relax_tau_1_s, finger.relax_tau_2_s, finger.relax_tau_3_s)
    cs = (finger.relax_weight_1, finger.relax_weight_2, finger.relax_weight_3)
    a, beta = prony_coefficients(h_s, taus)
    n = int(round(duration_s / h_s))
    h = [0.0, 0.0, 0.0]
    fe_old, d_old, f_old = 0.0, 0.0, 0.0
    w_in = w_out = 0.0
    for k in range(1, n + 1):
        d = d_peak * math.sin(math.pi * k / n)
        fe = elastic_force(d, b, m)
        h = [prony_step(h[i], a[i], cs[i], beta[i], fe - fe_old) for i in range(3)]
        f = contact_force(d, fe, finger.relax_weight_inf, h[0], h[1], h[2])
        work = 0.5 * (f + f_old) * (d - d_old)
        if k <= n // 2:
            w_in += work
        else:
            w_out -= work
        fe_old, d_old, f_old = fe, d, f
    return 1.0 - w_out / w_in


def complex_relaxation(finger, frequency_hz: float) -> complex:
    """``G*(jw) = c0 + sum_i c_i jw tau_i / (1 + jw tau_i)`` at ``frequency_hz`` (-).

    The Fourier form of the reduced relaxation function (:func:`relaxation_function`): the
    force answer to a small sinusoidal change of the elastic force about a relaxed state.
    ``G*(0) = c0``; ``G*(inf) = 1``.
    """
    jw = 2j * math.pi * float(frequency_hz)
    g = complex(finger.relax_weight_inf)
    for c, tau in ((finger.relax_weight_1, finger.relax_tau_1_s), (finger.relax_weight_2, finger.relax_tau_2_s),
                   (finger.relax_weight_3, finger.relax_tau_3_s)):
        g += c * jw * tau / (1.0 + jw * tau)
    return g


def dynamic_stiffness_n_per_m(finger, force_n: float, frequency_hz: float) -> float:
    """Magnitude of the pulp's small-signal stiffness at a relaxed contact force, N/m.

    ``|K(jw)| = (b + m F/c0) |G*(jw)|`` (module docstring): the stiffness a loop sees at
    ``frequency_hz`` about a contact force ``force_n`` held long enough to relax (the elastic
    force sits at ``F/c0``).  0 Hz gives the relaxed stiffness ``c0 (b + m F/c0)``; a high
    frequency the instantaneous tangent stiffness ``b + m F/c0``.
    """
    k_inst = tangent_stiffness_n_per_m(relaxed_elastic_force_n(float(force_n), finger.relax_weight_inf),
                                       finger.stiffness_b_n_per_m, finger.exponent_m_per_m)
    return k_inst * abs(complex_relaxation(finger, frequency_hz))


def ramp_compression_at_force_m(finger, force_n: float, speed_m_per_s: float, step_m: float = 1e-6) -> float:
    """Compression (m) at which a constant-speed ramp from first contact reaches ``force_n``.

    The board advances into an unloaded pulp at ``speed_m_per_s`` (a ramp-and-hold
    indentation's ramp); the pulp is advanced with the loop's own laws
    (:func:`elastic_force`, :func:`prony_step`, :func:`contact_force`) in steps of
    ``step_m`` of compression, and the crossing is interpolated linearly between steps.
    """
    if not (force_n > 0.0 and speed_m_per_s > 0.0 and step_m > 0.0):
        raise ValueError(f"ramp_compression_at_force_m needs force_n, speed_m_per_s and step_m > 0, "
                         f"got {force_n}, {speed_m_per_s}, {step_m}")
    b, m = finger.stiffness_b_n_per_m, finger.exponent_m_per_m
    taus = (finger.relax_tau_1_s, finger.relax_tau_2_s, finger.relax_tau_3_s)
    cs = (finger.relax_weight_1, finger.relax_weight_2, finger.relax_weight_3)
    a, beta = prony_coefficients(step_m / speed_m_per_s, taus)
    h = [0.0, 0.0, 0.0]
    fe_old, f_old, d = 0.0, 0.0, 0.0
    d_max = compression_at_force_m(relaxed_elastic_force_n(float(force_n), finger.relax_weight_inf), b, m)
    while d <= d_max + step_m:
        d += step_m
        fe = elastic_force(d, b, m)
        h = [prony_step(h[i], a[i], cs[i], beta[i], fe - fe_old) for i in range(3)]
        f = contact_force(d, fe, finger.relax_weight_inf, h[0], h[1], h[2])
        if f >= force_n:
            return d - step_m * (f - force_n) / (f - f_old)
        fe_old, f_old = fe, f
    raise ValueError(f"a ramp at {speed_m_per_s} m/s does not reach {force_n} N")  # pragma: no cover
