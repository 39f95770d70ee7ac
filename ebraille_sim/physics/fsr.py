"""Interlink FSR 402 forward model: contact force to divider voltage to ADC code.

Chain, in the order the signal passes (each block from its physics):

1. **Mechanical lag.** The polymer film and actuator settle with a first-order lag
   (1-2 ms rise, Interlink integration guide), advanced at the physics rate.
2. **Hysteresis.** A Prandtl-Ishlinskii sum of ``N_PLAYS`` play operators acting on
   ``ln(F + F_eps)``: relative, rate-independent, and with a major loop whose loading
   branch has the higher resistance by ``h`` = (R_F+ - R_F-)/R_F+ (10 %, datasheet).
   The play widths grow linearly and sum (weighted) to ``-ln(1-h)/(2n)``.  Its central
   (initial) branch is the static curve the estimator is calibrated on.
3. **Power-law conduction with stand-off.** ``G = 1/R_so + F_eff^n / (k c_creep c_temp)``:
   the tunnelling/contact path conducts ~F^n (Interlink: roughly 1/R in force), in
   parallel with the >10 MOhm unloaded film.
4. **Creep.** While loaded, resistance creeps logarithmically in load time,
   ``c_creep = 1 + d log10(1 + t_load/t0)``, with ``d`` set so that a 30 min hold gives
   +6 % (seed paper's static test; datasheet: < 5 % per decade).  Unloaded, the load time
   relaxes exponentially (recovery).
5. **Temperature.** ``c_temp = 1 + alpha dT`` (datasheet: -15 % at +85 C).
6. **Divider** (paper eq. 1), FSR to the supply, R2 to ground: ``V = Vs R2/(R2 + R)``.
7. **Electrical noise** (Gaussian, from a counter-based generator, see :mod:`ebraille_sim.physics.noise`),
   **ADC** quantisation to ``bits`` with clipping at the rails, sampled at the sensor rate.

Faults (open circuit, short, stuck ADC, forced voltage) replace the divider output.

Examples
--------
>>> from ebraille_sim.physics.params import FSRS, CircuitParams
>>> round(static_voltage(1.0, FSRS["nominal"], CircuitParams(r2_ohm=10e3)), 3)
2.5
"""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit


N_PLAYS = 4
"""Play operators of the hysteresis model (each carries one state slot)."""

F_EPS_N = 1e-3
"""Force offset inside the logarithm of the hysteresis operator (N)."""


@njit(cache=True, inline="always")
def play(x, y_prev, width):
    """Play (backlash) operator: output stays within ``width`` of the input."""
    lo = x - width
    hi = x + width
    if y_prev < lo:
        return lo
    if y_prev > hi:
        return hi
    return y_prev


@njit(cache=True, inline="always")
def conductance_s(force_eff_n, k_ohm, n, g_standoff_s, scale):
    """Film conductance (S): stand-off path in parallel with the power-law path."""
    if force_eff_n <= 0.0:
        return g_standoff_s
    return g_standoff_s + force_eff_n ** n / (k_ohm * scale)


@njit(cache=True, inline="always")
def divider_voltage(g_s, r2_ohm, supply_v):
    """Paper eq. 1 with R_FSR = 1/G (V)."""
    return supply_v * r2_ohm * g_s / (r2_ohm * g_s + 1.0)


@njit(cache=True, inline="always")
def adc_code(v, lsb_v, max_code):
    """Round-down ADC conversion with clipping at the rails."""
    c = math.floor(v / lsb_v)
    if c < 0.0:
        return 0.0
    if c > max_code:
        return max_code
    return c


def play_widths(fsr) -> tuple[list[float], list[float]]:
    """Play widths (in ln N) and weights giving the FSR's hysteresis fraction."""
    total = fsr.hysteresis_log_halfwidth
    weights = [1.0 / N_PLAYS] * N_PLAYS
    base = [(j + 1) for j in range(N_PLAYS)]
    norm = sum(w * b for w, b in zip(weights, base))
    return [total * b / norm for b in base], weights


def static_resistance(force_n: float, fsr, load_time_s: float = 0.0, temp_offset_k: float = 0.0) -> float:
    """Resistance on the central (virgin) branch, with optional creep and temperature."""
    creep = 1.0 + fsr.creep_per_decade * math.log10(1.0 + load_time_s / fsr.creep_t0_s)
    scale = creep * (1.0 + fsr.temperature_coeff_per_k * temp_offset_k)
    g = 1.0 / fsr.standoff_resistance_ohm
    if force_n > 0:
        g += force_n ** fsr.exponent / (fsr.resistance_at_1n_ohm * scale)
    return 1.0 / g


def static_voltage(force_n: float, fsr, circuit, load_time_s: float = 0.0) -> float:
    """Noise-free divider voltage on the central branch (V)."""
    return circuit.divider_v(static_resistance(force_n, fsr, load_time_s))
