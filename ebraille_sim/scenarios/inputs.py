"""Everything a closed-loop run needs before its first period, built from a scenario spec.

:func:`build_run_inputs` is the one place where a :class:`~ebraille_sim.scenarios.spec.ScenarioSpec`
and a seed become the reading schedule, the setpoint profile, the per-period plant input
arrays (finger position, driver supply, gravity, FSR temperature, faults, ...) and the
seed of the sensor noise.  The scenario runner (:func:`ebraille_sim.scenarios.runner.run_scenario`)
and the reinforcement-learning environment (:mod:`ebraille_sim.rl.env`, which draws a spec
per episode from :class:`ebraille_sim.scenarios.episodes.EpisodeDistribution`) both call
it, so a policy trains on the disturbance models it is evaluated on.

Seeds: the run's seed gives, in one compiled call (:func:`ebraille_sim.scenarios.draws.run_numbers`),
the sensor noise's seed and the generators of the reading schedule (dwell jitter) and of the
plant inputs (disturbance draws), each from its own stream of the seed's key.

Times: control period ``k`` (``k = 0 .. n - 1``) starts at ``t_k = (k + 1) dt - dt`` (the
runner's sample time minus one period, written so that the runner's historic arrays are
reproduced bit for bit); the setpoint is also given at ``t_n`` (the end of the run),
which the environment's last observation shows.

Examples
--------
>>> from ebraille_sim.scenarios.spec import parse_scenario
>>> spec = parse_scenario({"name": "x", "reading": {"text": "ab", "wpm": 120, "start_s": 0.5},
...                        "disturbances": {"tremor": {"rms_m": 10e-6}}}, source="inline")
>>> run = build_run_inputs(spec, seed=1)
>>> run.n_steps, run.t_s.shape, sorted(run.profiles)
(700, (701,), ['finger_pos_m'])
"""
from __future__ import annotations

import functools
import importlib
import math
import pathlib
from dataclasses import dataclass

import numpy as np

from ebraille_sim.plant.layout import N_INPUT, U
from ebraille_sim.scenarios.draws import generator_of, run_numbers
from ebraille_sim.scenarios.spec import DELEGATES, ScenarioError, ScenarioSpec

__all__ = ["RunInputs", "SCHEDULE_CELL_MARGIN", "MAX_RUN_BYTES", "BYTES_PER_CONTROL_SAMPLE", "MAX_CONTROL_SAMPLES",
           "MAX_SCHEDULE_CELLS", "base_input_row", "build_run_inputs", "build_schedule_for", "check_run_size",
           "input_profiles", "period_starts", "profile_table", "reading_text", "refresh_phases", "run_length", "setpoint_profile"]

MAX_RUN_BYTES = 2e9
"""Memory bound of one run's per-sample arrays, bytes (2 GB: a tenth of a 16-32 GB
workstation, so parallel sweeps fit)."""

BYTES_PER_CONTROL_SAMPLE = 8 * (14 + N_INPUT + 7)
"""Memory per control period of a run, bytes: float64 arrays of one value per period --
the runner's 10 trace columns, time, setpoint, cell index and character (14), one array
per plant input while the input profiles are built (``N_INPUT``) and about 7 temporaries of
the setpoint profile and the metrics.  Physics steps are not stored."""

MAX_CONTROL_SAMPLES = int(MAX_RUN_BYTES // BYTES_PER_CONTROL_SAMPLE)
"""Most control periods of one run (about 7.8 million: 3600 s at 2 kHz)."""

MAX_SCHEDULE_CELLS = 2_000_000
"""Most cells of a reading schedule (about 40 bytes each: start, dwell, flags and the
reference, 80 MB).  The scenario bounds (``duration_s <= 3600``, ``wpm <= 1000``) give at
most 480,000 cells; a long text read without ``duration_s`` can give more."""

SCHEDULE_CELL_MARGIN = 1.6
"""Cells transcribed per nominal dwell of a scenario with ``duration_s``, as a multiple.

A scenario that reads for ``duration_s`` repeats its text to ``ceil(1.6 (duration_s -
start_s) / mean_dwell) + 1`` cells.  Without jitter every dwell is at least the nominal
one (pauses only lengthen it), so a margin of 1 would fill the duration.  A jittered
dwell is ``mean (1 + j z)``, ``z ~ N(0, 1)``, clipped to ``[0.5, 1.5] mean``
(:func:`ebraille_sim.scenarios.reading.build_schedule`); its mean is the nominal dwell
and its standard deviation at most ``0.5 mean`` (``j <= 0.5``, the scenario bound).  The
``M = 1.6 N`` cells fall short of ``N`` nominal dwells only if their average dwell is
below ``1/1.6 = 0.625`` of nominal, ``0.375 / (0.5 / sqrt(M)) = 0.75 sqrt(M)`` standard
deviations below its mean: more than 3 for ``M >= 17``, i.e. any run longer than about
ten cells.  The bound without statistics (every dwell clipped to ``0.5 mean``) would be 2;
1.6 is what every shipped scenario's schedule was built with, so it stays."""


@dataclass(frozen=True, eq=False)
class RunInputs:
    """Everything drawn and computed for one run of a spec, before its first period.

    Attributes
    ----------
    spec : ScenarioSpec
    seed : int
        The run's master seed.
    sensor_seed : float
        Seed of the plant's counter-based ADC noise (52-bit integer as float).
    schedule : ReadingSchedule
    dt_s : float
        Control period, s.
    n_steps : int
        Control periods of the run (``duration_s``, or the end of the schedule).
    t_s : ndarray, shape (n_steps + 1,)
        Start time of period ``k`` at index ``k``; the last entry is the end of the run, s
        (computed when read: a run does not hold it).
    setpoint_n : ndarray, shape (n_steps + 1,)
        Force setpoint at ``t_s``, N.
    base_inputs : ndarray, shape (N_INPUT,)
        Constant plant inputs (:data:`ebraille_sim.plant.layout.INPUT_NAMES`): the device's
        gravity along the travel and driver supply, the finger at ``gap_m``, zero command.
    profiles : dict of str to ndarray
        Inputs that vary, each of shape ``(n_steps,)`` (value held over period ``k``),
        already combined with ``base_inputs`` (absolute values); the rows, in order, of one
        array of shape ``(len(profiles), n_steps)`` (:func:`profile_table`).
    """
    spec: ScenarioSpec
    seed: int
    sensor_seed: float
    schedule: object
    dt_s: float
    n_steps: int
    setpoint_n: np.ndarray
    base_inputs: np.ndarray
    profiles: dict

    @property
    def t_s(self) -> np.ndarray:
        return period_starts(self.n_steps + 1, self.dt_s)

    def input_at(self, name: str, k: int) -> float:
        """Plant input ``name`` during period ``k``."""
        arr = self.profiles.get(name)
        return float(self.base_inputs[U[name]] if arr is None else arr[k])

    def initial_inputs(self) -> np.ndarray:
        """The plant's input row for period 0 (``base_inputs`` with the varying inputs' first values)."""
        row = self.base_inputs.copy()
        for name, arr in self.profiles.items():
            row[U[name]] = arr[0]
        return row


def period_starts(n: int, dt_s: float) -> np.ndarray:
    """Start times ``(k + 1) dt - dt`` of periods ``k = 0 .. n - 1`` (s), computed in place in one array."""
    t = np.arange(1, n + 1, dtype=float)
    t *= dt_s
    t -= dt_s
    return t


def profile_table(profiles: dict, n: int) -> np.ndarray | None:
    """The array whose rows are the values of ``profiles`` in order (shape ``(len(profiles), n)``),
    when they are such rows (as :func:`build_run_inputs` packs them), else None."""
    arrs = list(profiles.values())
    base = arrs[0].base if arrs else None
    if not (isinstance(base, np.ndarray) and base.shape == (len(arrs), n) and base.dtype == np.float64
            and base.flags.c_contiguous):
        return None
    step = base.strides[0]
    start = base.ctypes.data
    if all(a.base is base and a.shape == (n,) and a.ctypes.data == start + j * step for j, a in enumerate(arrs)):
        return base
    return None


def reading_text(spec: ScenarioSpec) -> str:
    """The text a scenario reads (passage, inline text or file)."""
    r = spec.reading
    if r.text is not None:
        return r.text
    if r.file is not None:
        p = pathlib.Path(r.file)
        if not p.is_absolute():
            p = pathlib.Path(spec.base_dir) / p
        from ebraille_sim.base.files import read_text
        from ebraille_sim.scenarios.spec import MAX_READING_BYTES
        try:
            return read_text(p, "[reading] file", MAX_READING_BYTES)
        except (ValueError, FileNotFoundError) as exc:
            raise ScenarioError(f"{spec.source}: {exc}") from None
    try:
        return _passage(r.passage)
    except ValueError as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None


@functools.lru_cache(maxsize=64)
def _passage(name: str) -> str:
    """A shipped passage's text, read once per process (a sweep builds thousands of runs)."""
    from ebraille_sim.scenarios.passages import load_passage
    return load_passage(name)


@functools.lru_cache(maxsize=2048)
def _cells_of(text: str) -> tuple:
    """The cells of ``text`` (immutable, shared).  Cached per text: the env's episodes are
    excerpts that start at a word of a shipped passage, a few hundred texts per length."""
    from ebraille_sim.scenarios.braille import text_to_cells
    # the transcription the scenario baselines were recorded with (spaced hyphen, number
    # sign repeated after ':' and '-'); see ebraille_sim.scenarios.braille
    return tuple(text_to_cells(text))


def build_schedule_for(spec: ScenarioSpec, rng: np.random.Generator | None):
    """Reading schedule of a scenario, repeating the text to fill ``duration_s``.

    ``rng`` draws the dwell jitter (None: a schedule without jitter needs none).

    The number of cells is :data:`SCHEDULE_CELL_MARGIN` times the nominal count for the
    duration (see there).  Transcriptions are cached per text.
    """
    from ebraille_sim.scenarios.reading import build_schedule, mean_dwell_s
    r = spec.reading
    try:
        cells = list(_cells_of(reading_text(spec)))
    except ValueError as exc:
        raise ScenarioError(f"{spec.source}: {exc}") from None
    if not cells:
        raise ScenarioError(f"{spec.source}: the reading text is empty")
    mean = mean_dwell_s(r.wpm)
    if spec.duration_s is not None:
        check_run_size(spec, spec.duration_s)
        need = int(math.ceil((spec.duration_s - r.start_s) / mean * SCHEDULE_CELL_MARGIN)) + 1
        if min(need, r.max_characters or need) > MAX_SCHEDULE_CELLS:
            raise ScenarioError(f"{spec.source}: the reading schedule would hold {need} cells "
                                f"({spec.duration_s:g} s at {r.wpm:g} wpm, {SCHEDULE_CELL_MARGIN:g} x the "
                                f"nominal count), above the bound of {MAX_SCHEDULE_CELLS} cells")
        reps = max(1, int(math.ceil(need / len(cells))))
        cells = (cells * reps)[:max(need, 1)]
    if r.max_characters is not None:
        cells = cells[:r.max_characters]
    if len(cells) > MAX_SCHEDULE_CELLS:
        raise ScenarioError(f"{spec.source}: the reading text gives {len(cells)} cells, above the bound of "
                            f"{MAX_SCHEDULE_CELLS} cells of one schedule; set [reading] max_characters")
    if spec.duration_s is None:
        # the nominal end of the reading (jitter averages out): the exact end is checked by run_length
        pauses = sum(r.line_pause_s if c.line_end else (r.word_pause_s if c.kind == "space" else 0.0)
                     for c in cells) if (r.word_pause_s or r.line_pause_s) else 0.0
        t_end = r.start_s + len(cells) * mean + pauses
        check_run_size(spec, t_end, lambda: f"the reading of {len(cells)} cells at {r.wpm:g} wpm ends at {t_end:.4g} s")
    return build_schedule(cells, r.wpm, start_s=r.start_s, jitter_fraction=r.jitter_fraction,
                          word_pause_s=r.word_pause_s, line_pause_s=r.line_pause_s,
                          rng=rng if r.jitter_fraction > 0 else None)


def setpoint_profile(spec: ScenarioSpec, t_s: np.ndarray, schedule=None) -> np.ndarray:
    """Force setpoint at the times ``t_s`` (steps, optionally ramped over ``ramp_s``).

    In refresh mode (``[reading] mode = "refresh"``) the ``schedule`` is required and the
    setpoint drops to ``refresh_lift_force_n`` while each character is lifted or
    released (see :func:`refresh_phases`).
    """
    sp = _base_setpoint(spec, t_s)
    if spec.reading.mode == "refresh":
        if schedule is None:
            raise ValueError("setpoint_profile: refresh mode needs the reading schedule")
        pressed, _ = refresh_phases(spec, schedule, t_s)
        lift = np.minimum(spec.reading.refresh_lift_force_n, sp)
        sp = np.where(pressed, sp, lift)
    return sp


def refresh_phases(spec: ScenarioSpec, schedule, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-character refresh phases at the times ``t_s``.

    Each dwell ``[s, s + d)`` is split into lift ``[0, l)``, press ``[l, l + p)``, hold
    ``[l + p, 1 - r)`` and release ``[1 - r, 1)`` in units of ``d``, with ``l``, ``p``,
    ``r`` the ``refresh_*_fraction`` keys of ``[reading]``: the display leaves the skin
    (setpoint at the lift force) while the pattern changes at the character boundary,
    presses during ``p`` (the time allowed to reach the band) and holds.

    Returns
    -------
    pressed : ndarray of bool, shape t_s.shape
        True during press and hold, and outside the schedule.
    hold : ndarray of bool, shape t_s.shape
        True during the hold part of a dwell (the character's in-band window).
    """
    r = spec.reading
    k = np.asarray(schedule.index_at(t_s))
    inside = k >= 0
    kk = np.where(inside, k, 0)
    start = np.asarray(schedule.start_s)[kk] if len(schedule) else np.zeros_like(t_s)
    dwell = np.asarray(schedule.dwell_s)[kk] if len(schedule) else np.ones_like(t_s)
    u = (t_s - start) / dwell
    lo = r.refresh_lift_fraction
    hold_lo = lo + r.refresh_press_fraction
    hold_hi = 1.0 - r.refresh_release_fraction
    pressed = ~inside | ((u >= lo) & (u < hold_hi))
    hold = inside & (u >= hold_lo) & (u < hold_hi)
    return pressed, hold


def _base_setpoint(spec: ScenarioSpec, t_s: np.ndarray) -> np.ndarray:
    sp = np.full_like(t_s, spec.setpoint.force_n, dtype=float)
    prev = spec.setpoint.force_n
    ramp = spec.setpoint.ramp_s
    for t0, f in spec.setpoint.steps:
        if ramp > 0:
            frac = np.clip((t_s - t0) / ramp, 0.0, 1.0)
            sp = np.where(t_s >= t0, prev + (f - prev) * frac, sp)
        else:
            sp = np.where(t_s >= t0, f, sp)
        prev = f
    return sp


def base_input_row(device, gap_m: float) -> np.ndarray:
    """Constant plant inputs of a run: the rows :func:`ebraille_sim.plant.lumped.pack_devices`
    fills (gravity along the travel, driver supply), the finger at ``gap_m``, all else 0."""
    row = np.zeros(N_INPUT)
    row[U.gravity_along_m_per_s2] = -device.gravity_m_per_s2
    row[U.driver_supply_v] = device.driver_supply_v
    row[U.finger_pos_m] = gap_m
    return row


def input_profiles(spec: ScenarioSpec, t_s: np.ndarray, rng: np.random.Generator, base_inputs) -> dict:
    """Per-period plant inputs from the scenario's delegate sections, as arrays over ``t_s``.

    Each section's module returns ``{input_name: ("set" | "add", array)}``; "add" profiles
    are added to the constant input (e.g. finger motion around the gap).  Only inputs that
    vary are returned.

    Parameters
    ----------
    spec : ScenarioSpec
    t_s : ndarray, shape (n,)
        Start times of the control periods, s.
    rng : numpy.random.Generator
        The run's input generator.
    base_inputs : ndarray, shape (N_INPUT,), or a plant
        The constant inputs (:func:`base_input_row`); a plant's first input row is used
        when a plant is given.
    """
    row = base_inputs.inputs[0] if hasattr(base_inputs, "inputs") else np.asarray(base_inputs, dtype=float)
    # constants stay scalars: only the inputs a section drives become arrays, the rows of one
    # table in the order of their names, each filled as its section's array comes (and that
    # array dropped): a long run never holds its profiles twice
    values = row.tolist()
    base = {name: values[j] for name, j in U.items() if name != "command_v"}
    mods = [(key, section, importlib.import_module(DELEGATES[key])) for key, section in spec.sections.items()]
    mods = [(key, section, mod) for key, section, mod in mods if hasattr(mod, "build_inputs")]
    declared = sorted({name for key, section, mod in mods for name in mod.driven_inputs(section)})
    table = np.empty((len(declared), len(t_s)))
    rows = {name: table[j] for j, name in enumerate(declared)}
    touched = set()
    for key, section, mod in mods:
        try:
            built = mod.build_inputs(section, t_s, rng, spec.device, out=rows)
        except ScenarioError as exc:
            msg = str(exc)
            raise ScenarioError(msg if msg.startswith(f"{spec.source}:") else f"{spec.source}: {msg}") from None
        except ValueError as exc:
            raise ScenarioError(f"{spec.source}: [{key}] {exc}") from None
        for name in list(built):
            mode, arr = built.pop(name)
            if name not in base:
                raise ScenarioError(f"{spec.source}: [{key}] drives unknown input {name!r}")
            if name not in rows:
                raise ScenarioError(f"{spec.source}: [{key}] drives {name!r}, which its module's driven_inputs "
                                    f"does not name")
            r = rows[name]
            if mode == "add":
                np.add(r if name in touched else base[name], arr, out=r)
            elif arr is not r:                        # a module may have written its row itself
                r[...] = arr
            del arr
            touched.add(name)
    if len(touched) < len(declared):
        missing = sorted(set(declared) - touched)[0]
        raise ScenarioError(f"{spec.source}: a section's module names {missing!r} in driven_inputs but does "
                            f"not drive it")
    return rows


def check_run_size(spec: ScenarioSpec, t_end_s: float, why: str | None = None) -> int:
    """Number of control periods of a run ending at ``t_end_s``; raise if its arrays exceed the memory bound.

    Parameters
    ----------
    spec : ScenarioSpec
    t_end_s : float
        End of the run, s.
    why : str or callable, optional
        Where ``t_end_s`` comes from, for the message (default: ``duration_s``); a callable
        returns it, called only for the message.

    Raises
    ------
    ScenarioError
        One line with the duration, the control rate, the sample count and the bytes
        against :data:`MAX_RUN_BYTES`.
    """
    hz = spec.device.rates.control_rate_hz
    n = t_end_s * hz
    if not n <= MAX_CONTROL_SAMPLES:
        why = (why() if callable(why) else why) or f"duration_s = {t_end_s:g} s"
        raise ScenarioError(f"{spec.source}: {why}; at control_hz = {hz:g} that is {n:.4g} control periods x "
                            f"{BYTES_PER_CONTROL_SAMPLE} B of trace and input arrays = {n * BYTES_PER_CONTROL_SAMPLE / 1e9:.4g} GB, "
                            f"above the {MAX_RUN_BYTES / 1e9:g} GB bound of one run (at most {MAX_CONTROL_SAMPLES} "
                            f"periods, {MAX_CONTROL_SAMPLES / hz:.4g} s at this rate); shorten the run or lower control_hz")
    return int(n)


def run_length(spec: ScenarioSpec, schedule) -> tuple[float, int]:
    """Control period and number of periods of a run: ``duration_s`` or the schedule's end.

    Raises :class:`ScenarioError` for a run shorter than one period or one whose arrays
    exceed :data:`MAX_RUN_BYTES` (:func:`check_run_size`).
    """
    dt = 1.0 / spec.device.rates.control_rate_hz
    t_end = spec.duration_s if spec.duration_s is not None else schedule.t_end_s
    check_run_size(spec, t_end, None if spec.duration_s is not None else
                   lambda: f"the reading schedule of {len(schedule)} cells at {spec.reading.wpm:g} wpm ends at "
                           f"{t_end:.4g} s")
    n = int(round(t_end / dt))
    if n < 1:
        raise ScenarioError(f"{spec.source}: duration {t_end:g} s is shorter than one control period")
    return dt, n


def build_run_inputs(spec: ScenarioSpec, seed: int | None = None) -> RunInputs:
    """Reading schedule, setpoint, plant input profiles and sensor seed of one run.

    Parameters
    ----------
    spec : ScenarioSpec
        A validated scenario (a parsed file or one drawn by
        :meth:`ebraille_sim.scenarios.episodes.EpisodeDistribution.draw`).
    seed : int, optional
        The run's master seed (default ``spec.seed``): it gives the sensor seed and the
        reading's and the inputs' generators (module docstring).

    Returns
    -------
    RunInputs

    Raises
    ------
    ScenarioError
        For a negative seed, an unreadable or empty text, a run shorter than one period, or
        a section that drives an unknown input.
    """
    seed = spec.seed if seed is None else int(seed)
    if seed < 0:
        raise ScenarioError(f"seed must be >= 0, got {seed}")
    sensor_seed, w_reading, w_inputs = run_numbers(seed)
    # the reading generator draws only the dwell jitter (made only for a jittered schedule)
    jittered = spec.reading.jitter_fraction > 0
    schedule = build_schedule_for(spec, generator_of(w_reading) if jittered else None)
    dt, n = run_length(spec, schedule)
    # the period starts (k + 1) dt - dt, in one array: a one-hour run holds 3.6 million periods
    t_start = period_starts(n + 1, dt)
    sp = setpoint_profile(spec, t_start, schedule)
    base = base_input_row(spec.device, spec.finger.gap_m)
    profiles = input_profiles(spec, t_start[:n], generator_of(w_inputs), base)   # rows of one array
    del t_start
    return RunInputs(spec=spec, seed=seed, sensor_seed=sensor_seed, schedule=schedule, dt_s=dt,
                     n_steps=n, setpoint_n=sp, base_inputs=base, profiles=profiles)
