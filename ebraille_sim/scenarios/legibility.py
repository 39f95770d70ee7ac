"""Electrotactile legibility: stimulation intensity under each raised dot, from contact force.

The 3x2 electrode array on the board shows one Braille cell at a time: the electrodes of
the raised dots are stimulated.  What the reader feels depends on the current density at
each electrode, and that depends on how the pulp meets the board, which is what the force
loop controls.  The chain, per control sample and per electrode:

1. **Contact patch** (Hertz, sphere on a flat): the pulp is a sphere of radius ``R``
   pressed onto the board with force ``F``; the contact radius is
   ``a(F) = (3 F R / (4 E*))^(1/3)``, ``E* = E / (1 - nu^2)``.  With ``R = 8 mm`` and
   ``E = 0.1 MPa`` this is the same pulp as the exponential law of
   :mod:`ebraille_sim.physics.fingertip` (0.83 N at 1.4 mm by Hertz against 1 N by the
   exponential law, parameters table 1.5).
2. **Electrode coverage**: electrode ``e`` (a disc of diameter ``D_e`` centred at
   ``c_e``, the Braille dot positions at pitch ``p``) touches the skin over the
   intersection of its disc with the contact disc; ``phi_e = A_overlap / A_e`` in [0, 1].
3. **Electrode-skin impedance** (law [E], unsourced: parameters table 4.2 suggests the form)::

       Z(F) = Z_inf + (Z_0 - Z_inf) exp(-F / F_z)

   per fully covered electrode; a partly covered electrode has ``Z(F) / phi_e`` (the
   interface conducts through its wetted area).
4. **Stimulator**: constant current ``I_0`` up to a compliance voltage ``V_c``
   (``I_e = min(I_0, V_c phi_e / Z(F))``), or constant voltage ``V_0 = I_0 Z(F_sp)``
   calibrated to give ``I_0`` at the setpoint force ``F_sp`` (``I_e = V_0 phi_e / Z(F)``).
5. **Intensity** is proportional to the current density ``J_e = I_e / (phi_e A_e)``
   (parameters table 4.2 [E]); its ratio to the nominal ``J_nom`` (full coverage at the
   setpoint force) is the electrode's relative intensity.  A peeling electrode
   (``phi_e`` falling) under constant current therefore feels *stronger*, as reported
   for electrodes peeling off the skin ([R] Akhtar et al. 2018, PMC6656406), until the
   compliance voltage limits the current.

**Legibility.** The stimulation level is set at the geometric centre of the reader's
usable range, between the sensation threshold and the discomfort level, whose ratio is
the dynamic range ``DR``.  An electrode is *legible* while its relative intensity lies in
``[DR^-1/2, DR^1/2]``: below it the dot fades under threshold, above it the dot hurts and
masks its neighbours.  A character is legible when all its raised dots are legible for at
least :data:`LEGIBLE_REQUIRED` of its stimulation window (the whole dwell in continuous
contact, the hold part in refresh mode).  Cells without raised dots (spaces) are not
counted.

Parameters and sources
----------------------
The Hertz patch at 1 N is 3.56 mm in radius, 40 mm² in area; measured fingertip contact
areas at that force are larger (roughly twice), so the coverage is an estimate [E].  The
impedance law and its three constants are [E]/[M], and the 2 mA current is a design choice
[E] that copies the example stimulus of Akhtar et al. 2018 [R]; the legibility metrics
compare controllers on one chain, they do not predict absolute percepts.

======================  ==========  =====================================================
parameter               default     source
======================  ==========  =====================================================
pulp radius R           8 mm        [E] parameters table 1.5 (Hertz cross-check)
pulp modulus E          0.1 MPa     [R] 0.07-0.2 MPa Hertzian fit (parameters 1.5)
Poisson ratio nu        0.5         [E] nearly incompressible soft tissue
electrode pitch p       2.4 mm      [E] 2.3-2.5 mm to mimic the 2.34 mm dot spacing [R]
electrode diameter D_e  1.2 mm      [E] 1-1.5 mm (parameters table 4.1)
Z(F) law                exp. fall   [E] unsourced form
Z_0 (touching)          400 kOhm    [M] 10 kOhm-1 MOhm dry fingertip (Kaczmarek 1991)
Z_inf (pressed)         30 kOhm     [M] same range, moist/pressed end
F_z                     0.5 N       [E] 0.3-1 N (parameters table 4.2)
I_0                     2 mA        [E] choice; [R] Akhtar et al. 2018 used 2 mA, 200 us, 20 Hz
compliance V_c          300 V       [M] 50-300 V fingertip stimulators (Kaczmarek 1991)
dynamic range DR        2.0         [M] fingertip discomfort/threshold current ratio,
                                    small on the fingertip (Kaczmarek 1991); with the
                                    [R] Stevens exponent 1.51 of electrotactile
                                    magnitude, +/-41 % current is about x0.6-x1.7 felt
======================  ==========  =====================================================

Examples
--------
>>> import numpy as np

>>> round(float(contact_radius_m(1.0)) * 1e3, 2)          # mm at 1 N
3.56
>>> ratio = relative_intensity(np.array([1.0, 0.3]), np.array([1.0, 1.0]))
>>> ratio.shape
(2, 6)
>>> bool(np.all(ratio[0] == 1.0)), bool(ratio[1].min() < 0.7)
(True, True)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ebraille_sim.base.fields import sourced

__all__ = ["LegibilityParams", "LEGIBLE_REQUIRED", "METRIC_NAMES", "contact_radius_m", "electrode_centres_m",
           "coverage", "impedance_ohm", "relative_intensity", "character_legibility", "legibility_metrics"]

LEGIBLE_REQUIRED = 0.9
"""Fraction of a character's stimulation window in which all its raised dots must be legible."""

METRIC_NAMES = ["legible_char_fraction", "legible_char_fraction_cv"]
"""Metrics added to a run's metrics (see :func:`legibility_metrics`): the legible fraction
of characters with a constant-current stimulator (the default, :data:`DEFAULT`) and with a
constant-voltage one (:data:`CONSTANT_VOLTAGE`)."""


@dataclass(frozen=True)
class LegibilityParams:
    """Electrode array, skin contact and stimulator (sources in the module table)."""
    pulp_radius_m: float = sourced(8e-3, "m", "[E] parameters table 1.5; the Hertz patch (40 mm2 at 1 N) is "
                                   "smaller than measured fingertip contact areas")
    pulp_modulus_pa: float = sourced(0.1e6, "Pa", "[R] 0.07-0.2 MPa Hertzian fit")
    poisson_ratio: float = sourced(0.5, "-", "[E] nearly incompressible tissue")
    pitch_m: float = sourced(2.4e-3, "m", "[E] 2.3-2.5 mm; Braille dot spacing 2.34 mm [R]")
    electrode_diameter_m: float = sourced(1.2e-3, "m", "[E] 1-1.5 mm")
    array_offset_x_m: float = sourced(0.0, "m", "[E] array centred on the contact patch")
    array_offset_y_m: float = sourced(0.0, "m", "[E] array centred on the contact patch")
    impedance_touch_ohm: float = sourced(400e3, "ohm", "[M] Kaczmarek 1991, 10 k-1 M dry fingertip")
    impedance_pressed_ohm: float = sourced(30e3, "ohm", "[M] same range, pressed end")
    impedance_force_scale_n: float = sourced(0.5, "N", "[E] F_z 0.3-1 N of the unsourced exponential "
                                             "impedance law, parameters table 4.2")
    mode: str = sourced("constant_current", "-", "constant_current | constant_voltage")
    current_a: float = sourced(2e-3, "A", "[E] design choice, the example stimulus of [R] Akhtar et al. 2018")
    compliance_v: float = sourced(300.0, "V", "[M] 50-300 V")
    dynamic_range: float = sourced(2.0, "-", "[M] discomfort/threshold ratio on the fingertip")

    def __post_init__(self):
        if self.mode not in ("constant_current", "constant_voltage"):
            raise ValueError(f"LegibilityParams.mode must be 'constant_current' or 'constant_voltage', "
                             f"got {self.mode!r}")
        for name in ("pulp_radius_m", "pulp_modulus_pa", "pitch_m", "electrode_diameter_m",
                     "impedance_touch_ohm", "impedance_pressed_ohm", "impedance_force_scale_n",
                     "current_a", "compliance_v"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"LegibilityParams.{name} must be finite and > 0, got {v}")
        if not 0.0 <= self.poisson_ratio < 1.0:
            raise ValueError(f"LegibilityParams.poisson_ratio must lie in [0, 1), got {self.poisson_ratio}")
        if not self.dynamic_range > 1.0:
            raise ValueError(f"LegibilityParams.dynamic_range must be > 1, got {self.dynamic_range}")
        if self.impedance_pressed_ohm > self.impedance_touch_ohm:
            raise ValueError("LegibilityParams.impedance_pressed_ohm must not exceed impedance_touch_ohm")

    @property
    def band(self) -> tuple[float, float]:
        """Legible range of the relative intensity, ``(DR^-1/2, DR^1/2)``."""
        r = math.sqrt(self.dynamic_range)
        return 1.0 / r, r


DEFAULT = LegibilityParams()
CONSTANT_VOLTAGE = LegibilityParams(mode="constant_voltage")


def contact_radius_m(force_n, params: LegibilityParams = DEFAULT):
    """Hertz contact radius (m) of the pulp sphere on the flat board at ``force_n`` (N)."""
    e_star = params.pulp_modulus_pa / (1.0 - params.poisson_ratio ** 2)
    f = np.maximum(np.asarray(force_n, dtype=float), 0.0)
    return np.cbrt(3.0 * f * params.pulp_radius_m / (4.0 * e_star))


def electrode_centres_m(params: LegibilityParams = DEFAULT) -> np.ndarray:
    """Centres (x, y) of the six electrodes, shape (6, 2), in dot order 1..6.

    Dots 1-3 run down the left column, 4-6 down the right (:func:`ebraille_sim.scenarios.braille.dots_grid`).
    """
    p = params.pitch_m
    out = np.zeros((6, 2))
    for dot in range(1, 7):
        row, col = (dot - 1) % 3, (dot - 1) // 3
        out[dot - 1] = ((col - 0.5) * p + params.array_offset_x_m, (1 - row) * p + params.array_offset_y_m)
    return out


def _overlap_area(d, r, a):
    """Area of the intersection of discs of radii ``r`` and ``a`` whose centres are ``d`` apart."""
    d, a = np.broadcast_arrays(np.asarray(d, float), np.asarray(a, float))
    out = np.zeros(d.shape)
    small = np.minimum(r, a)
    inside = d <= np.abs(a - r)
    out[inside] = np.pi * small[inside] ** 2
    part = (~inside) & (d < a + r) & (a > 0)
    if np.any(part):
        dd, aa = d[part], a[part]
        c1 = np.clip((dd ** 2 + r ** 2 - aa ** 2) / (2 * dd * r), -1.0, 1.0)
        c2 = np.clip((dd ** 2 + aa ** 2 - r ** 2) / (2 * dd * aa), -1.0, 1.0)
        k = (-dd + r + aa) * (dd + r - aa) * (dd - r + aa) * (dd + r + aa)
        out[part] = r ** 2 * np.arccos(c1) + aa ** 2 * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(k, 0.0))
    return out


def coverage(force_n, params: LegibilityParams = DEFAULT) -> np.ndarray:
    """Covered fraction ``phi_e`` of each electrode, shape ``force_n.shape + (6,)``."""
    a = contact_radius_m(force_n, params)[..., None]
    d = np.hypot(*electrode_centres_m(params).T)
    r = 0.5 * params.electrode_diameter_m
    return _overlap_area(np.broadcast_to(d, a.shape[:-1] + (6,)), r, np.broadcast_to(a, a.shape[:-1] + (6,))) \
        / (math.pi * r * r)


def impedance_ohm(force_n, params: LegibilityParams = DEFAULT):
    """Impedance (ohm) of a fully covered electrode at contact force ``force_n`` (N)."""
    f = np.maximum(np.asarray(force_n, dtype=float), 0.0)
    return params.impedance_pressed_ohm + (params.impedance_touch_ohm - params.impedance_pressed_ohm) \
        * np.exp(-f / params.impedance_force_scale_n)


def _current_a(force_n, phi, params, setpoint_n):
    z = impedance_ohm(force_n, params)[..., None]
    if params.mode == "constant_current":
        return np.minimum(params.current_a, params.compliance_v * phi / z)
    v0 = params.current_a * impedance_ohm(setpoint_n, params)[..., None]
    return v0 * phi / z


def relative_intensity(force_n, setpoint_n, params: LegibilityParams = DEFAULT) -> np.ndarray:
    """Current density of each electrode relative to nominal, shape ``force_n.shape + (6,)``.

    Nominal is a fully covered electrode at the setpoint force.  An electrode out of
    contact has intensity 0.
    """
    force_n = np.asarray(force_n, dtype=float)
    setpoint_n = np.broadcast_to(np.asarray(setpoint_n, dtype=float), force_n.shape)
    phi = coverage(force_n, params)
    area = math.pi * (0.5 * params.electrode_diameter_m) ** 2
    i = _current_a(force_n, phi, params, setpoint_n)
    j = np.divide(i, phi * area, out=np.zeros_like(i), where=phi > 1e-12)
    ones = np.ones(setpoint_n.shape + (1,))
    j_nom = _current_a(setpoint_n, ones, params, setpoint_n) / area
    return j / j_nom


def character_legibility(force_n, setpoint_n, char_index, cells, params: LegibilityParams = DEFAULT) -> dict:
    """Legibility of a run with one stimulator.

    Parameters
    ----------
    force_n, setpoint_n : ndarray, shape (n,)
        True contact force and setpoint at the control samples, N.
    char_index : ndarray of int, shape (n,)
        Cell shown at each sample, -1 outside the stimulation windows.
    cells : sequence of :class:`ebraille_sim.scenarios.braille.Cell`
        The schedule's cells (indexed by ``char_index``).
    params : LegibilityParams

    Returns
    -------
    dict
        ``legible_char_fraction`` (characters with raised dots whose dots were all in the
        legible band for at least :data:`LEGIBLE_REQUIRED` of their window; None when no
        such character was shown), ``intensity_ratio_p05`` and ``intensity_ratio_p95``
        (5th and 95th percentiles of the relative intensity over all raised-dot samples;
        None without any), ``legible_by_char`` (dict: cell index -> legible fraction of
        its window).
    """
    ci = np.asarray(char_index)
    sel = ci >= 0
    out = {"legible_char_fraction": None, "intensity_ratio_p05": None, "intensity_ratio_p95": None,
           "legible_by_char": {}}
    if not sel.any():
        return out
    masks = np.array([c.mask for c in cells], dtype=np.int64)
    dots = ((masks[ci[sel]][:, None] >> np.arange(6)) & 1).astype(bool)        # (m, 6)
    ratio = relative_intensity(np.asarray(force_n)[sel], np.asarray(setpoint_n)[sel], params)
    lo, hi = params.band
    ok_dot = (ratio >= lo) & (ratio <= hi)
    ok = np.all(ok_dot | ~dots, axis=1)
    has_dots = dots.any(axis=1)
    if has_dots.any():
        active = ratio[dots]
        out["intensity_ratio_p05"] = float(np.percentile(active, 5))
        out["intensity_ratio_p95"] = float(np.percentile(active, 95))
    idx = ci[sel]
    shown = np.unique(idx[has_dots])
    if shown.size == 0:
        return out
    n_ok = np.bincount(idx, weights=ok.astype(float), minlength=len(cells))
    n_all = np.bincount(idx, minlength=len(cells))
    frac = n_ok[shown] / n_all[shown]
    out["legible_char_fraction"] = float(np.mean(frac >= LEGIBLE_REQUIRED))
    out["legible_by_char"] = {int(k): float(f) for k, f in zip(shown, frac)}
    return out


LEGIBILITY_CHUNK = 1 << 16
"""Samples per block of :func:`legibility_metrics` (its temporaries stay a few MB however
long the run)."""


def legibility_metrics(force_n, setpoint_n, char_index, cells) -> dict:
    """The run metrics :data:`METRIC_NAMES`: legible fraction with both stimulator types.

    Arguments as :func:`character_legibility`, whose ``legible_char_fraction`` this is:
    evaluated over blocks of :data:`LEGIBILITY_CHUNK` samples (the intensity is computed
    per sample and the per-character counts add up exactly), so an hour-long run needs no
    per-electrode array of the whole run.
    """
    return {"legible_char_fraction": _legible_fraction(force_n, setpoint_n, char_index, cells, DEFAULT),
            "legible_char_fraction_cv": _legible_fraction(force_n, setpoint_n, char_index, cells,
                                                          CONSTANT_VOLTAGE)}


def _legible_fraction(force_n, setpoint_n, char_index, cells, params: LegibilityParams):
    ci = np.asarray(char_index)
    f = np.asarray(force_n)
    sp = np.asarray(setpoint_n)
    n_cells = len(cells)
    masks = np.array([c.mask for c in cells], dtype=np.int64)
    n_ok = np.zeros(n_cells)
    n_all = np.zeros(n_cells, dtype=np.int64)
    shown = np.zeros(n_cells, dtype=bool)
    lo, hi = params.band
    for a in range(0, len(ci), LEGIBILITY_CHUNK):
        part = ci[a:a + LEGIBILITY_CHUNK]
        sel = part >= 0
        if not sel.any():
            continue
        idx = part[sel]
        dots = ((masks[idx][:, None] >> np.arange(6)) & 1).astype(bool)
        ratio = relative_intensity(f[a:a + LEGIBILITY_CHUNK][sel], sp[a:a + LEGIBILITY_CHUNK][sel], params)
        ok = np.all(((ratio >= lo) & (ratio <= hi)) | ~dots, axis=1)
        n_ok += np.bincount(idx, weights=ok.astype(float), minlength=n_cells)
        n_all += np.bincount(idx, minlength=n_cells)
        shown[idx[dots.any(axis=1)]] = True
    keep = np.nonzero(shown)[0]
    if keep.size == 0:
        return None
    return float(np.mean(n_ok[keep] / n_all[keep] >= LEGIBLE_REQUIRED))
