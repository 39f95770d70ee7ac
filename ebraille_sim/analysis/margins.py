"""Margins, sensitivity peak, bandwidth and step of a sampled loop.

:func:`loop_margins` finds the gain and phase margins of a discrete loop transfer from
its frequency response (crossings refined by a root finder), :func:`sensitivity_peak` the
peak ``Ms`` of the sensitivity; :func:`analyse_loop` closes the sampled plant of
:func:`ebraille_sim.analysis.sampled.loop_models` with a controller at an operating force
and reports them with the bandwidth and the closed-loop step; :func:`delay_analyses` does so
under both readings of the paper's input delay (``nk = 0`` and ``1``).

Examples
--------
>>> from ebraille_sim.analysis.margins import analyse_loop
>>> from controllers.pid import DEFAULT_PID
>>> a = analyse_loop(DEFAULT_PID, force_n=0.6)
>>> a.stable, round(a.ms, 2)
(True, 1.7)
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg
import scipy.optimize

from ebraille_sim.analysis.plant_model import OperatingPoint, operating_point
from ebraille_sim.analysis.sampled import loop_models
from ebraille_sim.estimation.registry import delay_readings
from ebraille_sim.physics.params import DeviceParams

__all__ = ["freq_grid", "freq_response", "sensitivity_peak", "LoopMargins", "loop_margins", "LoopAnalysis",
           "analyse_loop", "delay_devices", "delay_analyses"]


def freq_grid(dt: float, n: int = 400) -> np.ndarray:
    return np.logspace(-1.5, math.log10(0.999 * math.pi / dt), n)


def _response_function(sys: control.StateSpace):
    """Evaluator ``w -> L(e^{j w dt})`` of a SISO discrete system (Hessenberg form computed once)."""
    A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (sys.A, sys.B, sys.C, sys.D))
    d, dt = complex(D[0, 0]), sys.dt
    if A.size == 0:
        return lambda w: np.full(np.size(w), d)
    H, Q = scipy.linalg.hessenberg(A, calc_q=True)
    Bq = Q.T @ B
    Cq = C @ Q
    I = np.eye(A.shape[0])

    def response(w) -> np.ndarray:
        z = np.exp(1j * np.atleast_1d(np.asarray(w, float)) * dt)
        out = np.empty(len(z), complex)
        for k, zk in enumerate(z):
            out[k] = (Cq @ np.linalg.solve(zk * I - H, Bq))[0, 0] + d
        return out
    return response


def freq_response(sys: control.StateSpace, w: np.ndarray) -> np.ndarray:
    """Frequency response of a SISO discrete system on ``w`` (rad/s), by a Hessenberg solve."""
    return _response_function(sys)(w)


def _closed_loop_stable(loop: control.StateSpace) -> bool:
    """Whether ``L/(1 + L)`` (unity negative feedback) has every pole inside the unit circle."""
    A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (loop.A, loop.B, loop.C, loop.D))
    if abs(1.0 + D[0, 0]) < 1e-12:
        return False
    if A.size == 0:
        return True
    acl = A - B @ C / (1.0 + D[0, 0])
    return bool(np.max(np.abs(np.linalg.eigvals(acl))) < 1.0)


def sensitivity_peak(loop: control.StateSpace, w: np.ndarray | None = None) -> float:
    """``Ms = max |1/(1 + L)|`` on the unit circle (``inf`` if the closed loop is unstable)."""
    acl = loop.A - loop.B @ loop.C
    if np.max(np.abs(np.linalg.eigvals(acl))) >= 1.0:
        return math.inf
    w = freq_grid(loop.dt) if w is None else w
    return float(np.max(np.abs(1.0 / (1.0 + freq_response(loop, w)))))


@dataclass(frozen=True)
class LoopMargins:
    """Gain and phase margins of a loop transfer ``L`` (unity negative feedback).

    Every crossing of the unit circle (gain crossover) and of the negative real axis (phase
    crossover) between 0 and the Nyquist frequency is listed; the reported margins are the
    smallest ones.  The margins describe the distance of the Nyquist curve from -1; they
    say how far a *stable* closed loop is from instability only when
    ``closed_loop_stable`` is true.
    """
    gain_margin: float
    """Gain margin (absolute): ``1/|L|`` at the phase crossover whose value is nearest to 1
    on a log scale (a factor below 1 is a gain-reduction margin); ``inf`` without a phase
    crossover."""
    phase_margin_deg: float
    """``180 deg + arg L``, wrapped to (-180, 180], at the gain crossover where its magnitude
    is smallest; ``inf`` without a gain crossover."""
    gain_crossover_rad_s: float
    """Frequency of the reported phase margin (``nan`` without a gain crossover)."""
    phase_crossover_rad_s: float
    """Frequency of the reported gain margin (``nan`` without a phase crossover)."""
    closed_loop_stable: bool
    """Every pole of ``L/(1 + L)`` inside the unit circle."""
    gain_crossovers_rad_s: tuple = ()
    """All frequencies with ``|L| = 1``, ascending."""
    phase_margins_deg: tuple = ()
    """Phase margin at each gain crossover."""
    phase_crossovers_rad_s: tuple = ()
    """All frequencies with ``arg L = -180 deg (mod 360)``, ascending."""
    gain_margins: tuple = ()
    """Gain margin at each phase crossover."""


def _margin_grid(loop: control.StateSpace, response, w: np.ndarray | None, integrating: bool) -> np.ndarray:
    """Search grid for the crossings: the ``Ms`` grid (or ``w``), the Nyquist frequency, a
    low-frequency extension below the slowest pole or zero, and dense points around every
    lightly damped pole or zero (so that a narrow resonance cannot hide a pair of crossings)."""
    dt = loop.dt
    w_nyq = math.pi / dt
    base = freq_grid(dt) if w is None else np.asarray(w, float)
    roots = np.concatenate([np.asarray(loop.poles(), complex), np.asarray(loop.zeros(), complex)])
    roots = roots[np.isfinite(roots) & (np.abs(roots) > 1e-9)]
    s = np.log(roots) / dt                    # continuous-time equivalents
    corner = np.abs(s)
    slow = corner[corner > 1e-8 * w_nyq]
    lo = max(1e-8 * w_nyq, 0.01 * float(np.min(slow))) if slow.size else 1e-8 * w_nyq
    lo = min(lo, float(base[0]))
    parts = [base, [w_nyq], np.logspace(math.log10(lo), math.log10(base[0]), 1 + int(100 * math.log10(base[0] / lo)))]
    for wd, sigma in zip(np.abs(s.imag), np.abs(s.real)):
        if lo < wd < w_nyq and sigma < 0.5 * wd:
            parts.append(wd + sigma * np.linspace(-4.0, 4.0, 33))
    if not integrating:
        parts.append([0.0])
    elif abs(response(lo)[0]) < 1.0:
        # below lo the integrators dominate: extend down until |L| > 1
        w_low = lo
        while abs(response(w_low)[0]) < 1.0 and w_low > 1e-12 * w_nyq:
            w_low /= 10.0
        parts.append(np.logspace(math.log10(w_low), math.log10(lo), 1 + 10 * round(math.log10(lo / w_low))))
    grid = np.unique(np.concatenate([np.asarray(p, float) for p in parts]))
    return grid[(grid >= 0.0) & (grid <= w_nyq)]


def _crossings(fun, grid: np.ndarray, values: np.ndarray) -> list[float]:
    """Roots of ``fun`` on the grid: exact zeros and every sign change refined by ``brentq``."""
    out = [float(w) for w, v in zip(grid, values) if v == 0.0]
    ok = np.isfinite(values)
    for i in np.nonzero(ok[:-1] & ok[1:] & (values[:-1] * values[1:] < 0.0))[0]:
        out.append(float(scipy.optimize.brentq(fun, grid[i], grid[i + 1], xtol=1e-13, rtol=4 * np.finfo(float).eps)))
    return sorted(out)


def loop_margins(loop: control.StateSpace, w: np.ndarray | None = None) -> LoopMargins:
    """Gain and phase margins of a discrete SISO loop transfer from its frequency response.

    ``L(e^{j w dt})`` is evaluated on the ``Ms`` grid of :func:`sensitivity_peak` (or on
    ``w``, rad/s) extended as described in :func:`_margin_grid`, up to the Nyquist
    frequency ``pi/dt``.  A gain crossover is a sign change of ``ln|L|``, a phase crossover
    a sign change of ``Im L/|L| = sin(arg L)`` where ``Re L < 0``; each is refined by
    ``scipy.optimize.brentq`` on that continuous function of ``w``.  The phase margin at a
    gain crossover is ``arg(-L)`` in (-180, 180] deg, so no phase unwrapping (and no
    multiple of 360 deg) enters.  ``L`` is real at 0 and at the Nyquist frequency; there a
    negative value is a phase crossover, except at a zero of ``L`` on the unit circle.

    Parameters
    ----------
    loop : StateSpace
        Loop transfer (negative feedback), discrete time, one input and one output.
    w : ndarray, optional
        Base search grid (rad/s, positive, at most the Nyquist frequency).

    Returns
    -------
    LoopMargins
        The smallest margins, their frequencies, every crossing, and whether the closed
        loop is stable.
    """
    if not isinstance(loop, control.StateSpace):
        loop = control.ss(loop)
    if loop.ninputs != 1 or loop.noutputs != 1:
        raise ValueError(f"loop must have one input and one output, got {loop.ninputs} x {loop.noutputs}")
    if loop.dt is None or loop.dt is True or not loop.dt > 0:
        raise ValueError(f"loop must be discrete-time with a numeric sampling period, got dt={loop.dt}")
    w_nyq = math.pi / loop.dt
    if w is not None:
        w = np.asarray(w, float)
        if w.ndim != 1 or w.size < 2 or not np.all(np.isfinite(w)) or np.any(w <= 0) or np.any(w > w_nyq * (1 + 1e-12)):
            raise ValueError(f"w must be a 1-D grid of at least two frequencies in (0, {w_nyq:g}] rad/s")
        w = np.sort(w)
    response = _response_function(loop)
    # a pole this close to z = 1 acts as an integrator on the whole grid (and makes L(1) meaningless)
    poles = np.asarray(loop.poles(), complex)
    integrating = bool(np.any(np.abs(np.log(poles[np.abs(poles) > 1e-9])) < 1e-8 * math.pi))
    grid = _margin_grid(loop, response, w, integrating)
    ell = response(grid)
    real_end = (grid == 0.0) | (grid == w_nyq)
    ell[real_end] = ell[real_end].real          # L is real at z = 1 and z = -1
    with np.errstate(divide="ignore", invalid="ignore"):
        log_mag = np.log(np.abs(ell))
        sin_arg = ell.imag / np.abs(ell)

    def f_mag(x):
        return float(np.log(abs(response(x)[0])))

    def f_arg(x):
        v = response(x)[0]
        return 0.0 if x in (0.0, w_nyq) else float(v.imag / abs(v))

    wgc = _crossings(f_mag, grid, log_mag)
    pms = [math.degrees(np.angle(-response(x)[0])) for x in wgc]
    wpc, gms = [], []
    for x in _crossings(f_arg, grid, sin_arg):
        v = response(x)[0]
        if x in (0.0, w_nyq):
            v = complex(v.real, 0.0)
            # a zero of L at z = +-1 is the curve passing through the origin, not a crossing
            k = int(np.searchsorted(grid, x))
            neighbour = ell[k + 1] if x == 0.0 else ell[k - 1]
            if abs(v) <= 1e-6 * abs(neighbour):
                continue
        # a sign change of sin(arg L) across a zero of L on the unit circle is a jump, not a root
        if v.real < 0.0 and abs(v.imag) <= 1e-3 * abs(v):
            wpc.append(x)
            gms.append(1.0 / abs(v))
    if pms:
        i = int(np.argmin(np.abs(pms)))
        pm, w_pm = pms[i], wgc[i]
    else:
        pm, w_pm = math.inf, math.nan
    if gms:
        j = int(np.argmin(np.abs(np.log(gms))))
        gm, w_gm = gms[j], wpc[j]
    else:
        gm, w_gm = math.inf, math.nan
    return LoopMargins(gain_margin=gm, phase_margin_deg=pm, gain_crossover_rad_s=w_pm, phase_crossover_rad_s=w_gm,
                       closed_loop_stable=_closed_loop_stable(loop), gain_crossovers_rad_s=tuple(wgc),
                       phase_margins_deg=tuple(pms), phase_crossovers_rad_s=tuple(wpc), gain_margins=tuple(gms))


@dataclass
class LoopAnalysis:
    """Frequency and step analysis of one loop at one operating force.

    The margins are those of :func:`loop_margins`; on an unstable closed loop they are
    ``nan`` here (the crossings themselves stay in ``margins``).
    """
    force_n: float
    gain_margin: float
    """Gain margin (absolute, ``inf`` if the phase never crosses -180 deg, ``nan`` if the
    closed loop is unstable)."""
    phase_margin_deg: float
    """Phase margin (``inf`` if ``|L|`` never crosses 1, ``nan`` if the closed loop is unstable)."""
    gain_crossover_hz: float
    """Frequency of the phase margin (``nan`` if none or unstable)."""
    phase_crossover_hz: float
    """Frequency of the gain margin (``nan`` if none or unstable)."""
    ms: float
    """Sensitivity peak max |S|."""
    bandwidth_hz: float
    """First frequency where |T| falls 3 dB below its DC value."""
    step: dict
    """``control.step_info`` of the setpoint-to-estimate step (a unit step)."""
    stable: bool
    loop: control.StateSpace
    closed: control.StateSpace
    op: OperatingPoint
    margins: LoopMargins
    """Every crossing of ``L`` (:func:`loop_margins`), stable or not."""

    def summary(self) -> dict:
        keys = ("RiseTime", "SettlingTime", "Overshoot", "Peak")
        return {"force_n": self.force_n, "gain_margin": self.gain_margin, "phase_margin_deg": self.phase_margin_deg,
                "gain_crossover_hz": self.gain_crossover_hz, "phase_crossover_hz": self.phase_crossover_hz,
                "ms": self.ms, "bandwidth_hz": self.bandwidth_hz,
                "stable": self.stable, **{f"step_{k}": float(self.step.get(k, math.nan)) for k in keys}}

    def margin_label(self) -> str:
        """``PM .. deg at .. Hz, GM ..`` for a stable loop, ``closed loop unstable`` otherwise."""
        if not self.stable:
            return "closed loop unstable"
        pm = "PM none" if math.isinf(self.phase_margin_deg) else \
            f"PM {self.phase_margin_deg:.1f} deg at {self.gain_crossover_hz:.2f} Hz"
        gm = "GM inf" if math.isinf(self.gain_margin) else f"GM {self.gain_margin:.2f}"
        return f"{pm}, {gm}"


def analyse_loop(controller, device: DeviceParams = DeviceParams(), force_n: float = 1.0, *,
                 friction: str = "press", step_time_s: float = 3.0) -> LoopAnalysis:
    """Margins, Ms, bandwidth and closed-loop step of ``controller`` at ``force_n``.

    ``controller`` as in :func:`~ebraille_sim.analysis.sampled.loop_models`.  Margins from
    :func:`loop_margins` (the loop's frequency response, crossings refined by a root finder);
    the step from ``control.step_info`` on a ``step_time_s`` response.
    """
    op = operating_point(device, force_n, friction=friction)
    loop, closed = loop_models(device, force_n, controller, op=op)
    margins = loop_margins(loop)
    stable = margins.closed_loop_stable
    hz = 1.0 / (2 * math.pi)
    gm, pm, wgc, wpc = ((margins.gain_margin, margins.phase_margin_deg, margins.gain_crossover_rad_s * hz,
                         margins.phase_crossover_rad_s * hz) if stable else (math.nan,) * 4)
    ms = sensitivity_peak(loop)
    w = freq_grid(loop.dt, 800)
    t_mag = np.abs(freq_response(closed, w))
    t0 = abs(float(np.real(control.dcgain(closed)))) if stable else math.nan
    below = np.nonzero(t_mag < t0 / math.sqrt(2.0))[0] if stable else []
    bw = float(w[below[0]] / (2 * math.pi)) if len(below) else math.nan
    if stable:
        t = np.arange(0.0, step_time_s, closed.dt)
        resp = control.step_response(closed, T=t)
        info = control.step_info(resp.outputs, T=resp.time, yfinal=t0)
    else:
        info = {}
    return LoopAnalysis(force_n=float(force_n), gain_margin=gm, phase_margin_deg=pm, gain_crossover_hz=wgc,
                        phase_crossover_hz=wpc, ms=ms, bandwidth_hz=bw, step=dict(info), stable=stable, loop=loop,
                        closed=closed, op=op, margins=margins)


def delay_devices(device: DeviceParams, delays: bool = True) -> list[tuple[int | None, DeviceParams]]:
    """``device`` under each reading of the paper's input delay, ``[(nk, device)]``.

    With ``delays`` and an estimator that is a paper model at its own rate, one device per
    reading (``nk = 0, 1``, :func:`ebraille_sim.estimation.registry.delay_readings`); otherwise
    ``[(None, device)]``.
    """
    readings = delay_readings(device.estimator.model) if delays else {}
    if not readings:
        return [(None, device)]
    return [(k, dataclasses.replace(device, estimator=dataclasses.replace(device.estimator, model=m)))
            for k, m in readings.items()]


def delay_analyses(controller, device: DeviceParams = DeviceParams(), force_n: float = 1.0, *,
                   friction: str = "press") -> dict:
    """:func:`analyse_loop` under each reading of the paper's input delay, ``{nk: LoopAnalysis}``.

    The device's estimator is run as ``nk = 0`` (the paper's notation read literally) and
    ``nk = 1`` (MATLAB's convention) when it is a paper model at its own rate
    (:func:`delay_devices`); otherwise the one analysis is keyed
    ``None``.
    """
    return {nk: analyse_loop(controller, d, force_n, friction=friction) for nk, d in delay_devices(device)}
