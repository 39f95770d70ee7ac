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

**Computation.** Each law of the chain is one compiled scalar function (contact radius,
lens area, impedance, stimulator current, relative intensity of a sample); the array
functions below loop over them, and :func:`legibility_metrics` is one compiled pass over
the samples that keeps only per-character counts.

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
from typing import NamedTuple

import numpy as np

from ebraille_sim.base.compiled import njit
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


class _Contact(NamedTuple):
    """The contact geometry of :class:`LegibilityParams` as the compiled laws read it."""
    pulp_radius_m: float
    pulp_modulus_pa: float
    poisson_ratio: float
    electrode_radius_m: float


class _Stimulator(NamedTuple):
    """Skin impedance, stimulator and legible band of :class:`LegibilityParams` for the compiled laws."""
    impedance_touch_ohm: float
    impedance_pressed_ohm: float
    impedance_force_scale_n: float
    constant_voltage: bool
    current_a: float
    compliance_v: float
    electrode_area_m2: float
    band_low: float
    band_high: float


def _contact(params: LegibilityParams) -> _Contact:
    return _Contact(params.pulp_radius_m, params.pulp_modulus_pa, params.poisson_ratio,
                    0.5 * params.electrode_diameter_m)


def _stimulator(params: LegibilityParams) -> _Stimulator:
    lo, hi = params.band
    return _Stimulator(params.impedance_touch_ohm, params.impedance_pressed_ohm, params.impedance_force_scale_n,
                       params.mode == "constant_voltage", params.current_a, params.compliance_v,
                       math.pi * (0.5 * params.electrode_diameter_m) ** 2, lo, hi)


def _electrode_distances_m(params: LegibilityParams) -> np.ndarray:
    """Distance (m) of each electrode centre from the centre of the contact patch, shape (6,)."""
    return np.hypot(*electrode_centres_m(params).T)


# --- the laws, one sample at a time (every array function below loops over these) ---

@njit
def _contact_radius(force_n, contact):
    """Hertz contact radius (m) at one force (N): ``(3 F R / (4 E*))^(1/3)``, ``E* = E / (1 - nu^2)``."""
    e_star = contact.pulp_modulus_pa / (1.0 - contact.poisson_ratio ** 2)
    f = max(force_n, 0.0)
    return np.cbrt(3.0 * f * contact.pulp_radius_m / (4.0 * e_star))


@njit
def _lens_area(d, r, a):
    """Area of the intersection of discs of radii ``r`` and ``a`` whose centres are ``d`` apart."""
    if d <= abs(a - r):
        return np.pi * min(r, a) ** 2
    if d < a + r and a > 0.0:
        c1 = min(max((d ** 2 + r ** 2 - a ** 2) / (2 * d * r), -1.0), 1.0)
        c2 = min(max((d ** 2 + a ** 2 - r ** 2) / (2 * d * a), -1.0), 1.0)
        k = (-d + r + a) * (d + r - a) * (d - r + a) * (d + r + a)
        return r ** 2 * math.acos(c1) + a ** 2 * math.acos(c2) - 0.5 * math.sqrt(max(k, 0.0))
    return 0.0


@njit
def _impedance(force_n, stim):
    """Impedance (ohm) of a fully covered electrode at one force (N): ``Z_inf + (Z_0 - Z_inf) exp(-F / F_z)``."""
    f = max(force_n, 0.0)
    return stim.impedance_pressed_ohm + (stim.impedance_touch_ohm - stim.impedance_pressed_ohm) \
        * math.exp(-f / stim.impedance_force_scale_n)


@njit
def _current_a(phi, z_ohm, z_setpoint_ohm, stim):
    """Stimulator current (A) into an electrode of coverage ``phi`` and full-coverage impedance ``z_ohm``."""
    if stim.constant_voltage:
        return stim.current_a * z_setpoint_ohm * phi / z_ohm
    return min(stim.current_a, stim.compliance_v * phi / z_ohm)


@njit
def _sample_coverage(force_n, contact, distance_m, phi):
    """Covered fraction of each electrode at one force, into ``phi``."""
    a = _contact_radius(force_n, contact)
    r = contact.electrode_radius_m
    for e in range(distance_m.size):
        phi[e] = _lens_area(distance_m[e], r, a) / (np.pi * r * r)


@njit
def _sample_intensity(force_n, setpoint_n, phi, stim, ratio):
    """Relative intensity of each electrode at one sample, into ``ratio`` (0 where ``phi`` is 0)."""
    z = _impedance(force_n, stim)
    z_sp = _impedance(setpoint_n, stim)
    area = stim.electrode_area_m2
    j_nom = _current_a(1.0, z_sp, z_sp, stim) / area
    for e in range(phi.size):
        j = _current_a(phi[e], z, z_sp, stim) / (phi[e] * area) if phi[e] > 1e-12 else 0.0
        ratio[e] = j / j_nom


# --- array loops behind the public functions ---

@njit
def _contact_radii(force_n, contact):
    out = np.empty(force_n.size)
    for k in range(force_n.size):
        out[k] = _contact_radius(force_n[k], contact)
    return out


@njit
def _lens_areas(d, r, a):
    out = np.empty(d.size)
    for k in range(d.size):
        out[k] = _lens_area(d[k], r, a[k])
    return out


@njit
def _impedances(force_n, stim):
    out = np.empty(force_n.size)
    for k in range(force_n.size):
        out[k] = _impedance(force_n[k], stim)
    return out


@njit
def _coverages(force_n, contact, distance_m):
    out = np.empty((force_n.size, distance_m.size))
    for k in range(force_n.size):
        _sample_coverage(force_n[k], contact, distance_m, out[k])
    return out


@njit
def _intensities(force_n, setpoint_n, contact, distance_m, stim):
    out = np.empty((force_n.size, distance_m.size))
    phi = np.empty(distance_m.size)
    for k in range(force_n.size):
        _sample_coverage(force_n[k], contact, distance_m, phi)
        _sample_intensity(force_n[k], setpoint_n[k], phi, stim, out[k])
    return out


def _flat(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float).ravel()


# --- public array functions ---

def contact_radius_m(force_n, params: LegibilityParams = DEFAULT):
    """Hertz contact radius (m) of the pulp sphere on the flat board at ``force_n`` (N)."""
    f = np.asarray(force_n, dtype=float)
    return _contact_radii(_flat(f), _contact(params)).reshape(f.shape)[()]


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
    """Area of the intersection of discs of radii ``r`` and ``a`` whose centres are ``d`` apart (arrays)."""
    d, a = np.broadcast_arrays(np.asarray(d, float), np.asarray(a, float))
    return _lens_areas(_flat(d), float(r), _flat(a)).reshape(d.shape)


def coverage(force_n, params: LegibilityParams = DEFAULT) -> np.ndarray:
    """Covered fraction ``phi_e`` of each electrode, shape ``force_n.shape + (6,)``."""
    f = np.asarray(force_n, dtype=float)
    return _coverages(_flat(f), _contact(params), _electrode_distances_m(params)).reshape(f.shape + (6,))


def impedance_ohm(force_n, params: LegibilityParams = DEFAULT):
    """Impedance (ohm) of a fully covered electrode at contact force ``force_n`` (N)."""
    f = np.asarray(force_n, dtype=float)
    return _impedances(_flat(f), _stimulator(params)).reshape(f.shape)[()]


def relative_intensity(force_n, setpoint_n, params: LegibilityParams = DEFAULT) -> np.ndarray:
    """Current density of each electrode relative to nominal, shape ``force_n.shape + (6,)``.

    Nominal is a fully covered electrode at the setpoint force.  An electrode out of
    contact has intensity 0.
    """
    force_n = np.asarray(force_n, dtype=float)
    setpoint_n = np.broadcast_to(np.asarray(setpoint_n, dtype=float), force_n.shape)
    return _intensities(_flat(force_n), _flat(setpoint_n), _contact(params), _electrode_distances_m(params),
                        _stimulator(params)).reshape(force_n.shape + (6,))


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


@njit
def _legibility_counts(force_n, setpoint_n, char_index, masks, contact, distance_m, stims):
    """One pass over the samples: per cell, the samples in which each stimulator in
    ``stims`` kept all raised dots legible, the samples shown, and whether the cell has
    raised dots.  The coverage is computed once per sample for all stimulators."""
    n_cells = masks.size
    n_ok = np.zeros((len(stims), n_cells), np.int64)
    n_all = np.zeros(n_cells, np.int64)
    shown = np.zeros(n_cells, np.bool_)
    phi = np.empty(distance_m.size)
    ratio = np.empty(distance_m.size)
    for k in range(char_index.size):
        c = char_index[k]
        if c < 0:
            continue
        n_all[c] += 1
        dots = masks[c] & 0b111111
        if dots == 0:                                       # nothing to stimulate: vacuously legible
            for m in range(len(stims)):
                n_ok[m, c] += 1
            continue
        shown[c] = True
        _sample_coverage(force_n[k], contact, distance_m, phi)
        for m in range(len(stims)):
            stim = stims[m]
            _sample_intensity(force_n[k], setpoint_n[k], phi, stim, ratio)
            ok = True
            for e in range(distance_m.size):
                if (dots >> e) & 1 and not (ratio[e] >= stim.band_low and ratio[e] <= stim.band_high):
                    ok = False
                    break
            if ok:
                n_ok[m, c] += 1
    return n_ok, n_all, shown


def legibility_metrics(force_n, setpoint_n, char_index, cells) -> dict:
    """The run metrics :data:`METRIC_NAMES`: legible fraction with both stimulator types.

    Arguments as :func:`character_legibility`, whose ``legible_char_fraction`` this is:
    evaluated in one compiled pass over the samples that keeps only per-character counts
    (no per-electrode array of the run) and computes each sample's electrode coverage once
    for both stimulators.
    """
    cc, cv = _legible_fractions(force_n, setpoint_n, char_index, cells, (DEFAULT, CONSTANT_VOLTAGE))
    return {"legible_char_fraction": cc, "legible_char_fraction_cv": cv}


def _legible_fractions(force_n, setpoint_n, char_index, cells, params_list) -> list:
    """``legible_char_fraction`` of :func:`character_legibility` for each of ``params_list``."""
    ci = np.ascontiguousarray(char_index, dtype=np.int64).ravel()
    f = _flat(force_n)
    sp = _flat(np.broadcast_to(np.asarray(setpoint_n, dtype=float), f.shape))
    if f.size != ci.size:
        raise ValueError(f"force_n has {f.size} samples but char_index has {ci.size}")
    if ci.size and ci.max() >= len(cells):
        raise ValueError(f"char_index refers to cell {int(ci.max())} but there are {len(cells)} cells")
    masks = np.array([c.mask for c in cells], dtype=np.int64)
    by_geometry: dict = {}                                  # stimulators sharing a contact geometry
    for i, params in enumerate(params_list):
        geometry = (_contact(params), tuple(_electrode_distances_m(params)))
        by_geometry.setdefault(geometry, []).append(i)
    out: list = [None] * len(params_list)
    for (contact, distances), members in by_geometry.items():
        stims = tuple(_stimulator(params_list[i]) for i in members)
        n_ok, n_all, shown = _legibility_counts(f, sp, ci, masks, contact, np.array(distances), stims)
        keep = np.nonzero(shown)[0]
        if keep.size == 0:
            continue
        for row, i in enumerate(members):
            out[i] = float(np.mean(n_ok[row, keep] / n_all[keep] >= LEGIBLE_REQUIRED))
    return out
