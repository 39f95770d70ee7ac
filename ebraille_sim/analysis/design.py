"""Controller designs from the sampled plant: SIMC PI gains and the LQG design model.

:func:`simc_pid` fits a first-order-plus-delay model to the step of
:func:`ebraille_sim.analysis.sampled.linearize` (:func:`foptd_fit`) and applies
Skogestad's SIMC rules; :func:`make_lqg` is the registered ``"lqg"`` controller, designed
on the same plant.
"""
from __future__ import annotations

import dataclasses

import control
import numpy as np

from ebraille_sim.analysis.sampled import linearize
from ebraille_sim.physics.params import DeviceParams

__all__ = ["foptd_fit", "simc_pid", "make_lqg"]


def foptd_fit(plant: control.StateSpace, t_end_s: float = 6.0) -> tuple[float, float, float]:
    """First-order-plus-delay fit ``k e^{-theta s}/(tau s + 1)`` of a stable plant's step.

    Uses the 28 % / 63 % two-point method on the step response of ``plant`` (Smith's
    method), with the crossing times interpolated between samples; returns
    ``(k, tau_s, theta_s)``.  ``k`` is the response reached at ``t_end_s``: the FSR creep's
    10-100 s terms raise the DC gain by a few per cent more over minutes, which the
    controller's integral action takes up and a fit of the loop's time scale must not
    stretch over.  The delay is at least one sample period of the plant: the estimate is
    held over it, and a shorter delay cannot be read from the samples (with the pulp's
    tap-dissipation weights the two-point delay of the estimator-rate step is 5 ms).
    """
    t = np.arange(0.0, t_end_s, plant.dt)
    r = control.step_response(plant, T=t)
    y = np.asarray(r.outputs).ravel()
    k = float(y[-1])

    def crossing(level):
        j = int(np.argmax(y >= level))
        return float(r.time[j - 1] + (level - y[j - 1]) / (y[j] - y[j - 1]) * (r.time[j] - r.time[j - 1]))
    t28, t63 = crossing(0.283 * k), crossing(0.632 * k)
    tau = 1.5 * (t63 - t28)
    theta = max(t63 - tau, plant.dt)
    return k, tau, theta


def simc_pid(device: DeviceParams = DeviceParams(), force_n: float = 1.0, tau_c_s: float | None = None):
    """SIMC PI gains (Skogestad 2003) from a first-order-plus-delay fit of the sampled plant
    (:func:`~ebraille_sim.analysis.sampled.linearize`).

    ``kc = tau / (k (tau_c + theta))``, ``tau_I = min(tau, 4 (tau_c + theta))``, with the
    "tight" choice ``tau_c = theta`` unless given.  Returns a
    :class:`~controllers.pid.PIDConfig` with the default limits and derivative filter.
    """
    from controllers.pid import DEFAULT_PID
    plant = linearize(device, force_n)
    k, tau, theta = foptd_fit(plant)
    tc = theta if tau_c_s is None else tau_c_s
    kc = tau / (k * (tc + theta))
    ti = min(tau, 4.0 * (tc + theta))
    return dataclasses.replace(DEFAULT_PID, kp_v_per_n=kc, ki_v_per_ns=kc / ti, kd_vs_per_n=0.0)


def make_lqg(device: DeviceParams = DeviceParams(), **gains):
    """The registered ``"lqg"`` controller: :class:`controllers.lqg.LQG` designed on
    :func:`~ebraille_sim.analysis.sampled.linearize` of ``device`` at ``design_force_n``."""
    from controllers.lqg import LQG, config_from
    config = config_from(**gains)
    plant, op = linearize(device, config.design_force_n, return_point=True)
    return LQG(config, plant, op.command_v, op.estimate_n)
