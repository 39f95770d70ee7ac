"""Disturbances of a reading session, each from its physics: the ``[disturbances]`` section.

A scenario lists the disturbances it wants as sub-tables; each becomes a per-control-period
profile of one plant input (:data:`ebraille_sim.plant.layout.INPUT_NAMES`), built before the
loop runs by :func:`build_inputs` (called by :func:`ebraille_sim.scenarios.inputs.input_profiles`)::

    [disturbances.tremor]
    rms_m = 15e-6

    [disturbances.strap_slip]
    at_s = [6.0]
    displacement_m = 0.2e-3

Pulp relaxation needs no entry: the fingertip's quasi-linear viscoelasticity is part of
the plant (:mod:`ebraille_sim.physics.fingertip`) and acts in every scenario.  Likewise the FSR's
creep under load and its temperature coefficient are in the sensor model
(:mod:`ebraille_sim.physics.fsr`); the entries below drive them.

==================  =======================  =================================================
sub-table           plant input              physics
==================  =======================  =================================================
``tremor``          finger_pos_m (add)       physiological tremor, Gaussian, band 8-12 Hz
``pressing``        finger_pos_m (add)       the reader pressing and relaxing: slow (0.1-1 Hz)
                                             Gaussian excursions of the pulp
``strap_slip``      finger_pos_m (add)       the strap resettles: steps of the pulp relative
                                             to the frame, smoothed over the slip duration
``orientation``     gravity_along_m_per_s2   hand rotation: -g cos(theta(t)) along the travel,
                    (set)                    theta on a minimum-jerk path
``fsr_temperature`` fsr_temp_offset_k (set)  skin warming the FSR: first-order approach from
                                             the device's temperature to the skin's
``fsr_drift``       fsr_temp_offset_k (set)  a long session: the run starts ``session_offset_s``
                                             into continuous loading (pre-loaded creep)
``battery``         driver_supply_v (set)    Li-ion cell: OCV(SoC) minus the drop of a
                                             Thevenin (R0 + R1||C1) model; cut-off at 3.0 V
==================  =======================  =================================================

Finger position convention: ``finger_pos_m`` is the pulp surface relative to the device
frame along the board travel; a positive change moves the pulp away from the board (less
compression, less force).

**Pre-loaded creep through the temperature input.**  The sensor kernel creeps from a
recovered film at the start of a run (hereditary creep,
:func:`ebraille_sim.physics.fsr.creep_force`) and scales the film resistance by the
temperature law of ``u_T``, the ``fsr_temp_offset_k`` input.  A run that starts
``t_off`` into a session of held contact must see the resistance of a film crept for
``t_off + t``; for a held force the ratio ``D = c(t_off + t) / c(t)`` of
:func:`ebraille_sim.physics.fsr.held_resistance_factor` (load taken to start at t = 0,
which the first contact follows within a few tenths of a second) is folded into the same
input: ``u_T`` is the warm offset whose factor is ``T(dT) D``
(:func:`ebraille_sim.physics.fsr.temperature_offset_k`), where ``T`` is the temperature law
(:func:`ebraille_sim.physics.fsr.temperature_factor`, falling on both sides of 25 C) and ``dT``
the temperature offset of ``fsr_temperature`` (0 without it).

Every parameter, its unit, range and source are listed by :func:`parameter_table` (and in
``docs/scenarios.md``); the class docstrings give the equations.

Examples
--------
>>> import numpy as np
>>> from ebraille_sim.physics.params import DeviceParams
>>> sec = validate_section("inline", {"tremor": {"rms_m": 20e-6}})
>>> t = np.arange(2000) * 1e-3
>>> prof = build_inputs(sec, t, np.random.default_rng(0), DeviceParams())
>>> mode, x = prof["finger_pos_m"]
>>> mode, round(float(np.std(x)) * 1e6)
('add', 20)
>>> validate_section("inline", {"tremor": {"rms": 1}})
Traceback (most recent call last):
...
ebraille_sim.scenarios.spec.ScenarioError: inline: unknown key 'rms' in [disturbances.tremor]; allowed: band_hz, rms_m, transmission
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from ebraille_sim.base.fields import sourced
from ebraille_sim.scenarios.draws import child_generator
from ebraille_sim.base.validation import check_keys, check_number, check_pair
from ebraille_sim.estimation.firmware import firmware_fsr
from ebraille_sim.physics.fsr import held_resistance_factor, temperature_offset_k, temperature_scale
from ebraille_sim.physics.params import STANDARD_GRAVITY_M_PER_S2
from ebraille_sim.scenarios.spec import ScenarioError, check_section_table

__all__ = ["KINDS", "validate_section", "driven_inputs", "build_inputs", "parameter_table", "band_limited_noise",
           "minimum_jerk", "strap_transmission", "body_motion_budget", "li_ion_ocv_v", "Tremor", "Pressing", "StrapSlip",
           "Orientation", "FSRTemperature", "FSRDrift", "Battery"]

G_M_PER_S2 = STANDARD_GRAVITY_M_PER_S2

MAX_NOISE_RECORD_SAMPLES = 2 ** 25
"""Longest record :func:`band_limited_noise` synthesises, samples: about 40 bytes per
sample (the record, its spectrum, frequencies and draws), 1.3 GB at this bound."""

MIN_BAND_WIDTH_HZ = 0.01
"""Narrowest ``band_hz`` of a noise disturbance, Hz.  A band narrower than this is a single
sinusoid over any session (its components drift apart by less than one cycle in 100 s),
not the random process the model describes; the synthesis would also need a record of
4 / width s (400 s at this bound)."""


# --------------------------------------------------------------------------------------
# signal helpers
# --------------------------------------------------------------------------------------

def band_limited_noise(t_s: np.ndarray, f_lo_hz: float, f_hi_hz: float, rms: float,
                       rng: np.random.Generator) -> np.ndarray:
    """Stationary Gaussian noise with a flat spectrum in ``[f_lo_hz, f_hi_hz]``.

    Synthesised in the frequency domain (independent complex Gaussian bins inside the
    band, zero outside) over a record long enough to hold ``len(t_s)`` samples, four periods
    of ``f_lo_hz`` and four of the band's width, of the next length with no prime factor
    above 5 (:func:`fast_length`), scaled to the RMS ``rms`` over that record (computed from
    the spectrum, Parseval's theorem), then cut to ``len(t_s)``.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Uniformly spaced times, s.
    f_lo_hz, f_hi_hz : float
        Band edges, Hz (``0 <= f_lo < f_hi``, ``f_hi`` below the Nyquist frequency).
    rms : float
        Root-mean-square value of the process.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (n,)
    """
    n = len(t_s)
    if n == 0 or rms == 0.0:
        return np.zeros(n)
    dt = float(t_s[1] - t_s[0]) if n > 1 else 1e-3
    if not f_hi_hz < 0.5 / dt:
        raise ValueError(f"band edge {f_hi_hz:g} Hz is above the Nyquist frequency {0.5 / dt:g} Hz")
    if not f_hi_hz > f_lo_hz:
        raise ValueError(f"band [{f_lo_hz:g}, {f_hi_hz:g}] Hz is empty; it needs f_lo < f_hi")
    rec_s = max(4.0 / max(f_lo_hz, 1e-3), 4.0 / (f_hi_hz - f_lo_hz))
    if rec_s / dt > MAX_NOISE_RECORD_SAMPLES:
        raise ValueError(f"band [{f_lo_hz:g}, {f_hi_hz:g}] Hz needs a record of {rec_s:.4g} s (four periods of "
                         f"the lower edge and of the band width) = {rec_s / dt:.4g} samples at {1 / dt:g} Hz, "
                         f"above the bound of {MAX_NOISE_RECORD_SAMPLES:.4g} samples "
                         f"(~{MAX_NOISE_RECORD_SAMPLES * 40 / 1e9:.2g} GB); widen the band or lower the control rate")
    n_rec = fast_length(max(n, int(math.ceil(4.0 / (max(f_lo_hz, 1e-3) * dt))),
                            int(math.ceil(4.0 / ((f_hi_hz - f_lo_hz) * dt)))))
    i0, i1 = _band_bins(n_rec, dt, f_lo_hz, f_hi_hz)
    spec = np.zeros(n_rec // 2 + 1, dtype=complex)
    k = max(i1 - i0, 0)
    bins = spec[i0:i0 + k]
    bins.real = rng.standard_normal(k)
    bins.imag = rng.standard_normal(k)
    # the record's RMS from its spectrum (Parseval: no bin at 0 or at the Nyquist frequency, so
    # the mean is 0 and each bin stands for itself and its conjugate): 2 sum |X_i|^2 / n_rec^2
    s = math.sqrt(2.0 * float(np.vdot(bins, bins).real)) / n_rec
    if not s > 0:
        return np.zeros(n)
    x = np.fft.irfft(spec, n_rec)[:n]
    x *= rms / s
    return x


@functools.lru_cache(maxsize=1024)
def fast_length(n: int) -> int:
    """The smallest length ``>= n`` whose only prime factors are 2, 3 and 5: an FFT size that
    NumPy's FFT transforms in a few passes of small radices (a record of a prime length takes
    it five to six times as long: 1399 points 57 us, 1400 points 9 us).  Remembered per
    length (an env's episodes have a few hundred lengths).

    >>> fast_length(1399), fast_length(1400), fast_length(8000)
    (1440, 1440, 8000)
    """
    best = 1 << max(int(n) - 1, 0).bit_length()          # the next power of two
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            q = p35
            while q < n:
                q *= 2
            best = min(best, q)
            p35 *= 3
        p5 *= 5
    return best


def _band_bins(n_rec: int, dt: float, f_lo_hz: float, f_hi_hz: float) -> tuple[int, int]:
    """The bins ``[i0, i1)`` of ``numpy.fft.rfftfreq(n_rec, dt)`` (bin ``i`` at ``i * (1 / (n_rec dt))``,
    NumPy's product) with ``f_lo_hz <= f <= f_hi_hz`` and ``f > 0``: the frequencies rise with
    ``i``, so the band is one run of bins, found from the edges over / the bin width and a
    step or two of the same products."""
    val = 1.0 / (n_rec * dt)
    n_bins = n_rec // 2 + 1
    i0 = min(max(1, int(f_lo_hz / val) - 2), n_bins)
    while i0 < n_bins and not (i0 * val >= f_lo_hz and i0 * val > 0):
        i0 += 1
    i1 = min(max(int(f_hi_hz / val) + 2, 0), n_bins - 1)
    while i1 >= i0 and not i1 * val <= f_hi_hz:
        i1 -= 1
    return i0, i1 + 1


def minimum_jerk(u) -> np.ndarray:
    """Minimum-jerk transition 0 -> 1 (Flash & Hogan 1985): ``10u^3 - 15u^4 + 6u^5`` on [0, 1]."""
    u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    return u ** 3 * (10.0 - 15.0 * u + 6.0 * u * u)


def strap_transmission(f_hz: float, frame_mass_kg: float, strap_stiffness_n_per_m: float,
                       damping_ratio: float = 0.2) -> float:
    """Relative pulp-to-frame displacement per unit finger displacement at ``f_hz``.

    A frame of mass ``m`` carried by the finger through a strap of stiffness ``k`` lags
    the finger's motion; the relative motion of base excitation is
    ``|r^2 / (1 - r^2 + 2 j zeta r)|`` with ``r = f / f_n`` and ``f_n = sqrt(k/m) / 2 pi``.

    >>> round(strap_transmission(10.0, 0.015, 10e3), 3)     # 15 g frame, 10 N/mm strap
    0.006
    """
    fn = math.sqrt(strap_stiffness_n_per_m / frame_mass_kg) / (2 * math.pi)
    r = f_hz / fn
    return abs(r * r / complex(1 - r * r, 2 * damping_ratio * r))


FRAME_MASS_KG = 0.015
"""Mass of the finger-worn frame (motor, gearhead, board, battery, case), kg [E]: the mass
:func:`strap_transmission`'s example assumes."""

STRAP_STIFFNESS_N_PER_M = (5e3, 20e3)
"""Stiffness of the dorsal strap and nail bed in series, N/m [E] (parameters section 6:
5-20 N/mm, stiffer than the pulp but not rigid)."""

STRAP_DAMPING_RATIO = 0.2
"""Damping ratio of the frame on its strap [E] (:func:`strap_transmission`'s default)."""

FINGER_TREMOR_RMS_MAX_M = 200e-6
"""Largest finger tremor a wearer produces, m RMS: the 30 um mean of physiological finger tremor,
4-5 fold with the arm extended and more under mental stress ([R] Growdon et al. 2000), taken
as about 6.7 times the mean [E]."""

READING_ACCEL_MAX_M_PER_S2 = 20.0
"""Largest acceleration of the hand normal to the board during reading, m/s^2 [E] (2 g: line
returns and lifts of a finger whose velocity changes many times along a line, [R] Hughes et al.
2011, Hum Mov Sci 30:711, give no values)."""

SLIP_DEPTH_MAX_M = 0.5e-3
"""Largest single strap slip, m: a resettling by a fraction of the few millimetres of dorsal
soft tissue under the strap, 0.1-0.5 mm [E] (:class:`StrapSlip`)."""

SLIP_TOWARD_MAX_M = 0.1e-3
"""Largest strap slip toward the board (more compression) that the wearer's own motion produces,
m [E]: the contact force presses the frame onto a finger that tapers toward its tip, so a slip
under load runs distally and unloads the pulp ([D] the wedge); a slip toward the board needs
work done on the frame from outside it, and only the dorsal skin dragging the strap back as the
finger extends does that by itself, a fraction of :data:`SLIP_DEPTH_MAX_M`."""

SLIP_DURATION_MIN_S = 0.02
"""Shortest strap slip, s [E]: the skin under the strap shears over tens of milliseconds
(:class:`StrapSlip`'s 30 ms default); 20 ms is the fast end."""


def body_motion_budget(frame_mass_kg: float = FRAME_MASS_KG,
                       strap_stiffness_n_per_m: tuple = STRAP_STIFFNESS_N_PER_M,
                       damping_ratio: float = STRAP_DAMPING_RATIO) -> dict:
    """The relative motion between the pulp and the board that a wearer produces with the frame
    strapped to the finger (docs/safety.md, "Body motion"), SI units.

    The frame rides on the finger through the strap: the finger's own motion reaches the gap
    only as the frame's inertial lag, :func:`strap_transmission`, worst for the softest strap.
    Keys: ``tremor_transmission_max`` (over 8-12 Hz) and ``tremor_rms_max_m`` (finger tremor,
    :data:`FINGER_TREMOR_RMS_MAX_M`) with ``tremor_gap_rms_max_m`` (their product);
    ``pressing_transmission_max`` (at 1 Hz, the top of :class:`Pressing`'s band) and
    ``pressing_rms_max_m`` (the schema's largest pressing excursion through it);
    ``lift_depth_max_m`` (the frame's lag under the largest reading acceleration,
    twice the static ``m a / k`` for an acceleration that sets in at once) and ``lift_move_min_s``
    (a quarter period of the frame on the stiffest strap: the fastest rise of that lag);
    ``slip_depth_max_m``, ``slip_toward_max_m`` (toward the board) and ``slip_duration_min_s``
    (strap slips, which the strap does not attenuate: the strap itself moves on the skin).

    >>> b = body_motion_budget()
    >>> round(b["tremor_transmission_max"], 4), round(b["tremor_gap_rms_max_m"] * 1e6, 2)
    (0.0173, 3.47)
    >>> round(b["lift_depth_max_m"] * 1e3, 3), round(b["lift_move_min_s"] * 1e3, 2)
    (0.12, 1.36)
    """
    k_lo, k_hi = strap_stiffness_n_per_m
    t_tremor = max(strap_transmission(f, frame_mass_kg, k_lo, damping_ratio) for f in (8.0, 10.0, 12.0))
    t_press = strap_transmission(1.0, frame_mass_kg, k_lo, damping_ratio)
    return {
        "tremor_transmission_max": t_tremor,
        "tremor_rms_max_m": FINGER_TREMOR_RMS_MAX_M,
        "tremor_gap_rms_max_m": t_tremor * FINGER_TREMOR_RMS_MAX_M,
        "pressing_transmission_max": t_press,
        "pressing_rms_max_m": t_press * PRESSING_RMS_MAX_M,
        "lift_depth_max_m": 2.0 * frame_mass_kg * READING_ACCEL_MAX_M_PER_S2 / k_lo,
        "lift_move_min_s": 0.5 * math.pi * math.sqrt(frame_mass_kg / k_hi),
        "slip_depth_max_m": SLIP_DEPTH_MAX_M,
        "slip_toward_max_m": SLIP_TOWARD_MAX_M,
        "slip_duration_min_s": SLIP_DURATION_MIN_S,
    }


_OCV_SOC = np.array([0.0, 0.05, 0.10, 0.20, 0.30, 0.40, 0.50, 0.60, 0.70, 0.80, 0.90, 1.00])
_OCV_V = np.array([3.00, 3.45, 3.60, 3.68, 3.73, 3.77, 3.81, 3.86, 3.92, 3.99, 4.07, 4.18])
"""Open-circuit voltage of a LiCoO2/graphite polymer cell against state of charge [E]:
the shape of typical 0.2C discharge curves, anchored at the datasheet values 4.2 V full,
3.7 V nominal, 3.0 V discharge cut-off ([R] GMB 371042 and AIN 80 mAh LiPo data sheets)."""


def li_ion_ocv_v(soc) -> np.ndarray:
    """Open-circuit voltage (V) of one Li-ion polymer cell at state of charge ``soc`` in [0, 1]."""
    return np.interp(np.clip(soc, 0.0, 1.0), _OCV_SOC, _OCV_V)


# --------------------------------------------------------------------------------------
# the disturbances
# --------------------------------------------------------------------------------------

PRESSING_RMS_MAX_M = 0.7e-3
"""Largest pressing excursion of the pulp, m RMS [D]: a third of the 2.1 mm that the soft reader's
pulp compresses between the 0.2 N and 3 N ends of the tactile range ([R] seed paper), so that
three standard deviations span the range."""


@dataclass(frozen=True)
class Tremor:
    """Physiological tremor of the finger: band-limited Gaussian pulp motion.

    ``x(t) = transmission * n(t)``, ``n`` Gaussian with a flat spectrum in ``band_hz`` and
    RMS ``rms_m`` (:func:`band_limited_noise`).  Physiological finger tremor has its peak
    at 8-12 Hz, almost independent of the force exerted ([R] Sutton & Sykes 1967,
    J Physiol 191:699; [R] Lakie et al. 2015, J Physiol 593:4411: 6-12 Hz, mainly a
    mechanical resonance).  Mean finger tremor amplitude is about 30 um, doubled with the
    hand extended ([R] Growdon et al. 2000, Electromyogr Clin Neurophysiol 40:295,
    accelerometry, 40 subjects); the 7.5-12.5 Hz band holds about a quarter of the total
    displacement ([R] Carignan et al. 2009, Exp Brain Res 199:299, laser displacement of
    the index finger).  Default 15 um RMS [E] within these.

    ``transmission`` is the fraction of the finger's motion that appears between the
    pulp and the board.  1 (default) takes all of it: a frame that does not follow the
    finger (anchored elsewhere, a table-top display).  A frame strapped to the same phalanx
    follows the finger and transmits only its inertial lag, :func:`strap_transmission`
    (0.006 at 10 Hz for a 15 g frame on a 10 N/mm strap [E], strap stiffness 5-20 N/mm from
    parameters section 6; at most 0.0173 over 8-12 Hz, :func:`body_motion_budget`); even a
    strap that holds 3 N within the 6 mm rack travel passes at most 0.20 at 12 Hz.
    """
    rms_m: float = sourced(15e-6, "m", "[R]/[E] Growdon 2000 ~30 um mean; Carignan 2009 band share; at most "
                           "200 um (4-5 fold with the arm extended, more under stress)",
                           lo=0.0, hi=FINGER_TREMOR_RMS_MAX_M, kind="float", doc="RMS of the pulp's tremor motion.")
    band_hz: tuple = sourced((8.0, 12.0), "Hz", "[R] Sutton & Sykes 1967; Lakie 2015",
                             lo=0.0, hi=100.0, kind="band", doc="Frequency band of the tremor.")
    transmission: float = sourced(1.0, "-", "[E] 1 = frame does not follow the finger; "
                             "strap_transmission() for a strapped frame", lo=0.0, hi=1.0, kind="float",
                                  doc="Share of the pulp's motion relative to the frame (1: the frame does not follow).")

    drives = ("finger_pos_m",)
    """The plant inputs :meth:`inputs` returns."""

    def inputs(self, t_s, rng, device):
        x = band_limited_noise(t_s, self.band_hz[0], self.band_hz[1], self.rms_m, rng)
        return {"finger_pos_m": ("add", self.transmission * x)}


@dataclass(frozen=True)
class Pressing:
    """The reader pressing and relaxing: slow Gaussian excursions of the pulp.

    ``x(t)`` Gaussian, flat spectrum in ``band_hz``, RMS ``rms_m``.  Readers' contact
    force wanders around its mean: one Braille reader on a pressure mat averaged
    0.8-0.9 N, another about 0.1 N ([R] Niigata tactile-pressure study); searching a
    surface, force stays near 0.5-0.64 N ([R] Smith et al. 2002).  A force excursion of
    0.15 N RMS [E] through the pulp's tangent stiffness of 1.5 N/mm at 1 N ([E]
    parameters table 1.2) is 0.1 mm RMS [D]; its time scale, from line-length movements
    of a few seconds to word-scale adjustments, gives the band 0.1-1 Hz [E].
    """
    rms_m: float = sourced(0.1e-3, "m", "[D] 0.15 N RMS [E] / 1.5 N/mm [E]; at most a third of the soft "
                           "reader's 2.1 mm between 0.2 and 3 N [D]", lo=0.0, hi=PRESSING_RMS_MAX_M, kind="float",
                           doc="RMS of the pulp's slow pressing excursions.")
    band_hz: tuple = sourced((0.1, 1.0), "Hz", "[E] line- to word-scale adjustments", lo=0.0, hi=20.0, kind="band",
                             doc="Frequency band of the pressing.")

    drives = ("finger_pos_m",)
    """The plant inputs :meth:`inputs` returns."""

    def inputs(self, t_s, rng, device):
        return {"finger_pos_m": ("add", band_limited_noise(t_s, self.band_hz[0], self.band_hz[1], self.rms_m, rng))}


@dataclass(frozen=True)
class StrapSlip:
    """The strap slips: the pulp moves relative to the frame by a step, ramped over the slip.

    ``x(t) = sum_i D_i s((t - t_i) / T)`` with ``s`` the minimum-jerk ramp and ``T`` =
    ``duration_s``; each slip moves the pulp by ``d`` = ``displacement_m`` (positive: away
    from the board) until the strap seats: the accumulated offset ``X_i = clip(X_{i-1} + d,
    -X_max, X_max)`` and ``D_i = X_i - X_{i-1}``, with ``X_max`` = ``max_offset_m``.  Slip
    times ``t_i`` are ``at_s``, or a Poisson process of ``rate_per_min`` when ``at_s`` is
    empty.  The strap sits on the dorsal skin over the distal phalanx, which is a few
    millimetres of soft tissue [M]; a resettling by a fraction of it gives 0.1-0.5 mm [E]
    (0.2 mm default).  A strap slips as the skin under it shears, taking tens of
    milliseconds (30 ms [E]).  It cannot slide without end: the finger tapers toward its
    tip and the skin under the strap stretches, so the strap seats after about 1 mm [E]
    (``max_offset_m``), well inside the 6 mm rack travel; an hour of slips at 2 per minute
    therefore moves the pulp 1 mm, not 12.
    """
    at_s: tuple = sourced((), "s", "[E] scenario-chosen slip times", lo=0.0, hi=3600.0, kind="times",
                          doc="Times of the slips (empty: drawn at rate_per_min).")
    rate_per_min: float = sourced(0.0, "1/min", "[E] Poisson slip rate when at_s is empty",
                                  lo=0.0, hi=60.0, kind="float", doc="Rate of randomly timed slips when at_s is empty.")
    displacement_m: float = sourced(0.2e-3, "m", "[E] 0.1-0.5 mm resettling of the strap",
                                    lo=-2e-3, hi=2e-3, kind="float",
                                    doc="Pulp motion relative to the frame in one slip (> 0: away from the board).")
    duration_s: float = sourced(0.03, "s", "[E] skin shear under the strap, tens of ms (at least 10 ms)",
                                lo=0.01, hi=5.0, kind="float", doc="Time one slip takes.")
    max_offset_m: float = sourced(1e-3, "m", "[E] the strap seats after ~1 mm of slips (tapering finger, "
                                  "stretched skin)", lo=0.0, hi=3e-3, kind="float",
                                  doc="Largest total offset the slips add up to (the strap seats).")

    drives = ("finger_pos_m",)
    """The plant inputs :meth:`inputs` returns."""

    def inputs(self, t_s, rng, device):
        times = list(self.at_s)
        if not times and self.rate_per_min > 0 and len(t_s):
            t_end = float(t_s[-1])
            t = float(rng.exponential(60.0 / self.rate_per_min))
            while t < t_end:
                times.append(t)
                t += float(rng.exponential(60.0 / self.rate_per_min))
        x = np.zeros(len(t_s))
        offset = 0.0
        d, x_max = self.displacement_m, self.max_offset_m
        for ti in sorted(times):
            step = d if abs(offset + d) <= x_max else min(max(offset + d, -x_max), x_max) - offset
            if step != 0.0:
                # the ramp is 0 up to t_i and exactly 1 from t_i + T on: it is evaluated only
                # in between (from t_i + 2 T on every sample is past the end, whatever the rounding)
                lo = int(np.searchsorted(t_s, ti, side="right"))
                hi = int(np.searchsorted(t_s, ti + 2.0 * self.duration_s, side="left"))
                x[lo:hi] += step * minimum_jerk((t_s[lo:hi] - ti) / self.duration_s)
                x[hi:] += step
            offset += step
        return {"finger_pos_m": ("add", x)}


@dataclass(frozen=True)
class Orientation:
    """Hand orientation change: gravity along the board travel follows the hand's angle.

    ``g_along(t) = -g cos(theta(t))``, theta moving from ``from_deg`` to ``to_deg`` on a
    minimum-jerk path ([M] Flash & Hogan 1985) starting at ``at_s`` and lasting
    ``duration_s``, and back from ``return_at_s`` when given.  0 deg is the scenario's
    reference posture (travel vertical, board pressing up against gravity, as in
    ``[device] hand_orientation_deg``); without ``from_deg`` the start is that posture.
    Gravity acts on the board and racks (``moving_mass_kg``).  A forearm rotation of
    60-90 deg takes about 0.4-1 s [E] (0.6 s default).
    """
    from_deg: float = sourced(None, "deg", "[E] default: the device's hand_orientation_deg",
                              lo=-180.0, hi=180.0, kind="optional",
                              doc="Hand orientation before the change (None: the device's hand_orientation_deg).")
    to_deg: float = sourced(90.0, "deg", "[E] palm turned sideways", lo=-180.0, hi=180.0, kind="float",
                            doc="Hand orientation after the change.")
    at_s: float = sourced(5.0, "s", "[E] scenario-chosen", lo=0.0, hi=3600.0, kind="float", doc="Start of the change.")
    duration_s: float = sourced(0.6, "s", "[E] forearm rotation 0.4-1 s", lo=0.01, hi=60.0, kind="float",
                                doc="Time the change takes.")
    return_at_s: float = sourced(None, "s", "[E] optional return to from_deg", lo=0.0, hi=3600.0, kind="optional",
                                 doc="Time of the return to from_deg (None: none).")

    drives = ("gravity_along_m_per_s2",)
    """The plant inputs :meth:`inputs` returns."""

    def inputs(self, t_s, rng, device):
        a0 = self.from_deg
        if a0 is None:
            a0 = math.degrees(math.acos(max(-1.0, min(1.0, device.gravity_m_per_s2 / G_M_PER_S2))))
        th = a0 + (self.to_deg - a0) * minimum_jerk((t_s - self.at_s) / self.duration_s)
        if self.return_at_s is not None:
            th = th - (self.to_deg - a0) * minimum_jerk((t_s - self.return_at_s) / self.duration_s)
        return {"gravity_along_m_per_s2": ("set", -G_M_PER_S2 * np.cos(np.radians(th)))}


@dataclass(frozen=True)
class FSRTemperature:
    """Skin warming the FSR: a first-order approach to skin temperature.

    ``T(t) = T_start + (T_skin - T_start)(1 - exp(-(t - t_on)/tau))`` for ``t >= t_on``;
    the plant input is ``T - T_ref`` (the sensor model's resistance coefficient, -15 % at
    +85 C after 1 h [R] datasheet, applies to it).  Finger skin is 29.1 +/- 0.6 C at room
    temperature and 27-31 C with posture ([R] Shilco et al. 2019, J Therm Biol 80:82);
    the pulp pressed against the board is at the warm end (31 C default [E]).  The film
    (0.45 mm) sits on the board under the display; conduction through a ~1.5 mm
    board/overlay stack (k ~ 0.3 W/m/K, rho c ~ 2 MJ/m^3/K) gives L^2/a ~ 15 s, and the
    board's lateral heat capacity and loss to air stretch it to about a minute (60 s [E]).
    ``reference_c`` is the temperature at which the device was calibrated (25 C [E]).
    """
    start_c: float = sourced(25.0, "degC", "[E] device at room temperature", lo=-20.0, hi=60.0, kind="float",
                             doc="FSR temperature at the start.")
    skin_c: float = sourced(31.0, "degC", "[R] Shilco 2019: fingers 27-31 C", lo=20.0, hi=40.0, kind="float",
                            doc="Skin temperature it approaches.")
    reference_c: float = sourced(25.0, "degC", "[E] calibration temperature", lo=-20.0, hi=60.0, kind="float",
                                 doc="Temperature the FSR was calibrated at.")
    tau_s: float = sourced(60.0, "s", "[E] board/film conduction with losses", lo=1.0, hi=3600.0, kind="float",
                           doc="Time constant of the warming.")
    at_s: float = sourced(0.0, "s", "[E] device put on at t = at_s", lo=0.0, hi=3600.0, kind="float",
                          doc="Time the device is put on.")

    def offset_k(self, t_s):
        rise = np.where(t_s >= self.at_s, -np.expm1(-(t_s - self.at_s) / self.tau_s), 0.0)
        return self.start_c - self.reference_c + (self.skin_c - self.start_c) * rise


@dataclass(frozen=True)
class FSRDrift:
    """A long session: the run starts ``session_offset_s`` into continuous loading.

    The sensor model's resistance under a held force, ``c(t)``
    (:func:`ebraille_sim.physics.fsr.held_resistance_factor`: conductance rising about
    2.1-2.4 % per decade for days, datasheet < 5 % per decade), is advanced by the offset: the run sees
    ``c(t_off + t)`` instead of ``c(t)``.  Folded into the temperature input (module
    docstring).  The firmware has followed the same session: its creep compensation predicts
    with its own law (:func:`ebraille_sim.estimation.firmware.firmware_fsr`: the nominal film
    with the creep per decade the unit's bench measured) advanced by the same offset, the
    ``est_creep_preload`` input (``factor - 1`` of that law,
    :func:`ebraille_sim.estimation.firmware.creep_compensated_v`).  A reading session of
    30 min to 2 h [E] gives offsets of 1800-7200 s; standard FSR ink drifts about 12 % in
    conductance over 48 h ([R] Sensitronics).
    """
    session_offset_s: float = sourced(1800.0, "s", "[E] 30 min into a session; creep law of "
                                 "the FSR model (hereditary creep, conductance rising under load)",
                                     lo=0.0, hi=7 * 24 * 3600.0, kind="float",
                                      doc="Load time before the run starts (the session so far).")

    def factor(self, t_s, fsr):
        t = np.maximum(t_s, 0.0)
        return held_resistance_factor(self.session_offset_s + t, fsr) / held_resistance_factor(t, fsr)


@dataclass(frozen=True)
class Battery:
    """Battery voltage sag: the H-bridge supply from one or more Li-ion polymer cells.

    Thevenin model ([R] form: OCV(SoC) source, series resistance, RC pairs; e.g. the
    ``thevenin`` package documentation): ``dSoC/dt = -I/(3600 Q)``,
    ``dV1/dt = -V1/(R1 C1) + I/C1`` with ``tau1 = R1 C1``, terminal voltage per cell
    ``OCV(SoC) - I R0 - V1``.  The load current ``I`` is the device's mean draw
    (microcontroller, stimulator boost and the motor's mean current), held constant: the
    loop's own motor current peaks (< 0.3 A at stall) would add at most ``0.3 A x R0``
    ~ 0.1 V more, which this open-loop profile leaves out.  When a cell falls below
    ``cutoff_v`` the protection circuit opens and the supply is 0 from then on.

    Sources: capacity 105 mAh and R0 <= 380 mOhm (AC 1 kHz, 50 % SoC), 4.2 V full,
    3.0 V cut-off ([R] GMB 371042 LiPo data sheet; a 2 g cell that fits a finger-worn
    device); OCV curve [E] (:data:`_OCV_V`); R1 = 0.15 Ohm, tau1 = 30 s [E] (polarisation
    of small polymer cells, of the order of R0 and tens of seconds); load 30 mA [E]
    (ATmega328 at 16 MHz ~15 mA [M], stimulator 2 mA x 150 V x 4 ms/s x 6 electrodes
    through a 70 % boost ~3 mA [D], motor mean ~10 mA from the closed-loop energy).
    """
    cells_series: int = sourced(1, "-", "[E] one cell in a finger-worn device", lo=1, hi=4, kind="int",
                                doc="Li-ion polymer cells in series.")
    capacity_mah: float = sourced(105.0, "mAh", "[R] GMB 371042 data sheet", lo=1.0, hi=10000.0, kind="float",
                                  doc="Capacity of a cell.")
    soc_start: float = sourced(0.10, "-", "[E] a nearly empty cell", lo=0.0, hi=1.0, kind="float",
                               doc="State of charge at the start.")
    load_current_a: float = sourced(0.03, "A", "[E] mean device draw", lo=0.0, hi=2.0, kind="float",
                                    doc="Mean current the device draws.")
    r0_ohm: float = sourced(0.38, "ohm", "[R] GMB 371042: <= 380 mOhm", lo=0.0, hi=10.0, kind="float",
                            doc="Series resistance of a cell.")
    r1_ohm: float = sourced(0.15, "ohm", "[E] polarisation resistance", lo=0.0, hi=10.0, kind="float",
                            doc="Polarisation resistance of a cell.")
    tau1_s: float = sourced(30.0, "s", "[E] polarisation time constant", lo=0.1, hi=3600.0, kind="float",
                            doc="Polarisation time constant.")
    cutoff_v: float = sourced(3.0, "V", "[R] discharge cut-off voltage", lo=2.5, hi=3.6, kind="float",
                              doc="Cut-off voltage of a cell.")

    def supply_v(self, t_s):
        i = self.load_current_a
        soc = self.soc_start - i * t_s / (3600.0 * self.capacity_mah * 1e-3)
        v1 = i * self.r1_ohm * -np.expm1(-np.maximum(t_s, 0.0) / self.tau1_s)
        cell = li_ion_ocv_v(soc) - i * self.r0_ohm - v1
        cell = np.where(soc <= 0.0, 0.0, cell)
        dead = np.maximum.accumulate(cell < self.cutoff_v)
        return np.where(dead, 0.0, self.cells_series * cell)

    drives = ("driver_supply_v",)
    """The plant inputs :meth:`inputs` returns."""

    def inputs(self, t_s, rng, device):
        return {"driver_supply_v": ("set", self.supply_v(t_s))}


PROFILE_CHUNK = 1 << 16
"""Samples per chunk of the profiles computed sample by sample (:func:`build_inputs`)."""

KINDS: dict[str, type] = {
    "tremor": Tremor, "pressing": Pressing, "strap_slip": StrapSlip, "orientation": Orientation,
    "fsr_temperature": FSRTemperature, "fsr_drift": FSRDrift, "battery": Battery,
}
"""Sub-tables of ``[disturbances]`` and their parameter classes.  The order fixes the
random stream of each kind (child ``k`` of the run's input generator), so adding one
disturbance never changes the draws of another."""


# --------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------

def _fmt(x):
    return f"{x:g}"


@functools.lru_cache(maxsize=None)
def _kind_fields(cls) -> tuple[dict, tuple]:
    """The fields of a disturbance class by name, and their names sorted (read once per class)."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    return fields, tuple(sorted(fields))


def _check_kind(src, name, cls, table):
    where0 = f"[disturbances.{name}]"
    if not isinstance(table, dict):
        raise ScenarioError(f"{src}: {where0} must be a table")
    fields, names = _kind_fields(cls)
    out = {}
    try:
        check_keys(where0, table, names)
        for key, value in table.items():
            meta = fields[key].metadata
            where = f"{where0} {key}"
            kind = meta["kind"]
            if kind == "band":
                out[key] = check_pair(where, value, meta["lo"], meta["hi"], strict=True)
                width = out[key][1] - out[key][0]
                if width < MIN_BAND_WIDTH_HZ:
                    raise ValueError(f"{where} = [{out[key][0]:.10g}, {out[key][1]:.10g}] is {width:.3g} Hz wide, "
                                     f"narrower than {MIN_BAND_WIDTH_HZ:g} Hz: that is a single sinusoid over a "
                                     f"session, not a random band, and its synthesis needs a record of "
                                     f"4/width = {4 / width:.3g} s")
            elif kind == "times":
                if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
                    raise ValueError(f"{where} must be a list of times in s, got {value!r}")
                out[key] = tuple(sorted(check_number(where, v, meta["lo"], meta["hi"]) for v in value))
            else:
                out[key] = check_number(where, value, meta["lo"], meta["hi"], integer=(kind == "int"))
    except ValueError as exc:
        raise ScenarioError(f"{src}: {exc}") from None
    obj = cls(**out)
    if isinstance(obj, Orientation) and obj.return_at_s is not None and obj.return_at_s < obj.at_s + obj.duration_s:
        raise ScenarioError(f"{src}: {where0} return_at_s = {obj.return_at_s:g} must be at least "
                            f"at_s + duration_s = {obj.at_s + obj.duration_s:g}")
    return obj


def validate_section(source: str, value) -> dict:
    """Validate a ``[disturbances]`` table; returns ``{name: parameter object}``.

    Raises :class:`~ebraille_sim.scenarios.spec.ScenarioError` (one line) naming an unknown
    sub-table or key with the allowed ones, or a value out of range with the range.
    """
    check_section_table(source, "disturbances", value, sorted(KINDS))
    out = {}
    for name, table in value.items():
        out[name] = _check_kind(source, name, KINDS[name], table)
    return out


# --------------------------------------------------------------------------------------
# profiles
# --------------------------------------------------------------------------------------

def driven_inputs(section: dict) -> tuple:
    """The plant inputs :func:`build_inputs` returns for a validated ``[disturbances]`` section."""
    names = [name for kind in KINDS if kind in section for name in getattr(section[kind], "drives", ())]
    if "fsr_temperature" in section or "fsr_drift" in section:
        names.append("fsr_temp_offset_k")
    if "fsr_drift" in section:
        names.append("est_creep_preload")
    return tuple(dict.fromkeys(names))


def build_inputs(section: dict, t_s: np.ndarray, rng: np.random.Generator, device, out: dict | None = None) -> dict:
    """Per-period plant input profiles of a validated ``[disturbances]`` section.

    Parameters
    ----------
    section : dict
        As returned by :func:`validate_section`.
    t_s : ndarray, shape (n,)
        Start times of the control periods, s.
    rng : numpy.random.Generator
        The run's input generator; kind ``k`` of :data:`KINDS` draws from its child ``k``
        (:func:`ebraille_sim.scenarios.draws.child_generator`; only the children of the kinds
        present are made, and ``rng`` is left as it was).
    device : DeviceParams
    out : dict, optional
        ``{input_name: ndarray of shape (n,)}``: arrays a "set" profile computed in chunks
        (the FSR's temperature offset and creep preload) is written into and returned as.

    Returns
    -------
    dict
        ``{input_name: ("set" | "add", ndarray of shape (n,))}``.
    """
    t_s = np.asarray(t_s, dtype=float)
    rows = out or {}
    built: dict = {}
    for k, name in enumerate(KINDS):
        obj = section.get(name)
        if obj is None or not hasattr(obj, "inputs"):
            continue
        child = child_generator(rng, k)
        for inp, (mode, arr) in obj.inputs(t_s, child, device).items():
            if inp in built and mode == "add" and built[inp][0] == "add":
                np.add(built[inp][1], arr, out=built[inp][1])  # the kinds return arrays of their own
            else:
                built[inp] = (mode, arr)
    temp, drift = section.get("fsr_temperature"), section.get("fsr_drift")
    if temp is not None or drift is not None:
        alpha = device.fsr.temperature_coeff_per_k
        if drift is not None and not alpha < 0.0:
            raise ScenarioError("[disturbances.fsr_drift] needs an FSR with a negative temperature_coeff_per_k "
                                "(the creep offset is applied through the temperature input)")
        offset, preload = (rows.get(name) for name in ("fsr_temp_offset_k", "est_creep_preload"))
        offset = np.empty(len(t_s)) if offset is None else offset
        if drift is None:
            preload = None
        elif preload is None:
            preload = np.empty(len(t_s))
        # sample by sample, so in chunks: a long run's temporaries stay at the chunk's size
        for a in range(0, len(t_s), PROFILE_CHUNK):
            tc = t_s[a:a + PROFILE_CHUNK]
            dtemp = temp.offset_k(tc) if temp is not None else np.zeros(len(tc))
            if drift is None:
                offset[a:a + PROFILE_CHUNK] = dtemp
            else:
                scale = temperature_scale(dtemp, device.fsr) * drift.factor(tc, device.fsr)
                offset[a:a + PROFILE_CHUNK] = temperature_offset_k(scale, alpha, device.fsr.temperature_coeff_cold_per_k)
                preload[a:a + PROFILE_CHUNK] = drift.factor(tc, firmware_fsr(device.estimator)) - 1.0
        built["fsr_temp_offset_k"] = ("set", offset)
        if preload is not None:
            built["est_creep_preload"] = ("set", preload)
    return built


def parameter_table() -> list[tuple[str, str, object, str, str, str]]:
    """Rows ``(sub-table, key, default, unit, range, source)`` of every disturbance parameter."""
    rows = []
    for name, cls in KINDS.items():
        for f in dataclasses.fields(cls):
            m = f.metadata
            rows.append((name, f.name, f.default, m["unit"], f"[{_fmt(m['lo'])}, {_fmt(m['hi'])}]", m["source"]))
    return rows
