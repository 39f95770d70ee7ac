"""Published voltage-to-force estimators of the Interlink FSR 402, as data.

The seed paper, "Identification of a force-sensing resistor for tactile
applications", identifies with MATLAB's System Identification Toolbox sixteen
discrete-time models that estimate the contact force from the voltage-divider
output of the FSR:

* 4 linear models ``B/F`` of orders 2-5 (its Appendix 1),
* 12 block-oriented models (Hammerstein, Wiener, Hammerstein-Wiener; orders
  2-5) with 4-breakpoint piecewise-linear nonlinearities (Appendices 2-3).

Conventions used for every model here:

* input ``u``: detrended FSR voltage in V; output ``y``: detrended force in N;
* sample time 0.01 s (100 Hz);
* linear block ``z^-nk B(z^-1)/F(z^-1)`` with ``nk = 1`` (see ``NK``); the
  printed coefficients ``b0, b1, ...`` are the ones after the delay and
  ``a1, a2, ...`` are ``F``'s coefficients without the leading 1;
* the appendix coefficients are rounded to 3 decimals, so common
  ``(1 - z^-1)`` factors of ``B`` and ``F`` are detected with the tolerance
  ``UNIT_ROOT_TOL`` and cancelled by exact synthetic division
  (:meth:`ebraille_sim.estimation.blockmodels.LinearBF.cancel_unit_roots`).

The text extraction of the appendices garbled some signs and digits. Every
reading decision is listed in ``TRANSCRIPTION_DECISIONS``; the coefficient
tables below are the values after those decisions.

Examples
--------
>>> m = paper_model(*DEFAULT_ESTIMATOR)
>>> m.kind, round(m.linear.steady_state_gain(), 3)
('wiener', -0.192)
>>> round(m.steady_state(1.193), 1)
2.8
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ebraille_sim.estimation.blockmodels import BlockModel, LinearBF, PiecewiseLinear

__all__ = [
    "KINDS",
    "ORDERS",
    "SAMPLE_TIME_S",
    "NK",
    "NK_READINGS",
    "UNIT_ROOT_TOL",
    "STABILITY_MARGIN",
    "INPUT_RANGE_V",
    "DEFAULT_ESTIMATOR",
    "TranscriptionDecision",
    "TRANSCRIPTION_DECISIONS",
    "paper_model",
    "paper_model_table",
]

#: Model kinds, in the order of the paper's tables.
KINDS = ("linear", "hammerstein", "wiener", "hammerstein-wiener")
#: Orders of the linear block (``nb = nf = order``).
ORDERS = (2, 3, 4, 5)
#: Sample time of all models, s (100 Hz sampling).
SAMPLE_TIME_S = 0.01

#: Input delay of all models, samples.
#:
#: The paper does not print ``nk``; read literally, its notation ``B(z^-1)`` with a
#: printed ``b0`` gives ``nk = 0``.  ``nk = 1`` is MATLAB's default for
#: ``idnlhw``/``oe`` orders and matches the paper's remark that the first
#: ``nk`` coefficients of ``B`` are zeros while every printed ``b0`` is
#: non-zero (the printed list starts after the delay). ``nk`` only shifts the
#: output by one sample (10 ms): it changes neither the poles, the zeros, the
#: DC gain nor any static map, so the fifth-order Wiener consistency check
#: (DC gain -0.192 maps 0-1.19 V onto the output breakpoint span
#: [-0.229, 0]) holds for any ``nk`` and cannot decide it.  The choice is 10 ms of
#: estimator delay (docs/identification.md gives its effect on the loop): the default is
#: ``NK`` and the other reading is ``nk=0`` of :func:`paper_model` (model spec
#: ``"paper:wiener:5:nk0"``).  The default keeps the reading with the smaller margins (the
#: default PID's phase margin at 1 N is 33.9 deg with it, 57.0 deg without); robust tuning
#: checks both (:func:`ebraille_sim.analysis.robust.linearisation_points`), and
#: :func:`ebraille_sim.identification.sysid.fit_readings` fits both on one record.
NK = 1
NK_READINGS = (0, 1)
"""The two readings of the paper's input delay (samples): its notation read literally, and
MATLAB's convention."""

#: Absolute tolerance on ``B(1)`` and ``F(1)`` for detecting a common
#: ``(1 - z^-1)`` factor. Each printed coefficient carries a rounding error of
#: at most 5e-4, so ``B(1)`` and ``F(1)`` of a true unit root are at most
#: 5 x 5e-4 = 2.5e-3 off for the fifth-order models; after one division the
#: quotient's value at 1 is a weighted sum with weights 1..4, bounded by 5e-3.
#: Values genuinely away from zero in the tables are 6e-3 (``B(1)``) and
#: 1.3e-2 (``F(1)``) or larger, so 5e-3 separates the two cases.
UNIT_ROOT_TOL = 5e-3

#: A model counts as stable when every pole satisfies ``|p| < 1 - STABILITY_MARGIN``.
STABILITY_MARGIN = 1e-6

#: Steady FSR-voltage range used for the static force range in the table, V.
#: The input breakpoints of the paper span about 0.13-1.16 V and the
#: fifth-order Wiener model reaches its lowest output breakpoint at 1.193 V.
INPUT_RANGE_V = (0.0, 1.193)

#: The paper's best model overall (Table 7), used as the device's estimator.
DEFAULT_ESTIMATOR = ("wiener", 5)


# ---------------------------------------------------------------------------
# data provenance
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class TranscriptionDecision:
    """One reading decision on a garbled or ambiguous appendix entry.

    Parameters
    ----------
    location : str
        Appendix, model and column.
    printed : str
        The extracted text (``\\u2212`` is the minus sign U+2212, ``\\u0131`` the
        dotless i U+0131).
    read_as : str
        The value or reading adopted.
    reason : str
        The evidence for the reading.
    """

    location: str
    printed: str
    read_as: str
    reason: str


_B1_REASON = (
    "b1 is the B coefficient fixed by the estimator (MATLAB fixes it at +1); with +1, "
    "B(1) matches the unit root of F (or, for order 2 Wiener/H-W, leaves a finite gain "
    "consistent with the breakpoints); with -1 B(1) would be about -2 and the model would integrate"
)

TRANSCRIPTION_DECISIONS: tuple[TranscriptionDecision, ...] = (
    TranscriptionDecision(
        "Appendix 1, all rows",
        "two orders per line: 'Second order Third order', 'Fourth order Fifth order'",
        "each cell holds the value of the first-named order then of the second; a single value "
        "belongs to the higher order (it has one more coefficient)",
        "with this pairing B(1) and A(1) vanish to rounding for all four models",
    ),
    TranscriptionDecision(
        "Appendix 1, headers",
        "'a _I', 'a_3', ...",
        "a1..a5 = F coefficients without the leading 1",
        "column order of the table",
    ),
    TranscriptionDecision(
        "Appendix 1, fifth order, B",
        "8.591 \u221220.301 19.425 -8.932 1.216",
        "as printed; B(1) = -0.001 is rounding, cancelled within UNIT_ROOT_TOL",
        "A(1) = 0.000 for the same model",
    ),
    TranscriptionDecision("Appendix 2, order 2 Hammerstein, b1", "\u0131", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 2 Wiener, b1", "-1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 2 Hammerstein-Wiener, b1", "- 1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 3 Hammerstein, b1", "-1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 3 Wiener, b1", "-1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 3 Hammerstein-Wiener, b1", "- 1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 4 Hammerstein, b1", "- 1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 4 Wiener, b1", "-1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 4 Hammerstein-Wiener, b1", "- 1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 5 Hammerstein, b1", "-1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 5 Wiener, b1", "- 1", "+1", _B1_REASON),
    TranscriptionDecision("Appendix 2, order 5 Hammerstein-Wiener, b1", "I", "+1", _B1_REASON),
    TranscriptionDecision(
        "Appendix 2, fixed coefficient",
        "b1 = 1 in every row while |b0| > 1 in three rows (-1.006, -1.006, -1.157)",
        "the fixed coefficient is the b1 column, not the largest-magnitude one",
        "b1 is the only column equal to 1 in magnitude in all 12 rows",
    ),
    TranscriptionDecision(
        "Appendix 2, order 5 Hammerstein-Wiener, b0",
        "\u2212I.I57",
        "-1.157",
        "'I' stands for the digit 1; with -1.157 B(1) = 0.001 matches F(1) = 0.000, with +1.157 B(1) = 2.315",
    ),
    TranscriptionDecision(
        "Appendix 2, order 2 Wiener and Hammerstein-Wiener",
        "b = [-1.006, 1], F(1) = 0.014 and 0.013",
        "no unit root: kept uncancelled",
        "B(1) = -0.006 and F(1) >= 0.013 exceed the rounding bound; the poles (0.993, -0.998) and "
        "(0.993, -0.926) are stable and the DC gains (-0.43, -0.46) map 0-1.19 V into the printed "
        "output breakpoint spans",
    ),
    TranscriptionDecision(
        "Appendix 2, order 4 Hammerstein-Wiener",
        "B = [-0.341, 1, -0.977, 0.318], F = [1, -1.938, -0.039, 1.893, -0.916]",
        "two common (1 - z^-1) factors cancelled",
        "after one division B(1) = 0.000 and F(1) = 0.001 again (poles 0.992 vs zero 1.000); "
        "with a single cancellation the DC gain is 0/0 to rounding and the static force is flat "
        "(about 0.35 N for every voltage); with two, the gain is -0.156 and the static force rises "
        "from 0.36 N at 0 V to 2.0 N at 1.19 V like the other models",
    ),
    TranscriptionDecision(
        "Appendix 3, order 4 Wiener, x row",
        "\u00b7 \u00b7 \u00b7 ... then 0.000 -0.419 -0.286 -0.155 -0.020",
        "output x = [-0.419, -0.286, -0.155, -0.020]; the '0.000' is discarded",
        "the '0.000' sits in the last input column and a Wiener model has no input nonlinearity",
    ),
    TranscriptionDecision(
        "Appendix 3, order 4 Wiener, y row",
        "'7 7 101101' then 2.804 1.597 0.768 0.123",
        "output y = [2.804, 1.597, 0.768, 0.123]",
        "the label text is image residue",
    ),
    TranscriptionDecision(
        "Appendix 3, order 4 Hammerstein-Wiener, y row",
        "'Tidiffiller vyterier' 0.161 0.491 0.788 1.162 1.329 0.367 0.333 0.261",
        "input y = [0.161, 0.491, 0.788, 1.162], output y = [1.329, 0.367, 0.333, 0.261]",
        "the label is a garbled 'Hammer-Wiener'; both maps are then strictly monotone like every "
        "other map of the appendix (input increasing, output decreasing)",
    ),
    TranscriptionDecision(
        "Appendix 3, order 5 Hammerstein, x row, output columns",
        "1.527 0.507 0.555 0.201",
        "discarded",
        "a Hammerstein model has no output nonlinearity and the values are not monotone, so they "
        "fit no model's output map",
    ),
    TranscriptionDecision(
        "Appendix 3, order 5 Hammerstein, y row",
        "'That order Tiammer' - I.054 -3.710 -6.964 -11.386",
        "input y = [-1.054, -3.710, -6.964, -11.386]",
        "'I' stands for 1 and the sign is kept: the row decreases like the order 2-4 Hammerstein rows",
    ),
    TranscriptionDecision(
        "Appendix 3, order 5 Wiener, x row, input columns",
        "1.051 3.710 0.701 11.500",
        "discarded",
        "a Wiener model has no input nonlinearity; the numbers echo the Hammerstein y row",
    ),
    TranscriptionDecision(
        "Appendix 3, order 5 Hammerstein-Wiener, y row, last output value",
        "0.17 (end of the extracted text)",
        "0.170",
        "the third decimal is lost; 0.170 keeps the printed digits (true value in [0.170, 0.180))",
    ),
    TranscriptionDecision(
        "Appendix 3, order 5 Hammerstein-Wiener, label row",
        "'i iaiiiiilei \u2013 vviellei' with no numbers",
        "ignored",
        "garbled 'Hammer-Wiener' label; the y values are on the following line",
    ),
)


# ---------------------------------------------------------------------------
# coefficient tables (after the decisions above)
# ---------------------------------------------------------------------------
_Coeffs = tuple[tuple[float, ...], tuple[float, ...]]
_Breakpoints = tuple[tuple[float, ...], tuple[float, ...]]

# (kind, order) -> (b0..b_{nb-1}, f1..f_nf); f without the leading 1.
_LINEAR_BLOCKS: dict[tuple[str, int], _Coeffs] = {
    # Appendix 1
    ("linear", 2): ((5.184, -5.184), (-0.001, -0.999)),
    ("linear", 3): ((5.300, -10.546, 5.246), (-0.990, -0.998, 0.988)),
    ("linear", 4): ((6.122, -9.867, 3.963, -0.218), (-0.644, -0.850, 0.639, -0.145)),
    ("linear", 5): ((8.591, -20.301, 19.425, -8.932, 1.216), (-0.543, -1.340, 1.072, 0.360, -0.549)),
    # Appendix 2 (b1 read as +1 throughout)
    ("hammerstein", 2): ((-1.000, 1.0), (-0.006, -0.994)),
    ("wiener", 2): ((-1.006, 1.0), (0.005, -0.991)),
    ("hammerstein-wiener", 2): ((-1.006, 1.0), (-0.067, -0.920)),
    ("hammerstein", 3): ((-0.503, 1.0, -0.497), (-0.990, -0.998, 0.988)),
    ("wiener", 3): ((-0.506, 1.0, -0.494), (-0.978, -0.994, 0.972)),
    ("hammerstein-wiener", 3): ((-0.514, 1.0, -0.486), (-1.326, -0.249, 0.576)),
    ("hammerstein", 4): ((-0.951, 1.0, 0.375, -0.423), (-0.065, -1.323, 0.062, 0.326)),
    ("wiener", 4): ((-0.872, 1.0, 0.166, -0.294), (-0.180, -1.210, 0.178, 0.212)),
    ("hammerstein-wiener", 4): ((-0.341, 1.0, -0.977, 0.318), (-1.938, -0.039, 1.893, -0.916)),
    ("hammerstein", 5): ((-0.562, 1.0, -0.428, 0.004, -0.014), (-0.479, -1.450, 0.614, 0.475, -0.159)),
    ("wiener", 5): ((-0.529, 1.0, -0.631, 0.339, -0.179), (-0.264, -1.558, 0.176, 0.581, 0.065)),
    ("hammerstein-wiener", 5): ((-1.157, 1.0, 1.208, -0.828, -0.222), (0.271, -1.848, -0.656, 0.853, 0.380)),
}

# Appendix 3, input maps: voltage (V) -> linear-block input.
_INPUT_BREAKPOINTS: dict[tuple[str, int], _Breakpoints] = {
    ("hammerstein", 2): ((0.143, 0.479, 0.833, 1.150), (-0.506, -1.776, -3.315, -5.176)),
    ("hammerstein-wiener", 2): ((0.457, 0.789, 0.869, 1.145), (1.236, 1.789, 1.891, 2.243)),
    ("hammerstein", 3): ((0.136, 0.476, 0.817, 1.157), (-1.192, -3.940, -6.976, -10.964)),
    ("hammerstein-wiener", 3): ((-0.184, 0.484, 0.791, 1.216), (-0.708, -0.049, 0.139, 0.316)),
    ("hammerstein", 4): ((0.136, 0.475, 0.817, 1.155), (-0.708, -2.288, -4.116, -6.560)),
    ("hammerstein-wiener", 4): ((0.139, 0.505, 0.788, 1.158), (0.161, 0.491, 0.788, 1.162)),
    ("hammerstein", 5): ((0.134, 0.477, 0.816, 1.158), (-1.054, -3.710, -6.964, -11.386)),
    ("hammerstein-wiener", 5): ((0.135, 0.465, 0.804, 1.159), (0.039, 0.106, 0.160, 0.213)),
}

# Appendix 3, output maps: linear-block output -> force (N).
_OUTPUT_BREAKPOINTS: dict[tuple[str, int], _Breakpoints] = {
    ("wiener", 2): ((-0.628, -0.472, -0.301, -0.002), (3.431, 2.163, 1.157, 0.087)),
    ("hammerstein-wiener", 2): ((-1.305, -0.814, -0.577, 0.103), (3.620, 1.301, 0.724, 0.058)),
    ("wiener", 3): ((-0.293, -0.189, -0.132, -0.001), (3.083, 1.585, 1.018, 0.102)),
    ("hammerstein-wiener", 3): ((-0.049, -0.039, 0.005, 0.141), (1.507, 1.288, 0.761, 0.063)),
    ("wiener", 4): ((-0.419, -0.286, -0.155, -0.020), (2.804, 1.597, 0.768, 0.123)),
    ("hammerstein-wiener", 4): ((-0.115, -0.013, 0.016, 0.085), (1.329, 0.367, 0.333, 0.261)),
    ("wiener", 5): ((-0.229, -0.149, -0.092, 0.000), (2.834, 1.496, 0.843, 0.063)),
    ("hammerstein-wiener", 5): ((-0.073, -0.053, 0.043, 0.063), (1.354, 0.903, 0.267, 0.170)),
}


# ---------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------
def _check_key(kind: Any, order: Any) -> tuple[str, int]:
    if kind not in KINDS:
        allowed = ", ".join(repr(k) for k in KINDS)
        raise ValueError(f"unknown model kind {kind!r}; allowed: {allowed}")
    if isinstance(order, (bool, np.bool_)) or not isinstance(order, (int, np.integer)) or order not in ORDERS:
        allowed = ", ".join(str(o) for o in ORDERS)
        raise ValueError(f"model order must be one of {allowed}, got {order!r}")
    return kind, int(order)


def _nl(table: dict[tuple[str, int], _Breakpoints], key: tuple[str, int]) -> PiecewiseLinear | None:
    bp = table.get(key)
    return None if bp is None else PiecewiseLinear(*bp)


def _reduced(kind: str, order: int, cancel_unit_root: bool, nk: int = NK) -> tuple[LinearBF, LinearBF, int]:
    b, f = _LINEAR_BLOCKS[(kind, order)]
    raw = LinearBF(b=b, f=f, nk=nk)
    if not cancel_unit_root:
        return raw, raw, 0
    reduced, count = raw.cancel_unit_roots(UNIT_ROOT_TOL)
    return raw, reduced, count


def paper_model(kind: str, order: int, cancel_unit_root: bool = True, nk: int = NK) -> BlockModel:
    """One of the paper's identified voltage-to-force estimators.

    Parameters
    ----------
    kind : {"linear", "hammerstein", "wiener", "hammerstein-wiener"}
        Model structure.
    order : {2, 3, 4, 5}
        Order of the linear block.
    cancel_unit_root : bool, optional
        Cancel every common ``(1 - z^-1)`` factor of ``B`` and ``F`` detected
        within ``UNIT_ROOT_TOL`` (default). With False the printed
        coefficients are used as they are; most models then carry a pole at
        ``z = 1`` and their simulated output drifts.
    nk : {0, 1}, optional
        Input delay in samples (:data:`NK_READINGS`): the paper prints none; 1 (default) is
        MATLAB's convention, 0 the paper's notation read literally.

    Returns
    -------
    BlockModel
        Input: detrended FSR voltage (V); output: detrended force (N);
        ``dt_s = 0.01``; ``nk`` as given.

    Raises
    ------
    ValueError
        For an unknown kind or order (the message lists the allowed values).

    Examples
    --------
    >>> m = paper_model("wiener", 5)
    >>> [round(float(abs(p)), 3) for p in m.linear.poles()]
    [0.967, 0.942, 0.59, 0.121]
    """
    kind, order = _check_key(kind, order)
    if isinstance(nk, bool) or nk not in NK_READINGS:
        raise ValueError(f"nk must be one of {', '.join(map(str, NK_READINGS))} (the paper's two readings), got {nk!r}")
    _, linear, _ = _reduced(kind, order, cancel_unit_root, int(nk))
    suffix = ("" if cancel_unit_root else " (as printed)") + ("" if nk == NK else f", nk = {nk}")
    return BlockModel(
        linear=linear,
        input_nl=_nl(_INPUT_BREAKPOINTS, (kind, order)),
        output_nl=_nl(_OUTPUT_BREAKPOINTS, (kind, order)),
        dt_s=SAMPLE_TIME_S,
        name=f"paper {kind} order {order}{suffix}",
    )


def _describe(kind: str, order: int, cancel_unit_root: bool) -> dict[str, Any]:
    raw, linear, count = _reduced(kind, order, cancel_unit_root)
    model = paper_model(kind, order, cancel_unit_root)
    poles = linear.poles()
    max_abs = float(np.max(np.abs(poles))) if poles.size else 0.0
    stable = linear.is_stable(STABILITY_MARGIN)
    unit_pole = linear.has_unit_pole(UNIT_ROOT_TOL)
    b1, f1 = linear.unit_root_residuals()
    try:
        dc = linear.dc_gain(tol=UNIT_ROOT_TOL)
    except ValueError:
        dc = math.nan
    usable = bool(stable and not unit_pole and math.isfinite(dc))

    if usable:
        lo, hi = (float(v) for v in model.steady_state(np.asarray(INPUT_RANGE_V)))
        force = (lo, hi)
        if count:
            s = "s" if count > 1 else ""
            reason = f"stable after cancelling {count} common (1 - z^-1) factor{s}"
        else:
            reason = f"stable, no common unit root (B(1)={b1:.3f}, F(1)={f1:.3f})"
        slow = [p for p in poles if p.real < 0 and abs(p) > 0.99]
        if slow:
            reason += f"; lightly damped 50 Hz pole at {slow[0].real:.3f}"
    else:
        force = (math.nan, math.nan)
        if unit_pole and abs(b1) <= UNIT_ROOT_TOL:
            reason = f"common pole-zero pair at z = 1 left in place: DC gain 0/0 (B(1)={b1:.3g}, F(1)={f1:.3g})"
        elif unit_pole:
            reason = f"pole at z = 1 without a matching zero: integrates (F(1)={f1:.3g})"
        elif not stable:
            reason = f"unstable: max |pole| = {max_abs:.4f}"
        else:
            reason = "DC gain not finite"
    return {
        "kind": kind,
        "order": order,
        "name": model.name,
        "b": linear.b,
        "f": linear.f,
        "poles": tuple(complex(p) for p in poles),
        "max_abs_pole": max_abs,
        "stable": bool(stable),
        "unit_root_cancelled": count > 0,
        "unit_roots_cancelled": count,
        "dc_gain": float(dc),
        "steady_force_N": force,
        "usable": usable,
        "reason": reason,
    }


def paper_model_table(cancel_unit_root: bool = True) -> list[dict[str, Any]]:
    """Diagnostics of all 16 published models.

    Parameters
    ----------
    cancel_unit_root : bool, optional
        As in :func:`paper_model`.

    Returns
    -------
    list of dict
        One row per model, ordered by kind (``KINDS``) then order, with keys

        ``kind``, ``order``, ``name``
            Identification.
        ``b``, ``f``
            Linear-block coefficients used (``f`` without the leading 1).
        ``poles``
            Poles of ``F`` (after cancellation), complex, by decreasing modulus.
        ``max_abs_pole``
            Largest pole modulus.
        ``stable``
            All poles inside ``|z| < 1 - STABILITY_MARGIN``.
        ``unit_root_cancelled``, ``unit_roots_cancelled``
            Whether / how many common ``(1 - z^-1)`` factors were removed.
        ``dc_gain``
            ``B(1)/F(1)`` of the linear block (``inf`` for an integrator,
            ``nan`` for an indeterminate 0/0).
        ``steady_force_N``
            Static force (N) at the two ends of ``INPUT_RANGE_V`` (``nan`` if
            not usable).
        ``usable``
            Stable, no remaining pole at ``z = 1``, finite DC gain.
        ``reason``
            One-line explanation.
    """
    return [_describe(kind, order, cancel_unit_root) for kind in KINDS for order in ORDERS]
