"""Virtual FSR test bench: the seed paper's component test device, simulated.

A position-controlled linear actuator presses on the FSR 402 in its fixture; a miniature
load cell in series reads the force and a data-acquisition channel reads the FSR's divider
voltage.  Records are sampled at 100 Hz, stripped of content above 40 Hz with a zero-phase
FFT filter and detrended by the preload offsets, as in the paper.  The chain, in the order
the signal passes:

1. **Profile.**  A target force between ``min_force_n`` and ``max_force_n`` (the tactile range
   0.2-3 N, [R] seed paper) becomes a displacement command ``y_cmd = F / k'(f_exc)`` with the
   film's storage stiffness at the profile's excitation frequency ``f_exc``: the bench is
   driven in displacement, as the paper's was.
2. **Actuator.**  The command is quantised to the actuator's minimum controllable
   displacement (1.5 um, [R] seed paper) and followed by the position servo, a second-order
   low-pass (natural frequency and damping [E]), discretised exactly for a command
   interpolated linearly between samples (first-order hold, so that position and velocity
   stay consistent to well under a microsecond, which the DMA's damping estimate needs).
3. **Film.**  The FSR stack in its fixture is a causal viscoelastic solid run in the time
   domain (:class:`FilmParams`): a spring and two Maxwell branches, the film's (the
   standard linear solid fitted to Table 3's stiffness) and a slow fixture branch that
   relaxes under the 30-minute constant-displacement hold; plus ``m_ac y''`` with
   ``m_ac = 0.0491 g``.
4. **FSR and divider.**  The force drives the project's FSR forward model through
   :func:`ebraille_sim.plant.kernel.advance_sensor_only` (lag, hysteresis, power law, creep,
   divider eq. 1, noise, ADC) at ``internal_rate_hz``; nothing of the conduction law is
   re-implemented here.
5. **Load cell.**  The same force plus Gaussian noise, quantised to the acquisition
   resolution ([E] values of the Honeywell miniature 5 lb class).
6. **Acquisition and conditioning.**  Every channel sampled at ``sample_rate_hz``; the
   mean of the first ``baseline_s`` (the preload, recorded before the excitation starts) is
   removed and content above ``cutoff_hz`` is zeroed in the FFT (zero phase).

Profiles (:data:`PAPER_PROFILES`, :data:`HOLD_PROFILE`) are the paper's: the stepped up-chirp
0.2-0.9 Hz in 0.1 Hz steps then 1-20 Hz in 1 Hz steps (dwell: two cycles or one second,
whichever is longer, so every step holds whole cycles: 57.6 s in all), squares at 0.2 and
0.1 Hz, triangles at 0.25 and 0.1 Hz, a 0.1 Hz staircase of steps, and the 30-minute hold.

Seeds: one master seed per call; :class:`numpy.random.SeedSequence` spawns one child per
profile and, inside it, one for the FSR noise and one for the load cell, so the same seed
gives exactly the same records.

Examples
--------
>>> rec = run_profile(PAPER_PROFILES["square_0.2hz"], seed=1)
>>> rec.dt_s, rec.force_n.shape == rec.voltage_v.shape
(0.01, True)
>>> bool(abs(rec.force_n[:100].mean()) < 1e-3 and rec.force_n.max() > 2.5)
True
"""
from __future__ import annotations

import csv
import dataclasses
import math
import os
import pathlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.interpolate
import scipy.signal
from ebraille_sim.base.compiled import njit
from ebraille_sim.base.fields import sourced
from ebraille_sim.base.validation import check_number

from ebraille_sim.physics.fingertip import prony_coefficients
from ebraille_sim.plant.kernel import advance_sensor_only
from ebraille_sim.plant.layout import N_INPUT, S, U
from ebraille_sim.plant.loop import initial_state, pack_params
from ebraille_sim.physics.noise import seed_from
from ebraille_sim.estimation.paper_models import paper_model
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, CircuitParams, DeviceParams, check_finite

__all__ = [
    "TABLE3_FREQUENCIES_HZ", "TABLE3_DAMPING_N_S_PER_M", "TABLE3_STIFFNESS_N_PER_M",
    "EQ3_DAMPING_COEFFS", "EQ4_STIFFNESS_COEFFS", "ACTUATED_MASS_KG",
    "SLS_FIT_TABLE3", "fit_standard_linear_solid", "ActuatorParams", "LoadCellParams", "FilmParams", "BenchParams", "Profile", "BenchRecord",
    "chirp_schedule", "PAPER_PROFILES", "HOLD_PROFILE", "PROFILE_LABELS",
    "profile_signal", "run_profile", "run_profiles", "lowpass_fft", "condition", "load_csv",
    "hold_creep", "default_bench_device", "describe_bench", "CSV_COLUMNS",
]

# ---------------------------------------------------------------------------
# the paper's DMA data (Table 3 and eqs. 2-4)
# ---------------------------------------------------------------------------
TABLE3_FREQUENCIES_HZ = (0.125, 0.25, 0.375, 0.5)
"""[R] seed paper, Table 3: DMA excitation frequencies, Hz."""
TABLE3_DAMPING_N_S_PER_M = ((6.1797, 2.8768, 1.8284, 2.0041), (6.0950, 3.0445, 1.8667, 2.0822))
"""[R] seed paper, Table 3: damping c, N s/m, test 1 and test 2 (24 h later)."""
TABLE3_STIFFNESS_N_PER_M = ((97.32e3, 102.72e3, 105.07e3, 106.46e3), (94.81e3, 101.39e3, 101.69e3, 104.64e3))
"""[R] seed paper, Table 3: stiffness k, N/m (printed in kN/m), test 1 and test 2."""
EQ3_DAMPING_COEFFS = (53.96, -44.44, 10.81)
"""[R] seed paper, eq. 3: ``c = 53.96 f^2 - 44.44 f + 10.81`` (N s/m, f in Hz), highest power first."""
EQ4_STIFFNESS_COEFFS = (23.82e3, 94.32e3)
"""[R] seed paper, eq. 4: ``k = 23.82 f + 94.32`` kN/m, here in N/m, highest power first."""
ACTUATED_MASS_KG = 0.0491e-3
"""[R] seed paper, eq. 2: mass of the actuated film segment ``m_ac = m_c (D_ac/D_c)^2`` = 0.0491 g."""


# ---------------------------------------------------------------------------
# instrument parameters
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class ActuatorParams:
    """Position-controlled linear actuator of the component test device.

    The servo follows the (quantised) command as ``y'' = wn^2 (y_cmd - y) - 2 zeta wn y'``.
    """
    resolution_m: float = sourced(1.5e-6, "m", "[R] seed paper: minimum controllable displacement 1.5e-3 mm",
                                nonneg=True)
    servo_natural_hz: float = sourced(100.0, "Hz", "[E] position loop of a moving-magnet bench actuator at "
                                    "strokes of tens of micrometres; well above the 20 Hz chirp end",
                                    positive=True)
    servo_damping_ratio: float = sourced(0.7, "-", "[E] a tuned position loop", positive=True)
    displacement_resolution_m: float = sourced(0.2e-6, "m", "[E] displacement transducer read by a 16-bit "
                                             "channel over a +/-6.5 mm stroke", nonneg=True)

    def __post_init__(self):
        check_finite(self)


@dataclass(frozen=True)
class LoadCellParams:
    """Miniature load cell in series with the FSR, read by the bench's acquisition channel."""
    range_n: float = sourced(22.24, "N", "[R] seed paper: low-range 5 lb (about 22 N) Honeywell miniature cell",
                           positive=True)
    noise_n_rms: float = sourced(2.2e-3, "N", "[E] 0.01 % of full scale, typical of a miniature strain-gauge "
                               "cell through a lab amplifier at 100 Hz", nonneg=True)
    resolution_n: float = sourced(2.0 * 22.24 / 2 ** 16, "N", "[E] 16-bit acquisition over +/- full scale "
                                "(0.68 mN)", nonneg=True)

    def __post_init__(self):
        check_finite(self)


SLS_FIT_TABLE3 = (89.47e3, 17.20e3, 1.008)
"""[D] standard linear solid fitted to the means of Table 3's stiffness by least squares on the
relative error: ``k'(f) = k_inf + k_1 (w tau)^2 / (1 + (w tau)^2)`` with ``k_inf`` = 89.47 kN/m,
``k_1`` = 17.20 kN/m, ``tau`` = 1.008 s (N/m, N/m, s); within 0.7 % of all four points
(:func:`fit_standard_linear_solid` recomputes it)."""


def fit_standard_linear_solid(frequencies_hz=TABLE3_FREQUENCIES_HZ,
                              stiffness_n_per_m=None) -> tuple[float, float, float]:
    """Least-squares standard linear solid through storage-stiffness data.

    Parameters
    ----------
    frequencies_hz : sequence of float
        Excitation frequencies, Hz.
    stiffness_n_per_m : sequence of float, optional
        Storage stiffness at each frequency, N/m (default: the mean of Table 3's two tests).

    Returns
    -------
    k_inf_n_per_m, k_1_n_per_m, tau_s : float
        Relaxed stiffness, Maxwell-branch stiffness and its relaxation time.
    """
    import scipy.optimize

    f = np.asarray(frequencies_hz, dtype=float)
    k = (np.mean(TABLE3_STIFFNESS_N_PER_M, axis=0) if stiffness_n_per_m is None
         else np.asarray(stiffness_n_per_m, dtype=float))
    w = 2.0 * math.pi * f

    def resid(x):
        ke, k1, tau = x
        wt2 = (w * tau) ** 2
        return (ke + k1 * wt2 / (1.0 + wt2)) / k - 1.0

    r = scipy.optimize.least_squares(resid, [0.9 * k.min(), k.max() - k.min(), 1.0 / w.mean()],
                                     bounds=([0.0, 0.0, 1e-4], [np.inf, np.inf, 1e4]))
    return float(r.x[0]), float(r.x[1]), float(r.x[2])


@dataclass(frozen=True)
class FilmParams:
    """The FSR stack in its fixture as a causal viscoelastic solid (generalized Maxwell).

    ``F = k_e y + h_1 + h_f + m_ac y''`` with two Maxwell branches
    ``dh_i/dt = -h_i/tau_i + k_i dy/dt``: the film's branch (``k_1``, ``tau_1``) and a slow
    fixture branch (``k_f``, ``tau_f``).  The storage stiffness is
    ``k'(w) = k_e + sum_i k_i (w tau_i)^2/(1 + (w tau_i)^2)`` and the loss (as a damping)
    ``c(w) = sum_i k_i tau_i/(1 + (w tau_i)^2)``.  ``k_e + k_f`` and ``k_1``, ``tau_1`` are
    the standard linear solid fitted to Table 3's stiffness (:data:`SLS_FIT_TABLE3`; the
    fixture branch is fully stiff at the DMA frequencies).  The fixture branch is what
    relaxes under the paper's 30-minute constant-displacement hold.

    Table 3's damping (N s/m) is not reachable by this or any spring-plus-Maxwell material:
    such a material's damping falls with frequency, and its storage stiffness can rise
    between two frequencies by at most ``int c dw``; see
    :func:`ebraille_sim.identification.dma.causal_stiffness_rise_bound_n_per_m`.
    """
    mass_kg: float = sourced(ACTUATED_MASS_KG, "kg", "[R] seed paper eq. 2, m_ac = 0.0491 g", nonneg=True)
    equilibrium_stiffness_n_per_m: float = sourced(
        SLS_FIT_TABLE3[0] - 10.6e3, "N/m", "[D] k_inf of the Table 3 fit (89.47 kN/m) minus the fixture "
        "branch", positive=True)
    branch_stiffness_n_per_m: float = sourced(SLS_FIT_TABLE3[1], "N/m", "[D] k_1 of the Table 3 fit",
                                              nonneg=True)
    branch_tau_s: float = sourced(SLS_FIT_TABLE3[2], "s", "[D] tau of the Table 3 fit", positive=True)
    fixture_stiffness_n_per_m: float = sourced(
        10.6e3, "N/m", "[D] solved so that the 30-minute constant-displacement hold raises the "
        "resistance by 6 % ([R] seed paper) with the sensor's own creep included", nonneg=True)
    fixture_tau_s: float = sourced(300.0, "s", "[E] minutes-scale stress relaxation of the polymer stack "
                                   "and its adhesive fixture", positive=True)
    stiffness_scale: float = sourced(1.0, "-", "[E] multiplier for other FSR units or fixtures", positive=True)

    def __post_init__(self):
        check_finite(self)

    def _branches(self):
        return ((self.branch_stiffness_n_per_m, self.branch_tau_s),
                (self.fixture_stiffness_n_per_m, self.fixture_tau_s))

    def stiffness_n_per_m(self, f_hz):
        """Storage stiffness ``k'(f)``, N/m (array or float like ``f_hz``)."""
        w = 2.0 * math.pi * np.asarray(f_hz, dtype=float)
        k = self.equilibrium_stiffness_n_per_m + sum(ki * (w * ti) ** 2 / (1.0 + (w * ti) ** 2)
                                                     for ki, ti in self._branches())
        k = k * self.stiffness_scale
        return float(k) if np.ndim(k) == 0 else k

    def damping_n_s_per_m(self, f_hz):
        """Loss as a damping, ``c(f) = k''/w``, N s/m (array or float like ``f_hz``)."""
        w = 2.0 * math.pi * np.asarray(f_hz, dtype=float)
        c = sum(ki * ti / (1.0 + (w * ti) ** 2) for ki, ti in self._branches()) * self.stiffness_scale
        return float(c) if np.ndim(c) == 0 else c

    def force_n(self, y_m, a_m_per_s2, dt_s: float) -> np.ndarray:
        """Force of the film for a displacement record ``y_m`` from rest (N), time domain.

        Each Maxwell branch is advanced exactly for ``y`` varying linearly between samples
        (the ramp-invariant Prony step of :func:`ebraille_sim.physics.fingertip.prony_step`,
        run as a first-order recursive filter); ``a_m_per_s2`` is the acceleration for the
        inertial term.
        """
        y = np.asarray(y_m, dtype=float)
        dy = np.diff(y, prepend=0.0)
        f = self.equilibrium_stiffness_n_per_m * y
        for ki, ti in self._branches():
            (a,), (beta,) = prony_coefficients(dt_s, (ti,))
            f = f + scipy.signal.lfilter([ki * beta], [1.0, -a], dy)
        return f * self.stiffness_scale + self.mass_kg * np.asarray(a_m_per_s2, dtype=float)


def default_bench_device() -> DeviceParams:
    """The device whose FSR and divider sit in the bench fixture.

    The project's nominal FSR 402 and divider (so that a model identified here reads the
    device's sensor), read by the bench's 16-bit channel instead of the device's 10-bit ADC
    ([E] PCI conditioning module of the test device).
    """
    return DeviceParams(circuit=CircuitParams(adc_bits=16))


@dataclass(frozen=True)
class BenchParams:
    """The whole virtual bench: instruments, film, the FSR's device and the recording."""
    actuator: ActuatorParams = ActuatorParams()
    load_cell: LoadCellParams = LoadCellParams()
    film: FilmParams = FilmParams()
    device: DeviceParams = field(default_factory=default_bench_device)
    sample_rate_hz: float = sourced(100.0, "Hz", "[R] seed paper: all loadings sampled at 100 Hz", positive=True)
    internal_rate_hz: float = sourced(1000.0, "Hz", "[E] servo, film and FSR sample rate inside the bench; "
                                    "a whole multiple of sample_rate_hz and the device's sensor rate",
                                    positive=True)
    cutoff_hz: float = sourced(40.0, "Hz", "[R] seed paper: content above 40 Hz filtered out", positive=True)
    min_force_n: float = sourced(0.2, "N", "[R] seed paper: tactile forces 0.2-3 N; the preload",
                               positive=True)
    max_force_n: float = sourced(TACTILE_FORCE_MAX_N, "N", "[R] seed paper: tactile forces 0.2-3 N", positive=True)
    ramp_s: float = sourced(1.0, "s", "[E] positioning the effector onto the FSR with the micro-adjuster",
                          positive=True)
    settle_s: float = sourced(10.0, "s", "[E] time at preload before a recording starts", nonneg=True)
    baseline_s: float = sourced(2.0, "s", "[E] recorded at preload before the excitation; its mean is the "
                              "offset removed by detrending", positive=True)
    tail_s: float = sourced(1.0, "s", "[E] recorded at preload after the excitation", nonneg=True)

    def __post_init__(self):
        check_finite(self)
        ratio = self.internal_rate_hz / self.sample_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(f"internal_rate_hz ({self.internal_rate_hz:g}) must be a whole multiple of "
                             f"sample_rate_hz ({self.sample_rate_hz:g})")
        if self.device.rates.sensor_rate_hz != self.internal_rate_hz:
            raise ValueError(f"internal_rate_hz ({self.internal_rate_hz:g}) must equal the device's "
                             f"sensor_rate_hz ({self.device.rates.sensor_rate_hz:g})")
        if not 0 < self.cutoff_hz <= 0.5 * self.sample_rate_hz:
            raise ValueError(f"cutoff_hz {self.cutoff_hz:g} must lie in (0, {0.5 * self.sample_rate_hz:g}] Hz")
        if not self.min_force_n < self.max_force_n:
            raise ValueError(f"min_force_n ({self.min_force_n:g}) must be below max_force_n ({self.max_force_n:g})")
        if self.max_force_n > self.load_cell.range_n:
            raise ValueError(f"max_force_n ({self.max_force_n:g}) exceeds the load-cell range "
                             f"({self.load_cell.range_n:g} N)")

    @property
    def decimation(self) -> int:
        """Internal samples per recorded sample."""
        return int(round(self.internal_rate_hz / self.sample_rate_hz))


# ---------------------------------------------------------------------------
# profiles
# ---------------------------------------------------------------------------
_SHAPES = ("chirp", "sine", "square", "triangle", "step", "hold")


@dataclass(frozen=True)
class Profile:
    """One loading profile.

    Parameters
    ----------
    name : str
        Key used in tables and file names.
    shape : {"chirp", "sine", "square", "triangle", "step", "hold"}
        Waveform between the bench's ``min_force_n`` and ``max_force_n``.
    frequency_hz : float
        Fundamental (sine, square, triangle), step rate (step); unused for the chirp and
        the hold (0).
    periods : float
        Number of periods (sine, square, triangle) or of steps (step).
    hold_s : float
        Hold duration (hold only), s.
    hold_fraction : float
        Hold force as a fraction of the span above the preload (hold only).
    settle_s : float or None
        Overrides the bench's ``settle_s`` (the hold starts on a fresh sensor: 0).
    chirp_dwell_s : float or None
        Chirp only: time spent on each frequency step, s, rounded up to whole cycles (None:
        two cycles or one second, whichever is longer; see :func:`chirp_schedule`).
    """
    name: str
    shape: str
    frequency_hz: float = 0.0
    periods: float = 0.0
    hold_s: float = 0.0
    hold_fraction: float = 0.5
    settle_s: float | None = None
    chirp_dwell_s: float | None = None

    def __post_init__(self):
        if self.shape not in _SHAPES:
            raise ValueError(f"unknown profile shape {self.shape!r}; allowed: {', '.join(_SHAPES)}")
        for name in ("frequency_hz", "periods", "hold_s", "hold_fraction"):
            check_number(f"Profile.{name}", getattr(self, name), lo=0.0)
        if self.shape in ("sine", "square", "triangle", "step") and not (self.frequency_hz > 0 and self.periods > 0):
            raise ValueError(f"a {self.shape} profile needs frequency_hz > 0 and periods > 0")
        if self.shape == "hold" and not self.hold_s > 0:
            raise ValueError("a hold profile needs hold_s > 0")
        if self.chirp_dwell_s is not None:
            if self.shape != "chirp":
                raise ValueError(f"chirp_dwell_s applies to a chirp profile only, not a {self.shape}")
            check_number("Profile.chirp_dwell_s", self.chirp_dwell_s, lo=0.0, hi=600.0, lo_open=True)

    @property
    def duration_s(self) -> float:
        """Duration of the excitation (without baseline and tail), s."""
        if self.shape == "chirp":
            return float(np.sum(chirp_schedule(self.chirp_dwell_s)[1]))
        if self.shape == "hold":
            return self.hold_s
        return self.periods / self.frequency_hz


def chirp_schedule(dwell_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and dwell times (s) of the stepped up-chirp.

    0.2-0.9 Hz in 0.1 Hz steps, then 1-20 Hz in 1 Hz steps ([R] seed paper).  By default
    each step lasts two cycles or one second, whichever is longer ([E] the paper does not
    give the dwell); with ``dwell_s`` each lasts the whole number of cycles that first
    reaches ``dwell_s`` (at least one cycle).  Every step holds whole cycles, so the phase
    is continuous.
    """
    freqs = np.concatenate([np.round(np.arange(2, 10) * 0.1, 10), np.arange(1.0, 21.0)])
    if dwell_s is None:
        return freqs, np.maximum(2.0 / freqs, 1.0)
    dwell_s = check_number("dwell_s", dwell_s, lo=0.0, hi=600.0, lo_open=True)
    cycles = np.maximum(np.ceil(dwell_s * freqs - 1e-9), 1.0)
    return freqs, cycles / freqs


PAPER_PROFILES: dict[str, Profile] = {
    "chirp": Profile("chirp", "chirp"),
    "square_0.2hz": Profile("square_0.2hz", "square", 0.2, 6),
    "square_0.1hz": Profile("square_0.1hz", "square", 0.1, 3),
    "step_0.1hz": Profile("step_0.1hz", "step", 0.1, 6),
    "triangle_0.25hz": Profile("triangle_0.25hz", "triangle", 0.25, 8),
    "triangle_0.1hz": Profile("triangle_0.1hz", "triangle", 0.1, 3),
}
"""The paper's identification (chirp) and validation profiles, in the order of its tables.
Periods: [E] about 30 s per validation profile; the staircase climbs in three steps of 10 s
to the maximum and returns in three."""

HOLD_PROFILE = Profile("hold_30min", "hold", hold_s=1800.0, hold_fraction=0.5, settle_s=0.0)
"""[R] seed paper: static displacement held about 30 minutes (creep).  Hold force mid-span [E]."""

PROFILE_LABELS = {
    "chirp": "Chirp (0.2-20 Hz)", "square_0.2hz": "Square (0.20 Hz)", "square_0.1hz": "Square (0.10 Hz)",
    "step_0.1hz": "Step (0.1 Hz)", "triangle_0.25hz": "Triangle (0.25 Hz)", "triangle_0.1hz": "Triangle (0.1 Hz)",
    "hold_30min": "Static hold (30 min)",
}
"""Row labels of the paper's tables."""


def profile_signal(profile: Profile, t_s: np.ndarray, bench: BenchParams) -> tuple[np.ndarray, np.ndarray]:
    """Target force and excitation frequency of a profile.

    Parameters
    ----------
    profile : Profile
    t_s : ndarray, shape (n,)
        Time from the start of the excitation, s (``0 <= t < profile.duration_s``).
    bench : BenchParams
        Gives the force span ``min_force_n``-``max_force_n``.

    Returns
    -------
    force_n : ndarray, shape (n,)
        Target force, N, within ``[min_force_n, max_force_n]``; the chirp, sine, triangle
        and hold start at ``min_force_n`` (the preload) and rise smoothly, the square and
        the staircase step up at ``t = 0``.
    excitation_hz : ndarray, shape (n,)
        Excitation frequency, Hz: the displacement command is the target force divided by
        the film's storage stiffness at this frequency (the hold: its ramp, 0.5/ramp_s).
    """
    t = np.asarray(t_s, dtype=float)
    lo, hi = bench.min_force_n, bench.max_force_n
    span = hi - lo
    f0 = profile.frequency_hz
    if profile.shape == "chirp":
        freqs, dwell = chirp_schedule(profile.chirp_dwell_s)
        edges = np.concatenate([[0.0], np.cumsum(dwell)])
        idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, freqs.size - 1)
        # phase from the start of each step: whole cycles per step keep it continuous
        phase = 2.0 * np.pi * freqs[idx] * (t - edges[idx])
        return lo + span * 0.5 * (1.0 - np.cos(phase)), freqs[idx]
    exc = np.full_like(t, f0)
    if profile.shape == "sine":
        return lo + span * 0.5 * (1.0 - np.cos(2.0 * np.pi * f0 * t)), exc
    if profile.shape == "square":
        frac = np.mod(t * f0, 1.0)
        return np.where(frac < 0.5, hi, lo), exc
    if profile.shape == "triangle":
        frac = np.mod(t * f0, 1.0)
        return lo + span * (1.0 - np.abs(2.0 * frac - 1.0)), exc
    if profile.shape == "step":
        n = int(round(profile.periods))
        up = (n + 1) // 2
        levels = [min(k, up) if k <= up else 2 * up - k for k in range(1, n + 1)]
        levels = np.asarray(levels, dtype=float) / up
        k = np.clip(np.floor(t * f0).astype(int), 0, n - 1)
        return lo + span * levels[k], exc
    # hold: the half-cosine ramp is half a cycle at 0.5/ramp_s
    ramp = np.clip(t / bench.ramp_s, 0.0, 1.0)
    return (lo + span * profile.hold_fraction * 0.5 * (1.0 - np.cos(np.pi * ramp)),
            np.full_like(t, 0.5 / bench.ramp_s))


# ---------------------------------------------------------------------------
# records
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class BenchRecord:
    """One conditioned recording.

    Attributes
    ----------
    name : str
    dt_s : float
        Sample time, s.
    time_s : ndarray, shape (n,)
        From 0 at the start of the baseline.
    voltage_v, force_n : ndarray, shape (n,)
        Detrended and low-passed FSR divider voltage (V) and load-cell force (N): the
        identification input and output.
    voltage_offset_v, force_offset_n : float
        The removed baseline means (the preload's voltage and force).
    raw_voltage_v, raw_force_n : ndarray, shape (n,)
        As acquired (before conditioning).
    displacement_m : ndarray or None
        Actuator displacement as read by its transducer, m (bench records only).
    excitation_hz : ndarray or None
        Excitation frequency per sample (bench records only).
    true_force_n : ndarray or None
        Noise-free force on the FSR at the sample instants (bench records only).
    baseline_samples : int
        Samples averaged for the offsets.
    """
    name: str
    dt_s: float
    time_s: np.ndarray
    voltage_v: np.ndarray
    force_n: np.ndarray
    voltage_offset_v: float
    force_offset_n: float
    raw_voltage_v: np.ndarray
    raw_force_n: np.ndarray
    displacement_m: np.ndarray | None = None
    excitation_hz: np.ndarray | None = None
    true_force_n: np.ndarray | None = None
    baseline_samples: int = 0

    @property
    def n(self) -> int:
        return int(self.time_s.size)

    def to_csv(self, path) -> None:
        """Write the raw acquisition as ``time_s,voltage_v,force_n`` (readable by :func:`load_csv`)."""
        p = pathlib.Path(path)
        with p.open("w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["time_s", "voltage_v", "force_n"])
            for row in zip(self.time_s, self.raw_voltage_v, self.raw_force_n):
                w.writerow([f"{row[0]:.6f}", f"{row[1]:.7g}", f"{row[2]:.7g}"])


def lowpass_fft(x: np.ndarray, dt_s: float, cutoff_hz: float) -> np.ndarray:
    """Zero-phase brick-wall low-pass: FFT bins above ``cutoff_hz`` set to zero.

    The straight line through the first and last samples is removed before the transform
    and added back after, so that a record which starts and ends at different levels does
    not ring at its ends (the FFT treats the record as periodic).  Bins at the cut-off
    itself (to within 1e-9 relative) are kept.

    Parameters
    ----------
    x : ndarray, shape (n,)
    dt_s : float
        Sample time, s.
    cutoff_hz : float
        Highest frequency kept, Hz.

    Returns
    -------
    ndarray, shape (n,)

    Examples
    --------
    >>> t = np.arange(1000) * 0.01
    >>> rest = np.sin(np.pi * t / 10.0) ** 2          # starts and ends at rest
    >>> y = lowpass_fft(rest * (1 + np.sin(2 * np.pi * 45 * t)), 0.01, 40.0)
    >>> bool(np.max(np.abs(y - rest)) < 0.01)
    True
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    if n < 2:
        return x.copy()
    line = x[0] + (x[-1] - x[0]) * np.arange(n) / (n - 1)
    spec = np.fft.rfft(x - line)
    freqs = np.fft.rfftfreq(n, dt_s)
    spec[freqs > cutoff_hz * (1.0 + 1e-9)] = 0.0
    return np.fft.irfft(spec, n) + line


def condition(voltage_v, force_n, dt_s: float, baseline_s: float, cutoff_hz: float | None):
    """The paper's conditioning: remove the baseline offsets, then low-pass.

    Parameters
    ----------
    voltage_v, force_n : ndarray, shape (n,)
        Raw acquisition.
    dt_s : float
        Sample time, s.
    baseline_s : float
        Length of the initial stretch whose mean is removed, s (0: no detrending).
    cutoff_hz : float or None
        Zero-phase FFT cut-off, Hz (None: no filtering).

    Returns
    -------
    voltage_v, force_n : ndarray
    voltage_offset_v, force_offset_n : float
    baseline_samples : int
    """
    v = np.asarray(voltage_v, dtype=float)
    f = np.asarray(force_n, dtype=float)
    nb = int(round(baseline_s / dt_s))
    if nb > v.size:
        raise ValueError(f"baseline of {baseline_s:g} s is longer than the record ({v.size * dt_s:g} s)")
    v0 = float(np.mean(v[:nb])) if nb > 0 else 0.0
    f0 = float(np.mean(f[:nb])) if nb > 0 else 0.0
    v, f = v - v0, f - f0
    if cutoff_hz is not None:
        v = lowpass_fft(v, dt_s, cutoff_hz)
        f = lowpass_fft(f, dt_s, cutoff_hz)
    return v, f, v0, f0, nb


# ---------------------------------------------------------------------------
# simulation
# ---------------------------------------------------------------------------
@njit(cache=False)
def _sensor_run(s, p, u, force_n, n_sub, out_v):
    """Drive the FSR chain with one force per sensor sample; record the ADC voltage.

    Not cached on disk: Numba's cache would not notice a change in the kernel or the
    state layout it calls into (other files), so it is compiled once per process.
    """
    for i in range(force_n.size):
        advance_sensor_only(s, p, u, force_n[i], n_sub)
        out_v[i] = s[S.fsr_voltage_v]


def _servo(y_cmd: np.ndarray, dt_s: float, act: ActuatorParams):
    """Second-order position servo from rest: position, velocity and acceleration.

    Discretised exactly for a command interpolated linearly between samples (first-order
    hold).  With a zero-order hold the 1 kHz staircase aliases onto the 100 Hz records and
    skews position against velocity by about 2 us, which alone shifts the DMA's ``c`` by
    ``k * 2 us``, 0.2 N s/m.
    """
    wn = 2.0 * math.pi * act.servo_natural_hz
    z = act.servo_damping_ratio
    den = [1.0, 2.0 * z * wn, wn * wn]
    bp, ap, _ = scipy.signal.cont2discrete(([wn * wn], den), dt_s, method="foh")
    bv, av, _ = scipy.signal.cont2discrete(([wn * wn, 0.0], den), dt_s, method="foh")
    y = scipy.signal.lfilter(np.ravel(bp), ap, y_cmd)
    v = scipy.signal.lfilter(np.ravel(bv), av, y_cmd)
    a = wn * wn * (y_cmd - y) - 2.0 * z * wn * v
    return y, v, a


def _seed_sequence(seed) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative int or a SeedSequence, got {seed!r}")
    return np.random.SeedSequence(int(seed))


def run_profile(profile: Profile, bench: BenchParams | None = None, seed=0) -> BenchRecord:
    """Run one profile on the virtual bench.

    Parameters
    ----------
    profile : Profile
    bench : BenchParams, optional
        Default :class:`BenchParams` ().
    seed : int or numpy.random.SeedSequence
        Master seed; children are spawned for the FSR noise and the load cell.

    Returns
    -------
    BenchRecord
        Sampled at ``bench.sample_rate_hz`` from the start of the baseline to the end of
        the tail.
    """
    bench = BenchParams() if bench is None else bench
    if not isinstance(profile, Profile):
        raise ValueError(f"profile must be a Profile, got {type(profile).__name__}")
    ss_fsr, ss_cell = _seed_sequence(seed).spawn(2)

    dt = 1.0 / bench.internal_rate_hz
    dec = bench.decimation
    settle = bench.settle_s if profile.settle_s is None else profile.settle_s
    n_ramp = int(round(bench.ramp_s / dt))
    n_settle = int(round(settle / dt))
    n_base = int(round(bench.baseline_s * bench.sample_rate_hz)) * dec
    n_body = int(round(profile.duration_s * bench.sample_rate_hz)) * dec
    n_tail = int(round(bench.tail_s * bench.sample_rate_hz)) * dec
    n_pre = n_ramp + n_settle
    n = n_pre + n_base + n_body + n_tail

    lo = bench.min_force_n
    force_t = np.full(n, lo)
    t_body = np.arange(n_body) * dt
    f_body, exc_body = profile_signal(profile, t_body, bench)
    force_t[n_pre + n_base:n_pre + n_base + n_body] = f_body
    ramp = np.arange(n_ramp) / max(n_ramp, 1)
    force_t[:n_ramp] = lo * 0.5 * (1.0 - np.cos(np.pi * ramp))
    exc = np.full(n, exc_body[0] if exc_body.size else 0.0)
    exc[n_pre + n_base:n_pre + n_base + n_body] = exc_body

    film = bench.film
    k = film.stiffness_n_per_m(exc)
    res = bench.actuator.resolution_m
    y_cmd = force_t / k
    if res > 0:
        y_cmd = np.round(y_cmd / res) * res
    y, v, a = _servo(y_cmd, dt, bench.actuator)
    force = np.maximum(film.force_n(y, a, dt), 0.0)

    # FSR and divider through the project's sensor chain
    device = bench.device
    model = paper_model("wiener", 5)
    p = pack_params(device, seed_from(ss_fsr), model)
    s = initial_state(device, p)
    u = np.zeros(N_INPUT)
    u[U.driver_supply_v] = device.driver_supply_v
    volts = np.empty(n)
    _sensor_run(s, p, u, force, int(device.rates.substeps_per_sensor), volts)

    # acquisition at the recording rate
    start = n_pre
    idx = np.arange(start, n, dec)
    lc = bench.load_cell
    rng = np.random.default_rng(ss_cell)
    f_meas = force[idx] + lc.noise_n_rms * rng.standard_normal(idx.size)
    if lc.resolution_n > 0:
        f_meas = np.round(f_meas / lc.resolution_n) * lc.resolution_n
    disp = y[idx]
    rd = bench.actuator.displacement_resolution_m
    if rd > 0:
        disp = np.round(disp / rd) * rd
    dt_rec = 1.0 / bench.sample_rate_hz
    vc, fc, v0, f0, nb = condition(volts[idx], f_meas, dt_rec, bench.baseline_s, bench.cutoff_hz)
    return BenchRecord(
        name=profile.name, dt_s=dt_rec, time_s=np.arange(idx.size) * dt_rec, voltage_v=vc, force_n=fc,
        voltage_offset_v=v0, force_offset_n=f0, raw_voltage_v=volts[idx], raw_force_n=f_meas,
        displacement_m=disp, excitation_hz=exc[idx], true_force_n=force[idx], baseline_samples=nb)


def run_profiles(profiles, bench: BenchParams | None = None, seed=0) -> dict[str, BenchRecord]:
    """Run several profiles, each with its own child of the master ``seed``.

    Parameters
    ----------
    profiles : iterable of Profile
    bench : BenchParams, optional
    seed : int or SeedSequence

    Returns
    -------
    dict
        Profile name -> :class:`BenchRecord`, in the given order.
    """
    profiles = list(profiles)
    names = [pr.name for pr in profiles]
    if len(set(names)) != len(names):
        raise ValueError(f"profile names must be unique, got {names}")
    children = _seed_sequence(seed).spawn(len(profiles))
    return {pr.name: run_profile(pr, bench, ch) for pr, ch in zip(profiles, children)}


def hold_creep(record: BenchRecord, bench: BenchParams | None = None, hold_s: float | None = None,
               settle_after_s: float = 1.0) -> dict:
    """Resistance creep over a static hold, from the raw divider voltage.

    ``R = R2 (V_s / V - 1)`` (eq. 1 inverted); the creep is the change from
    ``settle_after_s`` after the hold force is reached to the end of the hold, both
    averaged over one second.

    Parameters
    ----------
    record : BenchRecord
        A run of a hold profile on ``bench``.
    bench : BenchParams, optional
        The bench that recorded it (its divider, ramp and tail).
    hold_s : float, optional
        Hold duration, s (default: that of :data:`HOLD_PROFILE`).
    settle_after_s : float
        Wait after the hold force is reached before the first average, s.

    Returns
    -------
    dict
        ``resistance_start_ohm``, ``resistance_end_ohm``, ``creep_fraction`` and the time
        series ``time_s``, ``resistance_ohm`` (one value per recorded sample of the hold).
    """
    bench = BenchParams() if bench is None else bench
    circ = bench.device.circuit
    n_base = record.baseline_samples
    fs = 1.0 / record.dt_s
    v = np.asarray(record.raw_voltage_v, dtype=float)
    t_hold = HOLD_PROFILE.hold_s if hold_s is None else float(hold_s)
    n_tail = int(round(bench.tail_s * fs))
    i0 = n_base + int(round((bench.ramp_s + settle_after_s) * fs))
    i1 = n_base + int(round(t_hold * fs))
    if record.n - n_tail < i1 or i0 + int(fs) >= i1:
        raise ValueError("record too short for a hold-creep estimate")
    with np.errstate(divide="ignore"):
        r = circ.r2_ohm * (circ.supply_v / v - 1.0)
    win = int(fs)
    r0 = float(np.mean(r[i0:i0 + win]))
    r1 = float(np.mean(r[i1 - win:i1]))
    return {"resistance_start_ohm": r0, "resistance_end_ohm": r1, "creep_fraction": r1 / r0 - 1.0,
            "time_s": record.time_s[i0:i1] - record.time_s[n_base], "resistance_ohm": r[i0:i1]}


# ---------------------------------------------------------------------------
# recorded data from a real bench
# ---------------------------------------------------------------------------
CSV_COLUMNS = ("time_s", "voltage_v", "force_n")


MAX_CSV_BYTES = 256 * 2 ** 20
"""Largest recorded CSV file read (256 MiB: hours of a bench sampled at 1 kHz)."""


def load_csv(path, baseline_s: float = 2.0, cutoff_hz: float | None = 40.0, min_samples: int = 100) -> BenchRecord:
    """Read a real bench recording and condition it like the virtual one.

    Parameters
    ----------
    path : str or Path
        CSV with a header naming ``time_s``, ``voltage_v`` and ``force_n`` (other columns
        are ignored); time strictly increasing and uniformly sampled (within 1 % of the
        median step).
    baseline_s : float
        Initial stretch (at preload, before the excitation) whose mean is removed; 0 keeps
        the offsets.
    cutoff_hz : float or None
        Zero-phase low-pass cut-off, Hz (None: no filtering); must be below the Nyquist
        frequency of the data.
    min_samples : int
        Fewest data rows accepted.

    Returns
    -------
    BenchRecord
        Named after the file stem; no displacement or excitation data.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        One line naming the problem: missing column, non-numeric or non-finite cell (row
        and column), non-increasing or non-uniform time, too few rows, bad cut-off.
    """
    from ebraille_sim.base.files import read_bytes
    p = pathlib.Path(path)
    if not (isinstance(baseline_s, (int, float)) and math.isfinite(baseline_s) and baseline_s >= 0):
        raise ValueError(f"baseline_s must be a finite number >= 0, got {baseline_s!r}")
    if not os.path.lexists(p):
        raise FileNotFoundError(f"CSV file not found: {p}")
    raw = read_bytes(p, "CSV file", MAX_CSV_BYTES)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{p}: not a UTF-8 text file") from None
    rows = list(csv.reader(text.splitlines()))
    rows = [r for r in rows if any(cell.strip() for cell in r)]
    if not rows:
        raise ValueError(f"{p}: empty file")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise ValueError(f"{p}: missing column(s) {', '.join(missing)}; the header must name "
                         f"{', '.join(CSV_COLUMNS)} (found: {', '.join(header) or 'nothing'})")
    cols = [header.index(c) for c in CSV_COLUMNS]
    data = np.empty((len(rows) - 1, 3))
    for i, r in enumerate(rows[1:]):
        line = i + 2
        for j, (ci, name) in enumerate(zip(cols, CSV_COLUMNS)):
            if ci >= len(r):
                raise ValueError(f"{p}: line {line} has no {name} value")
            try:
                val = float(r[ci])
            except ValueError:
                raise ValueError(f"{p}: line {line}, column {name}: {r[ci].strip()!r} is not a number") from None
            if not math.isfinite(val):
                raise ValueError(f"{p}: line {line}, column {name}: value {r[ci].strip()!r} is not finite")
            data[i, j] = val
    if data.shape[0] < min_samples:
        raise ValueError(f"{p}: {data.shape[0]} data row(s); at least {min_samples} are needed")
    t = data[:, 0]
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(f"{p}: time_s must increase strictly; line {k + 3} has {t[k + 1]:g} after {t[k]:g}")
    dt = float(np.median(steps))
    bad = np.abs(steps - dt) > 0.01 * dt
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{p}: time_s is not uniformly sampled: step {steps[k]:g} s at line {k + 3} "
                         f"(median {dt:g} s)")
    if cutoff_hz is not None and not 0 < cutoff_hz <= 0.5 / dt:
        raise ValueError(f"cutoff_hz {cutoff_hz:g} must lie in (0, {0.5 / dt:g}] Hz for data sampled every {dt:g} s")
    if baseline_s > t[-1] - t[0]:
        raise ValueError(f"{p}: baseline of {baseline_s:g} s is longer than the record ({t[-1] - t[0]:g} s)")
    v_raw, f_raw = data[:, 1], data[:, 2]
    vc, fc, v0, f0, nb = condition(v_raw, f_raw, dt, baseline_s, cutoff_hz)
    if np.ptp(vc) == 0 or np.ptp(fc) == 0:
        raise ValueError(f"{p}: voltage_v or force_n is constant; there is nothing to identify")
    return BenchRecord(name=p.stem, dt_s=dt, time_s=t - t[0], voltage_v=vc, force_n=fc, voltage_offset_v=v0,
                       force_offset_n=f0, raw_voltage_v=v_raw, raw_force_n=f_raw, baseline_samples=nb)


def describe_bench(bench: BenchParams | None = None) -> list[tuple[str, Any, str, str]]:
    """Rows (name, value, unit, source) of every bench parameter, for reports and docs."""
    bench = BenchParams() if bench is None else bench
    rows = []
    for prefix, obj in (("actuator", bench.actuator), ("load_cell", bench.load_cell), ("film", bench.film),
                        ("", bench)):
        for f in dataclasses.fields(obj):
            if "unit" not in f.metadata:
                continue
            name = f"{prefix}.{f.name}" if prefix else f.name
            rows.append((name, getattr(obj, f.name), f.metadata["unit"], f.metadata["source"]))
    return rows
