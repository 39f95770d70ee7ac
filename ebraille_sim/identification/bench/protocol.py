"""The bench protocol: the paper's loading profiles and the target force each one follows.

:data:`PAPER_PROFILES` are the identification chirp and the validation squares, triangles and
staircase, :data:`HOLD_PROFILE` the 30-minute creep hold; :func:`profile_signal` gives a
profile's target force and excitation frequency over time.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ebraille_sim.base.validation import check_number
from ebraille_sim.identification.bench.instruments import BenchParams

__all__ = ["Profile", "chirp_schedule", "PAPER_PROFILES", "HOLD_PROFILE", "PROFILE_LABELS", "profile_signal"]

_SHAPES = ("chirp", "sine", "square", "triangle", "step", "hold")


@dataclass(frozen=True)
class Profile:
    """One loading profile.

    Parameters
    ----------
    name : str
        Key used in tables and file names.
    shape : {"chirp", "sine", "square", "triangle", "step", "hold"}
        Waveform between the bench's ``min_force_n`` and ``max_force_n``.
    frequency_hz : float
        Fundamental (sine, square, triangle), step rate (step); unused for the chirp and
        the hold (0).
    periods : float
        Number of periods (sine, square, triangle) or of steps (step).
    hold_s : float
        Hold duration (hold only), s.
    hold_fraction : float
        Hold force as a fraction of the span above the preload (hold only).
    settle_s : float or None
        Overrides the bench's ``settle_s`` (the hold starts on a fresh sensor: 0).
    chirp_dwell_s : float or None
        Chirp only: time spent on each frequency step, s, rounded up to whole cycles (None:
        two cycles or one second, whichever is longer; see :func:`chirp_schedule`).
    """
    name: str
    shape: str
    frequency_hz: float = 0.0
    periods: float = 0.0
    hold_s: float = 0.0
    hold_fraction: float = 0.5
    settle_s: float | None = None
    chirp_dwell_s: float | None = None

    def __post_init__(self):
        if self.shape not in _SHAPES:
            raise ValueError(f"unknown profile shape {self.shape!r}; allowed: {', '.join(_SHAPES)}")
        for name in ("frequency_hz", "periods", "hold_s", "hold_fraction"):
            check_number(f"Profile.{name}", getattr(self, name), lo=0.0)
        if self.shape in ("sine", "square", "triangle", "step") and not (self.frequency_hz > 0 and self.periods > 0):
            raise ValueError(f"a {self.shape} profile needs frequency_hz > 0 and periods > 0")
        if self.shape == "hold" and not self.hold_s > 0:
            raise ValueError("a hold profile needs hold_s > 0")
        if self.chirp_dwell_s is not None:
            if self.shape != "chirp":
                raise ValueError(f"chirp_dwell_s applies to a chirp profile only, not a {self.shape}")
            check_number("Profile.chirp_dwell_s", self.chirp_dwell_s, lo=0.0, hi=600.0, lo_open=True)

    @property
    def duration_s(self) -> float:
        """Duration of the excitation (without baseline and tail), s."""
        if self.shape == "chirp":
            return float(np.sum(chirp_schedule(self.chirp_dwell_s)[1]))
        if self.shape == "hold":
            return self.hold_s
        return self.periods / self.frequency_hz


def chirp_schedule(dwell_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and dwell times (s) of the stepped up-chirp.

    0.2-0.9 Hz in 0.1 Hz steps, then 1-20 Hz in 1 Hz steps ([R] seed paper).  By default
    each step lasts two cycles or one second, whichever is longer ([E] the paper does not
    give the dwell); with ``dwell_s`` each lasts the whole number of cycles that first
    reaches ``dwell_s`` (at least one cycle).  Every step holds whole cycles, so the phase
    is continuous.
    """
    freqs = np.concatenate([np.round(np.arange(2, 10) * 0.1, 10), np.arange(1.0, 21.0)])
    if dwell_s is None:
        return freqs, np.maximum(2.0 / freqs, 1.0)
    dwell_s = check_number("dwell_s", dwell_s, lo=0.0, hi=600.0, lo_open=True)
    cycles = np.maximum(np.ceil(dwell_s * freqs - 1e-9), 1.0)
    return freqs, cycles / freqs


PAPER_PROFILES: dict[str, Profile] = {
    "chirp": Profile("chirp", "chirp"),
    "square_0.2hz": Profile("square_0.2hz", "square", 0.2, 6),
    "square_0.1hz": Profile("square_0.1hz", "square", 0.1, 3),
    "step_0.1hz": Profile("step_0.1hz", "step", 0.1, 6),
    "triangle_0.25hz": Profile("triangle_0.25hz", "triangle", 0.25, 8),
    "triangle_0.1hz": Profile("triangle_0.1hz", "triangle", 0.1, 3),
}
"""The paper's identification (chirp) and validation profiles, in the order of its tables.
Periods: [E] about 30 s per validation profile; the staircase climbs in three steps of 10 s
to the maximum and returns in three."""

HOLD_PROFILE = Profile("hold_30min", "hold", hold_s=1800.0, hold_fraction=0.5, settle_s=0.0)
"""[R] seed paper: static displacement held about 30 minutes (creep).  Hold force mid-span [E]."""

PROFILE_LABELS = {
    "chirp": "Chirp (0.2-20 Hz)", "square_0.2hz": "Square (0.20 Hz)", "square_0.1hz": "Square (0.10 Hz)",
    "step_0.1hz": "Step (0.1 Hz)", "triangle_0.25hz": "Triangle (0.25 Hz)", "triangle_0.1hz": "Triangle (0.1 Hz)",
    "hold_30min": "Static hold (30 min)",
}
"""Row labels of the paper's tables."""


def profile_signal(profile: Profile, t_s: np.ndarray, bench: BenchParams) -> tuple[np.ndarray, np.ndarray]:
    """Target force and excitation frequency of a profile.

    Parameters
    ----------
    profile : Profile
    t_s : ndarray, shape (n,)
        Time from the start of the excitation, s (``0 <= t < profile.duration_s``).
    bench : BenchParams
        Gives the force span ``min_force_n``-``max_force_n``.

    Returns
    -------
    force_n : ndarray, shape (n,)
        Target force, N, within ``[min_force_n, max_force_n]``; the chirp, sine, triangle
        and hold start at ``min_force_n`` (the preload) and rise smoothly, the square and
        the staircase step up at ``t = 0``.
    excitation_hz : ndarray, shape (n,)
        Excitation frequency, Hz: the displacement command is the target force divided by
        the film's storage stiffness at this frequency (the hold: its ramp, 0.5/ramp_s).
    """
    t = np.asarray(t_s, dtype=float)
    lo, hi = bench.min_force_n, bench.max_force_n
    span = hi - lo
    f0 = profile.frequency_hz
    if profile.shape == "chirp":
        freqs, dwell = chirp_schedule(profile.chirp_dwell_s)
        edges = np.concatenate([[0.0], np.cumsum(dwell)])
        idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, freqs.size - 1)
        # phase from the start of each step: whole cycles per step keep it continuous
        phase = 2.0 * np.pi * freqs[idx] * (t - edges[idx])
        return lo + span * 0.5 * (1.0 - np.cos(phase)), freqs[idx]
    exc = np.full_like(t, f0)
    if profile.shape == "sine":
        return lo + span * 0.5 * (1.0 - np.cos(2.0 * np.pi * f0 * t)), exc
    if profile.shape == "square":
        frac = np.mod(t * f0, 1.0)
        return np.where(frac < 0.5, hi, lo), exc
    if profile.shape == "triangle":
        frac = np.mod(t * f0, 1.0)
        return lo + span * (1.0 - np.abs(2.0 * frac - 1.0)), exc
    if profile.shape == "step":
        n = int(round(profile.periods))
        up = (n + 1) // 2
        levels = [min(k, up) if k <= up else 2 * up - k for k in range(1, n + 1)]
        levels = np.asarray(levels, dtype=float) / up
        k = np.clip(np.floor(t * f0).astype(int), 0, n - 1)
        return lo + span * levels[k], exc
    # hold: the half-cosine ramp is half a cycle at 0.5/ramp_s
    ramp = np.clip(t / bench.ramp_s, 0.0, 1.0)
    return (lo + span * profile.hold_fraction * 0.5 * (1.0 - np.cos(np.pi * ramp)),
            np.full_like(t, 0.5 / bench.ramp_s))
