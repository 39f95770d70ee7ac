"""The bench simulated: servo, film, the FSR's own forward model and the load cell, profile by profile.

:func:`run_profile` drives one profile of :mod:`~ebraille_sim.identification.bench.protocol`
through the instruments of :mod:`~ebraille_sim.identification.bench.instruments` and the
project's FSR chain (:func:`ebraille_sim.plant.kernel.advance_sensor_only`), and returns the
conditioned :class:`~ebraille_sim.identification.bench.records.BenchRecord`.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.interpolate
import scipy.signal

from ebraille_sim.base.compiled import njit
from ebraille_sim.estimation.paper_models import paper_model
from ebraille_sim.identification.bench.instruments import ActuatorParams, BenchParams
from ebraille_sim.identification.bench.protocol import Profile, profile_signal
from ebraille_sim.identification.bench.records import BenchRecord, condition
from ebraille_sim.physics.noise import seed_from
from ebraille_sim.plant.kernel import advance_sensor_only
from ebraille_sim.plant.layout import N_INPUT, S, U
from ebraille_sim.plant.lumped import initial_state, pack_params

__all__ = ["run_profile", "run_profiles", "seed_sequence"]


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


def seed_sequence(seed) -> np.random.SeedSequence:
    """The bench's master seed as a ``SeedSequence`` (one given is used as it is).

    Raises
    ------
    ValueError
        If ``seed`` is neither a non-negative int nor a ``SeedSequence``.
    """
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
    ss_fsr, ss_cell = seed_sequence(seed).spawn(2)

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
    children = seed_sequence(seed).spawn(len(profiles))
    return {pr.name: run_profile(pr, bench, ch) for pr, ch in zip(profiles, children)}
