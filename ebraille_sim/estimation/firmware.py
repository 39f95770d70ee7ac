"""The firmware's on-device signal chain, sample by sample between the ADC and the estimator.

At every sensor sample the device's firmware turns the ADC voltage into the input of the
block-oriented estimator (:func:`ebraille_sim.estimation.blockmodels.estimator_step`), in
this order (:func:`ebraille_sim.plant.kernel.advance` calls the functions):

1. **creep compensation** (when on, :func:`creep_compensated_v`): the film's predicted
   creep, the FSR's hereditary law run on the firmware's own estimate, replaced by the
   creep of the calibration hold;
2. **hysteresis compensation** (when on, :func:`hysteresis_compensated_v`): a running
   median (:func:`running_median_v`), a deadband or the turn test (:func:`turn_tested_v`),
   then the inverse of the film's play operators, which puts the voltage back on the
   loading branch the estimator was calibrated on;
3. **tare** (:func:`tared_v`): the no-load voltage measured at start-up subtracted;
4. **anti-alias filter** (:func:`biquad_step`): a second-order section at the sensor rate;

and after the estimator, **the unit's calibration table** (when the bench stored one,
:func:`table_calibrated_n`): the model's estimate mapped onto the known loads it read on the bench.

The firmware assumes the nominal FSR (:data:`FIRMWARE_FSR`), not the individual unit.
Each function advances its own state slots (declared here, composed by
:mod:`ebraille_sim.plant.layout`) in place and allocates nothing, so the kernel inlines it.
"""
from __future__ import annotations

import functools
import math

from ebraille_sim.base.compiled import njit
from ebraille_sim.base.validation import replace_fields
from ebraille_sim.physics.fsr import (F_EPS_N, N_CREEP, N_PLAYS, creep_force, divider_conductance_s, divider_voltage,
                                      inverse_hysteresis, log_force, play)
from ebraille_sim.physics.params import CALIBRATION_TABLE_MAX_POINTS, FSRS

__all__ = [
    "FIRMWARE_FSR", "firmware_fsr", "HYSTERESIS_MEDIAN", "biquad_step", "tared_v", "creep_compensated_v", "running_median_v",
    "turn_tested_v", "centred_x", "hysteresis_compensated_v", "CALIBRATION_TABLE_POINTS", "table_calibrated_n",
]

FIRMWARE_FSR = FSRS["nominal"]
"""The FSR model the estimator's creep and hysteresis compensations assume (the firmware does
not know the individual unit's parameters; the hysteresis compensation takes the unit's
measured loop width, :mod:`ebraille_sim.plant.lumped`)."""

def firmware_fsr(estimator):
    """The film the firmware's creep and hysteresis compensations assume: :data:`FIRMWARE_FSR`,
    with the creep per decade the unit's bench measured where the estimator carries one
    (:class:`~ebraille_sim.physics.params.EstimatorParams` ``creep_per_decade``; None keeps the
    nominal's)."""
    if estimator.creep_per_decade is None:
        return FIRMWARE_FSR
    return _firmware_fsr_with_creep(estimator.creep_per_decade)


@functools.lru_cache(maxsize=64)
def _firmware_fsr_with_creep(creep_per_decade: float):
    """:data:`FIRMWARE_FSR` with the unit's creep per decade, made once per value (a plant's
    packing asks for it once per compensation slot)."""
    return replace_fields(FIRMWARE_FSR, creep_per_decade=creep_per_decade)


ANTIALIAS_SLOTS = ("aa_z1", "aa_z2")
"""State slots of the anti-alias biquad (direct form II transposed)."""

TARE_SLOTS = ("tare_v",)
"""State slot of the no-load voltage subtracted from the input."""

CREEP_COMP_SLOTS = tuple(f"comp_creep_{j}_n" for j in range(N_CREEP))
"""State slots of the firmware's creep prediction: the hereditary terms of its own force
estimate (N), advanced by :func:`ebraille_sim.physics.fsr.creep_force`."""

CALIBRATION_TABLE_POINTS = CALIBRATION_TABLE_MAX_POINTS
"""Most points of a unit's calibration table (:func:`table_calibrated_n`)."""

HYSTERESIS_MEDIAN = 5
"""ADC samples in the hysteresis compensation's running median (odd)."""

HYSTERESIS_COMP_SLOTS = ("comp_hyst_v", "comp_hyst_x") + tuple(f"comp_play_{j}" for j in range(N_PLAYS)) \
    + tuple(f"comp_med_{j}" for j in range(HYSTERESIS_MEDIAN - 1)) + ("comp_turn_dir", "comp_turn_avg_v", "comp_turn_ext_v", "comp_turn_at_v") \
    + ("comp_centre_x",)
"""State slots of the firmware's hysteresis compensation: the voltage after its noise
deadband (V), the last inverted operator input (ln N), its copy of the film's play
operators (ln N), advanced by :func:`ebraille_sim.physics.fsr.inverse_hysteresis`, and the
previous ADC voltages of its running median (V, newest first); with the turn test
(:func:`turn_tested_v`), the direction the voltage is followed in (+1 rising, -1 falling, 0 none
yet), the voltage's exponential average (V), the median's extreme since the last turn (V) and
the median at that turn (V); with the centring (:func:`centred_x`), the input it last gave
(ln N)."""

OWNED_STATE_SLOTS = ANTIALIAS_SLOTS + TARE_SLOTS + CREEP_COMP_SLOTS + HYSTERESIS_COMP_SLOTS
"""Every state slot the firmware's chain declares (see :mod:`ebraille_sim.plant.layout`)."""


@njit(cache=True, inline="always")
def biquad_step(x, s, z1, z2, b0, b1, b2, a1, a2):
    """One sample of a second-order section (DF2T, ``a0 = 1``); ``s[z1]``, ``s[z2]`` advanced."""
    y = b0 * x + s[z1]
    s[z1] = b1 * x - a1 * y + s[z2]
    s[z2] = b2 * x - a2 * y
    return y


@njit(cache=True, inline="always")
def tared_v(v, tare_v):
    """Estimator input: the voltage less the no-load voltage (V)."""
    return v - tare_v


@njit(cache=True, inline="always")
def creep_compensated_v(v, f_est_n, s, z0, p, a0, weight, threshold_n, n_terms, exponent, g_standoff_s,
                        reference_gain, r2_ohm, supply_v, preload):
    """The divider voltage with the predicted creep of the film replaced by the calibration's (V).

    The firmware runs the FSR's hereditary creep law (:func:`ebraille_sim.physics.fsr.creep_force`,
    states ``s[z0:z0+n_terms]``, decays ``p[a0:...]``, term weight ``weight``) on its own
    force estimate ``f_est_n``, which predicts the crept force ``F_c`` and the creep gain
    ``c = F_c / F`` (1 at or below ``threshold_n``).  The measured voltage is turned back
    into the film's conductance (:func:`~ebraille_sim.physics.fsr.divider_conductance_s`),
    its power-law path is scaled by ``(c_ref / c)^n`` (``n`` the conduction exponent,
    ``c_ref = reference_gain`` the creep gain of the hold the divider was calibrated at),
    and the divider law gives the voltage again.  With the sensor's own creep parameters and
    an exact estimate, the result is the voltage the sensor gives after the calibration hold
    at the same force, whatever its load history.  Voltages outside ``(0, supply_v)`` (a
    railed divider or a fault) pass unchanged.

    ``preload`` carries the load the firmware followed before its states start: the film's
    resistance factor, by the same law, of that earlier load continued to now, relative to a
    film loaded from the states' start, minus one (0 for none; negative, as creep lowers the
    resistance).  The conduction path is scaled by ``1 + preload`` besides ``(c_ref / c)^n``:
    the prediction of a firmware that has followed the whole session
    (:class:`ebraille_sim.scenarios.disturbances.FSRDrift`).
    """
    f_c = creep_force(f_est_n, f_est_n, s, z0, p, a0, weight, threshold_n, n_terms)
    if not 0.0 < v < supply_v:
        return v
    gain = f_c / f_est_n if f_est_n > threshold_n else 1.0
    g = divider_conductance_s(v, r2_ohm, supply_v)
    g_u = g_standoff_s + (g - g_standoff_s) * (reference_gain / gain) ** exponent * (1.0 + preload)
    return divider_voltage(g_u, r2_ohm, supply_v)


@njit(cache=True, inline="always")
def running_median_v(v, s, m0):
    """Median of ``v`` and the four voltages before it (``s[m0:m0+4]``, newest first, shifted in
    place): :data:`HYSTERESIS_MEDIAN` = 5 samples, selected by comparisons, nothing allocated.
    A monotone sequence passes delayed by two samples and unchanged in value; a spike of one or
    two samples is removed."""
    a, b, c, d, e = v, s[m0], s[m0 + 1], s[m0 + 2], s[m0 + 3]
    s[m0 + 3] = d
    s[m0 + 2] = c
    s[m0 + 1] = b
    s[m0] = v
    if a > b:
        a, b = b, a
    if c > d:
        c, d = d, c
    if a > c:                      # the smaller of the two pairs' minima is below the median
        a, b, c, d = c, d, a, b
    if b > e:                      # of b, c <= d, e the second smallest is the median of five
        b, e = e, b
    if b > c:
        b, e, c, d = c, d, b, e
    return c if c < e else e


@njit(cache=True, inline="always")
def turn_tested_v(v, vm, s, v0, t0, deadband_v, follow_v, turn_v, turn_alpha):
    """The hysteresis compensation's voltage under the turn test (V): what the inverse operator
    is given in place of the plain deadband's output.

    The plain deadband (a play of half-width ``deadband_v`` on the median) cannot tell a small
    real reversal from noise: the force relaxing by a few percent in a hold moves the voltage
    back by less than its swing of ``2 deadband_v`` and is never read.  Here the voltage is
    followed in one direction at a time (``s[t0]``: +1 rising, -1 falling, 0 not yet known),
    and a move against it is a turn when either

    * the median ``vm`` has moved back by ``2 deadband_v - follow_v`` from the output (the
      plain deadband's swing of ``2 deadband_v`` from the peak), or
    * the exponential average of the ADC voltage ``v`` (``s[t0+1]``, weight ``turn_alpha`` per
      sample, about 0.1 count of noise at 0.4 count per sample) is ``turn_v`` behind the
      median's extreme since the last turn (``s[t0+2]``).  At a standing voltage noise does
      not give this.  A move that outruns the average, a press or a release faster than about
      ``turn_v`` per average time constant, does, within a sample or two: the test takes the
      end of every fast move for a turn.  That is the load's own behaviour: at a standing
      board the pulp relaxes, so the force turns as soon as a press stops, by a few percent,
      which the plain deadband never reads.  A move that goes on is read again once it
      passes the plain swing or outruns the average the other way.

    On a turn the output goes to within ``follow_v`` of the median (no nearer than it was)
    and the turn's voltage is kept (``s[t0+3]``).  A move in the followed direction passes a
    deadband of ``follow_v``: more than ``2 deadband_v`` from the turn the median itself,
    within that the less advanced of the median and the average.  Within that stretch the
    inverse operator is in the film's blind stretch, where any move reads as a large change of
    force; bounding it by the average keeps the noise's extremes from ratcheting the output
    away from the mean (at a standing 1.5 N the estimate is then the plain deadband's to
    3 mN, ``tests/test_sensor_chain.py``).
    """
    a = s[t0 + 1] + turn_alpha * (v - s[t0 + 1])
    s[t0 + 1] = a
    d = s[t0]
    y = s[v0]
    at = s[t0 + 3]
    back = 2.0 * deadband_v - follow_v
    if d >= 0.0:
        ext = vm if vm > s[t0 + 2] or d == 0.0 else s[t0 + 2]
        w = vm if vm > at + 2.0 * deadband_v else min(vm, a)
        if w > y + follow_v:
            y = w - follow_v
            d = 1.0
        elif vm < y - back or (d > 0.0 and a < ext - turn_v):
            y = min(y, vm + follow_v)
            d, ext, at = -1.0, vm, vm
    else:
        ext = vm if vm < s[t0 + 2] else s[t0 + 2]
        w = vm if vm < at - 2.0 * deadband_v else max(vm, a)
        if w < y - follow_v:
            y = w + follow_v
        elif vm > y + back or a > ext + turn_v:
            y = max(y, vm - follow_v)
            d, ext, at = 1.0, vm, vm
    s[t0 + 3] = at
    s[t0] = d
    s[t0 + 2] = ext
    return y


@njit(cache=True, inline="always")
def centred_x(x, moved, s, c0, play0, p, width0, n_plays, centre_alpha):
    """The input the hysteresis compensation reads (ln N): the inverse operator's ``x`` where the
    film last showed a move, relaxing towards the middle of the inputs its plays allow while it
    shows none.

    The plays ``s[play0:...]`` (widths ``p[width0:...]``) admit every input within each play's
    width of its output, ``max(y_j - w_j) .. min(y_j + w_j)``: after a move the exact inverse
    sits at the edge it crossed, and the film's blind stretch of twice the narrowest width
    lies behind it.  On a sample where the inverse moved (``moved``) the input read is the exact
    ``x``; on the others it moves by ``centre_alpha`` of its distance to the middle of that
    stretch (state ``s[c0]``).  An input that stands still in the stretch, or a pulp that
    relaxes inside it, is read half a stretch back rather than at the edge, and the reversal that
    crosses the stretch moves the reading by half of it rather than all of it.
    """
    if moved:
        xo = x
    else:
        lo = s[play0] - p[width0]
        hi = s[play0] + p[width0]
        for j in range(1, n_plays):
            a = s[play0 + j] - p[width0 + j]
            b = s[play0 + j] + p[width0 + j]
            if a > lo:
                lo = a
            if b < hi:
                hi = b
        xo = s[c0] + centre_alpha * (0.5 * (lo + hi) - s[c0])
    s[c0] = xo
    return xo


@njit(cache=True, inline="always")
def hysteresis_compensated_v(v, s, v0, x0, play0, m0, t0, c0, p, width0, weight0, n_plays, log_halfwidth,
                             deadband_v, follow_v, turn_v, turn_alpha, centre_alpha, k_ohm, exponent, g_standoff_s, r2_ohm,
                             supply_v):
    """The divider voltage with the film's hysteresis branch replaced by its loading branch (V).

    The divider is calibrated by pressing monotonically, so the estimator's static map is
    the loading branch of the film's hysteresis (:func:`ebraille_sim.physics.fsr.hysteresis`),
    on which the play operators sit at their lower edges and ``ln(F_eff + F_eps)`` is the
    input less ``log_halfwidth`` (the weighted sum of the widths).  After a reversal the
    film reads on an inner branch, up to ``2 log_halfwidth`` higher.  The firmware inverts
    the operator: the voltage ``v``, after a running median of :data:`HYSTERESIS_MEDIAN`
    samples (:func:`running_median_v`, states ``s[m0:...]``: a single noisy sample is no
    reversal) and a deadband of ``deadband_v`` (state ``s[v0]``: neither is a code toggling
    at a boundary), is turned into the film's conductance (divider inverse), its power-law
    path into a force with the nominal conduction law ``G = F^n / k``, and
    :func:`~ebraille_sim.physics.fsr.inverse_hysteresis` (plays ``s[play0:...]``, last input
    ``s[x0]``) gives the input; the voltage returned is the one the loading branch gives
    for it.  An individual sensor's sensitivity or creep gain enters the log-force as an
    offset that the rate-independent operator carries through, so only the nominal widths
    and exponent matter.  Inside the stretch after a reversal that the film does not show,
    and while the voltage stays within the deadband, the input is held at its last value.
    With ``centre_alpha > 0`` the input read relaxes, while the film shows no move, to the
    middle of the inputs the plays allow (:func:`centred_x`, state ``s[c0]``).  Voltages outside
    ``(0, supply_v)`` pass unchanged.
    """
    if not 0.0 < v < supply_v:
        return v
    vm = running_median_v(v, s, m0)
    if turn_v > 0.0:
        vf = turn_tested_v(v, vm, s, v0, t0, deadband_v, follow_v, turn_v, turn_alpha)
    else:
        vf = play(vm, s[v0], deadband_v)
    x = s[x0]
    moved = vf != s[v0]
    if moved:
        s[v0] = vf
        g_pow = divider_conductance_s(vf, r2_ohm, supply_v) - g_standoff_s
        f = (k_ohm * g_pow) ** (1.0 / exponent) if g_pow > 0.0 else 0.0
        x = inverse_hysteresis(log_force(f), x, s, play0, p, width0, weight0, n_plays)
        s[x0] = x
    if centre_alpha > 0.0:
        x = centred_x(x, moved, s, c0, play0, p, width0, n_plays, centre_alpha)
    f_load = math.exp(x - log_halfwidth) - F_EPS_N
    g_u = g_standoff_s + (f_load ** exponent / k_ohm if f_load > 0.0 else 0.0)
    return divider_voltage(g_u, r2_ohm, supply_v)


@njit(cache=True, inline="always")
def table_calibrated_n(f, p, x0, y0, n):
    """The estimate ``f`` (N) through the unit's calibration table: ``n`` points, the model's
    steady readings ``p[x0:x0+n]`` (ascending, > 0) at the known loads ``p[y0:y0+n]`` (N) of the
    bench (:func:`ebraille_sim.estimation.calibration.calibration_table`).

    Between two points the map is linear; below the first and above the last it is the
    proportional one of that end point (``f`` times its load over its reading), so it passes
    through zero, keeps the sign and stays continuous.  With ``n = 0`` the estimate is returned
    unchanged.  The table corrects what one divider setting cannot: a unit whose conduction
    exponent differs from the one the model was identified on reads a force away from the
    calibration load off by a factor that grows with the distance.
    """
    if n == 0:
        return f
    if f <= p[x0]:
        return f * (p[y0] / p[x0])
    last = n - 1
    if f >= p[x0 + last]:
        return f * (p[y0 + last] / p[x0 + last])
    j = 0
    while f > p[x0 + j + 1]:
        j += 1
    xa, xb = p[x0 + j], p[x0 + j + 1]
    return p[y0 + j] + (p[y0 + j + 1] - p[y0 + j]) * ((f - xa) / (xb - xa))
