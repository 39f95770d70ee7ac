"""Block-oriented (linear, Hammerstein, Wiener, Hammerstein-Wiener) models.

A block model chains up to three blocks, evaluated per sample in this order::

    u --> input_nl --> w --> B/F (with delay nk) --> x --> output_nl --> y

* ``input_nl`` and ``output_nl`` are static piecewise-linear maps
  (:class:`PiecewiseLinear`); an absent map is the identity.
* The linear block (:class:`LinearBF`) is the discrete-time transfer function
  ``x = z^-nk B(z^-1) / F(z^-1) w`` with ``B = b0 + b1 z^-1 + ...`` and
  ``F = 1 + f1 z^-1 + ...``, realised in direct form II transposed exactly as
  :func:`scipy.signal.lfilter` does.

The structure follows MATLAB's ``idnlhw`` with ``pwlinear`` nonlinearities.
All functions are pure; the classes are frozen dataclasses that hold data and
delegate to the module-level helpers.

The compiled closed loop evaluates a model one sample at a time with
:func:`estimator_step` (on the flat arrays of :meth:`BlockModel.kernel_arrays`),
after the firmware's chain (:mod:`ebraille_sim.estimation.firmware`); these Numba
functions are the one home of the in-loop estimator, and equal
:meth:`BlockModel.simulate` sample by sample.

Examples
--------
>>> lin = LinearBF(b=(0.5,), f=(-0.5,), nk=1)
>>> model = BlockModel(lin, None, PiecewiseLinear((0.0, 1.0), (0.0, 2.0)), dt_s=0.01)
>>> model.kind
'wiener'
>>> y, state = model.simulate([1.0, 1.0, 1.0])
>>> y.tolist()
[0.0, 1.0, 1.5]
>>> model.steady_state(1.0)
2.0
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ebraille_sim.base.compiled import njit

__all__ = [
    "PiecewiseLinear",
    "LinearBF",
    "BlockModel",
    "fitness",
    "DEFAULT_UNIT_ROOT_TOL",
    "BLOCK_MODEL_FORMAT",
    "BLOCK_MODEL_VERSION",
    "pwl_eval",
    "df2t_step",
    "estimator_step",
]

MAX_TF_LEN = 10
"""Longest numerator/denominator of a linear block the compiled loop evaluates."""

MAX_BREAKPOINTS = 12
"""Most breakpoints of each nonlinearity the compiled loop evaluates."""

OUTPUT_SLOTS = ("force_est_n", "est_raw_prev_n")
"""State slots of the estimate and of the previous raw model output (two-sample mean)."""

FILTER_SLOTS = tuple(f"est_z{j}" for j in range(MAX_TF_LEN - 1))
"""State slots of the linear block (direct form II transposed)."""

OWNED_STATE_SLOTS = OUTPUT_SLOTS + FILTER_SLOTS
"""Every state slot the in-loop estimator declares (see :mod:`ebraille_sim.plant.layout`); the
firmware's chain before it declares its own (:mod:`ebraille_sim.estimation.firmware`)."""

#: Default absolute tolerance on the remainders ``B(1)`` and ``F(1)`` of a
#: division by ``(1 - z^-1)``. It suits coefficients known to machine precision;
#: pass a larger value for rounded published coefficients.
DEFAULT_UNIT_ROOT_TOL = 1e-9

#: Value of the ``"format"`` key written by :meth:`BlockModel.to_dict`.
BLOCK_MODEL_FORMAT = "ebraille_sim.block_model"
#: Value of the ``"version"`` key written by :meth:`BlockModel.to_dict`.
BLOCK_MODEL_VERSION = 1

_KINDS = ("linear", "hammerstein", "wiener", "hammerstein-wiener")


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------
def _float_tuple(values: Any, name: str, *, min_len: int = 0) -> tuple[float, ...]:
    """Validate a 1-D sequence of finite reals and return it as a float tuple."""
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a sequence of real numbers ({exc})") from None
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if arr.size < min_len:
        raise ValueError(f"{name} needs at least {min_len} value(s), got {arr.size}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise ValueError(f"{name} must be finite; entry {bad} is {arr[bad]}")
    return tuple(float(v) for v in arr)


def _as_signal(u: Any, name: str = "u") -> np.ndarray:
    """Return ``u`` as a 1-D float64 array (a copy)."""
    arr = np.array(u, dtype=float, ndmin=1)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    return arr


def _divide_by_one_minus_x(coeffs: np.ndarray) -> tuple[np.ndarray, float]:
    """Divide ``c0 + c1 x + ... + cn x^n`` by ``(1 - x)``.

    Synthetic division: the quotient coefficients are the running sums
    ``q_k = c_0 + ... + c_k`` for ``k < n`` and the remainder is the full sum,
    i.e. the polynomial's value at ``x = 1``.
    """
    sums = np.cumsum(np.asarray(coeffs, dtype=float))
    return sums[:-1], float(math.fsum(coeffs))


# ---------------------------------------------------------------------------
# static nonlinearity
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class PiecewiseLinear:
    """Static piecewise-linear map through breakpoints ``(x_bp[k], y_bp[k])``.

    Parameters
    ----------
    x_bp : sequence of float, shape (n,)
        Breakpoint abscissae, finite and strictly increasing, ``n >= 2``.
    y_bp : sequence of float, shape (n,)
        Breakpoint ordinates, finite.

    Notes
    -----
    Between breakpoints the map interpolates linearly. Beyond the end
    breakpoints it continues the slope of the end segment (linear
    extrapolation): for ``x < x_bp[0]`` the first segment's slope is used, for
    ``x > x_bp[-1]`` the last one's. The map is therefore continuous,
    unbounded and defined on the whole real line. Units are those of the
    signals mapped (for the FSR models: volts in, newtons out, or the linear
    block's internal variable).

    Examples
    --------
    >>> pl = PiecewiseLinear((0.0, 1.0, 3.0), (0.0, 2.0, 3.0))
    >>> pl(0.5), pl(2.0), pl(-1.0), pl(5.0)
    (1.0, 2.5, -2.0, 4.0)
    >>> pl.inverse(2.5)
    2.0
    """

    x_bp: tuple[float, ...]
    y_bp: tuple[float, ...]

    def __post_init__(self) -> None:
        x = _float_tuple(self.x_bp, "x_bp")
        y = _float_tuple(self.y_bp, "y_bp")
        if len(x) != len(y):
            raise ValueError(f"x_bp and y_bp differ in length ({len(x)} vs {len(y)})")
        if len(x) < 2:
            raise ValueError(f"a piecewise-linear map needs at least 2 breakpoints, got {len(x)}")
        steps = np.diff(x)
        if np.any(steps <= 0.0):
            k = int(np.flatnonzero(steps <= 0.0)[0])
            raise ValueError(
                f"x_bp must be strictly increasing; x_bp[{k}]={x[k]} >= x_bp[{k + 1}]={x[k + 1]}"
            )
        object.__setattr__(self, "x_bp", x)
        object.__setattr__(self, "y_bp", y)

    @classmethod
    def identity(cls) -> "PiecewiseLinear":
        """Identity map ``y = x`` (breakpoints ``[-1, 1] -> [-1, 1]``)."""
        return cls((-1.0, 1.0), (-1.0, 1.0))

    @property
    def n_breakpoints(self) -> int:
        """Number of breakpoints."""
        return len(self.x_bp)

    def segment_slopes(self) -> np.ndarray:
        """Slopes of the ``n - 1`` segments, shape (n - 1,)."""
        return np.diff(self.y_bp) / np.diff(self.x_bp)

    def __call__(self, x: Any) -> Any:
        """Evaluate the map.

        Parameters
        ----------
        x : float or array_like
            Input value(s), any shape.

        Returns
        -------
        float or numpy.ndarray
            Mapped value(s): a float for scalar input, otherwise a float64
            array of the input's shape.
        """
        xa = np.asarray(x, dtype=float)
        xb = np.asarray(self.x_bp)
        yb = np.asarray(self.y_bp)
        slopes = self.segment_slopes()
        y = np.interp(xa, xb, yb)
        y = np.where(xa < xb[0], yb[0] + slopes[0] * (xa - xb[0]), y)
        y = np.where(xa > xb[-1], yb[-1] + slopes[-1] * (xa - xb[-1]), y)
        return float(y) if y.ndim == 0 else y

    def slope_at(self, x: Any) -> Any:
        """Local slope ``dy/dx``.

        At an interior breakpoint the slope of the segment to its right is
        returned; at the last breakpoint and beyond, the last segment's slope;
        before the first breakpoint, the first segment's slope.

        Parameters
        ----------
        x : float or array_like
            Input value(s), any shape.

        Returns
        -------
        float or numpy.ndarray
            Slope(s), same shape convention as :meth:`__call__`.
        """
        xa = np.asarray(x, dtype=float)
        idx = np.searchsorted(np.asarray(self.x_bp), xa, side="right") - 1
        idx = np.clip(idx, 0, self.n_breakpoints - 2)
        s = self.segment_slopes()[idx]
        return float(s) if np.ndim(s) == 0 else s

    def monotonicity(self) -> int:
        """``+1`` if strictly increasing, ``-1`` if strictly decreasing, else ``0``."""
        slopes = self.segment_slopes()
        if np.all(slopes > 0.0):
            return 1
        if np.all(slopes < 0.0):
            return -1
        return 0

    def inverted(self) -> "PiecewiseLinear":
        """The inverse map as a :class:`PiecewiseLinear`.

        Because the extrapolation continues the end segments, the inverse of
        the extended map is exactly the extended map of the swapped
        breakpoints.

        Raises
        ------
        ValueError
            If the map is not strictly monotone.
        """
        direction = self.monotonicity()
        if direction == 0:
            raise ValueError("map is not strictly monotone; it has no inverse")
        if direction > 0:
            return PiecewiseLinear(self.y_bp, self.x_bp)
        return PiecewiseLinear(self.y_bp[::-1], self.x_bp[::-1])

    def inverse(self, y: Any) -> Any:
        """Evaluate the inverse map, ``x`` such that ``self(x) == y``.

        Parameters
        ----------
        y : float or array_like
            Output value(s), any shape.

        Returns
        -------
        float or numpy.ndarray
            Input value(s), same shape convention as :meth:`__call__`.

        Raises
        ------
        ValueError
            If the map is not strictly monotone.
        """
        return self.inverted()(y)


# ---------------------------------------------------------------------------
# linear block
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class LinearBF:
    """Discrete-time transfer function ``z^-nk B(z^-1) / F(z^-1)``.

    Parameters
    ----------
    b : sequence of float, shape (nb,)
        Numerator coefficients ``b0, b1, ...`` of ``B = b0 + b1 z^-1 + ...``,
        *after* the input delay (``nb >= 1``).
    f : sequence of float, shape (nf,)
        Denominator coefficients ``f1, f2, ...`` of ``F = 1 + f1 z^-1 + ...``,
        given WITHOUT the leading 1 (``nf >= 0``).
    nk : int, optional
        Input delay in samples (``nk >= 0``). The full numerator in powers of
        ``z^-1`` is ``[0]*nk + b`` (see :meth:`numerator`).

    Notes
    -----
    The difference equation is
    ``x[n] = b0 w[n-nk] + b1 w[n-nk-1] + ... - f1 x[n-1] - f2 x[n-2] - ...``.

    Examples
    --------
    >>> lin = LinearBF(b=(0.5, 0.25), f=(-0.5, 0.1), nk=1)
    >>> lin.numerator().tolist(), lin.denominator().tolist()
    ([0.0, 0.5, 0.25], [1.0, -0.5, 0.1])
    >>> round(lin.dc_gain(), 12)
    1.25
    """

    b: tuple[float, ...]
    f: tuple[float, ...] = ()
    nk: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "b", _float_tuple(self.b, "b", min_len=1))
        object.__setattr__(self, "f", _float_tuple(self.f, "f"))
        nk = self.nk
        if isinstance(nk, (bool, np.bool_)) or not isinstance(nk, (int, np.integer)):
            raise ValueError(f"nk must be a non-negative int, got {nk!r}")
        if nk < 0:
            raise ValueError(f"nk must be a non-negative int, got {nk}")
        object.__setattr__(self, "nk", int(nk))

    # -- coefficient arrays ------------------------------------------------
    def numerator(self) -> np.ndarray:
        """Full numerator in powers of ``z^-1``, shape (nk + nb,): nk zeros then ``b``."""
        return np.concatenate([np.zeros(self.nk), np.asarray(self.b, dtype=float)])

    def denominator(self) -> np.ndarray:
        """Full denominator in powers of ``z^-1``, shape (nf + 1,): ``[1, f1, ...]``."""
        return np.concatenate([[1.0], np.asarray(self.f, dtype=float)])

    @property
    def order(self) -> int:
        """Number of filter states, ``max(nk + nb, nf + 1) - 1``."""
        return max(self.nk + len(self.b), len(self.f) + 1) - 1

    # -- poles, zeros, gains -------------------------------------------------
    def poles(self) -> np.ndarray:
        """Roots of ``z^nf F(z^-1)``, complex, shape (nf,), sorted by decreasing modulus.

        The ``nk`` poles at the origin introduced by the delay are not listed.
        """
        p = np.roots(self.denominator()).astype(complex)
        return p[np.argsort(-np.abs(p), kind="stable")]

    def zeros(self) -> np.ndarray:
        """Roots of ``z^(nb-1) B(z^-1)``, complex, sorted by decreasing modulus."""
        z = np.roots(np.asarray(self.b, dtype=float)).astype(complex)
        return z[np.argsort(-np.abs(z), kind="stable")]

    def unit_root_residuals(self) -> tuple[float, float]:
        """``(B(1), F(1))``: the remainders of dividing ``B`` and ``F`` by ``(1 - z^-1)``."""
        return float(math.fsum(self.b)), float(math.fsum((1.0,) + self.f))

    def dc_gain(self, tol: float = 1e-12) -> float:
        """Raw gain at ``z = 1``, ``B(1) / F(1)``.

        Parameters
        ----------
        tol : float, optional
            ``|F(1)| <= tol`` counts as a pole at ``z = 1``.

        Returns
        -------
        float
            The gain; ``+inf`` or ``-inf`` (sign of ``B(1)``) for a pole at
            ``z = 1`` that is not matched by a zero (an integrator).

        Raises
        ------
        ValueError
            If both ``|B(1)|`` and ``|F(1)|`` are within ``tol`` (0/0: cancel the
            common factor first, see :meth:`cancel_unit_root` and
            :meth:`steady_state_gain`).
        """
        b1, f1 = self.unit_root_residuals()
        if abs(f1) <= tol:
            if abs(b1) <= tol:
                raise ValueError(
                    f"DC gain is 0/0 (B(1)={b1:.3g}, F(1)={f1:.3g}): cancel the common (1 - z^-1) factor first"
                )
            return math.copysign(math.inf, b1)
        return b1 / f1

    def steady_state_gain(self, tol: float = DEFAULT_UNIT_ROOT_TOL) -> float:
        """Limit of the transfer function as ``z -> 1``.

        Unlike :meth:`dc_gain`, common ``(1 - z^-1)`` factors (detected within
        ``tol``) are cancelled first, so a pole-zero pair at ``z = 1`` does not
        make the gain indeterminate.

        Returns
        -------
        float
            The steady-state gain, ``+-inf`` if an unmatched pole at ``z = 1``
            remains.
        """
        reduced, _ = self.cancel_unit_roots(tol)
        b1, f1 = reduced.unit_root_residuals()
        if abs(f1) <= tol:
            return math.copysign(math.inf, b1) if b1 != 0.0 else math.nan
        return b1 / f1

    def is_stable(self, tol: float = 0.0) -> bool:
        """True when every pole satisfies ``|p| < 1 - tol``."""
        p = self.poles()
        return bool(p.size == 0 or np.max(np.abs(p)) < 1.0 - tol)

    def has_unit_pole(self, tol: float = DEFAULT_UNIT_ROOT_TOL) -> bool:
        """True when ``F`` has a factor ``(1 - z^-1)``, judged by ``|F(1)| <= tol``."""
        return abs(self.unit_root_residuals()[1]) <= tol

    def has_common_unit_root(self, tol: float = DEFAULT_UNIT_ROOT_TOL) -> bool:
        """True when both ``|B(1)| <= tol`` and ``|F(1)| <= tol`` (a pole-zero pair at ``z = 1``).

        Requires ``nb >= 2`` and ``nf >= 1`` so that both quotients are non-empty.
        """
        if len(self.b) < 2 or len(self.f) < 1:
            return False
        b1, f1 = self.unit_root_residuals()
        return abs(b1) <= tol and abs(f1) <= tol

    def cancel_unit_root(self, tol: float = DEFAULT_UNIT_ROOT_TOL) -> "LinearBF":
        """Remove one common ``(1 - z^-1)`` factor from ``B`` and ``F``.

        ``B`` and ``F`` are each divided by ``(1 - z^-1)`` with synthetic
        division; the quotients become the new ``b`` and ``f`` (``nb`` and
        ``nf`` drop by one, ``nk`` is kept). The remainders ``B(1)`` and
        ``F(1)`` decide whether the factor is present (both within ``tol``);
        they are then dropped, so the new model is exactly the quotient
        model: multiplying its ``B`` and ``F`` by ``(1 - z^-1)`` reproduces the
        original coefficients except the last one of each, which differs by
        the dropped remainder.

        Parameters
        ----------
        tol : float, optional
            Absolute tolerance on the remainders.

        Returns
        -------
        LinearBF
            The reduced model, or ``self`` unchanged when there is no common
            factor within ``tol`` (see :meth:`has_common_unit_root`).

        Examples
        --------
        >>> lin = LinearBF(b=(2.0, -3.0, 1.0), f=(-1.5, 0.5))
        >>> red = lin.cancel_unit_root()
        >>> red.b, red.f
        ((2.0, -1.0), (-0.5,))
        """
        if not self.has_common_unit_root(tol):
            return self
        qb, _ = _divide_by_one_minus_x(np.asarray(self.b))
        qf, _ = _divide_by_one_minus_x(self.denominator())
        return LinearBF(b=tuple(qb), f=tuple(qf[1:]), nk=self.nk)

    def cancel_unit_roots(
        self, tol: float = DEFAULT_UNIT_ROOT_TOL, max_count: int | None = None
    ) -> tuple["LinearBF", int]:
        """Repeat :meth:`cancel_unit_root` while a common factor is detected.

        Parameters
        ----------
        tol : float, optional
            Absolute tolerance on the remainders at each step.
        max_count : int or None, optional
            Upper bound on the number of factors removed (None: no bound).

        Returns
        -------
        model : LinearBF
            The reduced model.
        count : int
            Number of ``(1 - z^-1)`` factors removed.
        """
        model, count = self, 0
        while (max_count is None or count < max_count) and model.has_common_unit_root(tol):
            model, count = model.cancel_unit_root(tol), count + 1
        return model, count

    def normalised(self, index: int | None = None) -> tuple["LinearBF", float]:
        """Scale ``B`` so that one coefficient is exactly ``+1``.

        MATLAB's ``idnlhw`` fixes one ``B`` coefficient of the linear block at
        ``+1`` to remove the gain ambiguity between the blocks; this returns
        the model in that form together with the compensating gain.

        Parameters
        ----------
        index : int or None, optional
            Index into ``b`` of the coefficient to fix. None (default) picks
            the largest-magnitude coefficient (the first one on ties).

        Returns
        -------
        model : LinearBF
            Model with ``model.b[index] == 1.0``.
        gain : float
            ``b[index]`` of the original, so that ``gain * model`` equals the
            original transfer function.

        Raises
        ------
        ValueError
            If the chosen coefficient is zero or the index is out of range.
        """
        b = np.asarray(self.b)
        idx = int(np.argmax(np.abs(b))) if index is None else int(index)
        if not -len(b) <= idx < len(b):
            raise ValueError(f"index {idx} out of range for {len(b)} B coefficient(s)")
        gain = float(b[idx])
        if gain == 0.0:
            raise ValueError(f"B coefficient {idx} is zero; cannot normalise on it")
        scaled = b / gain
        scaled[idx] = 1.0
        return LinearBF(b=tuple(scaled), f=self.f, nk=self.nk), gain

    # -- simulation ------------------------------------------------------------
    def simulate(self, u: Any, zi: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """Filter a signal, carrying the filter state in and out.

        Parameters
        ----------
        u : array_like, shape (n,)
            Input samples.
        zi : array_like, shape (order,), optional
            Initial direct-form-II-transposed state (as for
            :func:`scipy.signal.lfilter`); None means zero state.

        Returns
        -------
        y : numpy.ndarray, shape (n,)
            Output samples.
        zf : numpy.ndarray, shape (order,)
            Final state; pass it as ``zi`` to continue the signal.
        """
        u = _as_signal(u)
        num, den = self.numerator(), self.denominator()
        if zi is None:
            zi = np.zeros(self.order)
        else:
            zi = np.array(zi, dtype=float)
            if zi.shape != (self.order,):
                raise ValueError(f"state must have shape ({self.order},), got {zi.shape}")
        from scipy.signal import lfilter
        y, zf = lfilter(num, den, u, zi=zi)
        return y, zf


# ---------------------------------------------------------------------------
# block model
# ---------------------------------------------------------------------------
_REQUIRED_KEYS = frozenset({"kind", "dt_s", "nk", "b", "f", "input_nl", "output_nl"})
_OPTIONAL_KEYS = frozenset({"name", "format", "version"})
_NL_KEYS = frozenset({"x_bp", "y_bp"})


def _kind_of(input_nl: PiecewiseLinear | None, output_nl: PiecewiseLinear | None) -> str:
    return _KINDS[(input_nl is not None) + 2 * (output_nl is not None)]


def _nl_to_dict(nl: PiecewiseLinear | None) -> dict[str, list[float]] | None:
    return None if nl is None else {"x_bp": list(nl.x_bp), "y_bp": list(nl.y_bp)}


def _nl_from_dict(value: Any, key: str) -> PiecewiseLinear | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise ValueError(f"{key} must be null or an object with x_bp and y_bp")
    unknown = sorted(set(value) - _NL_KEYS)
    if unknown:
        raise ValueError(f"unknown key(s) in {key}: {', '.join(unknown)}")
    missing = sorted(_NL_KEYS - set(value))
    if missing:
        raise ValueError(f"missing key(s) in {key}: {', '.join(missing)}")
    try:
        return PiecewiseLinear(value["x_bp"], value["y_bp"])
    except ValueError as exc:
        raise ValueError(f"{key}: {exc}") from None


@dataclass(frozen=True)
class BlockModel:
    """Linear block with optional static input and output nonlinearities.

    Parameters
    ----------
    linear : LinearBF
        Dynamic block ``z^-nk B/F``.
    input_nl : PiecewiseLinear or None
        Static map applied to the input before the linear block (Hammerstein
        part); None for none.
    output_nl : PiecewiseLinear or None
        Static map applied to the linear block's output (Wiener part); None
        for none.
    dt_s : float
        Sample time in seconds (> 0).
    name : str, optional
        Free label.

    Notes
    -----
    Evaluation order for every sample ``n`` (state ``z`` of length
    ``L - 1``, ``num``/``den`` padded to length ``L`` as in
    :meth:`kernel_arrays`)::

        w    = input_nl(u[n])                      # identity if absent
        x    = num[0] * w + z[0]
        z[i] = num[i+1] * w - den[i+1] * x + z[i+1]   for i = 0 .. L-3
        z[L-2] = num[L-1] * w - den[L-1] * x
        y[n] = output_nl(x)                        # identity if absent

    i.e. direct form II transposed, identical to :func:`scipy.signal.lfilter`.
    Piecewise-linear maps interpolate between breakpoints and extrapolate with
    the end-segment slopes.

    Examples
    --------
    >>> m = BlockModel(LinearBF((1.0,), (-0.5,)), None, None, dt_s=0.01)
    >>> m.kind, m.steady_state(1.0)
    ('linear', 2.0)
    """

    linear: LinearBF
    input_nl: PiecewiseLinear | None
    output_nl: PiecewiseLinear | None
    dt_s: float
    name: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.linear, LinearBF):
            raise ValueError(f"linear must be a LinearBF, got {type(self.linear).__name__}")
        for key in ("input_nl", "output_nl"):
            value = getattr(self, key)
            if value is not None and not isinstance(value, PiecewiseLinear):
                raise ValueError(f"{key} must be a PiecewiseLinear or None, got {type(value).__name__}")
        try:
            dt = float(self.dt_s)
        except (TypeError, ValueError):
            raise ValueError(f"dt_s must be a positive finite number, got {self.dt_s!r}") from None
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt_s must be a positive finite number, got {self.dt_s!r}")
        object.__setattr__(self, "dt_s", dt)
        if not isinstance(self.name, str):
            raise ValueError(f"name must be a str, got {type(self.name).__name__}")

    @property
    def kind(self) -> str:
        """``"linear"``, ``"hammerstein"``, ``"wiener"`` or ``"hammerstein-wiener"``."""
        return _kind_of(self.input_nl, self.output_nl)

    @property
    def order(self) -> int:
        """Length of the filter state vector."""
        return self.linear.order

    def _in(self, u: Any) -> Any:
        return u if self.input_nl is None else self.input_nl(u)

    def _out(self, x: Any) -> Any:
        return x if self.output_nl is None else self.output_nl(x)

    def simulate(self, u: Any, state: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """Simulate the model on an input signal.

        Parameters
        ----------
        u : array_like, shape (n,)
            Input samples (for the FSR estimators: detrended voltage, V).
        state : array_like, shape (order,), optional
            Filter state returned by a previous call; None starts from zero
            state (see :meth:`rest_state` for an equilibrium start).

        Returns
        -------
        y : numpy.ndarray, shape (n,)
            Output samples (for the FSR estimators: detrended force, N).
        state : numpy.ndarray, shape (order,)
            Final filter state. Feeding a signal in pieces, each with the state
            returned by the previous piece, gives exactly the output of one call
            on the whole signal.
        """
        w = np.asarray(self._in(_as_signal(u)), dtype=float)
        x, zf = self.linear.simulate(w, zi=state)
        return np.asarray(self._out(x), dtype=float), zf

    def steady_state(self, u_const: Any) -> Any:
        """Static map ``u -> y`` reached for a constant input.

        ``y = output_nl(g * input_nl(u))`` with ``g`` the linear block's
        :meth:`LinearBF.steady_state_gain`.

        Parameters
        ----------
        u_const : float or array_like
            Constant input level(s).

        Returns
        -------
        float or numpy.ndarray
            Steady output(s).

        Raises
        ------
        ValueError
            If the linear block has an unmatched pole at ``z = 1`` (no steady
            state).
        """
        g = self.linear.steady_state_gain()
        if not math.isfinite(g):
            raise ValueError("linear block integrates (pole at z = 1): there is no steady state")
        x = g * np.asarray(self._in(u_const), dtype=float)
        y = np.asarray(self._out(x), dtype=float)
        return float(y) if y.ndim == 0 else y

    def rest_state(self, u_const: float = 0.0) -> np.ndarray:
        """Filter state of the equilibrium under a constant input.

        Starting :meth:`simulate` from this state with ``u == u_const``
        yields the constant output :meth:`steady_state` ``(u_const)``.

        Parameters
        ----------
        u_const : float, optional
            Constant input level.

        Returns
        -------
        numpy.ndarray, shape (order,)
        """
        g = self.linear.steady_state_gain()
        if not math.isfinite(g):
            raise ValueError("linear block integrates (pole at z = 1): there is no rest state")
        w = float(self._in(float(u_const)))
        x = g * w
        L = self.order + 1
        num = np.zeros(L)
        den = np.zeros(L)
        n, d = self.linear.numerator(), self.linear.denominator()
        num[: n.size], den[: d.size] = n, d
        terms = num[1:] * w - den[1:] * x
        return np.cumsum(terms[::-1])[::-1].copy()

    def to_control(self):
        """The linear block ``z^-nk B(z^-1) / F(z^-1)`` as a python-control transfer function.

        The coefficients in powers of ``z^-1`` (:meth:`LinearBF.numerator`,
        :meth:`LinearBF.denominator`) are padded with zeros to a common length ``L`` and
        read in descending powers of ``z`` (multiplying both by ``z^(L-1)``), so the
        transfer function is exactly the filter that :meth:`simulate` applies between
        the input and output maps (the maps themselves are left out).  The sample time is
        :attr:`dt_s`.  python-control is imported here, so the estimation layer does not
        need it to load.

        Returns
        -------
        control.TransferFunction
            Discrete-time SISO transfer function with ``dt = dt_s``.

        Examples
        --------
        >>> m = BlockModel(LinearBF((0.5,), (-0.5,), nk=1), None, None, dt_s=0.01)
        >>> tf = m.to_control()
        >>> tf.dt, tf.num[0][0].tolist(), tf.den[0][0].tolist()
        (0.01, [0.5], [1.0, -0.5])
        """
        import control
        num, den = self.linear.numerator(), self.linear.denominator()
        n = max(num.size, den.size)
        num = np.concatenate([num, np.zeros(n - num.size)])
        den = np.concatenate([den, np.zeros(n - den.size)])
        return control.TransferFunction(num, den, self.dt_s)

    # -- serialisation -----------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description.

        Returns
        -------
        dict
            Keys ``format``, ``version``, ``name``, ``kind``, ``dt_s``, ``nk``,
            ``b``, ``f`` (without the leading 1), ``input_nl`` and
            ``output_nl`` (each ``None`` or ``{"x_bp": [...], "y_bp": [...]}``).
        """
        return {
            "format": BLOCK_MODEL_FORMAT,
            "version": BLOCK_MODEL_VERSION,
            "name": self.name,
            "kind": self.kind,
            "dt_s": self.dt_s,
            "nk": self.linear.nk,
            "b": list(self.linear.b),
            "f": list(self.linear.f),
            "input_nl": _nl_to_dict(self.input_nl),
            "output_nl": _nl_to_dict(self.output_nl),
        }

    @classmethod
    def from_dict(cls, d: Any) -> "BlockModel":
        """Build a model from :meth:`to_dict` output.

        Raises
        ------
        ValueError
            For a non-dict, unknown or missing keys, a wrong format tag or
            version, invalid values, or a ``kind`` that disagrees with the
            nonlinearities present.
        """
        if not isinstance(d, dict):
            raise ValueError(f"block-model description must be a JSON object, got {type(d).__name__}")
        unknown = sorted(set(d) - _REQUIRED_KEYS - _OPTIONAL_KEYS)
        if unknown:
            raise ValueError(f"unknown key(s) in block-model description: {', '.join(map(str, unknown))}")
        missing = sorted(_REQUIRED_KEYS - set(d))
        if missing:
            raise ValueError(f"missing key(s) in block-model description: {', '.join(missing)}")
        if d.get("format", BLOCK_MODEL_FORMAT) != BLOCK_MODEL_FORMAT:
            raise ValueError(f"format must be {BLOCK_MODEL_FORMAT!r}, got {d['format']!r}")
        if d.get("version", BLOCK_MODEL_VERSION) != BLOCK_MODEL_VERSION:
            raise ValueError(f"unsupported block-model version {d['version']!r} (expected {BLOCK_MODEL_VERSION})")
        input_nl = _nl_from_dict(d["input_nl"], "input_nl")
        output_nl = _nl_from_dict(d["output_nl"], "output_nl")
        kind = _kind_of(input_nl, output_nl)
        if d["kind"] != kind:
            raise ValueError(f"kind {d['kind']!r} disagrees with the nonlinearities present ({kind!r})")
        if isinstance(d["dt_s"], bool) or not isinstance(d["dt_s"], (int, float)):
            raise ValueError(f"dt_s must be a number, got {d['dt_s']!r}")
        linear = LinearBF(b=d["b"], f=d["f"], nk=d["nk"])
        return cls(linear, input_nl, output_nl, dt_s=d["dt_s"], name=d.get("name", ""))

    def save(self, path: str | Path) -> None:
        """Write :meth:`to_dict` as JSON (UTF-8, indented) to ``path``."""
        text = json.dumps(self.to_dict(), indent=2, allow_nan=False)
        Path(path).write_text(text + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: str | Path) -> "BlockModel":
        """Read a model written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            If the file is not valid JSON or not a valid description.
        """
        from ebraille_sim.base.files import read_json, short
        p = Path(path)
        if not os.path.lexists(p):
            raise FileNotFoundError(f"block-model file not found: {short(p)}")
        data = read_json(p, "block-model file")
        if not isinstance(data, dict):
            raise ValueError(f"invalid block-model file {short(p)}: holds a {type(data).__name__}, not an object")
        try:
            return cls.from_dict(data)
        except (ValueError, TypeError, KeyError, AttributeError, IndexError) as exc:
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
            raise ValueError(f"invalid block-model file {short(p)}: {first}") from None

    # -- compiled evaluator support ------------------------------------------
    def kernel_arrays(self) -> dict[str, Any]:
        """Flat arrays for a compiled per-sample evaluator.

        Returns
        -------
        dict
            ``num``, ``den`` : float64 arrays of common length ``L``; the full
            numerator (``nk`` leading zeros) and denominator (leading 1),
            zero-padded at the end.
            ``in_x``, ``in_y``, ``out_x``, ``out_y`` : float64 breakpoint
            arrays of the input and output maps (an absent map is given as the
            identity ``[-1, 1] -> [-1, 1]``, which extrapolates to ``y = x``).
            ``order`` : int, ``L - 1``, the length of the filter state.

        Notes
        -----
        The evaluation order is the one given in the class notes:
        ``u -> input_nl -> linear filter (direct form II transposed) ->
        output_nl -> y``.
        """
        num, den = self.linear.numerator(), self.linear.denominator()
        L = max(num.size, den.size)
        num_p = np.zeros(L)
        den_p = np.zeros(L)
        num_p[: num.size], den_p[: den.size] = num, den
        ident = PiecewiseLinear.identity()
        inl = self.input_nl or ident
        onl = self.output_nl or ident
        return {
            "num": num_p,
            "den": den_p,
            "in_x": np.asarray(inl.x_bp, dtype=np.float64),
            "in_y": np.asarray(inl.y_bp, dtype=np.float64),
            "out_x": np.asarray(onl.x_bp, dtype=np.float64),
            "out_y": np.asarray(onl.y_bp, dtype=np.float64),
            "order": int(L - 1),
        }


# ---------------------------------------------------------------------------
# compiled per-sample evaluator (the in-loop estimator)
# ---------------------------------------------------------------------------
@njit(cache=True, inline="always")
def pwl_eval(x, p, x0, y0, n):
    """Piecewise-linear map with breakpoints ``p[x0:x0+n]``, ``p[y0:y0+n]``.

    Beyond the end breakpoints the end segments are continued (linear extrapolation),
    as :class:`PiecewiseLinear` does.
    """
    j = 0
    while j < n - 2 and x > p[x0 + j + 1]:
        j += 1
    xa = p[x0 + j]
    xb = p[x0 + j + 1]
    ya = p[y0 + j]
    yb = p[y0 + j + 1]
    return ya + (yb - ya) * (x - xa) / (xb - xa)


@njit(cache=True, inline="always")
def df2t_step(x, s, z0, p, num0, den0, n):
    """One sample of ``num/den`` (length ``n``, ``den[0] = 1``) in direct form II transposed.

    The state ``s[z0:z0+n-1]`` is advanced in place; returns the output, exactly as
    :func:`scipy.signal.lfilter` computes it.
    """
    y = p[num0] * x + s[z0]
    for j in range(n - 2):
        s[z0 + j] = p[num0 + j + 1] * x + s[z0 + j + 1] - p[den0 + j + 1] * y
    if n >= 2:
        s[z0 + n - 2] = p[num0 + n - 1] * x - p[den0 + n - 1] * y
    return y


@njit(cache=True, inline="always")
def estimator_step(u, s, z0, raw_prev, p, in_x0, in_y0, n_in, num0, den0, n, out_x0, out_y0, n_out,
                   nyquist_average, clamp_nonnegative):
    """One sample of the block-oriented estimator: input map, linear block, output map.

    With ``nyquist_average`` the output is the mean of the last two model outputs
    (``s[raw_prev]`` keeps the previous one): a zero at z = -1 that removes the
    sample-to-sample ringing of a model pole near -1 (the paper's fifth-order Wiener has
    one at -0.967), at the price of half a sample of delay.  With ``clamp_nonnegative`` a
    negative estimate reads 0.
    """
    x = pwl_eval(u, p, in_x0, in_y0, n_in)
    y = df2t_step(x, s, z0, p, num0, den0, n)
    f = pwl_eval(y, p, out_x0, out_y0, n_out)
    if nyquist_average:
        f_raw = f
        f = 0.5 * (f + s[raw_prev])
        s[raw_prev] = f_raw
    if clamp_nonnegative and f < 0.0:
        f = 0.0
    return f


# ---------------------------------------------------------------------------
# goodness of fit
# ---------------------------------------------------------------------------
def fitness(measured: Any, modelled: Any) -> float:
    """Normalised-root-mean-square fit in percent.

    ``(1 - ||y_hat - y|| / ||y - mean(y)||) * 100`` with ``y`` the measured and
    ``y_hat`` the modelled signal (100 for a perfect fit, 0 for the constant
    mean, negative for worse than the mean).

    Parameters
    ----------
    measured : array_like, shape (n,)
        Measured signal ``y``.
    modelled : array_like, shape (n,)
        Modelled signal ``y_hat``, same shape.

    Returns
    -------
    float
        Fit in percent.

    Raises
    ------
    ValueError
        For mismatched shapes, non-finite values, or a constant measured
        signal (the fit is undefined).

    Examples
    --------
    >>> fitness([0.0, 1.0, 2.0], [0.0, 1.0, 2.0])
    100.0
    >>> fitness([0.0, 1.0, 2.0], [1.0, 1.0, 1.0])
    0.0
    """
    y = _as_signal(measured, "measured")
    y_hat = _as_signal(modelled, "modelled")
    if y.shape != y_hat.shape:
        raise ValueError(f"measured and modelled differ in shape ({y.shape} vs {y_hat.shape})")
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(y_hat))):
        raise ValueError("measured and modelled must be finite")
    spread = float(np.linalg.norm(y - np.mean(y)))
    if spread == 0.0:
        raise ValueError("measured signal is constant: the fit is undefined")
    return float((1.0 - np.linalg.norm(y_hat - y) / spread) * 100.0)
