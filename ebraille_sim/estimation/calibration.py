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

import bisect
import dataclasses
import functools
import math
from typing import TYPE_CHECKING

import numpy as np

from ebraille_sim.base.validation import replace_fields
from ebraille_sim.estimation.models import cached_model
from ebraille_sim.physics.fsr import adc_code, adc_voltage, divider_voltage, play_widths, static_conductance

if TYPE_CHECKING:
    from ebraille_sim.physics.params import DeviceParams

DEFAULT_FORCES_N = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0)
DEFAULT_HOLDS_S = (5.0, 20.0, 60.0)


def loading_branch_factor(fsr) -> float:
    """Force seen by the conduction law on the loading branch, as a fraction of the force.

    After a monotone press from zero every play operator of the hysteresis model
    (:func:`ebraille_sim.physics.fsr.hysteresis`) sits at its lower edge, so
    ``F_eff + F_eps = (F + F_eps) exp(-sum_j weight_j width_j)``; for ``F >> F_eps`` (1 mN)
    that is ``F_eff = F exp(-sum_j weight_j width_j)``.
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
    model the result is the unit's ``hysteresis_fraction`` up to the 1 mN offset of its log.
    """
    from ebraille_sim.physics.fsr import N_PLAYS, conductance_s, hysteresis, log_force
    widths, weights = play_widths(fsr)
    p = np.array(list(widths) + list(weights))
    s = np.full(N_PLAYS, log_force(0.0))

    def g(f_eff):
        return conductance_s(f_eff, fsr.resistance_at_1n_ohm, fsr.exponent, 0.0, 1.0)

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


def _interp(x: float, xs: list, ys: list, last: int) -> float:
    """``numpy.interp(x, xs, ys)`` of one float inside ``[xs[0], xs[-1]]`` (or NaN), in Python
    floats: the segment and the operations of NumPy's ``arr_interp`` for one point (the last
    breakpoint not above ``x``, the slope of its segment, ``slope (x - x_j) + y_j``, the other
    end when that is NaN), so the same number without the call into NumPy."""
    if x != x:
        return x
    j = bisect.bisect_right(xs, x) - 1
    if j == last or xs[j] == x:
        return ys[j]
    slope = (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j])
    y = slope * (x - xs[j]) + ys[j]
    if y != y:
        y = slope * (x - xs[j + 1]) + ys[j + 1]
        if y != y and ys[j] == ys[j + 1]:
            y = ys[j]
    return y


def _steady_map(model):
    """The scalar map ``u -> model.steady_state(u)``, with the linear block's gain and the
    nonlinearities' breakpoints read once (the same floating-point operations, so the same
    numbers)."""
    g = model.linear.steady_state_gain()
    if not math.isfinite(g):
        return model.steady_state              # raises as the model does

    def pwl(nl):
        if nl is None:
            return None
        xb = np.asarray(nl.x_bp, dtype=float)
        yb = np.asarray(nl.y_bp, dtype=float)
        slopes = nl.segment_slopes()
        x0, xn, y0, yn, s0, sn = (float(v) for v in (xb[0], xb[-1], yb[0], yb[-1], slopes[0], slopes[-1]))
        xs, ys = xb.tolist(), yb.tolist()
        last = len(xs) - 1

        def f(x):
            if x < x0:
                return y0 + s0 * (x - x0)
            if x > xn:
                return yn + sn * (x - xn)
            return _interp(x, xs, ys, last)
        return f

    f_in, f_out = pwl(model.input_nl), pwl(model.output_nl)

    def steady(u):
        x = g * (u if f_in is None else f_in(u))
        return x if f_out is None else f_out(x)
    return steady


@functools.lru_cache(maxsize=8)
def _steady_map_of(spec: str):
    return _steady_map(cached_model(spec))


@functools.lru_cache(maxsize=4096)
def _calibrated_r2(spec: str, fsr, circuit, force_n: float, hold_s: float) -> float | None:
    """R2 (ohm) of :func:`calibrate_device` for one estimator, FSR unit and divider; None when
    no R2 in [500, 50 000] ohm reads ``force_n`` exactly.  Cached: the parameters are frozen."""
    import scipy.optimize
    steady = _steady_map_of(spec)
    # the calibration protocol's voltages with every R2-independent factor computed once
    g_load = static_conductance(force_n * loading_branch_factor(fsr), fsr, load_time_s=hold_s)
    g_zero = static_conductance(0.0, fsr)
    supply, lsb, max_code = circuit.supply_v, circuit.adc_lsb_v, circuit.adc_max_code

    def err(log_r2):
        r2 = math.exp(log_r2)
        v0 = divider_voltage(g_zero, r2, supply)
        tare = adc_voltage(adc_code(v0, lsb, max_code), lsb)
        return float(steady(divider_voltage(g_load, r2, supply) - tare)) - force_n

    lo, hi = math.log(500.0), math.log(50000.0)
    if err(lo) * err(hi) > 0:
        return None
    return math.exp(scipy.optimize.brentq(err, lo, hi, xtol=1e-6))


def calibrate_device(device: DeviceParams, force_n: float = 1.0, hold_s: float = 20.0) -> DeviceParams:
    """Set R2 so that the device's estimator reads ``force_n`` exactly after a press and hold.

    One-point assembly calibration (the estimator is fixed; the potentiometer is turned):
    solved by Brent's method on ln R2 in [ln 500, ln 50 000] ohm.  The result depends only on
    the estimator, the FSR unit and the divider and is cached per combination, so drawing the
    same unit again costs a dictionary look-up.
    """
    r2 = _calibrated_r2(device.estimator.model, device.fsr, device.circuit, float(force_n), float(hold_s))
    if r2 is None:
        return device
    return replace_fields(device, circuit=replace_fields(device.circuit, r2_ohm=r2))


def calibrate_device_reference(device: DeviceParams, force_n: float = 1.0, hold_s: float = 20.0) -> DeviceParams:
    """:func:`calibrate_device` through :func:`steady_estimate` at every iterate, uncached
    (the protocol as written; the cached path must give the same R2 to the last bit)."""
    import scipy.optimize
    model = cached_model(device.estimator.model)
    fsr, circuit = device.fsr, device.circuit

    def err(log_r2):
        c = dataclasses.replace(circuit, r2_ohm=math.exp(log_r2))
        return steady_estimate(model, force_n, fsr, c, hold_s) - force_n

    lo, hi = math.log(500.0), math.log(50000.0)
    if err(lo) * err(hi) > 0:
        return device
    log_r2 = scipy.optimize.brentq(err, lo, hi, xtol=1e-6)
    return dataclasses.replace(device, circuit=dataclasses.replace(circuit, r2_ohm=math.exp(log_r2)))
