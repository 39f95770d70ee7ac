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
import math
from typing import TYPE_CHECKING

import numpy as np

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


def calibrate_device(device: DeviceParams, force_n: float = 1.0, hold_s: float = 20.0) -> DeviceParams:
    """Set R2 so that the device's estimator reads ``force_n`` exactly after a press and hold.

    One-point assembly calibration (the estimator is fixed; the potentiometer is turned):
    solved by Brent's method on ln R2 in [ln 500, ln 50 000] ohm.
    """
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
