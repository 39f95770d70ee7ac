"""Reading schedules: when each Braille cell is shown on the display.

Rate convention
---------------
Reading rate is given in words per minute (wpm) using the standard-word
convention of typing-rate measurement: one "word" is five characters, counted
as displayed Braille cells. Every cell counts once: a letter, a digit, a
punctuation cell, a composition sign (capital, number or letter sign) and the
empty cell of a space or a newline. Signs of several cells (the dash, the
ellipsis, ``%``) count as that many cells. The mean dwell per cell is
therefore::

    mean_dwell_s = 60 / (5 * wpm)

which gives 0.2 s per cell at 60 wpm, 0.1 s at 120 wpm, 75 ms at 160 wpm and
60 ms at 200 wpm (1000 cells per minute). The median braille reader reads
about 124 wpm and fast readers reach about 200 wpm (Legge et al. 1999, 44
readers); the shipped scenarios read at 60, 90, 120, 160 and 200 wpm. Any
finite rate in (0, 1000] (:data:`MAX_WPM`) is accepted.

A schedule shows cell ``k`` during the half-open interval
``[start_s[k], start_s[k] + dwell_s[k])``. Cells follow one another without
gaps, so the sum of the dwells equals the reading time
``t_end_s - t_start_s``. Optional pauses lengthen the dwell of space cells
(between words) and of line-end cells (from newlines in the text).

Examples
--------
>>> sched = build_schedule("ab c", wpm=60)
>>> sched.dwell_s.tolist()
[0.2, 0.2, 0.2, 0.2]
>>> int(sched.index_at(0.45))
2
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Sequence, Union

import numpy as np

from ebraille_sim.base.compiled import njit
from ebraille_sim.scenarios.braille import Cell, text_to_cells

__all__ = [
    "CELLS_PER_WORD",
    "MAX_WPM",
    "ReadingSchedule",
    "build_schedule",
    "mean_dwell_s",
    "realised_wpm",
]

CELLS_PER_WORD: int = 5
MAX_WPM: float = 1000.0


def _check_wpm(wpm: object) -> float:
    if type(wpm) is float and 0.0 < wpm <= MAX_WPM:
        return wpm                              # the common case, without the checks of numbers.Real
    if isinstance(wpm, bool) or not isinstance(wpm, numbers.Real):
        raise ValueError(f"wpm must be a positive finite number, got {wpm!r}")
    value = float(wpm)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"wpm must be a positive finite number, got {wpm!r}")
    if value > MAX_WPM:
        raise ValueError(f"wpm must be at most {MAX_WPM:g}, got {wpm!r}")
    return value


def _check_real(name: str, value: object, *, non_negative: bool) -> float:
    if type(value) is float and math.isfinite(value) and not (non_negative and value < 0.0):
        return value                            # the common case, without the checks of numbers.Real
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if non_negative and out < 0.0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return out


def mean_dwell_s(wpm: float) -> float:
    """Mean display time per cell for a reading rate.

    Parameters
    ----------
    wpm : float
        Reading rate in words per minute (one word = 5 cells), in (0, 1000].

    Returns
    -------
    float
        Mean dwell per cell in seconds, ``60 / (5 * wpm)``.

    Raises
    ------
    ValueError
        If `wpm` is not a finite number in (0, 1000].

    Examples
    --------
    >>> mean_dwell_s(120)
    0.1
    >>> round(mean_dwell_s(200), 9)
    0.06
    """
    return 60.0 / (CELLS_PER_WORD * _check_wpm(wpm))


@dataclass(frozen=True, eq=False)
class ReadingSchedule:
    """Timing of a sequence of Braille cells on the display.

    Build instances with :func:`build_schedule`.

    Parameters
    ----------
    cells : list of Cell
        Cells in reading order.
    start_s : numpy.ndarray
        Shape (n,); time in seconds at which each cell appears. Read-only.
    dwell_s : numpy.ndarray
        Shape (n,); time in seconds each cell stays on the display,
        pauses included. Read-only.
    wpm : float
        Nominal reading rate in words per minute (one word = 5 cells).
    t_end_s : float
        Time in seconds at which the last cell leaves the display. For an
        empty schedule this equals the requested start time.

    Examples
    --------
    >>> sched = build_schedule("hi", wpm=120, start_s=1.0)
    >>> sched.start_s.tolist(), round(sched.t_end_s, 9)
    ([1.0, 1.1], 1.2)
    """

    cells: list[Cell]
    start_s: np.ndarray
    dwell_s: np.ndarray
    wpm: float
    t_end_s: float

    def __post_init__(self) -> None:
        n = len(self.cells)
        if self.start_s.shape != (n,) or self.dwell_s.shape != (n,):
            raise ValueError(
                f"start_s and dwell_s must have shape ({n},), got "
                f"{self.start_s.shape} and {self.dwell_s.shape}"
            )

    def __len__(self) -> int:
        return len(self.cells)

    @property
    def t_start_s(self) -> float:
        """Time in seconds at which the first cell appears (``t_end_s`` if empty)."""
        return float(self.start_s[0]) if len(self.cells) else float(self.t_end_s)

    @property
    def duration_s(self) -> float:
        """Reading time in seconds, ``t_end_s - t_start_s``."""
        return float(self.t_end_s) - self.t_start_s

    def boundaries_s(self) -> np.ndarray:
        """Cell start times in seconds.

        Returns
        -------
        numpy.ndarray
            Copy of `start_s`, shape (n,).

        Examples
        --------
        >>> build_schedule("ab", wpm=60).boundaries_s().tolist()
        [0.0, 0.2]
        """
        return self.start_s.copy()

    def index_at(self, t: Union[float, np.ndarray]) -> Union[int, np.ndarray]:
        """Index of the cell on the display at time(s) `t`.

        Parameters
        ----------
        t : float or array_like
            Time(s) in seconds.

        Returns
        -------
        int or numpy.ndarray
            Cell index ``k`` with ``start_s[k] <= t < start_s[k] + dwell_s[k]``;
            -1 for ``t < t_start_s``, ``t >= t_end_s`` or NaN. A scalar input
            gives an ``int``; an array input gives an integer array of the
            same shape. A time equal to a boundary belongs to the cell that
            starts there.

        Examples
        --------
        >>> sched = build_schedule("abc", wpm=12)
        >>> sched.index_at(np.array([-0.5, 0.0, 1.0, 2.5, 3.0])).tolist()
        [-1, 0, 1, 2, -1]
        """
        t_arr = np.asarray(t, dtype=float)
        if len(self.cells) == 0:
            idx = np.full(t_arr.shape, -1, dtype=np.int64)
        elif t_arr.ndim == 1 and t_arr.flags.c_contiguous:
            idx = np.empty(t_arr.shape[0], dtype=np.int64)
            _cell_indices(self.start_s, float(self.t_end_s), t_arr, idx)
        else:
            idx = np.searchsorted(self.start_s, t_arr, side="right") - 1
            inside = (t_arr >= self.start_s[0]) & (t_arr < self.t_end_s)
            idx = np.where(inside, idx, -1).astype(np.int64)
        if np.ndim(t) == 0:
            return int(idx)
        return idx


@njit(cache=True)
def _cell_indices(starts, t_end_s, t, out):
    """:meth:`ReadingSchedule.index_at` of the 1-D times ``t`` into ``out`` in one compiled pass:
    ``-1`` outside ``[starts[0], t_end_s)`` (NaN included), else the last ``k`` with
    ``starts[k] <= t`` (``numpy.searchsorted(starts, t, side="right") - 1``).  The cell of the
    previous time and the one after it are tried first (``starts[k] <= t < starts[k + 1]``
    names the last such ``k``), then a bisection: a run's times rise, and most of them stay on
    the cell of the time before."""
    n = starts.shape[0]
    t0 = starts[0]
    k = 0
    for i in range(t.shape[0]):
        x = t[i]
        if x >= t0 and x < t_end_s:
            if starts[k] <= x and (k + 1 == n or x < starts[k + 1]):
                pass
            elif k + 1 < n and starts[k + 1] <= x and (k + 2 == n or x < starts[k + 2]):
                k += 1
            else:
                lo, hi = 0, n
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if starts[mid] <= x:
                        lo = mid + 1
                    else:
                        hi = mid
                k = lo - 1
            out[i] = k
        else:
            out[i] = -1


def build_schedule(
    text_or_cells: Union[str, Sequence[Cell]],
    wpm: float,
    *,
    start_s: float = 0.0,
    jitter_fraction: float = 0.0,
    word_pause_s: float = 0.0,
    line_pause_s: float = 0.0,
    rng: np.random.Generator | None = None,
) -> ReadingSchedule:
    """Assign a display interval to every Braille cell.

    Parameters
    ----------
    text_or_cells : str or sequence of Cell
        Text (transcribed with :func:`ebraille_sim.scenarios.braille.text_to_cells`)
        or cells already transcribed.
    wpm : float
        Nominal reading rate in words per minute, one word being 5 cells
        (spaces and signs included). Must be finite and in (0, 1000];
        about 124 wpm is the median braille reader, 200 wpm a fast one.
    start_s : float, optional
        Time in seconds at which the first cell appears. Default 0.
    jitter_fraction : float, optional
        Relative spread of the per-cell dwell. Each base dwell is
        ``mean * (1 + jitter_fraction * z)`` with ``z ~ N(0, 1)`` drawn from
        `rng`, clipped to ``[0.5, 1.5] * mean``. Default 0 (no jitter).
    word_pause_s : float, optional
        Extra time in seconds added to the dwell of each space cell that is
        not a line end. Default 0.
    line_pause_s : float, optional
        Extra time in seconds added to the dwell of each line-end cell
        (a newline), in place of `word_pause_s`. Default 0.
    rng : numpy.random.Generator, optional
        Random source for the jitter; required when ``jitter_fraction > 0``
        and unused otherwise.

    Returns
    -------
    ReadingSchedule
        Contiguous schedule; ``t_end_s = start_s + sum(dwell_s)``.

    Raises
    ------
    ValueError
        For an invalid `wpm`, a negative or non-finite jitter or pause, a
        non-finite `start_s`, a missing `rng` when jitter is requested, or
        text that cannot be transcribed.

    Examples
    --------
    >>> sched = build_schedule("a b", wpm=60, word_pause_s=0.3)
    >>> np.round(sched.dwell_s, 3).tolist()
    [0.2, 0.5, 0.2]
    >>> rng = np.random.default_rng(0)
    >>> len(build_schedule("abc", 90, jitter_fraction=0.1, rng=rng))
    3
    """
    wpm_value = _check_wpm(wpm)
    t0 = _check_real("start_s", start_s, non_negative=False)
    jitter = _check_real("jitter_fraction", jitter_fraction, non_negative=True)
    word_pause = _check_real("word_pause_s", word_pause_s, non_negative=True)
    line_pause = _check_real("line_pause_s", line_pause_s, non_negative=True)
    if jitter > 0.0:
        if rng is None:
            raise ValueError("rng (a numpy.random.Generator) is required when jitter_fraction > 0")
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")

    if isinstance(text_or_cells, str):
        cells = text_to_cells(text_or_cells)
    else:
        cells = list(text_or_cells)
        for k, cell in enumerate(cells):
            if not isinstance(cell, Cell):
                raise ValueError(f"item {k} is not a Cell, got {type(cell).__name__}")

    n = len(cells)
    mean = 60.0 / (CELLS_PER_WORD * wpm_value)
    dwell = np.full(n, mean, dtype=float)
    if jitter > 0.0 and n > 0:
        z = rng.standard_normal(n)
        dwell = np.clip(mean * (1.0 + jitter * z), 0.5 * mean, 1.5 * mean)

    if word_pause or line_pause:               # (without pauses every dwell stays as it is)
        line_end = np.fromiter((c.line_end for c in cells), dtype=bool, count=n)
        space = np.fromiter((c.kind == "space" for c in cells), dtype=bool, count=n)
        dwell = dwell + np.where(line_end, line_pause, np.where(space, word_pause, 0.0))

    ends = t0 + np.cumsum(dwell)
    starts = np.empty(n, dtype=float)
    if n:
        starts[0] = t0
        starts[1:] = ends[:-1]
    t_end = float(ends[-1]) if n else t0

    starts.setflags(write=False)
    dwell.setflags(write=False)
    return ReadingSchedule(
        cells=cells, start_s=starts, dwell_s=dwell, wpm=wpm_value, t_end_s=t_end
    )


def realised_wpm(schedule: ReadingSchedule) -> float:
    """Effective reading rate of a schedule, pauses and jitter included.

    Parameters
    ----------
    schedule : ReadingSchedule
        Schedule to measure.

    Returns
    -------
    float
        ``(len(schedule) / 5) / (duration_s / 60)`` in words per minute.

    Raises
    ------
    ValueError
        If the schedule is empty (no reading time).

    Examples
    --------
    >>> round(realised_wpm(build_schedule("hello", 60)), 6)
    60.0
    >>> round(realised_wpm(build_schedule("a b", 60, word_pause_s=0.4)), 6)
    36.0
    """
    duration = schedule.duration_s
    if len(schedule) == 0 or duration <= 0.0:
        raise ValueError("realised_wpm needs a schedule with at least one cell")
    return (len(schedule) / CELLS_PER_WORD) / (duration / 60.0)
