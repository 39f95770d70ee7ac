"""Identification of linear, Hammerstein, Wiener and Hammerstein-Wiener models.

The procedure follows MATLAB's ``idnlhw`` with ``pwlinear`` nonlinearities, the tool the
seed paper used, with SciPy doing the optimisation:

1. **Linear output-error initialisation** for every candidate input delay ``nk``: an ARX
   least-squares fit, Steiglitz-McBride iterations (the data prefiltered by ``1/F``), the
   output-error ``B`` for each candidate ``F``, then Levenberg-Marquardt refinement of the
   simulation error (:func:`scipy.optimize.least_squares`, ``method="lm"``) from the two
   best.  For the nonlinear kinds this runs on mean-free data (an offset would otherwise
   be fitted with slow poles).  The delays with the lowest error are carried on.
2. **Nonlinearity initialisation.**  The ``B`` coefficient of largest magnitude is fixed at
   ``+1`` (the gain is moved into the nonlinearity).  Breakpoints are spread evenly over
   the range of the block's input: the measured input for an input map, the simulated
   linear output for an output map; their values follow by linear least squares (the
   output is linear in them once the locations are fixed).  Models with an input map get
   a second start from a purely linear regression on the products of ``B`` coefficients
   and map values (:func:`_hammerstein_regression`).
3. **Joint refinement** of every parameter (``B`` but the fixed coefficient, ``F``,
   breakpoint locations and values) on the simulation error with Levenberg-Marquardt and
   an analytic Jacobian: the linear-block sensitivities are the input and output filtered
   by ``1/F`` and delayed (one filter pass each), the nonlinearity sensitivities are the
   piecewise-linear basis functions and their location derivatives (through the linear
   block for an input map).
4. **Multi-start.**  Further starts perturb the poles of the initial linear block (radius
   and angle, ``B`` re-solved) and the interior breakpoints, and, for Hammerstein-Wiener,
   start once from the Wiener side; the start with the best estimation fit wins.
5. **Stability guard.**  A trial step whose ``F`` has a root at ``|z| >= 1 - margin`` (or,
   with ``nyquist_clearance``, a root nearer than that to ``z = -1``) or whose breakpoints
   collapse is rejected (the residual is returned huge, so the trust
   region shrinks); initial linear blocks are stabilised by reflecting poles into the unit
   circle.

Model structure: ``nb = nf = order`` (the paper's orders 2-5), 4 breakpoints per map,
linear extrapolation beyond the end breakpoints (:class:`ebraille_sim.estimation.blockmodels.PiecewiseLinear`).
With linear extrapolation the outer breakpoints are not kinks and could slide along the end
segments without changing the map; they are therefore tied to the ends of the range of the
map's input over the estimation data, and the interior ones are ordered fractions of that
range (:func:`_fractions`).  Hammerstein-Wiener models have two more gauge freedoms (an
offset and a scale passed from the input map through ``B/F`` to the output map); the values
of the input map at its first and last breakpoints are held at their initial values to
remove them.

Initial-condition policy: every model is simulated from zero filter state (at rest), in
the estimation and in :func:`fitness` scores alike, and no initial stretch is discarded.
Detrended records start at rest, so that is consistent with the data; MATLAB's ``compare``
can instead estimate initial states, which can only raise a fit.

The returned models are :class:`~ebraille_sim.estimation.blockmodels.BlockModel` objects: they
simulate with ``model.simulate(u)[0]`` (or :func:`simulate`), save to JSON with
``model.save(path)`` and load into a scenario as ``[estimator] model = "path.json"``.
The paper's own 16 models load into the same class with :func:`paper_model`; they keep
the paper's fixed ``b1 = +1`` (see :mod:`ebraille_sim.estimation.paper_models`), the identified ones
fix the largest-magnitude coefficient, and both describe the same transfer functions.

Examples
--------
>>> import numpy as np
>>> from ebraille_sim.estimation.blockmodels import BlockModel, LinearBF, PiecewiseLinear
>>> true = BlockModel(LinearBF((1.0,), (-0.6,), nk=1), None,
...                   PiecewiseLinear((-1.0, 0.0, 1.0, 2.0), (-0.5, 0.0, 2.0, 5.0)), dt_s=0.01)
>>> u = np.repeat(np.random.default_rng(0).uniform(-0.5, 0.8, 300), 4)
>>> y = simulate(true, u)
>>> m = fit("wiener", u, y, order=1, nk=1, n_starts=1)
>>> fitness(y, simulate(m, u)) > 99.9
True
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.optimize
from scipy.signal import lfilter

from ebraille_sim.base.validation import check_number

from ebraille_sim.estimation.blockmodels import BlockModel, LinearBF, PiecewiseLinear, fitness
from ebraille_sim.estimation.paper_models import KINDS, NK_READINGS, ORDERS, SAMPLE_TIME_S, paper_model

__all__ = ["fit", "fit_report", "fit_readings", "FitResult", "fitness", "paper_model", "simulate", "match_poles",
           "shift_operating_point", "compare_with_paper", "KINDS", "ORDERS", "PAPER_FITNESS", "PAPER_PROFILE_ORDER", "DEFAULT_MARGIN"]

#: Poles must stay within ``|z| < 1 - DEFAULT_MARGIN`` during the search.
DEFAULT_MARGIN = 1e-4

PAPER_PROFILE_ORDER = ("chirp", "square_0.2hz", "square_0.1hz", "step_0.1hz", "triangle_0.25hz", "triangle_0.1hz")
"""Row order of the paper's fitness tables (profile keys of :data:`ebraille_sim.identification.bench.PAPER_PROFILES`)."""

PAPER_FITNESS: dict[str, dict[int, dict[str, float]]] = {
    kind: {order: dict(zip(PAPER_PROFILE_ORDER, col)) for order, col in zip(ORDERS, zip(*rows))}
    for kind, rows in {
        "linear": ((78.79, 78.85, 78.92, 78.93), (81.86, 83.12, 81.89, 81.89), (81.93, 83.28, 82.12, 82.10),
                   (76.25, 77.87, 76.62, 76.59), (76.51, 77.84, 76.79, 76.78), (65.52, 69.17, 66.14, 66.09)),
        "hammerstein": ((90.87, 95.89, 91.20, 91.84), (85.59, 79.15, 83.33, 86.52), (89.90, 90.31, 87.90, 90.92),
                        (83.01, 83.98, 86.17, 81.50), (86.69, 79.40, 84.96, 87.47), (65.44, 43.44, 69.43, 63.20)),
        "wiener": ((95.23, 95.47, 88.96, 93.46), (76.98, 84.16, 91.50, 93.02), (77.67, 84.52, 92.67, 93.52),
                   (89.54, 94.84, 92.82, 95.01), (78.87, 85.51, 91.03, 92.36), (49.82, 62.08, 82.02, 87.25)),
        "hammerstein-wiener": ((95.89, 94.46, 83.87, 84.53), (79.15, 82.11, 71.47, 83.58),
                               (79.71, 82.79, 76.58, 84.15), (83.98, 94.50, 89.07, 92.83),
                               (79.40, 79.78, 73.32, 82.68), (43.44, 62.04, 63.26, 75.93)),
    }.items()
}
"""[R] seed paper, Tables 5-8: fitness (%) by kind, order and profile."""


def compare_with_paper(table: dict, paper: dict | None = None) -> dict:
    """How a fitness table (kind -> order -> profile -> %) ranks against the paper's Tables 5-8.

    Parameters
    ----------
    table : dict
        Fitness by kind, order and profile (e.g. ``fitness.json`` of ``ebraille-sim identify``).
    paper : dict, optional
        The reference table (default :data:`PAPER_FITNESS`).

    Returns
    -------
    dict
        ``best`` (kind, order, mean fitness) and ``paper_best``; ``ranks`` (model ``kind-order``
        -> rank of its mean fitness among the models, 1 = best) and ``paper_ranks``;
        ``spearman_cells`` (rank correlation over every common cell) and
        ``spearman_means`` (over the model means); ``cells``, ``cells_within_5`` (cells
        within 5 points of the paper); ``wiener_triangle_0.1hz`` (fitness by order, the
        paper's and ours).
    """
    import scipy.stats

    paper = PAPER_FITNESS if paper is None else paper
    xs, ys, means, pmeans, keys = [], [], [], [], []
    for kind, by_order in paper.items():
        for order, row in by_order.items():
            ours = table.get(kind, {}).get(order, table.get(kind, {}).get(str(order)))
            if not ours:
                continue
            common = [name for name in row if name in ours]
            xs += [ours[name] for name in common]
            ys += [row[name] for name in common]
            means.append(float(np.mean([ours[name] for name in common])))
            pmeans.append(float(np.mean([row[name] for name in common])))
            keys.append(f"{kind}-{order}")
    if len(keys) < 2:
        raise ValueError("the table shares fewer than two models with the paper's")

    def ranks(vals):
        order = np.argsort(-np.asarray(vals), kind="stable")
        r = np.empty(len(vals), dtype=int)
        r[order] = np.arange(1, len(vals) + 1)
        return {k: int(v) for k, v in zip(keys, r)}

    ib, ip = int(np.argmax(means)), int(np.argmax(pmeans))
    tri = "triangle_0.1hz"
    wiener = table.get("wiener", {})
    return {
        "best": (keys[ib], means[ib]), "paper_best": (keys[ip], pmeans[ip]),
        "ranks": ranks(means), "paper_ranks": ranks(pmeans),
        "spearman_cells": float(scipy.stats.spearmanr(xs, ys)[0]),
        "spearman_means": float(scipy.stats.spearmanr(means, pmeans)[0]),
        "cells": len(xs), "cells_within_5": int(np.sum(np.abs(np.subtract(xs, ys)) <= 5.0)),
        "wiener_triangle_0.1hz": {
            "ours": {int(o): float(v[tri]) for o, v in wiener.items() if tri in v},
            "paper": {int(o): float(v[tri]) for o, v in paper.get("wiener", {}).items() if tri in v}},
    }


# ---------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------
def simulate(model: BlockModel, u: Any) -> np.ndarray:
    """Output of ``model`` for input ``u`` from rest (zero filter state), shape (n,)."""
    return model.simulate(u)[0]


def match_poles(estimated: Any, true: Any) -> float:
    """Largest distance between two pole sets after the best one-to-one pairing.

    Parameters
    ----------
    estimated, true : array_like of complex, same length

    Returns
    -------
    float
        ``max |p_est - p_true|`` over the pairing that minimises the sum of distances.
    """
    from scipy.optimize import linear_sum_assignment

    a = np.asarray(estimated, dtype=complex).ravel()
    b = np.asarray(true, dtype=complex).ravel()
    if a.size != b.size:
        raise ValueError(f"pole sets differ in size ({a.size} vs {b.size})")
    if a.size == 0:
        return 0.0
    d = np.abs(a[:, None] - b[None, :])
    r, c = linear_sum_assignment(d)
    return float(d[r, c].max())


def shift_operating_point(model: BlockModel, input_offset: float, output_offset: float,
                          name: str | None = None) -> BlockModel:
    """Re-express a model for signals measured from another reference.

    Returns ``m`` with ``m(u) = model(u - input_offset) + output_offset``.  A model
    identified on records detrended at the bench preload (input ``V - V_pre``, output
    ``F - F_pre``) becomes an estimator for the device, which tares the voltage at no load
    (input ``V - V_0``) and must read the absolute force: ``input_offset = V_pre - V_0``,
    ``output_offset = F_pre``.

    The offsets are folded into the static maps: an input shift of ``c`` moves an input
    map's breakpoints by ``c``, or, without an input map, an output map's breakpoints by
    ``g c`` (``g`` the steady-state gain of the linear block); the output offset is added
    to the output map's values, or, without one, to the input map's values divided by
    ``g``.  A linear model gains an output map (a shifted identity), so it becomes a
    Wiener model.  The maps agree exactly in steady state and, with the filter state at
    rest for the new input's zero (how the device starts its estimator), at every sample.

    Raises
    ------
    ValueError
        Non-finite offsets, or a linear block without a finite non-zero steady-state gain
        when the offset has to pass through it.
    """
    c, d = float(input_offset), float(output_offset)
    if not (math.isfinite(c) and math.isfinite(d)):
        raise ValueError(f"offsets must be finite, got {input_offset!r} and {output_offset!r}")
    inl, onl = model.input_nl, model.output_nl
    needs_gain = (inl is None and c != 0.0) or (onl is None and d != 0.0)
    g = model.linear.steady_state_gain() if needs_gain else 1.0
    if needs_gain and not (math.isfinite(g) and g != 0.0):
        raise ValueError(f"the linear block's steady-state gain is {g}; the offsets cannot pass through it")
    x_shift = 0.0
    if inl is not None:
        inl = PiecewiseLinear(tuple(np.asarray(inl.x_bp) + c), inl.y_bp)
    else:
        x_shift = g * c
    if onl is not None:
        onl = PiecewiseLinear(tuple(np.asarray(onl.x_bp) + x_shift), tuple(np.asarray(onl.y_bp) + d))
    elif inl is not None:
        inl = PiecewiseLinear(inl.x_bp, tuple(np.asarray(inl.y_bp) + d / g))
    else:   # linear: y = L(u) - g c + d
        e = d - x_shift
        onl = PiecewiseLinear((0.0, 1.0), (e, 1.0 + e))
    return BlockModel(model.linear, inl, onl, dt_s=model.dt_s, name=model.name if name is None else name)


def _shift(x: np.ndarray, d: int) -> np.ndarray:
    if d == 0:
        return x
    out = np.zeros_like(x)
    if d < x.shape[0]:
        out[d:] = x[:-d]
    return out


def _pwl_grad(x: np.ndarray, xb: np.ndarray, yb: np.ndarray):
    """Piecewise-linear map (end segments extrapolated) with its derivatives.

    Returns ``y``, the slope ``dy/dx``, ``dy/dxb`` (n, nbp) and ``dy/dyb`` (n, nbp).
    """
    nbp = xb.size
    j = np.clip(np.searchsorted(xb, x, side="right") - 1, 0, nbp - 2)
    x0, x1, y0, y1 = xb[j], xb[j + 1], yb[j], yb[j + 1]
    h = x1 - x0
    t = (x - x0) / h
    s = (y1 - y0) / h
    y = y0 + s * (x - x0)
    rows = np.arange(x.size)
    d_y = np.zeros((x.size, nbp))
    d_x = np.zeros((x.size, nbp))
    d_y[rows, j] = 1.0 - t
    d_y[rows, j + 1] = t
    d_x[rows, j] = -s * (1.0 - t)
    d_x[rows, j + 1] = -s * t
    return y, s, d_x, d_y


def _hat_basis(x: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """Values of the piecewise-linear basis (one column per breakpoint), shape (n, nbp)."""
    return _pwl_grad(x, xb, np.zeros_like(xb))[3]


@dataclass(frozen=True)
class _Poles:
    """Where the fitter may place the poles of ``F``: inside ``|z| < 1 - margin`` and, when
    ``clearance > 0``, at least ``clearance`` away from ``z = -1`` (the Nyquist frequency)."""
    margin: float
    clearance: float = 0.0

    def admissible(self, f: np.ndarray) -> bool:
        if f.size == 0:
            return True
        r = np.roots(np.concatenate([[1.0], f]))
        if float(np.max(np.abs(r))) >= 1.0 - self.margin:
            return False
        return not (self.clearance > 0.0 and float(np.min(np.abs(r + 1.0))) < self.clearance)


def _stabilise(f: np.ndarray, poles: _Poles) -> np.ndarray:
    """Move the roots of ``1 + f1 z^-1 + ...`` into the admissible region: reflected into
    ``|z| <= 1 - 2 margin``, and pushed out to ``2 clearance`` from ``z = -1``."""
    if f.size == 0:
        return f
    r = np.roots(np.concatenate([[1.0], f]))
    mag = np.abs(r)
    limit = 1.0 - 2.0 * poles.margin
    near = poles.clearance > 0.0 and bool(np.any(np.abs(r + 1.0) < 2.0 * poles.clearance))
    if np.all(mag < limit) and not near:
        return f
    r = np.where(mag > 1.0, r / mag ** 2, r)
    mag = np.abs(r)
    r = np.where(mag > limit, r * (limit / np.maximum(mag, 1e-300)), r)
    if poles.clearance > 0.0:
        d = r + 1.0
        dist = np.abs(d)
        away = np.where(dist > 1e-12, d / np.maximum(dist, 1e-300), 1.0 + 0.0j)
        r = np.where(dist < 2.0 * poles.clearance, -1.0 + 2.0 * poles.clearance * away, r)
    return np.real(np.poly(r))[1:]


# ---------------------------------------------------------------------------
# parametrisation
# ---------------------------------------------------------------------------
def _fractions(eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ordered positions ``0 = s_0 < s_1 < ... < s_{m-1} = 1`` from ``m - 2`` free numbers.

    The ``m - 1`` gaps are a softmax of ``(eta, 0)``.  Returns ``s`` (m,) and ``ds/deta``
    (m, m - 2).
    """
    z = np.concatenate([eta, [0.0]])
    e = np.exp(np.clip(z - np.max(z), -30.0, 0.0))
    g = e / e.sum()
    dg = (np.diag(g) - np.outer(g, g))[:, :-1]          # d g_i / d eta_j
    s = np.concatenate([[0.0], np.cumsum(g)])
    s[-1] = 1.0
    ds = np.vstack([np.zeros((1, eta.size)), np.cumsum(dg, axis=0)])
    ds[-1] = 0.0
    return s, ds


@dataclass
class _Structure:
    """Layout of the parameter vector for one kind/order/delay.

    Each piecewise-linear map has ``nbp`` breakpoints: the outer two sit at the ends of the
    range of the map's input over the estimation data (the measured input for an input
    map, the simulated linear output for an output map), the interior ones at ordered
    fractions of that range (:func:`_fractions`).  With linear extrapolation the outer
    breakpoints are not kinks, so this removes the directions along which they would slide
    without changing the map, and keeps the kinks where the data are.
    """
    kind: str
    nb: int
    nf: int
    nk: int
    nbp: int
    fixed_b: int | None               # index of the B coefficient held at +1 (None: all free)
    u_range: tuple[float, float] = (0.0, 1.0)
    pinned_in: tuple[int, ...] = ()   # input-map values held (H-W gauge)
    pinned_values: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def has_in(self) -> bool:
        return self.kind in ("hammerstein", "hammerstein-wiener")

    @property
    def has_out(self) -> bool:
        return self.kind in ("wiener", "hammerstein-wiener")

    def free_b(self) -> list[int]:
        return [j for j in range(self.nb) if j != self.fixed_b]

    def free_in_y(self) -> list[int]:
        return [j for j in range(self.nbp) if j not in self.pinned_in]

    def pack(self, b, f, eta_in=None, in_y=None, eta_out=None, out_y=None) -> np.ndarray:
        parts = [np.asarray(b, float)[self.free_b()], np.asarray(f, float)]
        if self.has_in:
            parts += [np.asarray(eta_in, float), np.asarray(in_y, float)[self.free_in_y()]]
        if self.has_out:
            parts += [np.asarray(eta_out, float), np.asarray(out_y, float)]
        return np.concatenate(parts)

    def unpack(self, theta: np.ndarray):
        i = 0
        fb = self.free_b()
        b = np.ones(self.nb)
        b[fb] = theta[i:i + len(fb)]
        i += len(fb)
        f = theta[i:i + self.nf]
        i += self.nf
        eta_in = in_y = eta_out = out_y = None
        m = self.nbp - 2
        if self.has_in:
            eta_in = theta[i:i + m]
            i += m
            in_y = np.empty(self.nbp)
            in_y[list(self.pinned_in)] = self.pinned_values
            fi = self.free_in_y()
            in_y[fi] = theta[i:i + len(fi)]
            i += len(fi)
        if self.has_out:
            eta_out = theta[i:i + m]
            i += m
            out_y = theta[i:i + self.nbp]
            i += self.nbp
        return b, f, eta_in, in_y, eta_out, out_y


def _forward(st: _Structure, theta: np.ndarray, u: np.ndarray, jac: bool, poles: _Poles):
    """Simulated output, Jacobian and breakpoints of ``theta``; None if not admissible.

    Returns ``(y, J, in_x, out_x)`` (``J`` is None unless ``jac``).
    """
    b, f, eta_in, in_y, eta_out, out_y = st.unpack(theta)
    if not poles.admissible(f):
        return None
    den = np.concatenate([[1.0], f])
    num = np.concatenate([np.zeros(st.nk), b])
    in_x = out_x = None
    if st.has_in:
        lo, hi = st.u_range
        s_in, ds_in = _fractions(eta_in)
        if np.min(np.diff(s_in)) < 1e-9:
            return None
        in_x = lo + (hi - lo) * s_in
        w, _, dw_dxb, dw_dyb = _pwl_grad(u, in_x, in_y)
    else:
        w = u
    x = lfilter(num, den, w)
    if st.has_out:
        i_lo, i_hi = int(np.argmin(x)), int(np.argmax(x))
        lo_x, hi_x = float(x[i_lo]), float(x[i_hi])
        if not hi_x - lo_x > 1e-12 * max(1.0, abs(lo_x), abs(hi_x)):
            return None
        s_out, ds_out = _fractions(eta_out)
        if np.min(np.diff(s_out)) < 1e-9:
            return None
        out_x = lo_x + (hi_x - lo_x) * s_out
        y, slope, dy_dxb, dy_dyb = _pwl_grad(x, out_x, out_y)
    else:
        y = x
    if not jac:
        return y, None, in_x, out_x
    cols = []
    w_f = lfilter([1.0], den, w)
    x_f = lfilter([1.0], den, x)
    for j in st.free_b():
        cols.append(_shift(w_f, st.nk + j))
    for i in range(1, st.nf + 1):
        cols.append(-_shift(x_f, i))
    jx = np.column_stack(cols)
    if st.has_in:
        lo, hi = st.u_range
        d_in = np.column_stack([dw_dxb @ ((hi - lo) * ds_in), dw_dyb[:, st.free_in_y()]])
        jx = np.column_stack([jx, lfilter(num, den, d_in, axis=0)])
    if st.has_out:
        dxb = np.outer(1.0 - s_out, jx[i_lo]) + np.outer(s_out, jx[i_hi])   # outer points follow the range
        j_up = slope[:, None] * jx + dy_dxb @ dxb
        jx = np.column_stack([j_up, dy_dxb @ ((hi_x - lo_x) * ds_out), dy_dyb])
    return y, jx, in_x, out_x


ANCHOR_REL = 1e-16
"""Weight of the anchoring rows in the joint refinement, relative to the largest squared
Jacobian column norm at the start (see :func:`_refine`)."""


def _refine(st: _Structure, theta0: np.ndarray, u: np.ndarray, y: np.ndarray, max_nfev: int, poles: _Poles):
    """Joint least-squares refinement of the simulation error; returns (theta, cost).

    The residual carries ``theta.size`` anchoring rows ``lam * (theta - theta0)``, ``lam`` being
    ``ANCHOR_REL ** 0.5`` times the largest Jacobian column norm at the start.  A block model's
    Jacobian is often rank-deficient (a breakpoint segment no sample reaches: singular values
    1e-13 of the largest); Levenberg-Marquardt then steps along the null directions by
    amplified rounding, and MINPACK's rounding there depended on where the process's heap put
    its work arrays, so the same seed gave different models from run to run (fitness moving
    in the 2nd-4th decimal, 0.2 points on another record).  The anchor holds those directions
    at the start and adds ``ANCHOR_REL`` of the curvature elsewhere, far below what the data
    resolve.  The returned cost is the data's alone.
    """
    big = 1e6 * (float(np.std(y)) + 1e-12)
    cache: dict = {}
    out0 = _forward(st, theta0, u, True, poles)
    if out0 is None:
        return theta0, math.inf
    r0 = out0[0] - y
    lam = math.sqrt(ANCHOR_REL) * max(float(np.max(np.linalg.norm(out0[1], axis=0))), 1e-300)
    anchor_jac = lam * np.eye(theta0.size)

    def fun(th):
        out = _forward(st, th, u, True, poles)
        cache["x"], cache["out"] = th.copy(), out
        if out is None:
            return np.full(y.size + th.size, big)
        return np.concatenate([out[0] - y, lam * (th - theta0)])

    def jac(th):
        out = cache["out"] if np.array_equal(cache.get("x"), th) else _forward(st, th, u, True, poles)
        if out is None:          # not reached at accepted points; keeps the solver safe
            return np.vstack([np.zeros((y.size, th.size)), anchor_jac])
        return np.vstack([out[1], anchor_jac])

    res = scipy.optimize.least_squares(fun, theta0, jac=jac, method="lm", x_scale="jac",
                                       max_nfev=max_nfev, xtol=1e-9, ftol=1e-9, gtol=1e-9)
    out = _forward(st, res.x, u, False, poles) if np.all(np.isfinite(res.x)) else None
    if out is None:
        return theta0, 0.5 * float(r0 @ r0)
    r = out[0] - y
    return res.x, 0.5 * float(r @ r)


# ---------------------------------------------------------------------------
# linear output-error initialisation
# ---------------------------------------------------------------------------
def _arx(u: np.ndarray, y: np.ndarray, nb: int, nf: int, nk: int) -> tuple[np.ndarray, np.ndarray]:
    """Equation-error least squares ``F(q) y = B(q) q^-nk u``."""
    cols = [-_shift(y, i) for i in range(1, nf + 1)] + [_shift(u, nk + j) for j in range(nb)]
    phi = np.column_stack(cols)
    start = nf + nk + nb
    theta, *_ = np.linalg.lstsq(phi[start:], y[start:], rcond=None)
    return theta[nf:], theta[:nf]


def _b_given_f(u: np.ndarray, y: np.ndarray, f: np.ndarray, nb: int, nk: int) -> np.ndarray:
    """Output-error ``B`` for a fixed ``F`` (linear least squares)."""
    u_f = lfilter([1.0], np.concatenate([[1.0], f]), u)
    phi = np.column_stack([_shift(u_f, nk + j) for j in range(nb)])
    b, *_ = np.linalg.lstsq(phi, y, rcond=None)
    return b


def _oe_refine(u, y, b, f, nk, max_nfev, poles):
    st = _Structure("linear", b.size, f.size, nk, 2, None)
    theta, cost = _refine(st, st.pack(b, f), u, y, max_nfev, poles)
    b, f, *_ = st.unpack(theta)
    return b.copy(), f.copy(), cost


def _linear_oe(u, y, nb, nf, nk, max_nfev, poles):
    """Linear output-error fit; returns (b, f, cost).

    Candidates: the ARX estimate and its Steiglitz-McBride iterates, each stabilised and
    given the output-error ``B`` for its ``F``; the two best by simulation error are
    refined and the better kept.
    """
    b, f = _arx(u, y, nb, nf, nk)
    cands = [_stabilise(f, poles)]
    for _ in range(6):   # Steiglitz-McBride
        den = np.concatenate([[1.0], cands[-1]])
        _, f_new = _arx(lfilter([1.0], den, u), lfilter([1.0], den, y), nb, nf, nk)
        cands.append(_stabilise(f_new, poles))
    scored = []
    for f_c in cands:
        b_c = _b_given_f(u, y, f_c, nb, nk)
        r = lfilter(np.concatenate([np.zeros(nk), b_c]), np.concatenate([[1.0], f_c]), u) - y
        scored.append((float(r @ r), b_c, f_c))
    scored.sort(key=lambda t: t[0])
    best = None
    for _, b_c, f_c in scored[:2]:
        out = _oe_refine(u, y, b_c, f_c, nk, max_nfev, poles)
        if best is None or out[2] < best[2]:
            best = out
    return best


def _perturb_f(f: np.ndarray, rng: np.random.Generator, poles: _Poles, scale: float = 0.15) -> np.ndarray:
    """Random perturbation of the poles (radius and angle), conjugate pairs kept."""
    if f.size == 0:
        return f
    r = np.roots(np.concatenate([[1.0], f]))
    out = []
    done = np.zeros(r.size, bool)
    for i, p in enumerate(r):
        if done[i]:
            continue
        done[i] = True
        rad = min(abs(p) * math.exp(scale * rng.standard_normal()), 1.0 - 2.0 * poles.margin)
        if abs(p.imag) > 1e-9:
            ang = min(abs(np.angle(p)) * math.exp(scale * rng.standard_normal()), math.pi - 1e-3)
            q = rad * np.exp(1j * ang)
            out += [q, np.conj(q)]
            j = int(np.argmin(np.where(done, np.inf, np.abs(r - np.conj(p)))))
            done[j] = True
        else:
            out.append(math.copysign(rad, p.real))
    f_new = np.real(np.poly(out))[1:]
    return _stabilise(f_new, poles) if poles.clearance > 0.0 else f_new


# ---------------------------------------------------------------------------
# nonlinear initialisation
# ---------------------------------------------------------------------------
def _range(x: np.ndarray) -> tuple[float, float]:
    lo, hi = float(np.min(x)), float(np.max(x))
    if hi - lo <= 1e-12 * max(1.0, abs(lo)):
        hi = lo + 1.0
    return lo, hi


def _normalise_index(b: np.ndarray, fix_b) -> int:
    return int(np.argmax(np.abs(b))) if fix_b == "largest" else int(fix_b)


def _hammerstein_regression(u, y, nb, nf, nk, nbp, poles, iterations=6):
    """Linear block and input-map values of a Hammerstein model by linear regression.

    With the input map written on the piecewise-linear basis, ``y = B/F q^-nk sum_k v_k
    phi_k(u)`` is linear in the products ``c_jk = b_j v_k``.  The basis sums to one, so a
    constant added to the map is not identifiable from the products: the first basis
    function is left out (``v_0 = 0``) and a constant term ``d B(1)/F(1)`` is estimated
    instead.  The products are estimated by least squares with ``F`` from
    Steiglitz-McBride iterations (equation error, then the data prefiltered by ``1/F``),
    and ``b`` and ``v`` follow from the best rank-one approximation of the matrix ``c``
    (its leading singular vectors); ``d`` is added back to every value.

    Returns ``b`` (nb,), ``f`` (nf,), ``v`` (nbp,) with the breakpoints evenly spread over
    the range of ``u``.
    """
    lo, hi = _range(u)
    phi = _hat_basis(u, np.linspace(lo, hi, nbp))[:, 1:]
    m = nbp - 1

    def regress(uf, yf, one, with_f):
        cols = [-_shift(yf, i) for i in range(1, nf + 1)] if with_f else []
        cols += [_shift(uf[:, k], nk + j) for j in range(nb) for k in range(m)] + [one]
        start = nf + nk + nb
        th, *_ = np.linalg.lstsq(np.column_stack(cols)[start:], yf[start:], rcond=None)
        return th

    ones = np.ones_like(u)
    th = regress(phi, y, ones, True)
    f = _stabilise(th[:nf], poles)
    for _ in range(iterations):
        den = np.concatenate([[1.0], f])
        th = regress(lfilter([1.0], den, phi, axis=0), lfilter([1.0], den, y), ones, True)
        f = _stabilise(th[:nf], poles)
    # output-error products for the final F, then the rank-one split
    den = np.concatenate([[1.0], f])
    th = regress(lfilter([1.0], den, phi, axis=0), y, lfilter([1.0], den, ones), False)
    c = th[:-1].reshape(nb, m)
    uu, sv, vt = np.linalg.svd(c)
    b, v = uu[:, 0] * sv[0], vt[0]
    d = th[-1] / b.sum() if abs(b.sum()) > 1e-12 else 0.0
    return b, f, np.concatenate([[0.0], v]) + d


def _init_theta(kind, u, y, b, f, nk, nbp, fix_b, rng=None, side="hammerstein", in_y=None):
    """Structure and starting vector for the joint refinement from a linear block ``(b, f)``.

    ``in_y`` (optional) gives the input-map values at evenly spread breakpoints together
    with ``b`` (as :func:`_hammerstein_regression` returns them).
    """
    nb, nf = b.size, f.size
    u_range = _range(u)
    if kind == "linear":
        st = _Structure("linear", nb, nf, nk, nbp, None, u_range)
        return st, st.pack(b, f)
    idx = _normalise_index(b, fix_b)
    g = float(b[idx]) if b[idx] != 0.0 else 1.0
    bn = b / g
    bn[idx] = 1.0
    den = np.concatenate([[1.0], f])
    num = np.concatenate([np.zeros(nk), bn])
    m = nbp - 2
    eta0 = np.zeros(m) if rng is None else 0.5 * rng.standard_normal(m)
    eta1 = np.zeros(m) if rng is None else 0.5 * rng.standard_normal(m)
    s0 = _fractions(eta0)[0]
    s1 = _fractions(eta1)[0]

    if kind == "wiener":
        x = lfilter(num, den, u)
        lo, hi = _range(x)
        out_y, *_ = np.linalg.lstsq(_hat_basis(x, lo + (hi - lo) * s1), y, rcond=None)
        st = _Structure("wiener", nb, nf, nk, nbp, idx, u_range)
        return st, st.pack(bn, f, eta_out=eta1, out_y=out_y)
    in_x = u_range[0] + (u_range[1] - u_range[0]) * s0
    if in_y is not None:
        in_y = g * np.asarray(in_y, float)
        if rng is not None:   # values at the jittered breakpoints
            even = np.linspace(u_range[0], u_range[1], nbp)
            in_y = _pwl_grad(in_x, even, in_y)[0]
    elif kind == "hammerstein" or side == "hammerstein":
        basis = lfilter(num, den, _hat_basis(u, in_x), axis=0)
        in_y, *_ = np.linalg.lstsq(basis, y, rcond=None)
    else:   # H-W from the Wiener side: identity input map times the linear gain
        in_y = g * in_x
    if kind == "hammerstein":
        st = _Structure("hammerstein", nb, nf, nk, nbp, idx, u_range)
        return st, st.pack(bn, f, eta_in=eta0, in_y=in_y)
    if np.any(np.diff(in_y) == 0):
        in_y = g * in_x
    x = lfilter(num, den, _pwl_grad(u, in_x, np.asarray(in_y))[0])
    lo, hi = _range(x)
    out_y, *_ = np.linalg.lstsq(_hat_basis(x, lo + (hi - lo) * s1), y, rcond=None)
    pinned = (0, nbp - 1)
    st = _Structure("hammerstein-wiener", nb, nf, nk, nbp, idx, u_range, pinned, np.asarray(in_y)[list(pinned)])
    return st, st.pack(bn, f, eta_in=eta0, in_y=in_y, eta_out=eta1, out_y=out_y)


def _to_model(st: _Structure, theta: np.ndarray, u: np.ndarray, dt_s: float, fix_b, name: str) -> BlockModel:
    """Block model from a parameter vector, renormalised to the ``fix_b`` convention."""
    out = _forward(st, theta, u, False, _Poles(0.0))
    b, f, _, in_y, _, out_y = st.unpack(theta)
    in_x, out_x = out[2], out[3]
    b = b.copy()
    if st.kind != "linear":
        idx = _normalise_index(b, fix_b)
        g = float(b[idx])
        b = b / g
        b[idx] = 1.0
        if st.has_out:
            out_x = np.asarray(out_x) / g
            out_y = np.asarray(out_y)
            if g < 0:
                out_x, out_y = out_x[::-1], out_y[::-1]
        else:
            in_y = np.asarray(in_y) * g
    lin = LinearBF(b=tuple(b), f=tuple(f), nk=st.nk)
    inl = PiecewiseLinear(tuple(in_x), tuple(in_y)) if st.has_in else None
    onl = PiecewiseLinear(tuple(out_x), tuple(out_y)) if st.has_out else None
    return BlockModel(lin, inl, onl, dt_s=dt_s, name=name)


# ---------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class FitResult:
    """Outcome of :func:`fit_report`.

    Attributes
    ----------
    model : BlockModel
        The identified model (the one :func:`fit` returns).
    fitness_pct : float
        Eq. 7 fit on the estimation data (simulated from rest), %.
    nk : int
        Input delay chosen.
    linear_fitness_by_nk : dict
        Fit (%) of the linear output-error model for each delay tried.
    start_fitness_pct : tuple of float
        Estimation fit of every start, in order (the best is kept).
    fitness_by_nk : dict
        Estimation fit (%) of the best start for each delay carried into the nonlinear
        refinement (the delays of ``linear_fitness_by_nk`` with the lowest error).
    """
    model: BlockModel
    fitness_pct: float
    nk: int
    linear_fitness_by_nk: dict
    start_fitness_pct: tuple
    fitness_by_nk: dict = field(default_factory=dict)


def _check_signal(x: Any, name: str) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a sequence of real numbers") from None
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        k = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise ValueError(f"{name} must be finite; sample {k} is {arr[k]}")
    return arr


def _check_int(v: Any, name: str, lo: int, hi: int | None = None) -> int:
    return check_number(name, v, lo, hi, integer=True)


def fit_report(kind: str, u: Any, y: Any, order: int, nk: int | None = None, *, dt_s: float = SAMPLE_TIME_S,
               n_breakpoints: int = 4, n_starts: int = 4, max_nk: int = 3, n_delay_candidates: int = 2,
               seed: int = 0, max_nfev: int = 200, fix_b: Any = "largest", margin: float = DEFAULT_MARGIN,
               nyquist_clearance: float = 0.0, name: str | None = None) -> FitResult:
    """Identify a block-oriented model and report how the search went.

    Parameters
    ----------
    kind : {"linear", "hammerstein", "wiener", "hammerstein-wiener"}
    u, y : array_like, shape (n,)
        Input and output records (for the FSR estimators: detrended voltage, V, and
        detrended force, N), starting at rest.
    order : int
        ``nb = nf = order`` (1-10; the paper uses 2-5).
    nk : int or None
        Input delay in samples; None searches ``0..max_nk``.
    dt_s : float
        Sample time stored in the model, s.
    n_breakpoints : int
        Breakpoints per piecewise-linear map (>= 2; the paper uses 4).
    n_starts : int
        Starts of the joint refinement per candidate delay (>= 1).
    max_nk : int
        Largest delay tried when ``nk`` is None.
    n_delay_candidates : int
        Delays (best by linear fit) carried into the nonlinear refinement.
    seed : int
        Seed of the random start perturbations.
    max_nfev : int
        Function evaluations per refinement.
    fix_b : "largest" or int
        B coefficient held at +1: the largest in magnitude (MATLAB ``idnlhw``) or an index.
    margin : float
        Poles are kept within ``|z| < 1 - margin``.
    nyquist_clearance : float
        Poles are kept at least this far from ``z = -1``, in ``[0, 1)``.  0 (default) lets
        the fit place them anywhere inside the stability margin, as MATLAB's ``idnlhw`` did
        for most of the paper's models (poles within 0.04 of ``z = -1``); a positive value
        keeps the linear block from resonating at the Nyquist frequency, where a record
        band-limited well below it carries no information.
    name : str, optional
        Model name (default ``"<kind> order <order>, identified"``).

    Returns
    -------
    FitResult

    Raises
    ------
    ValueError
        One line naming the problem: unknown kind or option, bad lengths, non-finite or
        constant data, too few samples for the number of parameters.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown model kind {kind!r}; allowed: {', '.join(KINDS)}")
    order = _check_int(order, "order", 1, 10)
    u = _check_signal(u, "u")
    y = _check_signal(y, "y")
    if u.shape != y.shape:
        raise ValueError(f"u and y differ in length ({u.size} vs {y.size})")
    if np.ptp(u) == 0 or np.ptp(y) == 0:
        raise ValueError("u and y must both vary; a constant record cannot identify a model")
    nbp = _check_int(n_breakpoints, "n_breakpoints", 2, 50)
    n_starts = _check_int(n_starts, "n_starts", 1)
    max_nk = _check_int(max_nk, "max_nk", 0, 50)
    n_delay_candidates = _check_int(n_delay_candidates, "n_delay_candidates", 1)
    max_nfev = _check_int(max_nfev, "max_nfev", 1)
    seed = _check_int(seed, "seed", 0)
    if not (fix_b == "largest" or (isinstance(fix_b, (int, np.integer)) and not isinstance(fix_b, bool)
                                   and 0 <= fix_b < order)):
        raise ValueError(f"fix_b must be 'largest' or an index 0..{order - 1}, got {fix_b!r}")
    margin = check_number("margin", margin, 0.0, 0.5, lo_open=True, hi_open=True)
    clearance = check_number("nyquist_clearance", nyquist_clearance, 0.0, 1.0, hi_open=True)
    poles = _Poles(margin, clearance)
    dt_s = check_number("dt_s", dt_s, lo=0.0, lo_open=True)
    nks = list(range(max_nk + 1)) if nk is None else [_check_int(nk, "nk", 0, 50)]
    n_par = 2 * order + (2 * nbp if kind != "linear" else 0) * (2 if kind == "hammerstein-wiener" else 1)
    if u.size < 10 * (n_par + max(nks) + 1):
        raise ValueError(f"{u.size} samples are too few for a {kind} model of order {order} "
                         f"({n_par} parameters); at least {10 * (n_par + max(nks) + 1)} are needed")
    name = f"{kind} order {order}, identified" if name is None else str(name)

    # 1. linear output-error per delay
    linear = {}
    u0, y0 = u - np.mean(u), y - np.mean(y)
    for d in nks:
        # the best linear approximation from mean-free data initialises the nonlinear
        # kinds (an offset would otherwise be fitted by slow poles); the linear kind is
        # refined on the data as they are
        b, f, cost = _linear_oe(u0, y0, order, order, d, max_nfev, poles)
        if kind == "linear":
            b_r, f_r, cost_r = _linear_oe(u, y, order, order, d, max_nfev, poles)
            b2, f2, cost2 = _oe_refine(u, y, b, f, d, max_nfev, poles)
            b, f, cost = (b_r, f_r, cost_r) if cost_r <= cost2 else (b2, f2, cost2)
        y_lin = lfilter(np.concatenate([np.zeros(d), b]), np.concatenate([[1.0], f]), u if kind == "linear" else u0)
        linear[d] = (b, f, cost, fitness(y if kind == "linear" else y0, y_lin))
    ranked = sorted(nks, key=lambda d: linear[d][2])[:n_delay_candidates]

    # 2-4. initialise, refine, multi-start
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
    best = None
    start_fits = []
    by_nk = {}
    for d in ranked:
        b0, f0, _, _ = linear[d]
        starts = []
        if kind in ("hammerstein", "hammerstein-wiener"):
            b_h, f_h, v_h = _hammerstein_regression(u, y, order, order, d, nbp, poles)
            starts.append((b_h, f_h, None, "hammerstein", v_h))
        starts.append((b0, f0, None, "hammerstein", None))
        if kind == "hammerstein-wiener":
            starts.append((b0, f0, None, "wiener", None))
        starts = starts[:n_starts]
        while len(starts) < n_starts:
            f_p = _perturb_f(f0, rng, poles)
            b_p = _b_given_f(u0, y0, f_p, order, d)
            starts.append((b_p, f_p, rng, "hammerstein" if len(starts) % 2 == 0 else "wiener", None))
        for b_s, f_s, r_s, side, v_s in starts:
            st, th0 = _init_theta(kind, u, y, b_s, f_s, d, nbp, fix_b, r_s, side, v_s)
            th, cost = _refine(st, th0, u, y, max_nfev, poles)
            if not math.isfinite(cost):
                continue
            model = _to_model(st, th, u, dt_s, fix_b, name)
            fit_pct = fitness(y, simulate(model, u))
            start_fits.append(fit_pct)
            by_nk[d] = max(by_nk.get(d, -math.inf), fit_pct)
            if best is None or fit_pct > best[0]:
                best = (fit_pct, model, d)
    if best is None:
        raise ValueError(f"no admissible {kind} model of order {order} was found (every start was unstable)")
    return FitResult(model=best[1], fitness_pct=best[0], nk=best[2],
                     linear_fitness_by_nk={d: linear[d][3] for d in nks}, start_fitness_pct=tuple(start_fits),
                     fitness_by_nk=dict(sorted(by_nk.items())))


def fit_readings(kind: str, u: Any, y: Any, order: int, nks=NK_READINGS, **options) -> dict:
    """Identify the same model once for each input delay in ``nks`` on the same data.

    The paper prints no input delay: ``nk = 0`` reads its notation literally, ``nk = 1`` is
    MATLAB's convention (:data:`ebraille_sim.estimation.paper_models.NK_READINGS`, the
    default ``nks``).  Each fit holds its delay fixed (:func:`fit_report` with ``nk``), so the
    results' ``fitness_pct`` compare the readings on one record.

    Parameters
    ----------
    kind, u, y, order
        As in :func:`fit_report`.
    nks : sequence of int
        The delays, samples (each 0-50, none twice).
    **options
        Keyword options of :func:`fit_report` (not ``nk``).

    Returns
    -------
    dict
        ``{nk: FitResult}`` in the order of ``nks``.
    """
    if "nk" in options:
        raise TypeError("fit_readings fixes nk itself; give the delays as nks")
    nks = [_check_int(k, "nk", 0, 50) for k in nks]
    if not nks or len(set(nks)) != len(nks):
        raise ValueError(f"nks must name at least one delay, none twice, got {nks!r}")
    return {k: fit_report(kind, u, y, order, k, **options) for k in nks}


def fit(kind: str, u: Any, y: Any, order: int, nk: int | None = None, **options) -> BlockModel:
    """Identify a block-oriented model; see :func:`fit_report` for the options.

    Parameters
    ----------
    kind : {"linear", "hammerstein", "wiener", "hammerstein-wiener"}
    u, y : array_like, shape (n,)
        Input and output records, starting at rest.
    order : int
        ``nb = nf = order``.
    nk : int or None
        Input delay; None searches it.
    **options
        Keyword options of :func:`fit_report`; an unknown one raises ``TypeError``.

    Returns
    -------
    BlockModel
        ``model.simulate(u)[0]`` is the output from rest.
    """
    return fit_report(kind, u, y, order, nk, **options).model
