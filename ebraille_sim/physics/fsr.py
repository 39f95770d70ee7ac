"""Interlink FSR 402 forward model: contact force to divider voltage to ADC code.

Chain, in the order the signal passes (each block from its physics):

1. **Mechanical lag.** The polymer film and actuator settle with a first-order lag
   (1-2 ms rise, Interlink integration guide), advanced at the physics rate.
2. **Hysteresis.** A Prandtl-Ishlinskii sum of ``N_PLAYS`` play operators acting on
   ``ln(F + F_eps)``: relative, rate-independent, and with a major loop whose loading
   branch has the higher resistance by ``h_p`` = (R_F+ - R_F-)/R_F+.  The datasheet's +10 %
   is measured at 1000 g with the creep included, so the plays carry what the creep does not
   (:func:`play_loop_fraction`, 7.05 % for the nominal film; :func:`datasheet_hysteresis`
   measures the whole loop the datasheet's way).  The play widths grow linearly and sum
   (weighted) to ``-ln(1-h_p)/(2n)``.  Its central (initial) branch is the static curve the
   estimator is calibrated on.
3. **Power-law conduction with stand-off and turn-on.** ``G = 1/R_so + F_c^n T(F_c) / (k c)``:
   the tunnelling/contact path conducts ~F^n (Interlink: roughly 1/R in force), scaled below
   the actuation force by the turn-on ``T(F) = 1/(1 + (F_a/F)^m)``, in parallel with the
   >10 MOhm unloaded film; ``c`` is the resistance factor of temperature and press.
4. **Creep (hereditary).**  The polymer's strain creeps under a held force and recovers
   when the force is removed (a generalized Kelvin/Burgers solid, Paredes-Madrid et al.
   2017), so the force the conduction law sees is
   ``F_c = F_eff + w sum_i z_i``, ``dz_i/dt = (F_eff - z_i)/tau_i``, with ``N_CREEP``
   retardation times spaced one per decade from ``tau_min`` to ``tau_max`` (10 ms-11.6 days)
   and the weight ``w`` per decade.  Under a constant force the conductance therefore
   *rises*, by about ``n w`` per decade of time for days (Interlink: < 5 % per decade;
   Sensitronics: 12 % in 48 h), and a step in force reaches the conduction law at once while
   the creep follows (a force change at 10 Hz sees less of the creep than a held one).  The
   creep term acts only while the film touches the electrodes (lagged force above
   ``load_threshold_n``); the states keep their memory and relax towards the applied force
   (recovery) at all times.
5. **Temperature and press.** ``c = c_T c_P``: ``c_T = 1 + alpha dT`` with one coefficient
   above the calibration temperature and one below (datasheet: -15 % at +85 C, -5 % at -40 C);
   ``c_P = exp(sigma z)``, one standard normal ``z`` drawn per press (single-part
   repeatability, datasheet 2 %).
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

import functools
import math

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.physics.noise import normal_at


N_PLAYS = 4
"""Play operators of the hysteresis model (each carries one state slot)."""

F_EPS_N = 1e-3
"""Force offset inside the logarithm of the hysteresis operator (N)."""

INVERSE_HYSTERESIS_TOL = 1e-12
"""Output change (ln N) below which :func:`inverse_hysteresis` holds its input: rounding, not force."""

N_CREEP = 9
"""Retardation terms of the hereditary creep (one per decade of time from 10 ms to 10^6 s, 11.6
days, each one state slot)."""

PRESS_INDEX_OFFSET = float(2 ** 51)
"""Offset of the press-to-press draws in the device's counter-based noise sequence
(:mod:`ebraille_sim.physics.noise`): above the FSR samples' indices and the current chain's
(``2**50`` on), so no two streams share a number."""

HYSTERESIS_TEST_FORCE_N = 9.80665
"""Force at which the datasheet states its hysteresis (its specifications are taken at 1000 g), N."""

HYSTERESIS_TEST_PEAK_N = 2.0 * 9.80665
"""Peak of the load cycle that measures the hysteresis at :data:`HYSTERESIS_TEST_FORCE_N` (2 kg), N."""

HYSTERESIS_TEST_RAMP_S = 1.0
"""Duration of each leg (0 to the peak, the peak back to 0) of that load cycle, s."""

STATE_SLOTS = ("fsr_force_lagged_n", "fsr_voltage_v", "fsr_code", "fsr_pressed", "fsr_press_count", "fsr_press_z")
"""State slots of the film and the ADC: lagged force, quantised voltage, code; whether the film
is pressed (1) or not (0), the presses so far and the standard normal draw of the present press."""

CREEP_SLOTS = tuple(f"creep_{j}_n" for j in range(N_CREEP))
"""State slots of the creep terms (hereditary force, N)."""

HYSTERESIS_SLOTS = tuple(f"play_{j}" for j in range(N_PLAYS))
"""State slots of the play operators (outputs in ln N)."""

OWNED_STATE_SLOTS = STATE_SLOTS + HYSTERESIS_SLOTS + CREEP_SLOTS
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


def creep_taus_s(tau_min_s: float, tau_max_s: float) -> list[float]:
    """Retardation times of the creep terms (s), spaced geometrically from ``tau_min_s`` to ``tau_max_s``."""
    r = (tau_max_s / tau_min_s) ** (1.0 / (N_CREEP - 1))
    return [tau_min_s * r ** j for j in range(N_CREEP)]


def creep_term_weight(per_decade: float, tau_min_s: float, tau_max_s: float) -> float:
    """Weight of each creep term such that the sum rises by ``per_decade`` per decade of time."""
    return per_decade * math.log10(tau_max_s / tau_min_s) / (N_CREEP - 1)


def creep_decay(dt_s: float, tau_s: float) -> float:
    """Per-sample decay ``exp(-dt/tau)`` of a creep term."""
    return math.exp(-dt_s / tau_s)


@njit(cache=True, inline="always")
def creep_state_step(z_n, f_eff_n, a):
    """One exact sample of a creep term for a force held over the sample: ``z <- a z + (1-a) F`` (N)."""
    return a * z_n + (1.0 - a) * f_eff_n


@njit(cache=True, inline="always")
def creep_force(f_eff_n, f_lagged_n, s, z0, p, a0, weight, threshold_n, n_terms):
    """Hereditary creep: force seen by the conduction law, ``F_eff + w sum_i z_i`` (N).

    Advances the creep states ``s[z0:z0+n_terms]`` in place (decays ``p[a0:...]``); the
    creep adds only while the film is loaded (``f_lagged_n > threshold_n``).
    """
    acc = 0.0
    for j in range(n_terms):
        zj = creep_state_step(s[z0 + j], f_eff_n, p[a0 + j])
        s[z0 + j] = zj
        acc += zj
    if f_lagged_n > threshold_n:
        return f_eff_n + weight * acc
    return f_eff_n


@njit(cache=True, inline="always")
def held_creep_gain(hold_s, weight, tau_min_s, tau_max_s, n_terms):
    """Creep gain ``F_c/F = 1 + w sum_i (1 - exp(-t/tau_i))`` after holding a force ``hold_s`` (s)
    on a recovered film (same retardation times as :func:`creep_taus_s`)."""
    r = (tau_max_s / tau_min_s) ** (1.0 / (n_terms - 1))
    acc = 0.0
    tau = tau_min_s
    for _ in range(n_terms):
        acc += -math.expm1(-hold_s / tau)
        tau *= r
    return 1.0 + weight * acc


@njit(cache=True, inline="always")
def temperature_factor(temp_offset_k, tempco_hot_per_k, tempco_cold_per_k):
    """Resistance factor of a temperature offset from the calibration temperature,
    ``1 + alpha dT`` with ``alpha`` the warm side's coefficient for ``dT >= 0`` and the cold
    side's below (the datasheet's two points, -15 % at +85 C and -5 % at -40 C, both falls)."""
    if temp_offset_k >= 0.0:
        return 1.0 + tempco_hot_per_k * temp_offset_k
    return 1.0 + tempco_cold_per_k * temp_offset_k


@njit(cache=True)
def _temperature_scale(offsets_k, tempco_hot_per_k, tempco_cold_per_k):
    out = np.empty(offsets_k.size)
    for i in range(offsets_k.size):
        out[i] = temperature_factor(offsets_k[i], tempco_hot_per_k, tempco_cold_per_k)
    return out


def temperature_scale(offsets_k, fsr) -> np.ndarray:
    """:func:`temperature_factor` of an FSR at each of the temperature offsets ``offsets_k`` (K, array)."""
    x = np.ascontiguousarray(offsets_k, dtype=float).ravel()
    return _temperature_scale(x, float(fsr.temperature_coeff_per_k), float(fsr.temperature_coeff_cold_per_k))


def temperature_offset_k(factor, tempco_hot_per_k: float, tempco_cold_per_k: float):
    """The temperature offset (K) whose :func:`temperature_factor` is ``factor`` (float or array).

    The law falls on both sides of the calibration temperature, so a factor below 1 has two
    offsets; the warm one is returned (the warm side's coefficient must be negative), and a
    factor above 1, which no temperature gives, is refused."""
    f = np.asarray(factor, dtype=float)
    if tempco_hot_per_k >= 0.0 or np.any(f > 1.0):
        raise ValueError("temperature_offset_k: the factor must be at most 1 and the warm coefficient negative "
                         f"(got factor up to {float(np.max(f)):g}, coefficient {tempco_hot_per_k:g} 1/K)")
    del tempco_cold_per_k                       # the warm branch is the one returned
    out = (f - 1.0) / tempco_hot_per_k
    return float(out) if np.ndim(out) == 0 else out


@njit(cache=True, inline="always")
def turn_on_factor(force_n, actuation_n, steepness):
    """Fraction of the power-law conduction that a force reaches (the turn-on region):
    ``1 / (1 + (F_a / F)^m)``, one half at the actuation force ``F_a``, ``F^m / F_a^m`` well
    below it (the film barely touches its electrodes) and 1 well above it."""
    if force_n <= 0.0:
        return 0.0
    return 1.0 / (1.0 + (actuation_n / force_n) ** steepness)


@njit(cache=True, inline="always")
def press_scatter(f_lagged_n, threshold_n, s, pressed, count, z, seed, sigma):
    """Resistance factor of the present press (single-part repeatability), ``exp(sigma z)``.

    A press starts when the lagged force rises above ``threshold_n`` (the film meets its
    electrodes); each start draws a new standard normal ``z`` from the device's counter-based
    sequence, number :data:`PRESS_INDEX_OFFSET` + presses so far (``s[count]``), kept in
    ``s[z]`` for the rest of the press; ``s[pressed]`` is 1 while pressed.  Before the first
    press ``z`` = 0."""
    if f_lagged_n > threshold_n:
        if s[pressed] == 0.0:
            s[pressed] = 1.0
            s[count] += 1.0
            s[z] = normal_at(seed, PRESS_INDEX_OFFSET + s[count])
    else:
        s[pressed] = 0.0
    return math.exp(sigma * s[z])


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


@njit(cache=True)
def inverse_hysteresis(l_out, x_prev, s, play0, p, width0, weight0, n_plays):
    """Input of the play operators that makes :func:`hysteresis` give ``l_out`` (both in ln N).

    ``l_out`` is ``ln(F_eff + F_eps)``, the operator's output; the plays ``s[play0:...]``
    (widths ``p[width0:...]``, weights ``p[weight0:...]`` summing to 1) hold the operator's
    memory and are advanced as :func:`hysteresis` advances them, so a sequence of outputs
    inverted one by one retraces the input.  The output is a nondecreasing, piecewise-linear
    function of the input: flat until the input has travelled a play's ``2 width`` from the
    last reversal, then rising with the weights of the plays that move.  Where it is strictly
    monotone the input is unique; where the output did not change (the flat stretch after a
    reversal) every input in it fits, and the one returned is ``x_prev``, the last input: a
    change the film does not show is taken as none.  Outputs within
    :data:`INVERSE_HYSTERESIS_TOL` of the plays' present output are taken as unchanged (the
    sum of the plays rounds differently from the ``log`` of the same force).
    """
    phi = 0.0
    for j in range(n_plays):
        phi += p[weight0 + j] * s[play0 + j]
    x = x_prev
    if abs(l_out - phi) > INVERSE_HYSTERESIS_TOL:
        up = l_out > phi
        cur = phi
        slope = 0.0
        used = 0
        for _ in range(n_plays):
            best = -1
            bx = 0.0
            for j in range(n_plays):
                if used & (1 << j):
                    continue
                b = s[play0 + j] + p[width0 + j] if up else s[play0 + j] - p[width0 + j]
                if best < 0 or (b < bx if up else b > bx):
                    best = j
                    bx = b
            end = cur + slope * (bx - x)
            if slope > 0.0 and ((end >= l_out) if up else (end <= l_out)):
                break
            cur = end
            x = bx
            slope += p[weight0 + best]
            used |= 1 << best
        x += (l_out - cur) / slope
    for j in range(n_plays):
        s[play0 + j] = play(x, s[play0 + j], p[width0 + j])
    return x


@njit(cache=True, inline="always")
def conductance_s(force_eff_n, k_ohm, n, g_standoff_s, scale, actuation_n, steepness):
    """Film conductance (S): stand-off path in parallel with the power-law path, which the
    turn-on region (:func:`turn_on_factor`) scales below the actuation force; ``scale``
    multiplies the path's resistance (temperature, press scatter)."""
    if force_eff_n <= 0.0:
        return g_standoff_s
    return g_standoff_s + force_eff_n ** n * turn_on_factor(force_eff_n, actuation_n, steepness) / (k_ohm * scale)


@njit(cache=True, inline="always")
def divider_voltage(g_s, r2_ohm, supply_v):
    """Paper eq. 1 with R_FSR = 1/G (V)."""
    return supply_v * r2_ohm * g_s / (r2_ohm * g_s + 1.0)


@njit(cache=True, inline="always")
def divider_conductance_s(v, r2_ohm, supply_v):
    """Inverse of :func:`divider_voltage`: the film conductance that gives ``v`` (S),
    ``G = V / (R2 (Vs - V))``, for ``0 <= v < supply_v``."""
    return v / (r2_ohm * (supply_v - v))


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


def play_loop_widths(play_fraction: float, exponent: float) -> tuple[list[float], list[float]]:
    """Play widths (in ln N) and weights whose major loop is ``(R_F+ - R_F-)/R_F+ = play_fraction``
    through the power law of exponent ``exponent``: total half-width ``-ln(1-h)/(2n)``."""
    total = -math.log(1.0 - play_fraction) / (2.0 * exponent)
    weights = [1.0 / N_PLAYS] * N_PLAYS
    base = [(j + 1) for j in range(N_PLAYS)]
    norm = sum(w * b for w, b in zip(weights, base))
    return [total * b / norm for b in base], weights


def play_widths(fsr) -> tuple[list[float], list[float]]:
    """Play widths (in ln N) and weights of an FSR: its rate-independent loop
    (:func:`play_loop_fraction`; computed once per unit, new lists each call)."""
    widths, weights = _play_widths_of(fsr)
    return list(widths), list(weights)


@functools.lru_cache(maxsize=16)
def _play_widths_of(fsr) -> tuple[tuple, tuple]:
    """:func:`play_widths` of ``fsr`` as tuples (a drawn unit's bench and its plant's packing ask once each)."""
    widths, weights = play_loop_widths(play_loop_fraction(fsr), fsr.exponent)
    return tuple(widths), tuple(weights)


@functools.lru_cache(maxsize=64)
def _ramp_creep_terms_of(tau_min_s: float, tau_max_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Creep states ``z_i / F_peak`` of a recovered film at the two passes through
    :data:`HYSTERESIS_TEST_FORCE_N` of the datasheet's load cycle (a triangle 0 ->
    :data:`HYSTERESIS_TEST_PEAK_N` -> 0, each leg :data:`HYSTERESIS_TEST_RAMP_S`), from the exact
    solution of ``dz/dt = (F - z)/tau`` for a ramp of rate ``r``: rising
    ``z = r (t - tau (1 - e^(-t/tau)))``; falling, ``t'`` after the peak where ``z = z_p``,
    ``z = F_p - r t' + r tau - (F_p + r tau - z_p) e^(-t'/tau)``.  They depend on the creep's
    time constants only, which a drawn unit shares with its part: computed once per pair
    (read-only arrays; 28 us a call, three calls a drawn device)."""
    taus = np.array(creep_taus_s(tau_min_s, tau_max_s))
    t_r = HYSTERESIS_TEST_RAMP_S
    r = 1.0 / t_r                                          # per unit peak force
    t_up = HYSTERESIS_TEST_FORCE_N / HYSTERESIS_TEST_PEAK_N * t_r
    z_up = r * (t_up + taus * np.expm1(-t_up / taus))
    z_peak = r * (t_r + taus * np.expm1(-t_r / taus))
    t_dn = t_r - t_up                                      # time after the peak of the falling pass
    z_dn = 1.0 - r * t_dn + r * taus - (1.0 + r * taus - z_peak) * np.exp(-t_dn / taus)
    z_up.flags.writeable = False
    z_dn.flags.writeable = False
    return z_up, z_dn


def creep_loop_fraction(fsr) -> float:
    """``(R_F+ - R_F-)/R_F+`` at 1 kg that the creep alone gives in the datasheet's load cycle:
    the film creeps between the rising and the falling pass, so the falling pass reads the lower
    resistance (conduction ``~F_c^n``, ``F_c = F + w sum z_i``; see :func:`_ramp_creep_terms_of`)."""
    w = creep_term_weight(fsr.creep_per_decade, fsr.creep_tau_min_s, fsr.creep_tau_max_s)
    up, dn = _ramp_creep_sums_of(fsr.creep_tau_min_s, fsr.creep_tau_max_s)
    x = HYSTERESIS_TEST_FORCE_N / HYSTERESIS_TEST_PEAK_N
    return 1.0 - ((x + w * up) / (x + w * dn)) ** fsr.exponent


@functools.lru_cache(maxsize=64)
def _ramp_creep_sums_of(tau_min_s: float, tau_max_s: float) -> tuple:
    """The sums of :func:`_ramp_creep_terms` (NumPy's ``sum`` of each, as NumPy floats), once per pair."""
    z_up, z_dn = _ramp_creep_terms_of(tau_min_s, tau_max_s)
    return z_up.sum(), z_dn.sum()


def play_loop_fraction(fsr) -> float:
    """The rate-independent (play operator) loop of an FSR: its datasheet hysteresis
    ``hysteresis_fraction``, measured with the creep, less the creep's share,
    ``1 - (1 - h)/(1 - h_creep)`` (:func:`creep_loop_fraction`; 0 when the creep alone makes the
    loop)."""
    return max(0.0, 1.0 - (1.0 - fsr.hysteresis_fraction) / (1.0 - creep_loop_fraction(fsr)))


@njit(cache=True)
def _cycle_forces(force, a_lag, s, p, weight, threshold_n):
    """The force the film's conduction sees (its plays and creep applied) and the lagged force at
    each sample of the applied ``force`` (one sample a step), through :func:`lag_step`,
    :func:`hysteresis` and :func:`creep_force` from the recovered state ``s`` (plays, then creep
    terms) with the widths, weights and creep decays in ``p``."""
    seen = np.empty(force.size)
    lagged = np.empty(force.size)
    f_lag = 0.0
    for i in range(force.size):
        f_lag = lag_step(f_lag, force[i], a_lag)
        f_eff = hysteresis(f_lag, s, 0, p, 0, N_PLAYS, N_PLAYS)
        seen[i] = creep_force(f_eff, f_lag, s, N_PLAYS, p, 2 * N_PLAYS, weight, threshold_n, N_CREEP)
        lagged[i] = f_lag
    return seen, lagged


@njit(cache=True)
def interp_point(x, xs, ys):
    """``numpy.interp(x, xs, ys)`` of one float inside ``[xs[0], xs[-1]]`` (or NaN): the segment
    and the operations of NumPy's ``arr_interp`` for one point (the last breakpoint not above
    ``x``, the slope of its segment, ``slope (x - x_j) + y_j``, the other end when that is NaN),
    so the same number without the call into NumPy."""
    if x != x:
        return x
    lo, hi = 0, xs.shape[0]
    while lo < hi:                              # bisect_right
        mid = (lo + hi) // 2
        if x < xs[mid]:
            hi = mid
        else:
            lo = mid + 1
    j = lo - 1
    if j == xs.shape[0] - 1 or xs[j] == x:
        return ys[j]
    slope = (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j])
    y = slope * (x - xs[j]) + ys[j]
    if y != y:
        y = slope * (x - xs[j + 1]) + ys[j + 1]
        if y != y and ys[j] == ys[j + 1]:
            y = ys[j]
    return y


@njit(cache=True)
def _branch_resistance(force_n, lagged, seen, k_ohm, n, actuation_n, steepness):
    """:func:`_resistance_at` of a branch whose lagged force passes ``force_n`` between two of its
    samples (NumPy's ``searchsorted`` and ``interp`` of those two, the same numbers); NaN
    otherwise (an end of the branch, or a NaN met), for the caller to fall back."""
    lo, hi = 0, lagged.size
    while lo < hi:                              # searchsorted(side="right")
        mid = lo + ((hi - lo) >> 1)
        if lagged[mid] != lagged[mid]:
            return math.nan
        if force_n < lagged[mid]:
            hi = mid
        else:
            lo = mid + 1
    if lo < 1 or lo > lagged.size - 1:
        return math.nan
    xs = np.empty(2)
    ys = np.empty(2)
    for m in range(2):
        xs[m] = lagged[lo - 1 + m]
        ys[m] = 1.0 / conductance_s(seen[lo - 1 + m], k_ohm, n, 0.0, 1.0, actuation_n, steepness)
    return interp_point(force_n, xs, ys)


@njit(cache=True)
def _loop_fraction(seen, lagged, force_n, k_ohm, n, actuation_n, steepness):
    """``1 - R_down/R_up`` of :func:`datasheet_hysteresis` from its cycle's samples: the peak of the
    lagged force (``np.argmax``), each branch's resistance at ``force_n``
    (:func:`_branch_resistance`, the falling one reversed); NaN where the caller must fall back."""
    peak = 0
    for i in range(lagged.size):
        if lagged[i] != lagged[i]:
            return math.nan
        if lagged[i] > lagged[peak]:
            peak = i
    r_up = _branch_resistance(force_n, lagged[:peak + 1], seen[:peak + 1], k_ohm, n, actuation_n, steepness)
    r_dn = _branch_resistance(force_n, lagged[peak:][::-1], seen[peak:][::-1], k_ohm, n, actuation_n, steepness)
    return 1.0 - r_dn / r_up


def _resistance_at(force_n: float, lagged: np.ndarray, seen: np.ndarray, fsr) -> float:
    """The film's resistance (stand-off path left out) where the lagged force of one monotone
    branch (``lagged`` increasing) passes ``force_n``: interpolated between the two samples around
    it (``np.interp``), the conduction law evaluated at those two only."""
    i = int(np.searchsorted(lagged, force_n, side="right"))
    idx = np.array(sorted({max(i - 1, 0), min(i, lagged.size - 1)}))
    res = np.array([1.0 / conductance_s(seen[j], fsr.resistance_at_1n_ohm, fsr.exponent, 0.0, 1.0,
                                        fsr.actuation_force_n, fsr.turn_on_steepness) for j in idx])
    return float(np.interp(force_n, lagged[idx], res))


@functools.lru_cache(maxsize=8)
def _load_cycle(ramp_s: float, dt_s: float, peak_n: float) -> np.ndarray:
    """The applied force of :func:`datasheet_hysteresis`'s load cycle at each sample: 0 to ``peak_n``
    in ``ramp_s`` and back, every ``dt_s`` (made once per cycle, read-only)."""
    n = int(round(ramp_s / dt_s))
    force = np.concatenate([np.linspace(0.0, peak_n, n + 1), np.linspace(peak_n, 0.0, n + 1)[1:]])
    force.flags.writeable = False
    return force


def datasheet_hysteresis(fsr, ramp_s: float = HYSTERESIS_TEST_RAMP_S, dt_s: float = 1e-3,
                         force_n: float = HYSTERESIS_TEST_FORCE_N, peak_n: float = HYSTERESIS_TEST_PEAK_N) -> float:
    """``(R_F+ - R_F-)/R_F+`` at ``force_n`` (default :data:`HYSTERESIS_TEST_FORCE_N`), measured the
    datasheet's way on a recovered film: the force rises linearly to ``peak_n`` (default
    :data:`HYSTERESIS_TEST_PEAK_N`) in ``ramp_s`` and falls back in as long, sampled every ``dt_s``
    through the plant's own laws (mechanical lag, :func:`hysteresis`, :func:`creep_force`,
    :func:`conductance_s`); the stand-off path is left out and the resistances at the force are
    interpolated between samples."""
    widths, weights = play_widths(fsr)
    p = np.array(list(widths) + list(weights)
                 + [creep_decay(dt_s, tau) for tau in creep_taus_s(fsr.creep_tau_min_s, fsr.creep_tau_max_s)])
    s = np.zeros(N_PLAYS + N_CREEP)
    s[:N_PLAYS] = log_force(0.0)
    w = creep_term_weight(fsr.creep_per_decade, fsr.creep_tau_min_s, fsr.creep_tau_max_s)
    a_lag = lag_alpha(dt_s, fsr.mechanical_lag_s)
    seen, lagged = _cycle_forces(_load_cycle(float(ramp_s), float(dt_s), float(peak_n)), a_lag, s, p, w,
                                 fsr.load_threshold_n)
    loop = _loop_fraction(seen, lagged, float(force_n), fsr.resistance_at_1n_ohm, fsr.exponent, fsr.actuation_force_n,
                          fsr.turn_on_steepness)
    if loop == loop:
        return float(loop)
    return _loop_of_samples(seen, lagged, force_n, fsr)


def _loop_of_samples(seen: np.ndarray, lagged: np.ndarray, force_n: float, fsr) -> float:
    """:func:`_loop_fraction` through NumPy (``argmax``, ``searchsorted``, ``interp``): every cycle,
    a branch that does not pass ``force_n`` between two samples included."""
    peak = int(np.argmax(lagged))
    r_up = _resistance_at(force_n, lagged[:peak + 1], seen[:peak + 1], fsr)
    r_dn = _resistance_at(force_n, lagged[peak:][::-1], seen[peak:][::-1], fsr)
    return float(1.0 - r_dn / r_up)


def creep_gain(hold_s, fsr):
    """:func:`held_creep_gain` of an FSR after holding ``hold_s`` (s; float or array); a Python
    or NumPy float is one call, without the vectorising."""
    w = creep_term_weight(fsr.creep_per_decade, fsr.creep_tau_min_s, fsr.creep_tau_max_s)
    if type(hold_s) is float or type(hold_s) is np.float64:
        return float(held_creep_gain(float(hold_s), w, fsr.creep_tau_min_s, fsr.creep_tau_max_s, N_CREEP))
    f = np.vectorize(lambda t: held_creep_gain(float(t), w, fsr.creep_tau_min_s, fsr.creep_tau_max_s, N_CREEP))
    out = f(np.asarray(hold_s, dtype=float))
    return float(out) if np.ndim(out) == 0 else out


def creep_frequency_response(f_hz, fsr):
    """Complex gain of the creep from the applied to the crept force at ``f_hz`` (Hz), small signal.

    ``H(jw) = 1 + w sum_i 1/(1 + j w tau_i)``; ``H(0)`` is the fully crept gain.
    """
    w = creep_term_weight(fsr.creep_per_decade, fsr.creep_tau_min_s, fsr.creep_tau_max_s)
    om = 2.0 * math.pi * np.asarray(f_hz, dtype=float)
    return 1.0 + w * sum(1.0 / (1.0 + 1j * om * t) for t in creep_taus_s(fsr.creep_tau_min_s, fsr.creep_tau_max_s))


def held_resistance_factor(hold_s, fsr):
    """Resistance of a film held ``hold_s`` (s) at a constant force, relative to its
    instantaneous value: ``creep_gain^-n`` (stand-off path neglected)."""
    return np.asarray(creep_gain(hold_s, fsr)) ** (-fsr.exponent)


def static_conductance(force_n: float, fsr, load_time_s: float = 0.0, temp_offset_k: float = 0.0) -> float:
    """Conductance (S) on the central (virgin) branch after holding ``force_n`` for
    ``load_time_s`` on a recovered film, with an optional temperature offset.

    The same laws as the compiled loop: :func:`conductance_s` of the force grown by
    :func:`held_creep_gain` (when above the load threshold), scaled by :func:`temperature_factor`.
    """
    f = float(force_n)
    w = (creep_term_weight(fsr.creep_per_decade, fsr.creep_tau_min_s, fsr.creep_tau_max_s)
         if f > fsr.load_threshold_n else 0.0)
    return _static_conductance(f, float(load_time_s), float(temp_offset_k), fsr.load_threshold_n, w,
                               fsr.creep_tau_min_s, fsr.creep_tau_max_s, fsr.temperature_coeff_per_k,
                               fsr.temperature_coeff_cold_per_k, fsr.resistance_at_1n_ohm, fsr.exponent,
                               1.0 / fsr.standoff_resistance_ohm, fsr.actuation_force_n, fsr.turn_on_steepness)


@njit(cache=True)
def _static_conductance(f, load_time_s, temp_offset_k, threshold_n, weight, tau_min_s, tau_max_s, tempco_hot_per_k,
                        tempco_cold_per_k, k_ohm, n, g_standoff_s, actuation_n, steepness):
    """:func:`static_conductance`'s laws in one compiled call (``weight``: the creep terms' weight,
    :func:`creep_term_weight`)."""
    if f > threshold_n:
        f *= held_creep_gain(load_time_s, weight, tau_min_s, tau_max_s, N_CREEP)
    return conductance_s(f, k_ohm, n, g_standoff_s, temperature_factor(temp_offset_k, tempco_hot_per_k,
                                                                      tempco_cold_per_k), actuation_n, steepness)


def static_resistance(force_n: float, fsr, load_time_s: float = 0.0, temp_offset_k: float = 0.0) -> float:
    """Resistance (ohm) on the central (virgin) branch, with optional creep and temperature."""
    return 1.0 / static_conductance(force_n, fsr, load_time_s, temp_offset_k)


def static_voltage(force_n: float, fsr, circuit, load_time_s: float = 0.0) -> float:
    """Noise-free divider voltage on the central branch (V), through :func:`divider_voltage`."""
    return divider_voltage(static_conductance(force_n, fsr, load_time_s), circuit.r2_ohm, circuit.supply_v)
