"""Dynamic mechanical analysis (DMA) of the FSR on the virtual bench, and the paper's
second-order model (eqs. 2-6, Tables 3-4).

The DMA drives the FSR with a sinusoidal displacement at 0.125, 0.25, 0.375 and 0.5 Hz
([R] seed paper, Table 3) and estimates the stiffness ``k`` and damping ``c`` of eq. 5,
``F = m_ac y'' + c y' + k y``, from the recorded displacement and force:

* **least squares.**  Over a whole number of cycles after the first (settling) ones,
  ``F - m_ac y1'' = F0 + k y1 + c y1'`` is solved by linear least squares, where ``y1`` is
  the fundamental of the measured displacement (its own least-squares fit of a constant, a
  cosine and a sine at the excitation frequency) and ``y1'``, ``y1''`` its exact
  derivatives.  Using the fundamental keeps the transducer's quantisation steps from
  turning into velocity spikes; for a sinusoidal excitation it is the same as the
  complex-stiffness ratio of force and displacement phasors used by DMA instruments.
  Standard errors come from the residual variance.
* **loop area**, as a cross-check of ``c``: the energy dissipated per cycle is
  ``E = c pi w Y^2``, so ``c = (oint F dy) / (pi w Y^2)``.

The paper's eqs. 3-4 (a quadratic ``c(f)`` and a linear ``k(f)``) are then refitted to the
virtual results (:func:`fit_dma_polynomials`), and the second-order voltage-to-force model
of eq. 6, ``F = A (m_ac V'' + c V' + k V)``, is fitted on the chirp (``A`` by linear least
squares) and scored on every profile (:func:`second_order_table`, the analogue of
Table 4).  Outside the DMA band eq. 6 holds ``k`` and ``c`` at their band-edge values (eqs. 3-4 were
fitted only there).

Table 3 and causality: a linear, causal, passive material whose storage stiffness rises by
9 % over two octaves must dissipate.  For a spring-plus-Maxwell material the rise between
two frequencies is at most ``int c dw`` and the damping cannot rise with frequency
(:func:`causal_stiffness_rise_bound_n_per_m`: Table 3's printed damping allows about 9 N/m
of rise against the 9.5 kN/m it prints, and its damping rises from 0.375 to 0.5 Hz); the
local Kramers-Kronig approximation :func:`implied_damping_n_s_per_m` puts the loss at kN s/m.
The bench film is therefore a causal solid fitted to Table 3's *stiffness*
(:class:`ebraille_sim.identification.bench.FilmParams`), and this DMA measures it by
running the time-domain bench: ``k`` comes out within 1 % of Table 3, ``c`` in kN s/m.

Examples
--------
>>> from ebraille_sim.identification.bench import BenchParams, LoadCellParams
>>> ideal = BenchParams(load_cell=LoadCellParams(noise_n_rms=0.0, resolution_n=0.0))
>>> res = dma_test(ideal, frequencies_hz=(0.25,), cycles=3)
>>> round(res.points[0].stiffness_n_per_m / 1e3, 1)
101.3
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ebraille_sim.base.validation import check_number
from ebraille_sim.identification.bench import (ACTUATED_MASS_KG, EQ3_DAMPING_COEFFS, EQ4_STIFFNESS_COEFFS, TABLE3_DAMPING_N_S_PER_M,
                    TABLE3_FREQUENCIES_HZ, TABLE3_STIFFNESS_N_PER_M, BenchParams, BenchRecord, Profile,
                    run_profile, seed_sequence)
from ebraille_sim.estimation.blockmodels import fitness

__all__ = ["DMA_FREQUENCIES_HZ", "PAPER_A", "TABLE4_FITNESS", "DMAPoint", "DMAResult", "estimate_kc",
           "ideal_instruments",
           "dma_test", "fit_dma_polynomials", "table3_comparison", "implied_damping_n_s_per_m",
           "causal_stiffness_rise_bound_n_per_m",
           "SecondOrderModel", "fit_second_order", "second_order_table"]

DMA_FREQUENCIES_HZ = TABLE3_FREQUENCIES_HZ
"""[R] seed paper, Table 3: DMA excitation frequencies, Hz."""
PAPER_A = 2.258e-5
"""[R] seed paper: proportionality constant A of eq. 6, fitted on the chirp (k in N/m, V in volts)."""
TABLE4_FITNESS = {"chirp": 73.46, "square_0.2hz": 63.85, "square_0.1hz": 62.81, "step_0.1hz": 69.55,
                  "triangle_0.25hz": 74.26, "triangle_0.1hz": 61.40}
"""[R] seed paper, Table 4: fitness (%) of the second-order model of eq. 6."""


@dataclass(frozen=True)
class DMAPoint:
    """Stiffness and damping estimated at one excitation frequency.

    Attributes
    ----------
    frequency_hz : float
    stiffness_n_per_m, damping_n_s_per_m : float
        Least-squares estimates of ``k`` and ``c`` (eq. 5, with ``m_ac`` known).
    stiffness_se_n_per_m, damping_se_n_s_per_m : float
        Their standard errors.
    damping_loop_n_s_per_m : float
        ``c`` from the hysteresis-loop area.
    amplitude_m : float
        Displacement amplitude of the fundamental, m.
    force_amplitude_n : float
        Force amplitude of the fundamental, N.
    cycles : int
        Cycles analysed.
    """
    frequency_hz: float
    stiffness_n_per_m: float
    damping_n_s_per_m: float
    stiffness_se_n_per_m: float
    damping_se_n_s_per_m: float
    damping_loop_n_s_per_m: float
    amplitude_m: float
    force_amplitude_n: float
    cycles: int


@dataclass(frozen=True)
class DMAResult:
    """A DMA test: one :class:`DMAPoint` per frequency and the refitted eqs. 3-4."""
    points: tuple
    damping_coeffs: tuple
    stiffness_coeffs: tuple

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.array([p.frequency_hz for p in self.points])

    @property
    def stiffness_n_per_m(self) -> np.ndarray:
        return np.array([p.stiffness_n_per_m for p in self.points])

    @property
    def damping_n_s_per_m(self) -> np.ndarray:
        return np.array([p.damping_n_s_per_m for p in self.points])


def _harmonic(x: np.ndarray, t: np.ndarray, w: float) -> tuple[float, float, float]:
    """Least-squares ``x ~ x0 + a cos(wt) + b sin(wt)``; returns (x0, a, b)."""
    basis = np.column_stack([np.ones_like(t), np.cos(w * t), np.sin(w * t)])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    return float(coef[0]), float(coef[1]), float(coef[2])


def estimate_kc(displacement_m, force_n, dt_s: float, frequency_hz: float,
                mass_kg: float = ACTUATED_MASS_KG) -> dict:
    """Stiffness and damping from a displacement and force record at one frequency.

    Parameters
    ----------
    displacement_m, force_n : array_like, shape (n,)
        A whole number of cycles of steady sinusoidal excitation.
    dt_s : float
        Sample time, s.
    frequency_hz : float
        Excitation frequency, Hz.
    mass_kg : float
        Moving mass of eq. 5 (the paper's ``m_ac``), kg.

    Returns
    -------
    dict
        ``stiffness_n_per_m``, ``damping_n_s_per_m``, their standard errors
        (``..._se_...``), ``damping_loop_n_s_per_m``, ``amplitude_m``, ``force_amplitude_n``.

    Examples
    --------
    >>> t = np.arange(800) * 0.01
    >>> y = 1e-5 * np.sin(2 * np.pi * 0.5 * t)
    >>> f = 1e5 * y + 2.0 * 1e-5 * np.pi * np.cos(2 * np.pi * 0.5 * t)
    >>> r = estimate_kc(y, f, 0.01, 0.5, mass_kg=0.0)
    >>> round(r["stiffness_n_per_m"]), round(r["damping_n_s_per_m"], 6)
    (100000, 2.0)
    """
    y = np.asarray(displacement_m, dtype=float)
    f = np.asarray(force_n, dtype=float)
    if y.shape != f.shape or y.ndim != 1:
        raise ValueError(f"displacement and force must be 1-D and of equal length, got {y.shape} and {f.shape}")
    if not (frequency_hz > 0 and dt_s > 0):
        raise ValueError(f"frequency_hz and dt_s must be > 0, got {frequency_hz} and {dt_s}")
    if y.size < 8:
        raise ValueError(f"a DMA record needs at least 8 samples, got {y.size}")
    w = 2.0 * math.pi * frequency_hz
    t = np.arange(y.size) * dt_s
    _, a, b = _harmonic(y, t, w)
    y1 = a * np.cos(w * t) + b * np.sin(w * t)
    v1 = w * (-a * np.sin(w * t) + b * np.cos(w * t))
    acc1 = -w * w * y1
    amp = math.hypot(a, b)
    if amp == 0.0:
        raise ValueError("the displacement has no component at the excitation frequency")
    rhs = f - mass_kg * acc1
    X = np.column_stack([np.ones_like(t), y1, v1])
    coef, *_ = np.linalg.lstsq(X, rhs, rcond=None)
    resid = rhs - X @ coef
    dof = max(y.size - 3, 1)
    cov = float(resid @ resid) / dof * np.linalg.inv(X.T @ X)
    _, fa, fb = _harmonic(f, t, w)
    # loop area: oint F dy per cycle, trapezoids closed periodically (the record holds whole cycles)
    cycles = y.size * dt_s * frequency_hz
    fc = f - np.mean(f)
    energy = float(np.sum(0.5 * (fc + np.roll(fc, -1)) * (np.roll(y, -1) - y))) / cycles
    return {"stiffness_n_per_m": float(coef[1]), "damping_n_s_per_m": float(coef[2]),
            "stiffness_se_n_per_m": float(math.sqrt(cov[1, 1])), "damping_se_n_s_per_m": float(math.sqrt(cov[2, 2])),
            "damping_loop_n_s_per_m": energy / (math.pi * w * amp * amp),
            "amplitude_m": amp, "force_amplitude_n": math.hypot(fa, fb)}


def ideal_instruments(bench: BenchParams | None = None) -> BenchParams:
    """The same bench with noise-free, unquantised instruments (load cell, actuator, transducer).

    The film, the FSR and the recording are unchanged; this is the bench "with the paper's
    mechanical parameters" and nothing between them and the estimate.
    """
    import dataclasses

    bench = BenchParams() if bench is None else bench
    return dataclasses.replace(
        bench, load_cell=dataclasses.replace(bench.load_cell, noise_n_rms=0.0, resolution_n=0.0),
        actuator=dataclasses.replace(bench.actuator, resolution_m=0.0, displacement_resolution_m=0.0))


def dma_test(bench: BenchParams | None = None, frequencies_hz=DMA_FREQUENCIES_HZ, cycles: int = 10,
             settle_cycles: int = 1, seed=0) -> DMAResult:
    """Run the DMA on the virtual bench.

    Each frequency is a sinusoidal profile between the bench's minimum and maximum force
    (0.2-3 N) of ``settle_cycles + cycles`` cycles; the first ``settle_cycles`` are
    discarded.  Each frequency has its own child of the master ``seed``.

    Parameters
    ----------
    bench : BenchParams, optional
    frequencies_hz : sequence of float
    cycles, settle_cycles : int
    seed : int or SeedSequence

    Returns
    -------
    DMAResult
        With eqs. 3-4 refitted when at least 3 (damping) and 2 (stiffness) frequencies
        were run (otherwise the coefficient tuples are empty).
    """
    bench = BenchParams() if bench is None else bench
    freqs = [float(f) for f in frequencies_hz]
    if not freqs or any(not (math.isfinite(f) and f > 0) for f in freqs):
        raise ValueError(f"frequencies_hz must be positive numbers, got {frequencies_hz!r}")
    for name, v, lo in (("cycles", cycles, 1), ("settle_cycles", settle_cycles, 0)):
        check_number(name, v, lo=lo, integer=True)
    children = seed_sequence(seed).spawn(len(freqs))
    points = []
    for f, ch in zip(freqs, children):
        rec = run_profile(Profile(f"dma_{f:g}hz", "sine", f, settle_cycles + cycles), bench, ch)
        fs = 1.0 / rec.dt_s
        i0 = rec.baseline_samples + int(round(settle_cycles / f * fs))
        i1 = rec.baseline_samples + int(round((settle_cycles + cycles) / f * fs))
        r = estimate_kc(rec.displacement_m[i0:i1], rec.raw_force_n[i0:i1], rec.dt_s, f, bench.film.mass_kg)
        points.append(DMAPoint(frequency_hz=f, cycles=int(cycles), **r))
    c_co, k_co = (), ()
    if len(freqs) >= 3:
        c_co, k_co = fit_dma_polynomials(freqs, [p.damping_n_s_per_m for p in points],
                                         [p.stiffness_n_per_m for p in points])
    return DMAResult(points=tuple(points), damping_coeffs=c_co, stiffness_coeffs=k_co)


def fit_dma_polynomials(frequencies_hz, damping_n_s_per_m, stiffness_n_per_m) -> tuple[tuple, tuple]:
    """Least-squares fits of the paper's forms: eq. 3 (quadratic ``c(f)``), eq. 4 (linear ``k(f)``).

    Returns
    -------
    damping_coeffs : tuple of 3 floats
        ``(c2, c1, c0)`` of ``c = c2 f^2 + c1 f + c0``, N s/m.
    stiffness_coeffs : tuple of 2 floats
        ``(k1, k0)`` of ``k = k1 f + k0``, N/m.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.array(TABLE3_FREQUENCIES_HZ * 2)
    >>> c, k = fit_dma_polynomials(f, np.ravel(TABLE3_DAMPING_N_S_PER_M), np.ravel(TABLE3_STIFFNESS_N_PER_M))
    >>> [round(v, 2) for v in c], [round(v / 1e3, 2) for v in k]
    ([53.96, -44.44, 10.81], [23.82, 94.32])
    """
    f = np.asarray(frequencies_hz, dtype=float)
    c = np.asarray(damping_n_s_per_m, dtype=float)
    k = np.asarray(stiffness_n_per_m, dtype=float)
    if not (f.shape == c.shape == k.shape and f.ndim == 1):
        raise ValueError("frequencies, damping and stiffness must be 1-D arrays of equal length")
    if np.unique(f).size < 3:
        raise ValueError("eq. 3 (a quadratic) needs at least 3 distinct frequencies")
    return tuple(float(v) for v in np.polyfit(f, c, 2)), tuple(float(v) for v in np.polyfit(f, k, 1))


def table3_comparison(result: DMAResult) -> list[dict]:
    """Virtual DMA next to Table 3, one row per Table 3 frequency present in ``result``.

    Each row: ``frequency_hz``, ``k_virtual``, ``k_test1``, ``k_test2`` (N/m),
    ``c_virtual``, ``c_test1``, ``c_test2`` (N s/m), and the relative differences
    ``k_rel_test1``, ``k_rel_test2``, ``c_rel_test1``, ``c_rel_test2`` (virtual/test - 1).
    """
    rows = []
    for p in result.points:
        hits = [i for i, f in enumerate(TABLE3_FREQUENCIES_HZ) if abs(f - p.frequency_hz) < 1e-9]
        if not hits:
            continue
        i = hits[0]
        row = {"frequency_hz": p.frequency_hz, "k_virtual": p.stiffness_n_per_m, "c_virtual": p.damping_n_s_per_m,
               "k_se": p.stiffness_se_n_per_m, "c_se": p.damping_se_n_s_per_m, "c_loop": p.damping_loop_n_s_per_m}
        for t in (0, 1):
            row[f"k_test{t + 1}"] = TABLE3_STIFFNESS_N_PER_M[t][i]
            row[f"c_test{t + 1}"] = TABLE3_DAMPING_N_S_PER_M[t][i]
            row[f"k_rel_test{t + 1}"] = p.stiffness_n_per_m / TABLE3_STIFFNESS_N_PER_M[t][i] - 1.0
            row[f"c_rel_test{t + 1}"] = p.damping_n_s_per_m / TABLE3_DAMPING_N_S_PER_M[t][i] - 1.0
        rows.append(row)
    return rows


def causal_stiffness_rise_bound_n_per_m(frequencies_hz, damping_n_s_per_m) -> float:
    """Largest storage-stiffness rise a spring-plus-Maxwell material with this damping allows.

    For ``k'(w) = k_e + sum_i k_i x_i^2/(1 + x_i^2)`` and ``c(w) = sum_i k_i tau_i/(1 + x_i^2)``
    (``x_i = w tau_i``, every ``k_i, tau_i > 0``): ``dk'/dw = sum_i k_i tau_i 2 x_i/(1 + x_i^2)^2
    <= c(w)`` because ``2 x/(1 + x^2) <= 1``; and ``c`` falls with ``w``.  Hence between
    consecutive frequencies ``k'(w_b) - k'(w_a) <= c(w_a) (w_b - w_a)``; the bound is the sum
    over the intervals (N/m).  Table 3's damping allows about 9 N/m of rise over
    0.125-0.5 Hz; its stiffness rises by about 9.5 kN/m.
    """
    f = np.asarray(frequencies_hz, dtype=float)
    c = np.asarray(damping_n_s_per_m, dtype=float)
    if not (f.ndim == 1 and f.shape == c.shape and f.size >= 2 and np.all(np.diff(f) > 0)):
        raise ValueError("frequencies_hz must be increasing and match damping_n_s_per_m (at least 2 points)")
    return float(np.sum(c[:-1] * np.diff(2.0 * math.pi * f)))


def implied_damping_n_s_per_m(frequencies_hz, stiffness_n_per_m) -> np.ndarray:
    """Damping implied by a storage-stiffness dispersion for a linear passive material.

    Local approximation of the Kramers-Kronig relations (the "pi/2 rule", exact for a
    power-law modulus of small exponent): ``k''(w) = (pi/2) dk'/d ln w``, ``c = k''/w``.
    The slope is that of a straight-line fit of ``k`` against ``ln f``.

    Returns
    -------
    ndarray
        ``c`` at each frequency, N s/m.
    """
    f = np.asarray(frequencies_hz, dtype=float)
    k = np.asarray(stiffness_n_per_m, dtype=float)
    slope = np.polyfit(np.log(f), k, 1)[0]
    return 0.5 * math.pi * slope / (2.0 * math.pi * f)


# ---------------------------------------------------------------------------
# eq. 6: the second-order voltage-to-force model
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class SecondOrderModel:
    """``F = A (m_ac V'' + c(f) V' + k(f) V)`` (eq. 6) with eqs. 3-4 for ``c`` and ``k``.

    ``f`` is the excitation frequency of the profile at each sample, clamped to the DMA
    band (``k`` and ``c`` held at their band-edge values outside it).  Derivatives of the
    voltage are central differences (:func:`numpy.gradient`).
    """
    amplitude: float
    damping_coeffs: tuple = EQ3_DAMPING_COEFFS
    stiffness_coeffs: tuple = EQ4_STIFFNESS_COEFFS
    mass_kg: float = ACTUATED_MASS_KG
    band_hz: tuple = (TABLE3_FREQUENCIES_HZ[0], TABLE3_FREQUENCIES_HZ[-1])

    def regressor(self, voltage_v, excitation_hz, dt_s: float) -> np.ndarray:
        """``m_ac V'' + c V' + k V`` (the model output for ``A = 1``)."""
        v = np.asarray(voltage_v, dtype=float)
        f = np.clip(np.asarray(excitation_hz, dtype=float), *self.band_hz)
        dv = np.gradient(v, dt_s)
        ddv = np.gradient(dv, dt_s)
        return self.mass_kg * ddv + np.polyval(self.damping_coeffs, f) * dv + np.polyval(self.stiffness_coeffs, f) * v

    def predict(self, voltage_v, excitation_hz, dt_s: float) -> np.ndarray:
        """Force, N, for a detrended voltage record."""
        return self.amplitude * self.regressor(voltage_v, excitation_hz, dt_s)


def fit_second_order(record: BenchRecord, damping_coeffs=EQ3_DAMPING_COEFFS,
                     stiffness_coeffs=EQ4_STIFFNESS_COEFFS, mass_kg: float = ACTUATED_MASS_KG) -> SecondOrderModel:
    """Eq. 6 with ``A`` fitted by least squares on ``record`` (the paper: the chirp).

    Raises
    ------
    ValueError
        If the record carries no excitation frequencies (a CSV record).
    """
    if record.excitation_hz is None:
        raise ValueError(f"record {record.name!r} has no excitation frequencies; eq. 6 needs bench records")
    model = SecondOrderModel(1.0, tuple(damping_coeffs), tuple(stiffness_coeffs), mass_kg)
    z = model.regressor(record.voltage_v, record.excitation_hz, record.dt_s)
    a = float(z @ record.force_n) / float(z @ z)
    return SecondOrderModel(a, tuple(damping_coeffs), tuple(stiffness_coeffs), mass_kg)


def second_order_table(records: dict, model: SecondOrderModel) -> dict[str, float]:
    """Fitness (%) of ``model`` on each record (the analogue of Table 4)."""
    return {name: fitness(rec.force_n, model.predict(rec.voltage_v, rec.excitation_hz, rec.dt_s))
            for name, rec in records.items()}
