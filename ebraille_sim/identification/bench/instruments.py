"""The bench's instruments: the actuator, the load cell, the FSR film in its fixture, the recording.

The paper's dynamic mechanical analysis of the film (Table 3, eqs. 2-4) fixes the film's
viscoelastic model (:class:`FilmParams`, a standard linear solid fitted to Table 3 plus a
slow fixture branch); :class:`BenchParams` gathers every instrument with the FSR's device
and the recording's rates and spans.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.signal

from ebraille_sim.base.fields import sourced
from ebraille_sim.physics.fingertip import prony_coefficients
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, CircuitParams, DeviceParams, check_finite

__all__ = [
    "TABLE3_FREQUENCIES_HZ", "TABLE3_DAMPING_N_S_PER_M", "TABLE3_STIFFNESS_N_PER_M", "EQ3_DAMPING_COEFFS",
    "EQ4_STIFFNESS_COEFFS", "ACTUATED_MASS_KG", "SLS_FIT_TABLE3", "fit_standard_linear_solid", "ActuatorParams",
    "LoadCellParams", "FilmParams", "default_bench_device", "BenchParams", "describe_bench",
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
