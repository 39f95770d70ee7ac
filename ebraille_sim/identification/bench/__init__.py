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

The package holds the instruments and the film (:mod:`.instruments`), the protocol of
profiles (:mod:`.protocol`), the records with their conditioning and CSV input
(:mod:`.records`), and the simulation of a run (:mod:`.simulation`); every name is
importable from the package itself.

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

from ebraille_sim.identification.bench.instruments import (ACTUATED_MASS_KG, EQ3_DAMPING_COEFFS, EQ4_STIFFNESS_COEFFS,
                                                           SLS_FIT_TABLE3, TABLE3_DAMPING_N_S_PER_M,
                                                           TABLE3_FREQUENCIES_HZ, TABLE3_STIFFNESS_N_PER_M,
                                                           ActuatorParams, BenchParams, FilmParams, LoadCellParams,
                                                           default_bench_device, describe_bench,
                                                           fit_standard_linear_solid)
from ebraille_sim.identification.bench.protocol import (HOLD_PROFILE, PAPER_PROFILES, PROFILE_LABELS, Profile,
                                                        chirp_schedule, profile_signal)
from ebraille_sim.identification.bench.records import (CSV_COLUMNS, BenchRecord, condition, hold_creep, load_csv,
                                                       lowpass_fft)
from ebraille_sim.identification.bench.simulation import run_profile, run_profiles, seed_sequence

__all__ = [
    "TABLE3_FREQUENCIES_HZ", "TABLE3_DAMPING_N_S_PER_M", "TABLE3_STIFFNESS_N_PER_M",
    "EQ3_DAMPING_COEFFS", "EQ4_STIFFNESS_COEFFS", "ACTUATED_MASS_KG",
    "SLS_FIT_TABLE3", "fit_standard_linear_solid", "ActuatorParams", "LoadCellParams", "FilmParams", "BenchParams", "Profile", "BenchRecord",
    "chirp_schedule", "PAPER_PROFILES", "HOLD_PROFILE", "PROFILE_LABELS",
    "profile_signal", "run_profile", "run_profiles", "lowpass_fft", "condition", "load_csv",
    "hold_creep", "default_bench_device", "describe_bench", "CSV_COLUMNS", "seed_sequence",
]
