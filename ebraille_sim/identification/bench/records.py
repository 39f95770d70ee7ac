"""Bench records: the conditioned recording, its conditioning, real recordings from CSV, hold creep.

A record holds the voltage and load-cell force sampled at the recording rate, detrended by
the preload offsets and low-passed in the FFT (:func:`condition`), with the raw channels
kept.  :func:`load_csv` conditions a real bench's recording the same way; :func:`hold_creep`
reads the film's resistance creep from a hold record.
"""
from __future__ import annotations

import csv
import math
import os
import pathlib
from dataclasses import dataclass

import numpy as np

from ebraille_sim.identification.bench.instruments import BenchParams
from ebraille_sim.identification.bench.protocol import HOLD_PROFILE

__all__ = ["BenchRecord", "lowpass_fft", "condition", "hold_creep", "CSV_COLUMNS", "load_csv"]


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
