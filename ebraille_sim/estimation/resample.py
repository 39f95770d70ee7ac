"""A block model's linear block re-discretised at another sample rate.

The paper's estimators were identified at 100 Hz; the device samples its FSR at 1 kHz.
:func:`resample` gives a block model with the same input and output maps whose linear
block runs at another rate, by one stated method:

1. **Continuous equivalent.**  Every stable *positive real* pole and every positive real
   zero ``z`` of the block maps to a first-order factor ``(s + a)``, ``a = -ln(z) / T``
   (``T`` the block's period): these are the block's dynamics that a real continuous-time
   system has.  A negative real pole or zero has no real continuous equivalent (``ln z`` is
   complex, an oscillation at the Nyquist frequency of the 100 Hz sampling), and complex
   pairs go with them: the paper's fifth-order Wiener block has poles at z = -0.967,
   -0.590, -0.121 and zeros at -0.029 +- 0.597j, which together shape its response above
   the 40 Hz band its data were filtered to (its gain is 1.70 at 40 Hz against 0.19 at
   DC) and keeping the zeros without the poles would leave an improper model.  The
   ``nk`` samples of input delay are dropped as well: they are the one-sample latency of
   the 100 Hz acquisition, not of the film.
2. **DC gain.**  The continuous model ``G(s) = g prod(s + a_z) / prod(s + a_p)`` takes the
   block's DC gain, so a held voltage reads the same force at every rate (the divider
   calibration of :mod:`ebraille_sim.estimation.calibration` does not move).
3. **Zero-order hold.**  ``G`` is sampled at the new period with a zero-order hold (the
   estimator's input is a sampled, held voltage): exact for a piecewise-constant input.

For ``"paper:wiener:5"`` this is ``G(s) = -0.192 (s + 5.35) / (s + 5.96)``; at 1 kHz its
pole is ``0.942^(1/10)`` and the block has one sample of direct feedthrough.  Which rates
suit a device is a property of the device: the estimator period must be a whole number of
sensor periods (:func:`resample` checks it when given the sensor rate;
:func:`ebraille_sim.plant.lumped.check_sensor_rates` checks it for every device).

Estimator names carry the rate after ``@``: ``"paper:wiener:5@1000"`` is
``resample(paper_model("wiener", 5), 1000.0)`` (:func:`ebraille_sim.estimation.registry.load_estimator`).

Examples
--------
>>> from ebraille_sim.estimation.paper_models import paper_model
>>> fast = resample(paper_model("wiener", 5), 1000.0)
>>> fast.dt_s, fast.kind, fast.linear.nk, len(fast.linear.f)
(0.001, 'wiener', 0, 1)
>>> round(fast.linear.dc_gain(), 6) == round(paper_model("wiener", 5).linear.dc_gain(), 6)
True
>>> split_rate("paper:wiener:5@1000")
('paper:wiener:5', 1000.0)
"""
from __future__ import annotations

import math
import re

import numpy as np

from ebraille_sim.estimation.blockmodels import BlockModel, LinearBF

__all__ = ["RATE_SEPARATOR", "split_rate", "continuous_equivalent", "zoh_discretised", "resample"]

RATE_SEPARATOR = "@"
"""Separates an estimator's name from the rate it is re-discretised at (``"paper:wiener:5@1000"``)."""

_REAL_TOL = 1e-9
"""Imaginary part (relative to the modulus) below which a root counts as real."""

_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")


def split_rate(spec: str) -> tuple[str, float | None]:
    """Split ``"NAME@RATE"`` into ``(NAME, RATE in Hz)``; ``(spec, None)`` without a rate.

    A ``"paper:..."`` name must end in a number of Hz after ``@``; for a file path the part
    after the last ``@`` is a rate only if it reads as a number (so a path may contain ``@``).

    Raises
    ------
    ValueError
        One line, for a paper name whose rate is not a positive finite number.
    """
    if RATE_SEPARATOR not in spec:
        return spec, None
    base, text = spec.rsplit(RATE_SEPARATOR, 1)
    numeric = bool(_NUMBER.match(text.strip()))
    if not numeric:
        if spec.startswith("paper:"):
            raise ValueError(f"estimator model {spec!r}: the rate after '@' must be a number of Hz, got {text!r}")
        return spec, None
    rate = float(text)
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"estimator model {spec!r}: the rate after '@' must be a positive number of Hz, got {text!r}")
    return base, rate


def _real_positive(roots: np.ndarray) -> list[float]:
    return sorted(float(r.real) for r in roots
                  if abs(r.imag) <= _REAL_TOL * max(1.0, abs(r)) and r.real > 0.0)


def continuous_equivalent(linear: LinearBF, dt_s: float) -> tuple[float, np.ndarray, np.ndarray]:
    """The continuous-time model of step 1-2 of the module's method.

    Parameters
    ----------
    linear : LinearBF
        Discrete block at the period ``dt_s``; stable, with a finite non-zero DC gain.
    dt_s : float
        Its period, s.

    Returns
    -------
    gain : float
        ``g`` of ``G(s) = g prod(s + a_z) / prod(s + a_p)`` (the DC gain matched).
    a_zeros_per_s, a_poles_per_s : ndarray
        ``a = -ln(z) / dt_s`` of the kept positive real zeros and poles, 1/s.

    Raises
    ------
    ValueError
        One line, for a positive real pole on or outside the unit circle, a DC gain that
        is zero or infinite, or more kept zeros than poles (an improper model).
    """
    dc = linear.steady_state_gain()
    if not math.isfinite(dc) or dc == 0.0:
        raise ValueError(f"cannot re-discretise a linear block with DC gain {dc:g}: it needs a finite, "
                         f"non-zero one to match")
    poles = _real_positive(linear.poles())
    zeros = _real_positive(linear.zeros())
    unstable = [p for p in poles if p >= 1.0]
    if unstable:
        raise ValueError(f"cannot re-discretise a linear block with a positive real pole at z = {unstable[0]:.6g}: "
                         f"it has no stable continuous equivalent")
    if len(zeros) > len(poles):
        raise ValueError(f"cannot re-discretise: {len(zeros)} positive real zero(s) against {len(poles)} "
                         f"positive real pole(s) give an improper continuous model")
    a_z = np.array([-math.log(z) / dt_s for z in zeros])
    a_p = np.array([-math.log(p) / dt_s for p in poles])
    gain = dc * float(np.prod(a_p)) / float(np.prod(a_z))
    return gain, a_z, a_p



def zoh_discretised(num_s, den_s, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(num_z, den_z)`` of the continuous transfer function ``num_s / den_s`` (descending
    powers, ``len(num_s) <= len(den_s)``, at least one pole) behind a zero-order hold of
    ``dt_s``: the steps of ``scipy.signal.cont2discrete((num_s, den_s), dt_s, method="zoh")``
    in its order (normalise, controller canonical state space, the exponential of the
    augmented matrix, back to a transfer function), so the coefficients are SciPy's to the last
    bit (tested) without importing its signal package.  ``num_z`` has one row."""
    import scipy.linalg
    den = np.atleast_1d(np.asarray(den_s, float))
    den = den[int(np.argmax(den != 0.0)):]
    num = np.atleast_1d(np.asarray(num_s, float)) / den[0]
    den = den / den[0]
    lead = 0
    while lead < num.size - 1 and abs(num[lead]) <= 1e-14:
        lead += 1
    num = num[lead:]
    k = den.size
    num = np.concatenate((np.zeros(k - num.size), num))
    a = np.r_[-np.array([den[1:]]), np.eye(k - 2, k - 1)]
    b = np.eye(k - 1, 1)
    c = np.array([num[1:] - num[0] * den[1:]])
    d = np.array([[num[0]]])
    n = a.shape[0]
    em = np.vstack((np.hstack((a, b)), np.zeros((1, n + 1))))
    ms = scipy.linalg.expm(dt_s * em)[:n, :]
    ad, bd = ms[:, :n], ms[:, n:]
    den_z = np.poly(ad)
    num_z = np.empty((1, n + 1))
    num_z[0] = np.poly(ad - np.dot(bd, c)) + (d[0] - 1) * den_z
    return num_z, den_z

def resample(model: BlockModel, rate_hz: float, sensor_rate_hz: float | None = None) -> BlockModel:
    """``model`` with its linear block re-discretised at ``rate_hz`` (the module's method).

    Parameters
    ----------
    model : BlockModel
        The identified model (input and output maps are kept as they are).
    rate_hz : float
        New sample rate, Hz (> 0).
    sensor_rate_hz : float, optional
        The sensor rate the estimator will decimate: when given, the new period must be a
        whole number of sensor periods.

    Returns
    -------
    BlockModel
        Same maps, ``dt_s = 1 / rate_hz``, linear block ``b0 + b1 z^-1 + ...`` over
        ``1 + f1 z^-1 + ...`` with no input delay (one leading zero of ``b`` becomes
        ``nk = 1`` for a strictly proper continuous model); named ``"NAME@RATE Hz"``.

    Raises
    ------
    ValueError
        One line, for a rate that is not positive and finite or not a whole divisor of the
        sensor rate, and for the blocks :func:`continuous_equivalent` refuses.
    """
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float)) or not (
            math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ValueError(f"estimator rate must be a positive finite number of Hz, got {rate_hz!r}")
    rate_hz = float(rate_hz)
    if sensor_rate_hz is not None:
        ratio = float(sensor_rate_hz) / rate_hz
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(f"estimator rate {rate_hz:g} Hz: its period must be a whole number of sensor periods "
                             f"(sensor rate {float(sensor_rate_hz):g} Hz, ratio {ratio:.6g})")
    gain, a_z, a_p = continuous_equivalent(model.linear, model.dt_s)
    num_s = gain * np.poly(-a_z) if a_z.size else np.array([gain])
    den_s = np.poly(-a_p) if a_p.size else np.array([1.0])
    dt_new = 1.0 / rate_hz
    if den_s.size == 1:
        b, f = (float(num_s[0] / den_s[0]),), ()
    else:
        num_d, den_d = zoh_discretised(num_s, den_s, dt_new)
        b = np.ravel(num_d) / den_d[0]
        f = tuple(np.asarray(den_d[1:], float) / den_d[0])
    b = np.asarray(b, float)
    nk = 0
    if b.size > 1 and abs(b[0]) <= 1e-14 * float(np.max(np.abs(b))):
        b, nk = b[1:], 1
    name = f"{model.name or 'model'}@{rate_hz:g} Hz"
    return BlockModel(LinearBF(b=tuple(b), f=f, nk=nk), model.input_nl, model.output_nl, dt_s=dt_new, name=name)
