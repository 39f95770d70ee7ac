"""Electrotactile legibility: stimulation intensity under each raised dot, from contact force.

The 3x2 electrode array on the board shows one Braille cell at a time: the electrodes of
the raised dots are stimulated.  What the reader feels depends on the current density at
each electrode, and that depends on how the pulp meets the board, which is what the force
loop controls.  The chain, per control sample and per electrode:

1. **Contact patch** (measured finger-pad law, not a Hertz sphere): the gross contact
   area of the pulp on the flat board grows as a power of the normal force,
   ``A(F) = A_1 (F / 1 N)^n``, with ``A_1 = 100 mm2`` and ``n = 1/3``.  Measured finger
   pads flatten much faster than a Hertz sphere at low force and much slower above it
   (the pad stiffens as it is compressed, so the Hertz exponent 2/3 over-predicts the
   growth).  The patch is taken as the disc of the same area, radius
   ``a(F) = (A(F) / pi)^(1/2)`` (5.64 mm at 1 N; the Hertz sphere of R = 8 mm,
   E = 0.1 MPa gave 3.56 mm, 40 mm2).
2. **Electrode coverage**: electrode ``e`` (a disc of diameter ``D_e`` centred at
   ``c_e``, the Braille dot positions at pitch ``p``) touches the skin over the
   intersection of its disc with the contact disc; ``phi_e = A_overlap / A_e`` in [0, 1].
3. **Electrode-skin impedance**: current crosses the stratum corneum only where the
   fingerprint ridges really touch the electrode, and the real contact area of a rough
   elastic contact grows in proportion to the local pressure.  With the mean patch
   pressure ``p(F) = F / A(F)`` the impedance of a fully covered electrode is::

       Z(F) = Z_inf + Z_sc (p_ref / p(F))^k

   (``Z_inf`` the tissue and spreading resistance beneath the interface, ``Z_sc`` the
   interface at the reference pressure ``p_ref``, ``k = 1`` for real contact area
   proportional to pressure).  Below the touch force ``F_t`` the impedance stays at
   ``Z(F_t)`` (an open contact is not evaluated).  A partly covered electrode has
   ``Z(F) / phi_e`` (the interface conducts through its covered area).
4. **Stimulator**: constant current ``I_0`` up to a compliance voltage ``V_c``
   (``I_e = min(I_0, V_c phi_e / Z(F))``), or constant voltage ``V_0 = I_0 Z(F_sp)``
   calibrated to give ``I_0`` at the setpoint force ``F_sp`` (``I_e = V_0 phi_e / Z(F)``).
5. **Intensity** is proportional to the current density ``J_e = I_e / (phi_e A_e)``;
   its ratio to the nominal ``J_nom`` (full coverage at the setpoint force) is the
   electrode's relative intensity.  A peeling electrode (``phi_e`` falling) under
   constant current therefore feels *stronger*, as reported for electrodes peeling off
   the skin ([R] Akhtar et al. 2018, PMC6656406), until the compliance voltage limits
   the current.

**Legibility.** The stimulation level is set at the geometric centre of the reader's
usable range, between the sensation threshold and the maximal current without
discomfort, whose ratio is the dynamic range ``DR`` ([R] definition, Kaczmarek, Webster
& Radwin 1992).  An electrode is *legible* while its relative intensity lies in
``[DR^-1/2, DR^1/2]``: below it the dot fades under threshold, above it the dot hurts and
masks its neighbours.  With ``I_0 = 2 mA`` and ``DR = 2`` the implied sensation threshold
is 1.41 mA and the discomfort level 2.83 mA.  A character is legible when all its raised
dots are legible for at least :data:`LEGIBLE_REQUIRED` of its stimulation window (the
whole dwell in continuous contact, the hold part in refresh mode).  Cells without raised
dots (spaces) are not counted.

**Computation.** Each law of the chain is one compiled scalar function (contact area,
contact radius, lens area, impedance, stimulator current, relative intensity of a
sample); the array functions below loop over them, and :func:`legibility_metrics` is one
compiled pass over the samples that keeps only per-character counts.

Parameters and sources
----------------------
The contact area follows measured finger-pad areas (a power law of force), not a Hertz
sphere: the Hertz patch of an 8 mm, 0.1 MPa pulp is 40 mm² at 1 N, about half of what is
measured.  The impedance law's form comes from the contact physics [D]; its scale and
exponent are [E]/[M], and the 2 mA current is a design choice [E] that copies the example
stimulus of Akhtar et al. 2018 [R]; the legibility metrics compare controllers on one
chain, they do not predict absolute percepts.

======================  ==========  =====================================================
parameter               default     source
======================  ==========  =====================================================
area at 1 N A_1         100 mm2     [M] 60-150 mm2 gross finger-pad area near 1 N on a
                                    flat plate (Serina et al. 1997/1998, measured at
                                    0.25-7 N [R] PMID 9796686; Warman & Ennos 2009;
                                    Dzidek et al. 2017)
area exponent n         1/3         [M] 0.2-0.5 measured (Soneda & Nakano 2010; Dzidek
                                    et al. 2017, whose Hertz fit needs a secant modulus
                                    rising with force [R] PMC5332579); Hertz gives 2/3
electrode pitch p       2.4 mm      [E] 2.3-2.5 mm to mimic the 2.34 mm dot spacing [R]
electrode diameter D_e  1.2 mm      [E] 1-1.5 mm (parameters table 4.1)
Z_inf (tissue)          30 kOhm     [M] low end of 10 kOhm-1 MOhm per fingertip
                                    electrode (Kaczmarek et al. 1991)
Z_sc at p_ref           50 kOhm     [E] makes Z(1 N) = 80 kOhm, inside the same range
p_ref                   10 kPa      [D] mean patch pressure at 1 N: 1 N / A_1
pressure exponent k     1           [E] real contact area proportional to pressure
                                    (rough elastic contact); 0.5-1 plausible
touch force F_t         1 mN        [E] lightest touch evaluated (Z = 5 MOhm)
I_0                     2 mA        [E] design choice; [R] Akhtar et al. 2018 used 2 mA,
                                    200 us, 20 Hz
compliance V_c          300 V       [M] 50-300 V fingertip stimulators (Kaczmarek 1991)
dynamic range DR        2.0         [M] fingertip ratio, small (Kaczmarek et al. 1991);
                                    the threshold it implies, 1.41 mA, lies in the [M]
                                    1-3 mA fingertip range.  [R] 3.9 on the upper arm
                                    (median 3.5 mA perception, 13.8 mA intolerance,
                                    81 subjects, Sci Rep 2022, PMID 35513410) is the
                                    upper end to sweep
======================  ==========  =====================================================

Examples
--------
>>> import numpy as np

>>> round(float(contact_area_m2(1.0)) * 1e6, 1)          # mm2 at 1 N
100.0
>>> round(float(contact_radius_m(1.0)) * 1e3, 2)          # mm at 1 N
5.64
>>> ratio = relative_intensity(np.array([1.0, 0.1]), np.array([1.0, 1.0]))
>>> ratio.shape
(2, 6)
>>> bool(np.all(ratio[0] == 1.0)), bool(ratio[1].max() < 0.7)
(True, True)
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.base.fields import sourced

__all__ = ["LegibilityParams", "LEGIBLE_REQUIRED", "METRIC_NAMES", "contact_area_m2", "contact_radius_m", "electrode_centres_m",
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
    contact_area_1n_m2: float = sourced(100e-6, "m2", "[M] 60-150 mm2 gross finger-pad area near 1 N "
                                        "(Serina 1997, Warman & Ennos 2009, Dzidek 2017)")
    contact_area_exponent: float = sourced(1.0 / 3.0, "-", "[M] 0.2-0.5 measured (Soneda & Nakano 2010, "
                                           "Dzidek 2017); Hertz 2/3")
    pitch_m: float = sourced(2.4e-3, "m", "[E] 2.3-2.5 mm; Braille dot spacing 2.34 mm [R]")
    electrode_diameter_m: float = sourced(1.2e-3, "m", "[E] 1-1.5 mm")
    array_offset_x_m: float = sourced(0.0, "m", "[E] array centred on the contact patch")
    array_offset_y_m: float = sourced(0.0, "m", "[E] array centred on the contact patch")
    impedance_pressed_ohm: float = sourced(30e3, "ohm", "[M] Kaczmarek 1991, 10 k-1 M per fingertip electrode")
    impedance_interface_ohm: float = sourced(50e3, "ohm", "[E] stratum corneum at p_ref; Z(1 N) = 80 k")
    reference_pressure_pa: float = sourced(10e3, "Pa", "[D] 1 N / 100 mm2")
    pressure_exponent: float = sourced(1.0, "-", "[E] real contact area proportional to pressure; 0.5-1")
    touch_force_n: float = sourced(1e-3, "N", "[E] lightest touch evaluated")
    mode: str = sourced("constant_current", "-", "constant_current | constant_voltage")
    current_a: float = sourced(2e-3, "A", "[E] design choice, the example stimulus of [R] Akhtar et al. 2018")
    compliance_v: float = sourced(300.0, "V", "[M] 50-300 V")
    dynamic_range: float = sourced(2.0, "-", "[M] fingertip discomfort/threshold current ratio; [R] 3.9 upper arm")

    def __post_init__(self):
        if self.mode not in ("constant_current", "constant_voltage"):
            raise ValueError(f"LegibilityParams.mode must be 'constant_current' or 'constant_voltage', "
                             f"got {self.mode!r}")
        for name in ("contact_area_1n_m2", "contact_area_exponent", "pitch_m", "electrode_diameter_m",
                     "impedance_pressed_ohm", "impedance_interface_ohm", "reference_pressure_pa",
                     "pressure_exponent", "touch_force_n", "current_a", "compliance_v"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"LegibilityParams.{name} must be finite and > 0, got {v}")
        if not self.contact_area_exponent < 1.0:
            raise ValueError(f"LegibilityParams.contact_area_exponent must be < 1 (the patch pressure must "
                             f"rise with force), got {self.contact_area_exponent}")
        if not self.dynamic_range > 1.0:
            raise ValueError(f"LegibilityParams.dynamic_range must be > 1, got {self.dynamic_range}")

    @property
    def band(self) -> tuple[float, float]:
        """Legible range of the relative intensity, ``(DR^-1/2, DR^1/2)``."""
        r = math.sqrt(self.dynamic_range)
        return 1.0 / r, r


DEFAULT = LegibilityParams()
CONSTANT_VOLTAGE = LegibilityParams(mode="constant_voltage")


class _Contact(NamedTuple):
    """The contact geometry of :class:`LegibilityParams` as the compiled laws read it."""
    contact_area_1n_m2: float
    contact_area_exponent: float
    electrode_radius_m: float


class _Stimulator(NamedTuple):
    """Skin impedance, stimulator and legible band of :class:`LegibilityParams` for the compiled laws."""
    contact_area_1n_m2: float
    contact_area_exponent: float
    impedance_pressed_ohm: float
    impedance_interface_ohm: float
    reference_pressure_pa: float
    pressure_exponent: float
    touch_force_n: float
    constant_voltage: bool
    current_a: float
    compliance_v: float
    electrode_area_m2: float
    band_low: float
    band_high: float


def _contact(params: LegibilityParams) -> _Contact:
    return _Contact(params.contact_area_1n_m2, params.contact_area_exponent, 0.5 * params.electrode_diameter_m)


def _stimulator(params: LegibilityParams) -> _Stimulator:
    lo, hi = params.band
    return _Stimulator(params.contact_area_1n_m2, params.contact_area_exponent, params.impedance_pressed_ohm,
                       params.impedance_interface_ohm, params.reference_pressure_pa, params.pressure_exponent,
                       params.touch_force_n, params.mode == "constant_voltage", params.current_a,
                       params.compliance_v, math.pi * (0.5 * params.electrode_diameter_m) ** 2, lo, hi)


def _impedance_law(stim: _Stimulator) -> tuple:
    """The fields :func:`_impedance` reads (stimulators equal in them share its values)."""
    return (stim.contact_area_1n_m2, stim.contact_area_exponent, stim.impedance_pressed_ohm,
            stim.impedance_interface_ohm, stim.reference_pressure_pa, stim.pressure_exponent, stim.touch_force_n)


def _electrode_distances_m(params: LegibilityParams) -> np.ndarray:
    """Distance (m) of each electrode centre from the centre of the contact patch, shape (6,)."""
    return np.hypot(*electrode_centres_m(params).T)


# --- the laws, one sample at a time (every array function below loops over these) ---

@njit(error_model="numpy", inline="always")
def _contact_area_m2(force_n, area_1n_m2, exponent):
    """Gross contact area (m2) of the pulp on the board at one force (N): ``A_1 F^n``, 0 without force."""
    if force_n <= 0.0:
        return 0.0
    return area_1n_m2 * force_n ** exponent


@njit(error_model="numpy")
def _contact_radius(force_n, contact):
    """Radius (m) of the disc with the contact area at one force (N): ``(A(F) / pi)^(1/2)``."""
    return _radius_of_area(_contact_area_m2(force_n, contact.contact_area_1n_m2, contact.contact_area_exponent))


@njit(error_model="numpy", inline="always")
def _radius_of_area(area_m2):
    """Radius (m) of the disc of area ``area_m2``."""
    return math.sqrt(area_m2 / np.pi)


@njit(error_model="numpy", inline="always")
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


@njit(error_model="numpy", inline="always")
def _impedance(force_n, stim):
    """Impedance (ohm) of a fully covered electrode at one force (N): ``Z_inf + Z_sc (p_ref / p(F))^k``.

    ``p(F) = F / A(F)`` is the mean pressure of the contact patch; forces below the touch
    force are evaluated at the touch force.
    """
    f = max(force_n, stim.touch_force_n)
    return _impedance_at(f, _contact_area_m2(f, stim.contact_area_1n_m2, stim.contact_area_exponent), stim)


@njit(error_model="numpy", inline="always")
def _impedance_at(force_n, area_m2, stim):
    """:func:`_impedance` at a force at or above the touch force whose contact area is ``area_m2``."""
    q = stim.reference_pressure_pa / (force_n / area_m2)
    k = stim.pressure_exponent
    return stim.impedance_pressed_ohm + stim.impedance_interface_ohm * (q if k == 1.0 else q ** k)


@njit(error_model="numpy", inline="always")
def _current_a(phi, z_ohm, z_setpoint_ohm, stim):
    """Stimulator current (A) into an electrode of coverage ``phi`` and full-coverage impedance ``z_ohm``."""
    if stim.constant_voltage:
        return stim.current_a * z_setpoint_ohm * phi / z_ohm
    return min(stim.current_a, stim.compliance_v * phi / z_ohm)


@njit(error_model="numpy")
def _sample_coverage(force_n, contact, distance_m, phi):
    """Covered fraction of each electrode at one force, into ``phi``."""
    _coverage_at_radius(_contact_radius(force_n, contact), contact, distance_m, phi)


@njit(error_model="numpy", inline="always")
def _electrode_coverage(d, r, a):
    """Covered fraction of an electrode of radius ``r`` (m) whose centre is ``d`` (m) from the
    centre of a contact disc of radius ``a`` (m)."""
    return _lens_area(d, r, a) / (np.pi * r * r)


@njit(error_model="numpy")
def _coverage_at_radius(a, contact, distance_m, phi):
    """:func:`_sample_coverage` for a contact disc of radius ``a`` (m)."""
    r = contact.electrode_radius_m
    for e in range(distance_m.size):
        phi[e] = _electrode_coverage(distance_m[e], r, a)


@njit(error_model="numpy", inline="always")
def _nominal(setpoint_n, stim):
    """Full-coverage impedance (ohm) and nominal current density (A/m2) at the setpoint (N)."""
    z_sp = _impedance(setpoint_n, stim)
    return z_sp, _current_a(1.0, z_sp, z_sp, stim) / stim.electrode_area_m2


@njit(error_model="numpy")
def _sample_intensity(force_n, setpoint_n, phi, stim, ratio):
    """Relative intensity of each electrode at one sample, into ``ratio`` (0 where ``phi`` is 0)."""
    z_sp, j_nom = _nominal(setpoint_n, stim)
    _sample_intensity_z(_impedance(force_n, stim), z_sp, j_nom, phi, stim, ratio)


@njit(error_model="numpy")
def _sample_intensity_z(z, z_sp, j_nom, phi, stim, ratio):
    """:func:`_sample_intensity` given the full-coverage impedance ``z`` (ohm) at the sample's force."""
    for e in range(phi.size):
        ratio[e] = _electrode_ratio(phi[e], z, z_sp, j_nom, stim)


@njit(error_model="numpy", inline="always")
def _electrode_ratio(phi, z, z_sp, j_nom, stim):
    """Relative intensity of one electrode of coverage ``phi`` (0 where ``phi`` is 0)."""
    j = _current_a(phi, z, z_sp, stim) / (phi * stim.electrode_area_m2) if phi > 1e-12 else 0.0
    return j / j_nom


# --- array loops behind the public functions ---

@njit(error_model="numpy")
def _contact_areas(force_n, contact):
    out = np.empty(force_n.size)
    for k in range(force_n.size):
        out[k] = _contact_area_m2(force_n[k], contact.contact_area_1n_m2, contact.contact_area_exponent)
    return out


@njit(error_model="numpy")
def _contact_radii(force_n, contact):
    out = np.empty(force_n.size)
    for k in range(force_n.size):
        out[k] = _contact_radius(force_n[k], contact)
    return out


@njit(error_model="numpy")
def _lens_areas(d, r, a):
    out = np.empty(d.size)
    for k in range(d.size):
        out[k] = _lens_area(d[k], r, a[k])
    return out


@njit(error_model="numpy")
def _impedances(force_n, stim):
    out = np.empty(force_n.size)
    for k in range(force_n.size):
        out[k] = _impedance(force_n[k], stim)
    return out


@njit(error_model="numpy")
def _coverages(force_n, contact, distance_m):
    out = np.empty((force_n.size, distance_m.size))
    for k in range(force_n.size):
        _sample_coverage(force_n[k], contact, distance_m, out[k])
    return out


@njit(error_model="numpy")
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

def contact_area_m2(force_n, params: LegibilityParams = DEFAULT):
    """Gross contact area (m2) of the pulp on the flat board at ``force_n`` (N): ``A_1 F^n``."""
    f = np.asarray(force_n, dtype=float)
    return _contact_areas(_flat(f), _contact(params)).reshape(f.shape)[()]


def contact_radius_m(force_n, params: LegibilityParams = DEFAULT):
    """Radius (m) of the disc with the pulp's contact area at ``force_n`` (N)."""
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


@njit(error_model="numpy")
def _legibility_counts(force_n, setpoint_n, char_index, masks, contact, distance_m, stims, z_first):
    """One pass over the samples: per cell, the samples in which each stimulator in
    ``stims`` kept all raised dots legible, the samples shown, and whether the cell has
    raised dots.  An electrode's coverage is computed when a raised dot first needs it in a
    sample and then shared by all stimulators, the impedance once per sample for stimulators
    of the same impedance law (``z_first[m]``: the first stimulator whose law is that of
    ``stims[m]``), the setpoint's nominal values once per setpoint, the contact area once per
    sample for the coverage and the impedances (the stimulators in ``stims`` share the patch
    law of ``contact``: :func:`_legible_fractions` groups them by it); a raised dot whose
    coverage equals that of a dot already found legible in the sample with the same
    stimulator is legible too (the same ratio), so fully covered dots are checked once."""
    n_cells = masks.size
    n_ok = np.zeros((len(stims), n_cells), np.int64)
    n_all = np.zeros(n_cells, np.int64)
    shown = np.zeros(n_cells, np.bool_)
    phi = np.empty(distance_m.size)
    phi_at = np.full(distance_m.size, -1, np.int64)         # the sample each phi[e] was computed for
    z_sp = np.empty(len(stims))
    j_nom = np.empty(len(stims))
    z = np.empty(len(stims))
    r = contact.electrode_radius_m
    sp_last = math.nan                                      # setpoint whose nominal values are held
    for k in range(char_index.size):
        c = char_index[k]
        if c < 0:
            continue
        if not setpoint_n[k] == sp_last:
            sp_last = setpoint_n[k]
            for m in range(len(stims)):
                z_sp[m], j_nom[m] = _nominal(sp_last, stims[m])
        n_all[c] += 1
        dots = masks[c] & 0b111111
        if dots == 0:                                       # nothing to stimulate: vacuously legible
            for m in range(len(stims)):
                n_ok[m, c] += 1
            continue
        shown[c] = True
        fk = force_n[k]
        area = _contact_area_m2(fk, contact.contact_area_1n_m2, contact.contact_area_exponent)
        a = _radius_of_area(area)
        for m in range(len(stims)):
            stim = stims[m]
            if z_first[m] < m:
                z[m] = z[z_first[m]]
            elif fk >= stim.touch_force_n:
                z[m] = _impedance_at(fk, area, stim)
            else:
                z[m] = _impedance(fk, stim)
            ok = True
            legible_phi = math.nan                          # a coverage found legible in this sample
            for e in range(distance_m.size):                # the raised dots only, to the first dim one
                if (dots >> e) & 1:
                    if phi_at[e] != k:
                        phi[e] = _electrode_coverage(distance_m[e], r, a)
                        phi_at[e] = k
                    if phi[e] == legible_phi:
                        continue
                    q = _electrode_ratio(phi[e], z[m], z_sp[m], j_nom[m], stim)
                    if not (q >= stim.band_low and q <= stim.band_high):
                        ok = False
                        break
                    legible_phi = phi[e]
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
        laws = [_impedance_law(st) for st in stims]
        z_first = np.array([laws.index(law) for law in laws], dtype=np.int64)
        n_ok, n_all, shown = _legibility_counts(f, sp, ci, masks, contact, np.array(distances), stims, z_first)
        keep = np.nonzero(shown)[0]
        if keep.size == 0:
            continue
        for row, i in enumerate(members):
            out[i] = float(np.mean(n_ok[row, keep] / n_all[keep] >= LEGIBLE_REQUIRED))
    return out
