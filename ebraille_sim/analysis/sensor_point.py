"""The sensor chain at an operating point: the FSR's loading branch, the firmware, the estimator.

The static values and slopes the small-signal models need at a contact force held on a
recovered film (see the *FSR* paragraph of :mod:`ebraille_sim.analysis.plant_model`): the
divider voltage and its slope on the loading branch (:func:`sensor_point`), the operating
values of the estimator's input and output maps, and the firmware's creep compensation
with its partial derivatives (:func:`compensation_point`), all evaluated with the very
functions the kernel runs.
"""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.physics import fsr as _fsr
from ebraille_sim.physics.params import DeviceParams

__all__ = ["sensor_point", "compensation_point"]


def sensor_point(device: DeviceParams, force_n: float, load_time_s: float, model=None, direction: float = 1.0):
    """Loading-branch voltage, its instantaneous slope and the estimator's operating values.

    The slope is ``c_h dV/dF_c`` at the crept force of a press held ``load_time_s``: the creep
    states are held (their small-signal dynamics are :func:`ebraille_sim.analysis.sampled.creep_model`).  At a breakpoint of
    a piecewise-linear map the slope of the segment the signal enters when the force moves in
    ``direction`` (+1 rising, -1 falling) is used.
    """
    from ebraille_sim.estimation.calibration import _tare, loading_branch_factor, loading_voltage
    from ebraille_sim.estimation.registry import load_estimator
    model = model if model is not None else load_estimator(device.estimator.model)
    fsr, circ = device.fsr, device.circuit
    v0 = loading_voltage(force_n, fsr, circ, load_time_s)
    c_h = loading_branch_factor(fsr)
    f_c = force_n * c_h * (_fsr.creep_gain(load_time_s, fsr) if force_n * c_h > fsr.load_threshold_n else 1.0)

    def v_of_crept(f):
        # the divider voltage of a crept force (no further creep: load time 0)
        return _fsr.divider_voltage(_fsr.static_conductance(f, fsr, 0.0), circ.r2_ohm, circ.supply_v)
    h = 1e-4 * max(f_c, 1e-2)
    slope = c_h * (v_of_crept(f_c + h) - v_of_crept(f_c - h)) / (2 * h)
    tare = _tare(fsr, circ) if device.estimator.tare_at_start else 0.0
    # the estimator reads the compensated voltage (the same whatever the estimate: the
    # firmware's creep gain does not depend on the force it has followed)
    u0 = (compensation_point(device, v0, force_n, load_time_s)[0] if device.estimator.creep_compensation
          else v0) - tare
    w0 = model._in(u0)
    side = 1.0 if direction >= 0 else -1.0
    du = side * 1e-9 * max(1.0, abs(u0))
    in_slope = 1.0 if model.input_nl is None else float(model.input_nl.slope_at(u0 + du))
    gain = model.linear.steady_state_gain()
    y0 = gain * w0
    dy = side * math.copysign(1.0, gain * in_slope) * 1e-9 * max(1.0, abs(y0))
    out_slope = 1.0 if model.output_nl is None else float(model.output_nl.slope_at(y0 + dy))
    est = float(model.steady_state(u0))
    return model, v0, slope, u0, in_slope, y0, out_slope, est


def compensation_point(device: DeviceParams, raw_v: float, estimate_n: float, load_time_s: float):
    """The kernel's creep compensation at an operating point, and its partial derivatives.

    Evaluates :func:`ebraille_sim.estimation.firmware.creep_compensated_v` itself with the
    parameters :func:`ebraille_sim.plant.lumped.pack_params` packs, its creep terms having
    followed ``estimate_n`` for ``load_time_s`` (``z_i = F (1 - a_i^k)``).  Returns
    ``(v_out, d/dv, d/dF_est, d/dz_i, a_i)``; the derivatives are central differences of
    that function (it is smooth away from the load threshold and the rails).
    """
    from ebraille_sim.estimation.firmware import creep_compensated_v
    from ebraille_sim.plant.layout import N_CREEP, P
    from ebraille_sim.plant.lumped import pack_params
    p = pack_params(device, 0.0)
    a = np.array([p[P[f"comp_creep_a{j}"]] for j in range(N_CREEP)])
    k = int(round(load_time_s * device.rates.sensor_rate_hz))
    z = estimate_n * (1.0 - a ** k)
    fn = creep_compensated_v.py_func

    def out(v, f, zz):
        st = np.zeros(N_CREEP)
        st[:] = zz
        return fn(v, f, st, 0, p, P.comp_creep_a0, p[P.comp_creep_weight], p[P.comp_load_threshold_n], N_CREEP,
                  p[P.comp_fsr_n], p[P.comp_g_standoff_s], p[P.comp_reference_gain], p[P.r2_ohm],
                  p[P.divider_supply_v], 0.0)
    v0 = out(raw_v, estimate_n, z)
    hv = 1e-6 * max(abs(raw_v), 1e-3)
    hf = 1e-6 * max(abs(estimate_n), 1e-3)
    d_v = (out(raw_v + hv, estimate_n, z) - out(raw_v - hv, estimate_n, z)) / (2 * hv)
    d_f = (out(raw_v, estimate_n + hf, z) - out(raw_v, estimate_n - hf, z)) / (2 * hf)
    d_z = np.empty(N_CREEP)
    for j in range(N_CREEP):
        e = np.zeros(N_CREEP)
        e[j] = hf
        d_z[j] = (out(raw_v, estimate_n, z + e) - out(raw_v, estimate_n, z - e)) / (2 * hf)
    return v0, d_v, d_f, d_z, a
