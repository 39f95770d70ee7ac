"""Contact-force tracking metrics, evaluated on the TRUE force the finger feels.

All names carry SI units.  The reading window is ``[reading_start_s, t_end)`` (after the
onset); the onset window is ``[0, reading_start_s)``.

=========================  ============================================================
metric                     definition
=========================  ============================================================
force_rmse_n               RMS of (true - setpoint) over the reading window
force_mae_n                mean |true - setpoint| over the reading window
in_band_fraction           fraction of reading-window samples with |true - sp| <= band*sp
char_in_band_fraction      fraction of displayed characters during whose dwell the force
                           was in band for at least 90 % of the samples
peak_force_n               largest true force over the whole run
contact_loss_count         times the true force fell below the contact threshold
                           (0.02 N) during the reading window, after being above it
onset_overshoot_fraction   max(0, peak true force in the onset window / sp - 1)
settling_time_s            from first contact to the start of the first 0.2 s stretch
                           entirely in band (None if it never settles)
estimate_rmse_n            RMS of (estimated - true) over the reading window
energy_j                   net electrical energy delivered to the motor, int V i dt
real_time_factor           simulated time / wall-clock time of the loop
characters                 Braille cells displayed
wpm                        realised reading rate (5 cells per word)
=========================  ============================================================
"""
from __future__ import annotations

import math

import numpy as np

CONTACT_THRESHOLD_N = 0.02
CHAR_IN_BAND_REQUIRED = 0.9
SETTLE_HOLD_S = 0.2

METRIC_NAMES = [
    "force_rmse_n", "force_mae_n", "in_band_fraction", "char_in_band_fraction", "peak_force_n",
    "contact_loss_count", "onset_overshoot_fraction", "settling_time_s", "estimate_rmse_n", "energy_j",
    "real_time_factor", "characters", "wpm",
]


IN_BAND_CHUNK = 1 << 16
"""Samples per chunk of :func:`in_band` on long 1-D runs (its temporaries stay at that size)."""


def in_band(force_n, setpoint_n, band_fraction):
    """Boolean array: |force - setpoint| <= band_fraction * setpoint."""
    f = np.asarray(force_n)
    sp = np.asarray(setpoint_n)
    if f.ndim == 1 and sp.shape == f.shape and f.size > IN_BAND_CHUNK:
        out = np.empty(f.shape, dtype=bool)
        for a in range(0, f.size, IN_BAND_CHUNK):
            out[a:a + IN_BAND_CHUNK] = in_band(f[a:a + IN_BAND_CHUNK], sp[a:a + IN_BAND_CHUNK], band_fraction)
        return out
    d = np.asarray(f - sp)
    d = np.abs(d, out=d) if d.ndim else np.abs(d)
    return d <= band_fraction * sp


def settling_time(t_s, force_n, setpoint_n, band_fraction, hold_s=SETTLE_HOLD_S, ok=None):
    """Time from first contact to the start of the first ``hold_s`` stretch in band.

    Returns None when there is no contact or the force never stays in band for ``hold_s``.
    ``ok``: :func:`in_band` of these arguments when the caller has it already.
    """
    t_s = np.asarray(t_s)
    touch = np.asarray(force_n) > CONTACT_THRESHOLD_N
    if not touch.any():
        return None
    start = int(np.argmax(touch))                  # the first contact
    del touch
    if ok is None:
        ok = in_band(force_n, setpoint_n, band_fraction)
    dt = t_s[1] - t_s[0] if len(t_s) > 1 else 0.0
    need = max(1, int(round(hold_s / dt))) if dt > 0 else 1
    # the first window of ``need`` samples entirely in band, from the first contact on:
    # in-band counts over every window by a cumulative sum (linear in the samples)
    # 32-bit counts (exact below 2**31 samples) halve the memory of a long run's pass
    wide = np.int64 if len(ok) >= 2**31 else np.int32
    counts = np.zeros(len(ok) - start + 1, dtype=wide)
    np.cumsum(ok[start:], dtype=wide, out=counts[1:])
    if counts.size <= need:
        return None
    full = counts[need:] - counts[:-need] == need
    del counts
    if not full.any():
        return None
    return float(t_s[start + int(np.argmax(full))] - t_s[start])       # the first full window


def compute_metrics(trace: dict, reading_start_s: float, band_fraction: float, schedule=None,
                    wall_time_s: float | None = None) -> dict:
    """Metrics of a run from its trace (named arrays sampled at the control rate).

    Parameters
    ----------
    trace : dict of ndarray
        Needs ``t_s``, ``setpoint_n``, ``force_true_n``, ``force_est_n``, ``energy_j`` and
        ``char_index`` (the displayed cell, -1 when none).
    reading_start_s : float
        Start of the reading window, s.
    band_fraction : float
        Half-width of the tolerance band as a fraction of the setpoint.
    schedule : ReadingSchedule, optional
        For ``characters`` and ``wpm``.
    wall_time_s : float, optional
        Wall-clock time of the loop, for ``real_time_factor``.
    """
    t = np.asarray(trace["t_s"])
    f = np.asarray(trace["force_true_n"])
    fe = np.asarray(trace["force_est_n"])
    sp = np.asarray(trace["setpoint_n"])
    ci = np.asarray(trace["char_index"])
    read = t >= reading_start_s
    onset = ~read
    ok = in_band(f, sp, band_fraction)
    m: dict = {}
    # the reading window of a run's trace (times in order) is its tail: a slice, not a copy
    i0 = read.size - int(np.count_nonzero(read))
    if read[i0:].all():
        read = slice(i0, None)
    if f[read].size:
        # one temporary per long run: |e| and then |e|**2 (the bits of e**2) in place
        err = np.subtract(f[read], sp[read])
        m["force_mae_n"] = float(np.mean(np.abs(err, out=err)))
        m["force_rmse_n"] = float(np.sqrt(np.mean(np.square(err, out=err))))
        del err
        in_read = ok[read]
        m["in_band_fraction"] = np.count_nonzero(in_read) / in_read.size     # np.mean's bits: a whole sum / n
        del in_read
        err = np.subtract(fe[read], f[read])
        m["estimate_rmse_n"] = float(np.sqrt(np.mean(np.square(err, out=err))))
        del err
        touching = f[read] > CONTACT_THRESHOLD_N
        m["contact_loss_count"] = int(np.count_nonzero(touching[:-1] & ~touching[1:]))
    else:
        m.update(force_rmse_n=None, force_mae_n=None, in_band_fraction=None, estimate_rmse_n=None,
                 contact_loss_count=0)
    # per displayed character: in-band samples / samples, counted with the samples that show
    # none (any negative index) in a first bin that is dropped
    bins = np.maximum(ci, -1)
    bins += 1
    n_all = np.bincount(bins)[1:] if bins.size else np.zeros(0, dtype=np.int64)
    chars = np.nonzero(n_all)[0]
    if chars.size:
        n_ok = np.bincount(bins, weights=ok, minlength=n_all.size + 1)[1:]
    del bins
    if chars.size:
        good = int(np.count_nonzero(n_ok[chars] / n_all[chars] >= CHAR_IN_BAND_REQUIRED))
        m["char_in_band_fraction"] = good / chars.size
    else:
        m["char_in_band_fraction"] = None
    m["peak_force_n"] = float(f.max()) if f.size else 0.0
    if onset.any():
        sp0 = sp[onset][-1]
        m["onset_overshoot_fraction"] = float(max(0.0, f[onset].max() / sp0 - 1.0))
        m["settling_time_s"] = settling_time(t, f, sp, band_fraction, ok=ok)
    else:
        m["onset_overshoot_fraction"] = None
        m["settling_time_s"] = None
    m["energy_j"] = float(trace["energy_j"][-1]) if len(t) else 0.0
    duration = float(t[-1] - t[0] + (t[1] - t[0])) if len(t) > 1 else 0.0
    m["real_time_factor"] = (duration / wall_time_s) if wall_time_s else None
    if schedule is not None and len(schedule):
        m["characters"] = int(chars.size)
        from ebraille_sim.scenarios.reading import realised_wpm
        m["wpm"] = float(realised_wpm(schedule))
    else:
        m["characters"] = int(chars.size)
        m["wpm"] = None
    for k, v in m.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise FloatingPointError(f"metric {k} is not finite ({v}); the simulation diverged")
    return {k: m[k] for k in METRIC_NAMES}


CRITERIA = {
    "onset_overshoot_max": ("onset_overshoot_fraction", "le"),
    "in_band_min": ("in_band_fraction", "ge"),
    "peak_force_max_n": ("peak_force_n", "le"),
}
"""Scenario ``[criteria]`` keys: the metric each bounds and the direction of the bound."""


def evaluate_criteria(criteria: dict, metrics: dict) -> dict:
    """Check a scenario's ``[criteria]`` against its metrics.

    Returns ``{key: {"metric", "limit", "value", "passed"}}``; a metric that is None fails.
    """
    out = {}
    for key, limit in criteria.items():
        metric, how = CRITERIA[key]
        v = metrics.get(metric)
        ok = v is not None and (v <= limit if how == "le" else v >= limit)
        out[key] = {"metric": metric, "limit": limit, "value": v, "passed": bool(ok)}
    return out
