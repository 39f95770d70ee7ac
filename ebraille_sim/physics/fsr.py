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
>>> round(static_voltage(1.0, FSRS["nominal"], CircuitParams(r2_ohm=10e3)), 3)   # 10 kOhm || 10 MOhm
2.501
"""
from __future__ import annotations

import math

from ebraille_sim.base.compiled import njit


N_PLAYS = 4
"""Play operators of the hysteresis model (each carries one state slot)."""

F_EPS_N = 1e-3
"""Force offset inside the logarithm of the hysteresis operator (N)."""

STATE_SLOTS = ("fsr_force_lagged_n", "fsr_load_time_s", "fsr_voltage_v", "fsr_code")
"""State slots of the film and the ADC: lagged force, creep clock, quantised voltage, code."""

HYSTERESIS_SLOTS = tuple(f"play_{j}" for j in range(N_PLAYS))
"""State slots of the play operators (outputs in ln N)."""

OWNED_STATE_SLOTS = STATE_SLOTS + HYSTERESIS_SLOTS
"""Every state slot this module declares (see :mod:`ebraille_sim.plant.layout`)."""

FAULT_NONE, FAULT_OPEN, FAULT_SHORT, FAULT_STUCK, FAULT_VALUE = 0, 1, 2, 3, 4
"""Sensor fault codes: open circuit (divider reads 0 V), short (reads the supply), stuck (the
ADC repeats its last code), forced value (reads a given voltage)."""


@njit(cache=True, inline="always")
def lag_step(f_lagged_n, f_in_n, alpha):
    """First-order mechanical lag over one step: ``F_lag += (F - F_lag) alpha`` (N)."""
    return f_lagged_n + (f_in_n - f_lagged_n) * alpha


def lag_alpha(h_s: float, lag_s: float) -> float:
    """Per-step gain ``1 - exp(-h/tau)`` of the mechanical lag."""
    return 1.0 - math.exp(-h_s / lag_s)


@njit(cache=True, inline="always")
def creep_clock_step(load_time_s, f_lagged_n, threshold_n, dt_s, recovery_decay):
    """Load time after one sensor sample: counts up while loaded, decays while unloaded (s)."""
    if f_lagged_n > threshold_n:
        return load_time_s + dt_s
    return load_time_s * recovery_decay


def recovery_decay(dt_s: float, recovery_s: float) -> float:
    """Per-sample decay ``exp(-dt/tau)`` of the load time while unloaded."""
    return math.exp(-dt_s / recovery_s)


@njit(cache=True, inline="always")
def creep_factor(load_time_s, per_decade, t0_s):
    """Resistance factor of logarithmic creep, ``1 + d log10(1 + t_load/t0)``."""
    return 1.0 + per_decade * math.log10(1.0 + load_time_s / t0_s)


@njit(cache=True, inline="always")
def creep_per_decade_for(fraction, hold_s, t0_s):
    """Creep slope ``d`` per decade such that :func:`creep_factor` at ``hold_s`` is ``1 + fraction``."""
    return fraction / math.log10(1.0 + hold_s / t0_s)


@njit(cache=True, inline="always")
def temperature_factor(temp_offset_k, tempco_per_k):
    """Resistance factor of a temperature offset, ``1 + alpha dT``."""
    return 1.0 + tempco_per_k * temp_offset_k


@njit(cache=True, inline="always")
def log_force(f_n):
    """Input of the play operators, ``ln(F + F_eps)`` (ln N)."""
    return math.log(f_n + F_EPS_N)


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
def hysteresis(f_lagged_n, s, play0, p, width0, weight0, n_plays):
    """Prandtl-Ishlinskii hysteresis: effective force seen by the conduction law (N).

    Advances the play outputs ``s[play0:play0+n_plays]`` in place (widths
    ``p[width0:...]``, weights ``p[weight0:...]``) and returns
    ``exp(sum_j weight_j y_j) - F_eps``.
    """
    lf = log_force(f_lagged_n)
    leff = 0.0
    for j in range(n_plays):
        yj = play(lf, s[play0 + j], p[width0 + j])
        s[play0 + j] = yj
        leff += p[weight0 + j] * yj
    return math.exp(leff) - F_EPS_N


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
def sensor_voltage(fault, g_s, r2_ohm, supply_v, forced_v):
    """Divider output, or what a fault puts in its place (V); see the ``FAULT_*`` codes."""
    if fault == FAULT_OPEN:
        return 0.0
    if fault == FAULT_SHORT:
        return supply_v
    if fault == FAULT_VALUE:
        return forced_v
    return divider_voltage(g_s, r2_ohm, supply_v)


@njit(cache=True, inline="always")
def adc_code(v, lsb_v, max_code):
    """Round-down ADC conversion with clipping at the rails."""
    c = math.floor(v / lsb_v)
    if c < 0.0:
        return 0.0
    if c > max_code:
        return max_code
    return c


@njit(cache=True, inline="always")
def adc_sample(code_prev, v, lsb_v, max_code, fault):
    """The ADC code of one sample: a new conversion, or the last code while stuck."""
    if fault == FAULT_STUCK:
        return code_prev
    return adc_code(v, lsb_v, max_code)


@njit(cache=True, inline="always")
def adc_voltage(code, lsb_v):
    """Voltage the microcontroller reads for an ADC code, ``code LSB`` (V)."""
    return code * lsb_v


def play_widths(fsr) -> tuple[list[float], list[float]]:
    """Play widths (in ln N) and weights giving the FSR's hysteresis fraction."""
    total = fsr.hysteresis_log_halfwidth
    weights = [1.0 / N_PLAYS] * N_PLAYS
    base = [(j + 1) for j in range(N_PLAYS)]
    norm = sum(w * b for w, b in zip(weights, base))
    return [total * b / norm for b in base], weights


def static_conductance(force_n: float, fsr, load_time_s: float = 0.0, temp_offset_k: float = 0.0) -> float:
    """Conductance (S) on the central (virgin) branch, with optional creep and temperature.

    The same laws as the compiled loop: :func:`conductance_s` scaled by :func:`creep_factor`
    and :func:`temperature_factor`.
    """
    scale = (creep_factor(float(load_time_s), fsr.creep_per_decade, fsr.creep_t0_s)
             * temperature_factor(float(temp_offset_k), fsr.temperature_coeff_per_k))
    return conductance_s(float(force_n), fsr.resistance_at_1n_ohm, fsr.exponent,
                         1.0 / fsr.standoff_resistance_ohm, scale)


def static_resistance(force_n: float, fsr, load_time_s: float = 0.0, temp_offset_k: float = 0.0) -> float:
    """Resistance (ohm) on the central (virgin) branch, with optional creep and temperature."""
    return 1.0 / static_conductance(force_n, fsr, load_time_s, temp_offset_k)


def static_voltage(force_n: float, fsr, circuit, load_time_s: float = 0.0) -> float:
    """Noise-free divider voltage on the central branch (V), through :func:`divider_voltage`."""
    return divider_voltage(static_conductance(force_n, fsr, load_time_s), circuit.r2_ohm, circuit.supply_v)
