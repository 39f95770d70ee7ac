r"""Learning the per-character press: a repetitive correction of the reference in refresh reading.

In refresh reading (``[reading] mode = "refresh"``) the display leaves the skin at every
character boundary and presses again: the setpoint steps from the lift force up to the
reading force once per character, and every dwell repeats the same press, hold and release.
A loop on the force estimate meets each of those presses with the same handicap.  The
estimate arrives about 10 ms after the force (on the 1 kHz estimator path: the anti-alias
filter, the hysteresis compensation's running median, the Wiener model's lag), so after the
press the loop answers a force that has already moved: the pulp relaxes at a standing board
(its fast relaxation branch, milliseconds) while the estimate still shows the press's peak, and
the loop lets the force sag through the hold; or, on a stiff pulp, the press overshoots.  The
error is nearly the same in every dwell, and the controller knows when each dwell starts (the
setpoint's rise), so it can learn it.

:class:`RefreshLearner` is an iterative learning controller in series with the loop (it shapes
the reference the loop tracks, not the command, so the loop's own sensitivity keeps the
learning stable): with ``k`` the control samples since the setpoint's last rise and ``e_j`` the
error ``r - y`` of the estimate in dwell ``j``, the reference offset for the next dwell is

    c_{j+1}[k] = clip( Q( c_j[k] + gamma e_j[k + l] ),  +- limit * r_high )

* ``l`` (``lead_s``, 10 ms) is the lead: the error the estimate shows at ``k + l`` was caused
  about ``l`` earlier, so it is corrected there (the sensor chain's delay, docs/benchmark.md);
* ``Q`` is a centred moving average of half-width ``smoothing_s`` (25 ms, window 51 samples at
  1 kHz): the learning keeps the slow shape of the error (the sag through the hold) and leaves
  what rings faster to the loop and the hold damping: a learned correction at the loop's own
  ring frequency, where the closed loop's phase turns fast, was measured to grow instead of
  converge;
* only the error from ``after_s`` (28 ms) after the rise on, while the setpoint is at its high
  level, is learned: the press itself is limited by the drive's speed, and learning its error
  (the estimate far below a setpoint it cannot reach yet) drives the correction to its limit
  and the next press into an overshoot;
* the correction is bounded by ``limit_fraction`` of the high level (0.15).

A dwell counts as a refresh dwell when the setpoint rises by more than ``edge_fraction`` of its
new value, and the learner switches on once two successive dwells have the same length (to two
control samples) and the same low and high levels (to 2 % of the high one).  It switches off,
and forgets, when a dwell is longer than ``max_period_s`` or the pattern changes before it was
on.  Anything else (a constant setpoint, setpoint steps seconds apart) never switches it on, and
the loop is then exactly the loop without it.

The numbers were chosen on the training population of studies/benchmark/make_dob_tuning.py
(``--refresh-learning``) with ``pid_dob``; studies/benchmark/NOTES.md has the study.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ebraille_sim.base.validation import check_finite, check_number

__all__ = ["RefreshLearning", "RefreshLearner", "learn_dwell"]

PERIOD_TOLERANCE_SAMPLES = 2
"""Two dwells are the same length if they differ by at most this many control samples."""
LEVEL_TOLERANCE_FRACTION = 0.02
"""Two dwells have the same levels if both differ by at most this fraction of the high level."""


@dataclass(frozen=True)
class RefreshLearning:
    """Settings of :class:`RefreshLearner` (module docstring).

    Parameters
    ----------
    gain : float
        ``gamma``, the share of a dwell's error added to the next dwell's reference; in [0, 1]
        (0 learns nothing: ``pid_dob`` then builds no learner).
    lead_s : float
        ``l``, s; in [0, 0.2].
    smoothing_s : float
        Half-width of the moving average ``Q``, s; in [0, 0.2].
    after_s : float
        Errors are learned from this long after the setpoint's rise on, s; in [0, 1].
    limit_fraction : float
        Bound on the correction as a fraction of the high setpoint; in (0, 1].
    edge_fraction : float
        A rise of the setpoint by more than this fraction of its new value starts a dwell; in (0, 1).
    max_period_s : float
        Longest dwell learned, s; in (0, 10].

    Raises
    ------
    ValueError
        One line naming the offending field.
    """
    gain: float
    lead_s: float = 0.010
    smoothing_s: float = 0.025
    after_s: float = 0.028
    limit_fraction: float = 0.15
    edge_fraction: float = 0.05
    max_period_s: float = 1.0

    def __post_init__(self) -> None:
        for name, lo, hi, lo_open, hi_open in (("gain", 0.0, 1.0, False, False),
                                               ("lead_s", 0.0, 0.2, False, False),
                                               ("smoothing_s", 0.0, 0.2, False, False),
                                               ("after_s", 0.0, 1.0, False, False),
                                               ("limit_fraction", 0.0, 1.0, True, False),
                                               ("edge_fraction", 0.0, 1.0, True, True),
                                               ("max_period_s", 0.0, 10.0, True, False)):
            object.__setattr__(self, name, check_number(name, getattr(self, name), lo, hi,
                                                        lo_open=lo_open, hi_open=hi_open))


def learn_dwell(table: np.ndarray, err: np.ndarray, n: int, gain: float, lead: int, half_width: int,
                limit: float) -> None:
    """One learning step in place: ``table[:n - lead] += gain * err[lead:n]``, then a centred
    moving average of ``2 half_width + 1`` samples over ``table[:n]`` (the ends padded with
    their own values), then the whole table clipped to ``+-limit``."""
    if n - lead > 0:
        table[:n - lead] += gain * err[lead:n]
    if half_width > 0 and n > 0:
        padded = np.pad(table[:n], half_width, mode="edge")
        table[:n] = np.convolve(padded, np.full(2 * half_width + 1, 1.0 / (2 * half_width + 1)), mode="valid")
    np.clip(table, -limit, limit, out=table)


class RefreshLearner:
    """The reference correction of refresh reading (module docstring).

    Call :meth:`reset` at the controller's reset and :meth:`step` once per control sample,
    before the loop; add its return value to the loop's reference.

    Attributes
    ----------
    active : bool
        True while the refresh pattern is recognised and the correction applied.
    table : ndarray
        The learned correction per control sample since the setpoint's rise, N (read only).
    """

    def __init__(self, settings: RefreshLearning) -> None:
        if not isinstance(settings, RefreshLearning):
            raise TypeError(f"settings must be a RefreshLearning, got {type(settings).__name__}")
        self.settings = settings
        self._dt = None
        self.table = np.zeros(0)
        self._err = np.zeros(0)
        self.reset(setpoint_n=0.0)

    def reset(self, *, setpoint_n: float) -> None:
        """Forget everything learned; the next rise of the setpoint above ``setpoint_n`` starts a dwell."""
        self._r_prev = check_finite("setpoint_n", setpoint_n)
        self._k = -1
        self._period = None
        self._levels = None
        self.active = False
        self.table[:] = 0.0

    def _rate(self, dt_s: float) -> None:
        s = self.settings
        self._dt = dt_s
        self._n_max = max(1, int(round(s.max_period_s / dt_s)))
        self._lead = int(round(s.lead_s / dt_s))
        self._half = int(round(s.smoothing_s / dt_s))
        self._after = int(round(s.after_s / dt_s))
        self.table = np.zeros(self._n_max)
        self._err = np.zeros(self._n_max)
        self._k, self._period, self._levels, self.active = -1, None, None, False

    def _dwell_end(self, n: int, levels: tuple) -> None:
        lo, hi = levels
        same = (self._period is not None and abs(n - self._period) <= PERIOD_TOLERANCE_SAMPLES
                and abs(lo - self._levels[0]) < LEVEL_TOLERANCE_FRACTION * hi
                and abs(hi - self._levels[1]) < LEVEL_TOLERANCE_FRACTION * hi)
        if n <= self._n_max and (same or self.active):
            s = self.settings
            learn_dwell(self.table, self._err, n, s.gain, self._lead, self._half, s.limit_fraction * hi)
            self.active = True
        else:
            self.table[:] = 0.0
            self.active = False
        self._period, self._levels = n, levels

    def step(self, force_est_n: float, setpoint_n: float, dt_s: float) -> float:
        """Advance one control sample; return the reference correction to add to ``setpoint_n``, N
        (0 while the pattern is not recognised).  The arguments are the controller's, already
        checked finite (``dt_s`` > 0)."""
        y, r = force_est_n, setpoint_n
        if self._dt is None or not math.isclose(dt_s, self._dt, rel_tol=1e-9):
            self._rate(dt_s)
        rp = self._r_prev
        if r - rp > self.settings.edge_fraction * r:
            if self._k >= 0:
                self._dwell_end(self._k + 1, (rp, r))
            else:
                self._period, self._levels = None, (rp, r)
            self._k = 0
        elif self._k >= 0:
            self._k += 1
            if self._k >= self._n_max:
                self._k, self.active = -1, False
                self.table[:] = 0.0
        self._r_prev = r
        k = self._k
        if k < 0:
            return 0.0
        self._err[k] = (r - y) if (r >= self._levels[1] - 1e-9 and k >= self._after) else 0.0
        return float(self.table[k]) if self.active else 0.0
