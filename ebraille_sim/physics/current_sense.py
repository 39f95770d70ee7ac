"""Motor-current sensing: shunt, current-sense amplifier, anti-alias RC, ADC, firmware reading.

The firmware never sees the armature current itself; it reads it through the board's chain:

1. a low-side shunt ``R_sh`` carries the motor current ``i``;
2. a bidirectional current-sense amplifier (TI INA240A3: gain ``G`` = 100 V/V, its output
   centred on a mid-supply reference ``V_ref``) gives ``v_amp = V_ref + G (1 + e_G)(R_sh i + V_os)``,
   with the unit's gain error ``e_G``, input offset ``V_os`` and reference error;
3. a two-stage RC low-pass (two RC sections of ``tau = R C`` each, buffered) before the ADC
   input, each advanced exactly at the physics step for a held input:
   ``v_f <- v_in + (v_f - v_in) exp(-h/tau)`` (:func:`rc_step`);
4. the microcontroller's ADC converts ``v_f`` plus its own noise once per control period,
   just before the controller runs (round-down conversion, :func:`ebraille_sim.physics.fsr.adc_code`);
5. the firmware turns the code into amperes with the NOMINAL constants only, against the
   zero code it measured with the motor at rest (:func:`firmware_current_a`):
   ``i_meas = (code - code_zero) LSB / (G_nom R_sh,nom)``.

What the firmware does not know (the unit's gain error, shunt tolerance, the residual of its
offset zeroing, the ADC's noise and quantisation) stays in its reading; the worst case over a
production run bounds it (:func:`worst_case_error_a`), and the safety supervisor derates its
current limits by that bound.

The PWM drive.  The plant integrates the armature with the H-bridge's mean voltage.  At 20 kHz
and the Faulhaber 0816's L/R = 10 us the current inside one PWM period is far from its mean:
at 50 % duty it swings by 0.24 A peak to peak, 240 LSB of this chain.  Where in the period a
single conversion falls would then decide the reading, so the chain filters before it samples:
each RC section (corner 1.0 kHz) passes the 20 kHz fundamental at 1/20, the two at 1/400, and
:func:`pwm_ripple_at_adc_a` (the exact RL waveform of one PWM period through both sections in
their periodic steady state) leaves 0.6 mA peak to peak at 50 % duty and less at the holding
duties of reading: under one LSB, so a conversion at any phase reads the mean to within the
ADC's own step, which is what the plant's mean current gives.  (One RC section at 1.6 kHz
would leave 18 mA, 18 LSB; docs/model.md has the table.)

Examples
--------
>>> from ebraille_sim.physics.params import CurrentSenseParams
>>> cs = CurrentSenseParams()
>>> round(cs.lsb_a * 1e3, 3)                      # mA per ADC step
0.977
>>> round(worst_case_error_a(cs, 0.1) * 1e3, 2)   # mA at 0.1 A: 1.2 % of it and 3.1 mA
4.31
"""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.physics.fsr import adc_code
from ebraille_sim.physics.noise import normal_at

STATE_SLOTS = ("isense_filter1_v", "isense_filter2_v", "isense_count", "current_meas_a")
"""State slots of the chain: the two RC sections' output voltages, the physics steps so far (the
index of a conversion's noise, so that the reading at a given time does not depend on the
control rate) and the firmware's reading of the current (A)."""

OWNED_STATE_SLOTS = STATE_SLOTS
"""Every state slot this module declares (see :mod:`ebraille_sim.plant.layout`)."""

NOISE_INDEX_OFFSET = float(2 ** 50)
"""Offset of the chain's ADC noise indices in the device's counter-based noise sequence
(:mod:`ebraille_sim.physics.noise`): far above any FSR sample index, so the two streams
never share a number."""


@njit(cache=True, inline="always")
def amplifier_v(current_a, shunt_ohm, gain, gain_error, offset_v, ref_v):
    """Amplifier output, V: ``V_ref + G (1 + e_G) (R_sh i + V_os)``, clipped to the 0-5 V swing
    (:data:`AMP_SWING_V`)."""
    v = ref_v + gain * (1.0 + gain_error) * (shunt_ohm * current_a + offset_v)
    if v < 0.0:
        return 0.0
    if v > AMP_SWING_V:
        return AMP_SWING_V
    return v


AMP_SWING_V = 5.0
"""Output swing of the amplifier on the 5 V rail it shares with the ADC reference, V."""


@njit(cache=True, inline="always")
def rc_step(v_filter, v_in, decay):
    """One physics step of the first-order RC, exact for a held input: ``decay = exp(-h/tau)``."""
    return v_in + (v_filter - v_in) * decay


@njit(cache=True, inline="always")
def firmware_current_a(code, zero_code, lsb_v, nominal_v_per_a):
    """The firmware's current, A: the code's distance from the zero code measured at rest, over
    the NOMINAL transfer ``G_nom R_sh,nom`` (V/A)."""
    return (code - zero_code) * lsb_v / nominal_v_per_a


@njit(cache=True, inline="always")
def sample_current_a(v_filter, noise_v, zero_code, lsb_v, max_code, nominal_v_per_a):
    """One conversion of the filtered amplifier output plus the ADC's noise, read by the firmware (A)."""
    return firmware_current_a(adc_code(v_filter + noise_v, lsb_v, max_code), zero_code, lsb_v, nominal_v_per_a)


def zero_code(cs, sensor_seed: float, lsb_v: float, max_code: float) -> float:
    """The firmware's zero: the mean code of ``cs.zero_samples`` conversions with the motor at
    rest (no current), noise included, as the board's start-up calibration measures it.

    The conversions use noise indices just below :data:`NOISE_INDEX_OFFSET` (their own part of
    the device's noise sequence)."""
    v0 = amplifier_v(0.0, cs.shunt_ohm, cs.gain_v_per_v, cs.gain_error, cs.offset_v, cs.reference_v)
    return _mean_code_at_rest(v0, cs.adc_noise_lsb * lsb_v, float(sensor_seed), int(cs.zero_samples), lsb_v,
                              max_code)


@njit(cache=True)
def _mean_code_at_rest(v0, noise_rms_v, seed, n, lsb_v, max_code):
    """Mean of ``n`` conversions of ``v0`` plus the device's noise at indices below
    :data:`NOISE_INDEX_OFFSET` (one compiled call: every env reset packs a zero)."""
    total = 0.0
    for k in range(n):
        total += adc_code(v0 + noise_rms_v * normal_at(seed, NOISE_INDEX_OFFSET - 1.0 - k), lsb_v, max_code)
    return total / n


def mean_reading_a(cs, current_a: float, seed: float, n: int, zero: float | None = None) -> float:
    """The firmware's mean of ``n`` readings of a steady ``current_a`` (the RC sections settled),
    against the zero code ``zero`` it measured at rest before (None: :func:`zero_code` with
    ``seed``), A: what a calibration routine that holds a current and averages its conversions
    reads.  The unit's shunt error, gain error and offset are in it; the conversions' noise
    comes from the device's noise sequence of ``seed + 1`` (:func:`_mean_code_at_rest`)."""
    lsb, top = cs.adc_lsb_v, cs.adc_max_code
    v = amplifier_v(current_a, cs.shunt_ohm * (1.0 + cs.shunt_error), cs.gain_v_per_v, cs.gain_error, cs.offset_v,
                    cs.reference_v)
    code = _mean_code_at_rest(v, cs.adc_noise_lsb * lsb, float(seed) + 1.0, int(n), lsb, top)
    return firmware_current_a(code, zero_code(cs, seed, lsb, top) if zero is None else zero, lsb, cs.nominal_v_per_a)



def zero_and_mean_readings_a(cs, zero_seed: float, currents_a, seeds, n: int) -> tuple[float, list]:
    """:func:`zero_code` of ``zero_seed`` and, against that zero, :func:`mean_reading_a` of each
    steady current of ``currents_a`` with its seed of ``seeds`` (``n`` conversions each), in one
    compiled call: ``(zero, readings)``, the same numbers (a drive's calibration reads four)."""
    lsb, top = cs.adc_lsb_v, cs.adc_max_code
    out = _zero_and_means(np.asarray(currents_a, dtype=np.float64), np.asarray(seeds, dtype=np.float64),
                          float(zero_seed), int(cs.zero_samples), int(n), cs.shunt_ohm, cs.shunt_error, cs.gain_v_per_v,
                          cs.gain_error, cs.offset_v, cs.reference_v, cs.adc_noise_lsb * lsb, lsb, top,
                          cs.nominal_v_per_a)
    return out[0], out[1:].tolist()


@njit(cache=True)
def _zero_and_means(currents_a, seeds, zero_seed, zero_n, n, shunt_ohm, shunt_error, gain, gain_error, offset_v, ref_v,
                    noise_rms_v, lsb_v, max_code, nominal_v_per_a):
    """The zero code, then the mean readings (A), of :func:`zero_and_mean_readings_a`."""
    out = np.empty(currents_a.size + 1)
    v0 = amplifier_v(0.0, shunt_ohm, gain, gain_error, offset_v, ref_v)
    zero = _mean_code_at_rest(v0, noise_rms_v, zero_seed, zero_n, lsb_v, max_code)
    out[0] = zero
    shunt = shunt_ohm * (1.0 + shunt_error)
    for k in range(currents_a.size):
        v = amplifier_v(currents_a[k], shunt, gain, gain_error, offset_v, ref_v)
        code = _mean_code_at_rest(v, noise_rms_v, seeds[k] + 1.0, n, lsb_v, max_code)
        out[k + 1] = firmware_current_a(code, zero, lsb_v, nominal_v_per_a)
    return out


MEAN_QUANTISATION_LSB = 0.01
"""Bound on the bias of a mean of round-down conversions that the chain's own noise dithers
(0.5 LSB RMS), LSB [D]: the bias of a dithered quantiser falls as ``exp(-2 pi^2 sigma^2)``,
0.007 at 0.5 LSB; the round-down's half step is common to the reading and the zero and cancels
(tests/test_calibration.py measures it)."""


def mean_error_a(cs, n: int) -> float:
    """Largest error of a mean of ``n`` conversions of a steady input, A: three standard errors
    of the averaged noise and the dithered quantiser's bias (:data:`MEAN_QUANTISATION_LSB`)."""
    return cs.lsb_a * (3.0 * cs.adc_noise_lsb / math.sqrt(n) + MEAN_QUANTISATION_LSB)


def averaged_error_a(cs, n: int) -> float:
    """Largest error of :func:`mean_reading_a` beyond the unit's gain error, A: the mean's error
    (:func:`mean_error_a`) and that of the zero it is read against (``zero_samples`` conversions)."""
    return mean_error_a(cs, n) + mean_error_a(cs, cs.zero_samples)


def worst_case_error_a(cs, current_a: float) -> float:
    """Largest error of the firmware's reading at ``current_a`` over the chain's tolerances, A.

    Gain: amplifier gain error and shunt tolerance at their bounds; zero: the input offset at
    its bound drifts nothing after the zeroing, but the zeroing itself leaves half an LSB of
    round-down plus three standard errors of the averaged noise; one reading adds one LSB of
    round-down and three standard deviations of the ADC noise."""
    gain = abs(current_a) * (cs.gain_error_max + cs.shunt_tolerance)
    zero = cs.lsb_a * (0.5 + 3.0 * cs.adc_noise_lsb / math.sqrt(cs.zero_samples))
    reading = cs.lsb_a * (1.0 + 3.0 * cs.adc_noise_lsb)
    return gain + zero + reading


def pwm_ripple_at_adc_a(cs, supply_v: float, duty: float, r_ohm: float, l_h: float, pwm_hz: float,
                        back_emf_v: float = 0.0, points: int = 4000) -> tuple[float, float]:
    """Peak-to-peak ripple of the armature current over one PWM period, and what is left of it
    at the ADC input after the RC, both in amperes of current (the latter referred back through
    the nominal transfer).

    The armature under a locked-antiphase-free (sign-magnitude, drive/coast through the low
    side) PWM at ``duty``: ``L di/dt = V_on - R i - E`` during the on-time, ``- R i - E`` during
    the off-time, in its periodic steady state (exact exponentials); the RC is driven by the
    amplifier's image of that current and also settled to its periodic steady state."""
    import numpy as np
    T = 1.0 / pwm_hz
    tau_l = l_h / r_ohm
    ton = duty * T
    t = np.linspace(0.0, T, points, endpoint=False)
    i_on_ss = (supply_v - back_emf_v) / r_ohm
    i_off_ss = -back_emf_v / r_ohm
    a_on = math.exp(-ton / tau_l)
    a_off = math.exp(-(T - ton) / tau_l)
    # periodic start value i0: i(ton) = i_on_ss + (i0 - i_on_ss) a_on; i(T) = i_off_ss + (i(ton) - i_off_ss) a_off = i0
    i0 = (i_off_ss * (1 - a_off) + a_off * (i_on_ss * (1 - a_on))) / (1 - a_on * a_off)
    i_ton = i_on_ss + (i0 - i_on_ss) * a_on
    i = np.where(t < ton, i_on_ss + (i0 - i_on_ss) * np.exp(-t / tau_l),
                 i_off_ss + (i_ton - i_off_ss) * np.exp(-(t - ton) / tau_l))
    # the RC sections on the current's image, exact per sample for a held input, iterated to
    # their periodic steady state
    h = T / points
    decay = math.exp(-h / cs.filter_tau_s)
    y = [float(np.mean(i))] * int(cs.filter_stages)
    out = np.empty(points)
    for _ in range(int(40 * cs.filter_tau_s / T) + 3):
        for k in range(points):
            x = i[k]
            for j in range(len(y)):
                y[j] = x + (y[j] - x) * decay
                x = y[j]
            out[k] = x
    return float(i.max() - i.min()), float(out.max() - out.min())
