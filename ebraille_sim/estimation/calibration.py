"""Calibration of the simulated divider against an estimator model, and its static error.

The paper's Wiener estimator was identified on the paper's own FSR, fixture and divider,
with detrended signals (no-load offsets removed).  The simulated device uses the nominal
FSR 402 power law; for the paper's model to read it, the divider must be set the way a
technician would set the device's potentiometer R2 (adjustable 1-20 kOhm in the paper):

*Calibration protocol.*  The FSR is pressed from zero to a hold force and held, as in the
paper's static test; the estimator reads the tared, noise-free divider voltage on that
loading branch with the creep reached after ``hold_s``; R2 minimises the mean squared
relative error of the steady estimate over the hold forces (default 0.5-2 N, the reading
range) and hold times (default 5, 20 and 60 s).

The remaining error is real and the controller lives with it: it is reported by
:func:`static_error_table` and measured in closed loop as ``estimate_rmse_n``.

Examples
--------
>>> from ebraille_sim.estimation.paper_models import paper_model
>>> from ebraille_sim.physics.params import FSRS, CircuitParams
>>> r2 = calibrate_r2(paper_model("wiener", 5), FSRS["nominal"], CircuitParams())
>>> 1000 < r2 < 1600
True
"""
from __future__ import annotations

import dataclasses
import functools
import math
from typing import TYPE_CHECKING

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.base.seeds import default_rng
from ebraille_sim.base.validation import check_number, replace_fields
from ebraille_sim.estimation.registry import cached_model
from ebraille_sim.physics.fsr import (adc_code, adc_voltage, divider_conductance_s, divider_voltage, interp_point,
                                      play_widths, static_conductance)

if TYPE_CHECKING:
    from ebraille_sim.physics.params import DeviceParams

DEFAULT_FORCES_N = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0)
DEFAULT_HOLDS_S = (5.0, 20.0, 60.0)


@functools.lru_cache(maxsize=64)
def loading_branch_factor(fsr) -> float:
    """Force seen by the conduction law on the loading branch, as a fraction of the force.

    After a monotone press from zero every play operator of the hysteresis model
    (:func:`ebraille_sim.physics.fsr.hysteresis`) sits at its lower edge, so
    ``F_eff + F_eps = (F + F_eps) exp(-sum_j weight_j width_j)``; for ``F >> F_eps`` (1 mN)
    that is ``F_eff = F exp(-sum_j weight_j width_j)``.  Remembered per unit (a unit's bench
    asks for it three times).
    """
    widths, weights = play_widths(fsr)
    return math.exp(-sum(w * r for w, r in zip(weights, widths)))


@functools.lru_cache(maxsize=256)
def measured_hysteresis_fraction(fsr, force_n: float = 1.0, peak_n: float = 2.0, steps: int = 400) -> float:
    """The unit's hysteresis as an assembly check measures it: ``(R_F+ - R_F-)/R_F+`` at ``force_n``.

    The film is pressed from zero to ``force_n`` (``R_F+``, the loading branch), on to
    ``peak_n`` and let down to ``force_n`` again (``R_F-``), slowly (``steps`` force points a
    leg) and without creep, through the plant's own hysteresis and conduction laws
    (:func:`ebraille_sim.physics.fsr.hysteresis`, :func:`ebraille_sim.physics.fsr.conductance_s`);
    the stand-off path is left out, as a measurement at 1 N would subtract it.  For the play
    model the result is the unit's rate-independent loop
    (:func:`ebraille_sim.physics.fsr.play_loop_fraction`: its datasheet ``hysteresis_fraction``
    less the creep's share) up to the 1 mN offset of its log.
    """
    from ebraille_sim.physics.fsr import N_PLAYS, conductance_s, hysteresis, log_force
    widths, weights = play_widths(fsr)
    p = np.array(list(widths) + list(weights))
    s = np.full(N_PLAYS, log_force(0.0))

    def g(f_eff):
        return conductance_s(f_eff, fsr.resistance_at_1n_ohm, fsr.exponent, 0.0, 1.0, fsr.actuation_force_n,
                             fsr.turn_on_steepness)

    for f in np.linspace(0.0, force_n, steps):
        f_eff = hysteresis(float(f), s, 0, p, 0, N_PLAYS, N_PLAYS)
    g_load = g(f_eff)
    for f in np.concatenate([np.linspace(force_n, peak_n, steps), np.linspace(peak_n, force_n, steps)]):
        f_eff = hysteresis(float(f), s, 0, p, 0, N_PLAYS, N_PLAYS)
    return 1.0 - g_load / g(f_eff)


def loading_voltage(force_n: float, fsr, circuit, hold_s: float) -> float:
    """Noise-free divider voltage after pressing to ``force_n`` and holding ``hold_s``.

    The conduction, creep and divider laws are those of the compiled loop
    (:func:`ebraille_sim.physics.fsr.static_conductance`,
    :func:`ebraille_sim.physics.fsr.divider_voltage`).
    """
    f_eff = force_n * loading_branch_factor(fsr)
    return divider_voltage(static_conductance(f_eff, fsr, load_time_s=hold_s), circuit.r2_ohm, circuit.supply_v)


def _tare(fsr, circuit) -> float:
    """The no-load voltage as the ADC reads it (V), the tare of the estimator's input."""
    v0 = divider_voltage(static_conductance(0.0, fsr), circuit.r2_ohm, circuit.supply_v)
    return adc_voltage(adc_code(v0, circuit.adc_lsb_v, circuit.adc_max_code), circuit.adc_lsb_v)


def steady_estimate(model, force_n: float, fsr, circuit, hold_s: float) -> float:
    """The estimator's steady output for a held force (N)."""
    u = loading_voltage(force_n, fsr, circuit, hold_s) - _tare(fsr, circuit)
    return float(model.steady_state(u))


def calibrate_r2(model, fsr, circuit, forces_n=DEFAULT_FORCES_N, holds_s=DEFAULT_HOLDS_S,
                 r2_range_ohm=(1000.0, 20000.0)) -> float:
    """R2 (ohm) that makes ``model`` read ``fsr`` best under the calibration protocol."""
    import scipy.optimize

    def cost(log_r2):
        c = dataclasses.replace(circuit, r2_ohm=math.exp(log_r2))
        err = [(steady_estimate(model, f, fsr, c, h) - f) / f for f in forces_n for h in holds_s]
        return float(np.mean(np.square(err)))

    lo, hi = (math.log(x) for x in r2_range_ohm)
    res = scipy.optimize.minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                                         options={"xatol": 1e-6})
    return float(math.exp(res.x))


def static_error_table(model, fsr, circuit, forces_n=(0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0),
                       holds_s=(1.0, 60.0, 1800.0)) -> list[dict]:
    """Relative steady error of the estimate at each force and hold time (rows of dicts)."""
    rows = []
    for f in forces_n:
        row = {"force_n": f}
        for h in holds_s:
            row[f"rel_error_at_{h:g}s"] = (steady_estimate(model, f, fsr, circuit, h) - f) / f
        rows.append(row)
    return rows


@njit(cache=True)
def _pwl_at(x, xs, ys, s0, sn):
    """A nonlinearity of :func:`_steady_map` at ``x``: the breakpoints ``xs``, ``ys`` (none: the
    identity), extended beyond them with the end slopes ``s0`` and ``sn``."""
    n = xs.shape[0]
    if n == 0:
        return x
    if x < xs[0]:
        return ys[0] + s0 * (x - xs[0])
    if x > xs[n - 1]:
        return ys[n - 1] + sn * (x - xs[n - 1])
    return interp_point(x, xs, ys)


@njit(cache=True)
def _steady_at(u, g, in_x, in_y, in_s0, in_sn, out_x, out_y, out_s0, out_sn):
    """``model.steady_state(u)`` from :func:`_steady_map`'s table: ``output_nl(g input_nl(u))``."""
    return _pwl_at(g * _pwl_at(u, in_x, in_y, in_s0, in_sn), out_x, out_y, out_s0, out_sn)


def _steady_map(model):
    """The table of the scalar map ``u -> model.steady_state(u)`` for :func:`_steady_at`: the
    linear block's gain and the nonlinearities' breakpoints and end slopes, read once (the
    same floating-point operations, so the same numbers); None where the gain is not finite
    (the model's own map then raises)."""
    g = model.linear.steady_state_gain()
    if not math.isfinite(g):
        return None

    def pwl(nl):
        if nl is None:
            return np.zeros(0), np.zeros(0), 0.0, 0.0
        xb = np.ascontiguousarray(nl.x_bp, dtype=float)
        yb = np.ascontiguousarray(nl.y_bp, dtype=float)
        slopes = nl.segment_slopes()
        return xb, yb, float(slopes[0]), float(slopes[-1])

    return (float(g),) + pwl(model.input_nl) + pwl(model.output_nl)


@functools.lru_cache(maxsize=8)
def _steady_map_of(spec: str):
    return _steady_map(cached_model(spec))


_BRENT_XTOL = 1e-6
_BRENT_RTOL = 4 * float(np.finfo(float).eps)
_BRENT_MAXITER = 100


@njit(cache=True)
def _r2_error(log_r2, g_zero, g_load, supply, lsb, max_code, force_n, table):
    """Estimate minus ``force_n`` of the calibration protocol at ``R2 = exp(log_r2)``."""
    r2 = math.exp(log_r2)
    v0 = divider_voltage(g_zero, r2, supply)
    tare = adc_voltage(adc_code(v0, lsb, max_code), lsb)
    return _steady_at(divider_voltage(g_load, r2, supply) - tare, *table) - force_n


@njit(cache=True)
def _r2_root(lo, hi, g_zero, g_load, supply, lsb, max_code, force_n, table):
    """The root in ``[lo, hi]`` of :func:`_r2_error` by Brent's method, the operations of SciPy's
    ``brentq`` (its C routine, with ``xtol`` :data:`_BRENT_XTOL` and SciPy's default ``rtol``
    and iteration bound), so the same iterates.

    Returns ``(x, status)``: status 0 converged, 1 no sign change at the ends (no root in
    the bracket), 2 a NaN error at ``x``, 3 not converged.
    """
    xtol, rtol = _BRENT_XTOL, _BRENT_RTOL
    xpre, xcur = lo, hi
    xblk = fblk = spre = scur = 0.0
    fpre = _r2_error(xpre, g_zero, g_load, supply, lsb, max_code, force_n, table)
    if fpre != fpre:
        return xpre, 2
    fcur = _r2_error(xcur, g_zero, g_load, supply, lsb, max_code, force_n, table)
    if fcur != fcur:
        return xcur, 2
    if fpre * fcur > 0:
        return 0.0, 1
    if fpre == 0:
        return xpre, 0
    if fcur == 0:
        return xcur, 0
    for _ in range(_BRENT_MAXITER):
        if fpre * fcur < 0:
            xblk = xpre
            fblk = fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre = xcur
            xcur = xblk
            xblk = xpre
            fpre = fcur
            fcur = fblk
            fblk = fpre
        delta = (xtol + rtol * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0 or abs(sbis) < delta:
            return xcur, 0
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:
                stry = -fcur * (xcur - xpre) / (fcur - fpre)          # interpolate
            else:
                dpre = (fpre - fcur) / (xpre - xcur)                   # extrapolate
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            bound = 3 * abs(sbis) - delta
            if 2 * abs(stry) < (abs(spre) if abs(spre) < bound else bound):
                spre = scur                                            # good short step
                scur = stry
            else:
                spre = sbis                                            # bisect
                scur = sbis
        else:
            spre = sbis                                                # bisect
            scur = sbis
        xpre = xcur
        fpre = fcur
        if abs(scur) > delta:
            xcur += scur
        else:
            xcur += delta if sbis > 0 else -delta
        fcur = _r2_error(xcur, g_zero, g_load, supply, lsb, max_code, force_n, table)
        if fcur != fcur:
            return xcur, 2
    return xcur, 3


@functools.lru_cache(maxsize=4096)
def _calibrated_r2(spec: str, fsr, circuit, force_n: float, hold_s: float, load_n: float) -> float | None:
    """R2 (ohm) of :func:`calibrate_device` for one estimator, FSR unit and divider; None when
    no R2 in [500, 50 000] ohm reads ``force_n`` exactly while the film carries ``load_n``.
    Cached: the parameters are frozen.
    The protocol's error and Brent's method run in one compiled call (:func:`_r2_root`)."""
    table = _steady_map_of(spec)
    if table is None:
        cached_model(spec).steady_state(0.0)      # raises as the model does
    # the calibration protocol's voltages with every R2-independent factor computed once
    g_load = static_conductance(load_n * loading_branch_factor(fsr), fsr, load_time_s=hold_s)
    g_zero = static_conductance(0.0, fsr)
    lo, hi = math.log(500.0), math.log(50000.0)
    x, status = _r2_root(lo, hi, g_zero, g_load, circuit.supply_v, circuit.adc_lsb_v, circuit.adc_max_code,
                         force_n, table)
    if status == 1:
        return None
    if status == 2:
        raise ValueError(f"The function value at x={x} is NaN; solver cannot continue.")
    if status == 3:
        raise RuntimeError(f"Failed to converge after {_BRENT_MAXITER} iterations, value is {x}.")
    return math.exp(x)


def calibrate_device(device: DeviceParams, force_n: float = 1.0, hold_s: float = 20.0,
                     load_error: float = 0.0) -> DeviceParams:
    """Set R2 so that the device's estimator reads ``force_n`` after a press and hold of the
    known load.

    One-point assembly calibration (the estimator is fixed; the potentiometer is turned):
    solved by Brent's method on ln R2 in [ln 500, ln 50 000] ohm.  The load is known to its
    tolerance only: the film carries ``force_n (1 + load_error)`` while the technician sets the
    reading to ``force_n``, so a unit's estimate is off by that error from then on.  The result
    depends only on the estimator, the FSR unit, the divider and the load and is cached per
    combination, so drawing the same unit again costs a dictionary look-up.
    """
    load_error = check_number("calibration load_error", load_error, lo=-0.5, hi=0.5)
    r2 = _calibrated_r2(device.estimator.model, device.fsr, device.circuit, float(force_n), float(hold_s),
                        float(force_n) * (1.0 + load_error))
    if r2 is None:
        return device
    return replace_fields(device, circuit=replace_fields(device.circuit, r2_ohm=r2))


def calibrate_device_reference(device: DeviceParams, force_n: float = 1.0, hold_s: float = 20.0,
                               load_error: float = 0.0) -> DeviceParams:
    """:func:`calibrate_device` through :func:`steady_estimate` at every iterate, uncached
    (the protocol as written; the cached path must give the same R2 to the last bit)."""
    import scipy.optimize
    model = cached_model(device.estimator.model)
    fsr, circuit = device.fsr, device.circuit

    def err(log_r2):
        c = dataclasses.replace(circuit, r2_ohm=math.exp(log_r2))
        return steady_estimate(model, force_n * (1.0 + load_error), fsr, c, hold_s) - force_n

    lo, hi = math.log(500.0), math.log(50000.0)
    if err(lo) * err(hi) > 0:
        return device
    log_r2 = scipy.optimize.brentq(err, lo, hi, xtol=1e-6)
    return dataclasses.replace(device, circuit=dataclasses.replace(circuit, r2_ohm=math.exp(log_r2)))


# ---- the unit's calibration table ---------------------------------------------------------------

TABLE_LOADS_N = (0.5, 1.0, 1.5, 2.0)
"""Known loads of the calibration table, N [E]: the reading range of the paper's tactile forces
(0.5-2 N) in four weights, the divider's own 1 N among them."""

TABLE_PRESSES = 5
"""Presses of each table load, averaged [E]: the film's press-to-press repeatability (2 %) is a
new draw at every press, so the mean of five has a fifth of its variance."""

TABLE_HOLD_S = 20.0
"""Hold of every table press before the reading, s [E]: that of the divider's calibration (the
creep compensation's reference hold)."""

TABLE_CONVERSIONS = 256
"""ADC conversions averaged for each table reading [E] (as the drive's calibration averages its
current, :data:`CALIBRATION_CONVERSIONS`): the divider's noise (0.4 LSB) dithers the
quantisation, so the mean is the voltage to ``noise / 16``."""


@functools.lru_cache(maxsize=64)
def _fsr_unit_seed(fsr, circuit) -> int:
    """The noise of a unit's table: a fixed function of its FSR unit and divider (the bench ran
    once; its press scatter and conversion noise are the unit's, not the session's)."""
    import zlib
    return zlib.crc32(repr((fsr, circuit)).encode()) % (1 << 31)


def table_reading_n(model, force_n: float, fsr, circuit, hold_s: float, press_z=0.0, noise_v=0.0):
    """The model's steady estimate on the bench (N): the film pressed from no load to ``force_n``
    (loading branch) and held ``hold_s``, its resistance scaled by the press's scatter
    ``exp(press_repeatability * press_z)`` (:func:`ebraille_sim.physics.fsr.press_scatter`), the
    divider voltage read with the error ``noise_v`` of the conversions' mean, tared by the
    no-load reading (:func:`steady_estimate` with the press and the noise).  ``force_n``,
    ``press_z`` and ``noise_v`` may be arrays that broadcast together (one reading each, an
    array back; e.g. a column of loads against a table of their presses)."""
    branch = loading_branch_factor(fsr)
    forces = np.asarray(force_n, dtype=float)
    g = np.array([static_conductance(f * branch, fsr, load_time_s=hold_s) for f in forces.ravel()]).reshape(forces.shape)
    g_standoff = 1.0 / fsr.standoff_resistance_ohm
    z, e = np.asarray(press_z, dtype=float), np.asarray(noise_v, dtype=float)
    g = g_standoff + (g - g_standoff) / np.exp(fsr.press_repeatability * z)
    u = divider_voltage(g, circuit.r2_ohm, circuit.supply_v) + e - _tare(fsr, circuit)
    y = model.steady_state(u)
    return float(y) if np.ndim(y) == 0 else np.asarray(y, dtype=float)


@njit(cache=True)
def _table_presses(g_load, scatter, draws, sd_v, g_standoff_s, r2_ohm, supply_v, tare_v, g, in_x, in_y, in_s0, in_sn,
                   out_x, out_y, out_s0, out_sn):
    """The readings of :func:`calibration_table`'s presses (one row a load): :func:`table_reading_n`
    of the film's conductance ``g_load`` of each load, each press's resistance scaled by its
    ``scatter`` (the stand-off path kept), the divider's voltage with the conversions' noise
    ``sd_v * draws[..., 1]``, tared, through :func:`_steady_map`'s table (the operations of
    NumPy's broadcasts and of the model's map, element by element: the same numbers)."""
    out = np.empty(scatter.shape)
    for i in range(scatter.shape[0]):
        for k in range(scatter.shape[1]):
            gk = g_standoff_s + (g_load[i] - g_standoff_s) / scatter[i, k]                    # plant truth
            u = divider_voltage(gk, r2_ohm, supply_v) + sd_v * draws[i, k, 1] - tare_v
            out[i, k] = _steady_at(u, g, in_x, in_y, in_s0, in_sn, out_x, out_y, out_s0, out_sn)
    return out


def calibration_table(device: DeviceParams, loads_n=TABLE_LOADS_N, load_errors=None,
                      anchor_n: float | None = 1.0) -> tuple | None:
    """The bench's calibration table of ``device`` (its divider already set): ``(loads, readings)``,
    or None when the readings do not rise with the load (no table can be stored).

    Each known load of ``loads_n`` is pressed :data:`TABLE_PRESSES` times from no load and held
    :data:`TABLE_HOLD_S`; each press reads the model's steady estimate from the mean of
    :data:`TABLE_CONVERSIONS` conversions (:func:`table_reading_n`), and the readings of a load are
    averaged.  The film carries ``load (1 + error)`` (``load_errors``, one a load, the fixture's
    placement; default none) while the bench stores the nominal load; each press draws its own
    scatter and each reading its own conversion noise from the unit's seed
    (:func:`_fsr_unit_seed`).  Nothing of the unit but its readings reaches the table.

    With ``anchor_n`` (default 1 N, the divider's load) the readings are scaled so that the load
    nearest it reads itself: the divider's calibration keeps the level it set there and the table
    corrects the shape (the readings' ratios), so the presses' scatter of that one load does not
    move the level of every force.  None keeps the readings as read.

    >>> from ebraille_sim.physics.params import DeviceParams
    >>> loads, reads = calibration_table(calibrate_device(DeviceParams()))
    >>> loads, [round(r, 3) for r in reads]
    ((0.5, 1.0, 1.5, 2.0), [0.571, 1.0, 1.453, 1.996])
    """
    errors = (0.0,) * len(loads_n) if load_errors is None else tuple(load_errors)
    if len(errors) != len(loads_n):
        raise ValueError(f"calibration_table: {len(errors)} load errors for {len(loads_n)} loads")
    fsr, circuit = device.fsr, device.circuit
    rng = default_rng(_fsr_unit_seed(fsr, circuit))
    sd_v = fsr.noise_v_rms / math.sqrt(TABLE_CONVERSIONS)
    draws = rng.standard_normal((len(loads_n), TABLE_PRESSES, 2))   # each press: its scatter, then its noise
    carried = [load * (1.0 + err) for load, err in zip(loads_n, errors)]
    steady = _steady_map_of(device.estimator.model)
    if steady is None:                            # the model's own map (it raises)
        presses = table_reading_n(cached_model(device.estimator.model), np.array([[c] for c in carried]), fsr, circuit,
                                  TABLE_HOLD_S, press_z=draws[..., 0], noise_v=sd_v * draws[..., 1])
    else:                                         # table_reading_n of every press in one compiled call
        branch = loading_branch_factor(fsr)
        g_load = np.array([static_conductance(c * branch, fsr, load_time_s=TABLE_HOLD_S) for c in carried])
        presses = _table_presses(g_load, np.exp(fsr.press_repeatability * draws[..., 0]), draws, sd_v,
                                 1.0 / fsr.standoff_resistance_ohm, circuit.r2_ohm, circuit.supply_v,
                                 _tare(fsr, circuit), *steady)
    readings = presses.mean(axis=1).tolist()      # each load's presses averaged, as np.mean of its row
    if not (readings[0] > 0.0 and all(a < b for a, b in zip(readings, readings[1:]))):
        return None
    if anchor_n is not None:
        one = min(range(len(loads_n)), key=lambda j: abs(loads_n[j] - anchor_n))
        level = loads_n[one] / readings[one]
        readings = [r * level for r in readings]
    return tuple(float(x) for x in loads_n), tuple(float(r) for r in readings)


CREEP_READ_S = (2.0, 20.0)
"""Times into the table's 1 N holds at which the bench reads the divider for the unit's creep, s:
one decade of load time, the second the hold's reading."""


def bench_creep_per_decade(device: DeviceParams, load_n: float = 1.0, load_error: float = 0.0) -> float:
    """The unit's creep per decade as the bench measures it in the calibration table's holds of
    ``load_n``: in each of the :data:`TABLE_PRESSES` presses the mean of :data:`TABLE_CONVERSIONS`
    conversions at 2 s and at 20 s (:data:`CREEP_READ_S`), each turned back into the film's path
    conductance with the divider's inverse and the nominal stand-off; the ratio of the two, to
    the power ``1 / n`` of the nominal film's exponent, is the creep gain's growth over the decade,
    and the nominal film's creep law (its retardation times, ``F_c/F = 1 + w sum(1 - e^(-t/tau))``,
    :func:`ebraille_sim.physics.fsr.held_creep_gain`) gives the per-decade rise that grows so.
    The press's scatter cancels in the ratio; the unit's exponent, unknown to the bench, scales
    the result by ``n_nominal / n_unit`` (about +/- 12 %).  Clipped to [0, 0.2]."""
    from ebraille_sim.estimation.firmware import FIRMWARE_FSR
    from ebraille_sim.physics.fsr import N_CREEP
    fsr, circuit = device.fsr, device.circuit
    nom = FIRMWARE_FSR
    rng = default_rng(_fsr_unit_seed(fsr, circuit) + 1)
    sd_v = fsr.noise_v_rms / math.sqrt(TABLE_CONVERSIONS)
    f_eff = load_n * (1.0 + load_error) * loading_branch_factor(fsr)
    g_off = 1.0 / nom.standoff_resistance_ohm
    held = np.array([static_conductance(f_eff, fsr, load_time_s=t) for t in CREEP_READ_S])   # plant truth (bench)
    draws = rng.standard_normal((TABLE_PRESSES, 1 + len(CREEP_READ_S)))   # each press: its scatter, its reads' noise
    scale = np.exp(fsr.press_repeatability * draws[:, :1])
    ratios = _creep_read_ratios(held, scale, draws, 1.0 / fsr.standoff_resistance_ohm, circuit.r2_ohm,
                                circuit.supply_v, sd_v, g_off)
    ratio = float(np.mean(ratios ** (1.0 / nom.exponent)))
    a0, a1, decade = _nominal_creep_rise(nom.creep_tau_min_s, nom.creep_tau_max_s)
    w = (ratio - 1.0) / (a1 - ratio * a0)
    per_decade = w * (N_CREEP - 1) / decade
    return float(min(max(per_decade, 0.0), 0.2))


@njit(cache=True)
def _creep_read_ratios(held, scale, draws, g_standoff_s, r2_ohm, supply_v, sd_v, g_off_s):
    """Per press of :func:`bench_creep_per_decade`, the path conductance the bench reads at its
    second creep read over that at its first: the film's conductances ``held`` with the press's
    scatter ``scale`` (the stand-off path kept), through the divider, plus each read's noise
    ``sd_v * draws[:, 1:]``, back through the divider's inverse less the nominal stand-off
    ``g_off_s`` (the operations of NumPy's broadcasts, element by element: the same numbers)."""
    out = np.empty(scale.shape[0])
    for i in range(scale.shape[0]):
        g_path = np.empty(2)
        for j in range(2):
            g = g_standoff_s + (held[j] - g_standoff_s) / scale[i, 0]                 # plant truth
            v = divider_voltage(g, r2_ohm, supply_v) + sd_v * draws[i, 1 + j]
            g_path[j] = divider_conductance_s(v, r2_ohm, supply_v) - g_off_s
        out[i] = g_path[1] / g_path[0]
    return out


@functools.lru_cache(maxsize=8)
def _nominal_creep_rise(tau_min_s: float, tau_max_s: float) -> tuple[float, float, float]:
    """The nominal film's creep rise ``F_c/F - 1`` of unit weight at the two creep reads, and the
    decades its retardation times span (:func:`bench_creep_per_decade`'s constants)."""
    from ebraille_sim.physics.fsr import N_CREEP, held_creep_gain
    a = [held_creep_gain(t, 1.0, tau_min_s, tau_max_s, N_CREEP) - 1.0 for t in CREEP_READ_S]
    return a[0], a[1], math.log10(tau_max_s / tau_min_s)


LOOP_FORCE_N, LOOP_PEAK_N, LOOP_RAMP_S = 1.0, 2.0, 1.0
"""The bench's load cycle for the unit's hysteresis: 0 to 2 N and back in 1 s legs, the film's
resistance read at 1 N on the way up and on the way down (the datasheet's cycle, 1 kg in 2 kg in
1 s legs, scaled to the reading range), N, N, s."""


def bench_hysteresis_fraction(device: DeviceParams) -> float:
    """The unit's loop ``(R_F+ - R_F-)/R_F+`` at 1 N as the bench measures it: the cycle of
    :data:`LOOP_FORCE_N`, :data:`LOOP_PEAK_N`, :data:`LOOP_RAMP_S` on a recovered film, sampled at
    1 kHz (:func:`ebraille_sim.physics.fsr.datasheet_hysteresis`, the film's own laws, its creep
    included, as the bench's fixture meets them).  The firmware keeps this number, creep and all:
    it leaves the play operators the part the bench's creep (:func:`bench_creep_per_decade`) does
    not explain (:func:`ebraille_sim.physics.fsr.play_loop_fraction` of the nominal film with that
    creep).  Single conversions on the ramps read the resistance to about 0.1 %, 1 % of the loop:
    left out."""
    from ebraille_sim.physics.fsr import datasheet_hysteresis
    film = device.fsr                                                  # plant truth (the bench's fixture)
    return float(datasheet_hysteresis(film, ramp_s=LOOP_RAMP_S, force_n=LOOP_FORCE_N, peak_n=LOOP_PEAK_N))


def with_calibration_table(device: DeviceParams, loads_n=TABLE_LOADS_N, load_errors=None) -> DeviceParams:
    """``device`` with what the unit's bench measures stored in its estimator: the calibration
    table (:func:`calibration_table`), the creep per decade the table's 1 N holds give
    (:func:`bench_creep_per_decade`, for the creep and hysteresis compensations) and the unit's loop on the bench's
    load cycle (:func:`bench_hysteresis_fraction`, for the hysteresis compensation); without a
    table (the readings do not rise with the load) the creep and the loop alone."""
    errors = (0.0,) * len(loads_n) if load_errors is None else tuple(load_errors)
    one = min(range(len(loads_n)), key=lambda j: abs(loads_n[j] - 1.0))
    creep = bench_creep_per_decade(device, loads_n[one], errors[one])
    table = calibration_table(device, loads_n, load_errors)
    fields = {"creep_per_decade": creep, "hysteresis_fraction": bench_hysteresis_fraction(device),
              "calibration_loads_n": (), "calibration_readings_n": ()}
    if table is not None:
        fields.update(calibration_loads_n=table[0], calibration_readings_n=table[1])
    return replace_fields(device, estimator=replace_fields(device.estimator, **fields))


BENCH_R2_RANGE_OHM = (500.0, 50000.0)
"""R2 range of :func:`bench_calibrate_device`, ohm (that of :func:`calibrate_device`)."""

BENCH_R2_STEP_OHM = 10.0
"""Resolution a technician sets R2 to on the bench, ohm (the shipped 1 140 ohm is the
nominal unit's 1 143 ohm at this step)."""


@functools.lru_cache(maxsize=256)
def _bench_r2(spec: str, fsr, circuit) -> float:
    """:func:`calibrate_r2` of one estimator, FSR unit and divider over :data:`BENCH_R2_RANGE_OHM`
    (cached: the parameters are frozen)."""
    return calibrate_r2(cached_model(spec), fsr, circuit, r2_range_ohm=BENCH_R2_RANGE_OHM)


def bench_calibrate_device(device: DeviceParams) -> tuple[DeviceParams, bool]:
    """The device with R2 set by the bench protocol of :func:`calibrate_r2` (presses to the
    known loads :data:`DEFAULT_FORCES_N`, each held :data:`DEFAULT_HOLDS_S`; R2 minimises the
    mean squared relative error of the steady estimate) for its own FSR unit and estimator,
    set to the nearest :data:`BENCH_R2_STEP_OHM`, and whether that R2 lies inside :data:`BENCH_R2_RANGE_OHM` (False: within 5 % of an end,
    where the bounded search stops when the best R2 lies beyond it; the unit reads off).

    >>> from ebraille_sim.physics.params import DeviceParams
    >>> dev, ok = bench_calibrate_device(DeviceParams())
    >>> ok, dev.circuit.r2_ohm
    (True, 1140.0)
    """
    best = _bench_r2(device.estimator.model, device.fsr, device.circuit)
    inside = all(abs(math.log(best / end)) > 0.05 for end in BENCH_R2_RANGE_OHM)
    r2 = BENCH_R2_STEP_OHM * round(best / BENCH_R2_STEP_OHM)
    return replace_fields(device, circuit=replace_fields(device.circuit, r2_ohm=r2)), inside


# ---- the drive's end-of-line calibration ----------------------------------------------------------

CALIBRATION_CONVERSIONS = 256
"""Conversions of the motor current averaged at each point of the drive's calibration [E]
(a quarter second at the 1 kHz control rate)."""

RESISTANCE_TEST_V = 1.0
"""Voltage the at-rest resistance test applies backward, V [E]: the board is held at its retracted
end stop, so the motor cannot turn and no back-EMF opposes it; on the Faulhaber 0816 006 SR it
draws 47 mA, 48 steps of the chain's ADC."""

PUSH_TEST_CURRENTS_A = (0.010, 0.050)
"""The two motor currents at which the line pushes the board slowly into its force gauge, A [E]:
on the nominal drive 0.1 N and 2.6 N, the reading range and above."""

FORCE_GAUGE_TOLERANCE = 0.01
"""Relative error of the line's force gauge at the test forces [E] (a 10 N bench gauge of 0.1 %
of full scale read at about 1 N)."""

FREE_RUN_V = 3.0
"""Voltage of the free-run test, V [E]: the board runs forward with nothing in its way (about
28 mm/s on the nominal drive) while the line measures its speed."""

SPEED_REFERENCE_TOLERANCE = 0.005
"""Relative error of the line's speed reference at the free-run speed [E] (an optical encoder or
a laser triangulation sensor on the board, timed over a few millimetres)."""


@dataclasses.dataclass(frozen=True)
class DriveCalibration:
    """What the end-of-line calibration stored for one drive (:func:`calibrate_drive`), in the
    firmware's own units: amperes as its current chain reads them."""
    resistance_ohm: float
    """Armature resistance, ohm: the test voltage over the averaged reading at rest."""
    push_force_per_a_n: float
    """Slope of the gauge's force against the read current, N/A."""
    push_offset_n: float
    """The gauge's force at zero read current on that line, N (negative: the drive's friction)."""
    back_emf_v_s_per_m: float
    """Back-EMF per rack speed, V s/m: the free run's voltage less ``R i_read`` over the line's speed."""
    free_run_current_a: float
    """The current of the free run as the firmware read it, A."""
    test_currents_a: tuple
    """The two currents of the push test as the firmware read them, A."""


def _unit_seed(motor, drivetrain, current_sense, driver_supply_v) -> int:
    """The noise of a unit's calibration: a fixed function of the unit's drive and current chain
    (the calibration ran once, at the line; its noise is the unit's, not the session's)."""
    import zlib
    key = repr((motor, drivetrain, current_sense, driver_supply_v))
    return zlib.crc32(key.encode()) % (1 << 31)


def calibrate_drive(device: DeviceParams) -> DriveCalibration:
    """The end-of-line calibration of ``device``'s drive, through the board's own current chain.

    1. *Resistance at rest*: the board held at its retracted end stop, the driver applies
       :data:`RESISTANCE_TEST_V` backward; the firmware averages :data:`CALIBRATION_CONVERSIONS`
       readings (:func:`ebraille_sim.physics.current_sense.mean_reading_a`) and stores
       ``R = U / i_read``.
    2. *Push per ampere*: the board advances slowly into the line's force gauge at the two
       currents of :data:`PUSH_TEST_CURRENTS_A`, horizontal (no weight along the push); at each
       the gauge reads the steady push of the drive (eq. (1) of docs/safety.md with the guide
       rods' Coulomb friction against it), high or low by the gauge's error; the line through
       the two points (force against the read current) is stored.
    3. *Back-EMF constant*: the board runs free at :data:`FREE_RUN_V` (no gauge, horizontal);
       the line's speed reference (:data:`SPEED_REFERENCE_TOLERANCE`) times the run, and the
       firmware stores ``(U - R i_read) / v``.  The run is steady: the current is the one the
       Coulomb friction of the motor and of the guide rods takes, and the speed the armature's
       law gives at that current (:func:`~ebraille_sim.physics.limits.rack_speed_from_emf_m_per_s`;
       viscous friction, a few per cent of the current, is left out: the pair still obeys the
       armature's law, which is all the measurement uses).

    The measurement uses the unit's true constants, as the line's hardware meets them, and
    nothing else reaches the firmware: it keeps the three numbers of :class:`DriveCalibration`.
    The gauge's error and the conversions' noise are the unit's own (:func:`_unit_seed`).

    Examples
    --------
    >>> from ebraille_sim.physics.params import DeviceParams
    >>> cal = calibrate_drive(DeviceParams())
    >>> round(cal.resistance_ohm, 1), round(cal.push_force_per_a_n, 1), round(cal.push_offset_n, 2)
    (21.2, 63.1, -0.62)
    """
    return _calibrate_drive(device.motor, device.drivetrain, device.current_sense, device.driver_supply_v)


@functools.lru_cache(maxsize=1024)
def _calibrate_drive(m, dt, cs, driver_supply_v: float) -> DriveCalibration:
    """:func:`calibrate_drive` of a device with the motor ``m``, drive train ``dt``, current chain
    ``cs`` and driver supply (all of the device it reads), remembered per four: the key hashes
    these parts, not the whole device (a drawn device is new at every reset)."""
    from ebraille_sim.physics.current_sense import zero_and_mean_readings_a
    from ebraille_sim.physics.limits import push_force_bound_n, rack_speed_from_emf_m_per_s, shaft_to_rack_per_m
    n = CALIBRATION_CONVERSIONS
    seed = _unit_seed(m, dt, cs, driver_supply_v)                  # plant truth: what the line's hardware meets
    i_rest = -RESISTANCE_TEST_V / m.resistance_ohm                 # plant truth
    g = shaft_to_rack_per_m(dt.gear_ratio, dt.pinion_radius_m)
    i_free = (dt.guide_coulomb_n / (dt.gear_efficiency * g) + m.friction_torque_nm) / m.torque_constant_nm_per_a  # plant truth
    # one zeroing at rest before the tests, then the means of the resistance test, the two push
    # tests and the free run, each with its own noise (mean_reading_a of each, in one call)
    _, (i_read_rest, *reads, i_read) = zero_and_mean_readings_a(
        cs, seed, (i_rest,) + PUSH_TEST_CURRENTS_A + (i_free,),
        (float(seed),) + tuple(seed + 2.0 * (k + 1) for k in range(len(PUSH_TEST_CURRENTS_A))) + (seed + 7.0,), n)
    r_ohm = -RESISTANCE_TEST_V / i_read_rest
    rng = default_rng(seed)
    gauge = 1.0 + FORCE_GAUGE_TOLERANCE * (2.0 * rng.random() - 1.0)
    forces = []
    for i in PUSH_TEST_CURRENTS_A:
        push = push_force_bound_n(i, m.torque_constant_nm_per_a, g, dt.gear_efficiency,  # plant truth
                                  m.friction_torque_nm, 0.0) - dt.guide_coulomb_n      # plant truth
        forces.append(gauge * push)
    slope = (forces[1] - forces[0]) / (reads[1] - reads[0])
    v_free = rack_speed_from_emf_m_per_s(FREE_RUN_V, i_free, m.resistance_ohm, m.back_emf_v_s_per_rad, g)  # plant truth
    v_ref = v_free * (1.0 + SPEED_REFERENCE_TOLERANCE * (2.0 * rng.random() - 1.0))
    return DriveCalibration(resistance_ohm=float(r_ohm), push_force_per_a_n=float(slope),
                            push_offset_n=float(forces[0] - slope * reads[0]), test_currents_a=tuple(reads),
                            back_emf_v_s_per_m=float((FREE_RUN_V - r_ohm * i_read) / v_ref),
                            free_run_current_a=float(i_read))
