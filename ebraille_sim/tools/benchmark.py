r"""Controller benchmark: a fixed, versioned suite, a population, bounds and one score.

A *suite* (:data:`SUITES`) is a list of :class:`BenchScenario` s (a shipped scenario, a
duration, optionally a reading rate) with a number of readers.  Every controller runs every
scenario on every reader; reader 0 is the scenario's own (nominal) device, readers
``1..n-1`` are drawn by :func:`ebraille_sim.scenarios.population.sample_devices` around it
from :data:`POPULATION_SEED` (the same draws in every scenario and for every controller).
The episode seed is ``scenario seed + 101 * reader``: every controller meets the same
reader, schedule and sensor noise, so differences between controllers are paired.  Episodes
run through :func:`ebraille_sim.scenarios.runner.run_scenario`, so the runner's controller
wrappers (the safety supervisor) apply as they do to ``ebraille-sim run``.  The numbers
depend only on the suite and the controllers, never on ``jobs``.

Statistics per controller and scenario, over its readers: the median and ``CVaR_10`` (the
mean of the worst ``ceil(0.1 n)`` episodes, i.e. the lowest values) of ``in_band_fraction``
and ``char_in_band_fraction``, the median of ``legible_char_fraction`` and ``energy_j``, and
the largest ``peak_force_n``.

Score (higher is better, at most 100)::

    score = 100 * mean_s [ (CVaR_10(in_band_s) + CVaR_10(char_in_band_s)) / 2 ]
            - 100 * (fraction of all episodes whose peak force exceeds 3.0 N)

with ``s`` over the tracking scenarios (the fault scenarios enter only the peak-force term);
an episode that fails (e.g. a diverged simulation) counts as one over 3.0 N and adds nothing
to the CVaR.

Bounds.  ``actuator_bound`` (:mod:`controllers.bounds`) is a controller fed the TRUE contact
force at the control rate.  ``sensor_bound`` is derived from each ``actuator_bound``
episode: its true-force trajectory ``F`` shifted by the estimator's error along it,
``F - (F_est - F)``, is what the finger would feel if a controller held the *estimate* as
well as ``actuator_bound`` holds the true force; its metrics are computed on that
trajectory (energy is the actuator run's).  It is a first-order estimate, not a proof
(docs/benchmark.md).  ``hysteresis_bound`` is ``actuator_bound``'s controller fed the true
force through the unit's FSR hysteresis and its exact inverse
(:class:`controllers.bounds.HysteresisSeen`): what the film lets any firmware know, with no
other sensor error, so it shows what the film's blind stretch after a reversal costs.  Both
derived bounds are left out of the fault scenarios.

Latched faults.  Every episode row records the fault the safety supervisor latched
(``supervisor_fault``, None when it never retracted).  No tracking scenario has a fault in
it, so a latched fault there is a false alarm that retracted the board for the rest of the
run: the leaderboard counts those episodes per controller (``tracking_faults``), to tell a
controller that loses the force from one whose loop misleads the detectors.

Examples
--------
>>> res = run_benchmark(["pid"], suite="quick", jobs=1)
>>> print(format_leaderboard(res).splitlines()[0])
suite quick v2: 4 scenarios x 2 readers
"""
from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import pathlib
import time
from dataclasses import dataclass

import numpy as np

from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N

__all__ = ["BenchScenario", "Suite", "SUITES", "SUITE_VERSION", "POPULATION_SEED", "BOUNDS", "cvar_low",
           "scenario_spec", "scenario_devices", "plan_episodes", "estimator_settings", "run_episode", "run_benchmark",
           "sensor_bound_metrics", "summarise", "score_formula", "format_leaderboard",
           "format_markdown", "results_document", "write_results", "load_results", "compare", "format_compare"]

SUITE_VERSION = 2
"""Bumped whenever a suite's scenarios, durations, readers or seeds change (results of
different versions are not comparable)."""

POPULATION_SEED = 2026
"""Master seed of the drawn readers."""

ALPHA = 0.1
"""Tail fraction of the CVaR."""

BOUNDS = ("actuator_bound", "hysteresis_bound", "sensor_bound")
"""Leaderboard entries that are bounds, not controllers one could ship."""

FRACTIONS = ("in_band_fraction", "char_in_band_fraction")
KEPT = FRACTIONS + ("peak_force_n", "energy_j", "legible_char_fraction", "force_rmse_n", "estimate_rmse_n",
                    "onset_overshoot_fraction")


@dataclass(frozen=True)
class BenchScenario:
    """One scenario of a suite.

    Attributes
    ----------
    key : str
        Name on the leaderboard.
    scenario : str
        Shipped scenario name.
    duration_s : float
        Episode length, s.
    wpm : float or None
        Reading rate replacing the scenario's (None keeps it).
    fault : bool
        A fault scenario: reported, but only its peak force enters the score.
    """
    key: str
    scenario: str
    duration_s: float
    wpm: float | None = None
    fault: bool = False


@dataclass(frozen=True)
class Suite:
    """A named list of scenarios and the number of readers (nominal + drawn)."""
    name: str
    scenarios: tuple
    readers: int


_STANDARD = (
    BenchScenario("reading_60wpm", "steady_60wpm", 12.0),
    BenchScenario("reading_120wpm", "steady_120wpm", 12.0),
    BenchScenario("reading_200wpm", "steady_120wpm", 12.0, wpm=200.0),
    BenchScenario("setpoint_steps", "setpoint_steps", 14.0),
    BenchScenario("contact_onset", "contact_onset", 6.0),
    BenchScenario("tremor_90wpm", "tremor_90wpm", 15.0),
    BenchScenario("pressing_90wpm", "pressing_90wpm", 20.0),
    BenchScenario("strap_slip", "strap_slip", 24.0),
    BenchScenario("battery_sag", "battery_sag", 45.0),
    BenchScenario("everyday_session", "everyday_session", 30.0),
    BenchScenario("refresh_60wpm", "refresh_60wpm", 12.0),
    BenchScenario("refresh_120wpm", "refresh_120wpm", 12.0),
    BenchScenario("fault_fsr_open", "fault_fsr_open", 8.0, fault=True),
    BenchScenario("fault_motor_stall", "fault_motor_stall", 9.0, fault=True),
)

STANDARD_READERS = 64
"""Readers of the standard suite (nominal + 63 drawn): its CVaR10 is the mean of the worst
7 readers, a tail, not the single worst reader."""

SUITES = {
    "standard": Suite("standard", _STANDARD, readers=STANDARD_READERS),
    "quick": Suite("quick", (
        BenchScenario("reading_120wpm", "steady_120wpm", 4.0),
        BenchScenario("pressing_90wpm", "pressing_90wpm", 6.0),
        BenchScenario("refresh_120wpm", "refresh_120wpm", 5.0),
        BenchScenario("fault_fsr_open", "fault_fsr_open", 6.0, fault=True),
    ), readers=2),
}
"""The suites by name: ``standard`` (the leaderboard's) and ``quick`` (for tests and CI)."""


def score_formula() -> str:
    """The overall score's formula, as stated in the docs and ``--help``."""
    return ("score = 100 * mean over tracking scenarios of (CVaR10(in_band) + CVaR10(char_in_band)) / 2 "
            f"- 100 * fraction of episodes with peak force > {TACTILE_FORCE_MAX_N:g} N")


def cvar_low(values, alpha: float = ALPHA) -> float:
    """Mean of the lowest ``ceil(alpha n)`` values (the worst tail of a higher-is-better metric).

    Examples
    --------
    >>> cvar_low([0.9, 0.5, 1.0, 0.8], 0.5)
    0.65
    """
    v = np.sort(np.asarray([x for x in values if x is not None and math.isfinite(x)], dtype=float))
    if v.size == 0:
        return math.nan
    return float(round(v[:max(1, math.ceil(alpha * v.size))].mean(), 12))


def get_suite(name: str) -> Suite:
    """The suite called ``name``; a one-line ValueError names the known ones otherwise."""
    if name not in SUITES:
        raise ValueError(f"unknown suite {name!r}; suites: {', '.join(sorted(SUITES))}")
    return SUITES[name]


def reader_count(suite: Suite, readers=None) -> int:
    """Readers per scenario: ``readers`` (a whole number >= 1), or the suite's when None."""
    if readers is None:
        return suite.readers
    if isinstance(readers, bool) or not isinstance(readers, (int, np.integer)) or readers < 1:
        raise ValueError(f"readers must be a whole number >= 1 (reader 0 is the nominal device), got {readers!r}")
    return int(readers)


def plan_episodes(controllers, suite: Suite, readers: int | None = None) -> list[tuple]:
    """``(controller, scenario index, reader)`` for every episode, in a fixed order."""
    n = reader_count(suite, readers)
    return [(c, i, r) for c in controllers for i in range(len(suite.scenarios)) for r in range(n)]


@functools.lru_cache(maxsize=64)
def scenario_spec(sc: BenchScenario):
    """The scenario every episode of ``sc`` runs: the shipped scenario with the suite's
    duration and, when ``sc.wpm`` is set, its reading rate (each reader's seed is
    ``seed + 101 * reader``)."""
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario(sc.scenario)
    spec = dataclasses.replace(spec, duration_s=float(sc.duration_s))
    if sc.wpm is not None:
        spec = dataclasses.replace(spec, reading=dataclasses.replace(spec.reading, wpm=float(sc.wpm)))
    return spec


@functools.lru_cache(maxsize=64)
def scenario_devices(sc: BenchScenario, readers: int, population_seed: int | None = None) -> list:
    """The readers of ``sc`` in a suite of ``readers``: the scenario's nominal device, then
    ``readers - 1`` drawn from it with :data:`POPULATION_SEED` (the same for every controller),
    calibrated as the scenario's unit is.  With ``population_seed`` all ``readers`` are drawn
    from that seed instead (no nominal reader: a set of readers apart from the benchmark's,
    for choosing among candidates without touching them)."""
    from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
    spec = scenario_spec(sc)
    pop = PopulationSpec(calibrate=spec.calibrated)
    if population_seed is not None:
        return sample_devices(int(population_seed), readers, pop, base=spec.device)
    return [spec.device] + sample_devices(POPULATION_SEED, readers - 1, pop, base=spec.device)


def episode_seed(spec, reader: int, population_seed: int | None = None) -> int:
    """The seed of reader ``reader``'s episode: ``seed + 101 * reader`` of the scenario, moved
    by ``10**6 * (population_seed + 1)`` for readers drawn from their own ``population_seed``."""
    extra = 0 if population_seed is None else 10 ** 6 * (int(population_seed) + 1)
    return spec.seed + 101 * reader + extra


def sensor_bound_metrics(res) -> dict:
    """Metrics of an ``actuator_bound`` run (a :class:`~ebraille_sim.scenarios.runner.RunResult`
    with its trace) with its force shifted by the estimator's error along it, ``F - (F_est - F)``:
    what a controller holding the estimate as well as the bound holds the true force would give
    (module docstring)."""
    from ebraille_sim.scenarios.inputs import refresh_phases
    from ebraille_sim.scenarios.legibility import legibility_metrics
    from ebraille_sim.scenarios.metrics import compute_metrics
    spec, tr = res.spec, res.trace
    f = np.maximum(2.0 * tr["force_true_n"] - tr["force_est_n"], 0.0)
    window = dict(tr, force_true_n=f, force_est_n=tr["force_true_n"])
    if spec.reading.mode == "refresh":
        _, hold = refresh_phases(spec, res.schedule, tr["t_s"])
        window["char_index"] = np.where(hold, tr["char_index"], -1)
    m = compute_metrics(window, spec.reading.start_s, spec.setpoint.band_fraction, res.schedule, None)
    m.update(legibility_metrics(f, tr["setpoint_n"], window["char_index"], res.schedule.cells))
    m["energy_j"] = res.metrics["energy_j"]
    return m


def estimator_settings(settings) -> dict:
    """Checked estimator settings for every episode: ``{field: value}`` of
    :class:`ebraille_sim.physics.params.EstimatorParams`, or ``KEY=VALUE`` strings (``true`` /
    ``false``, numbers, or text); one-line ValueError for an unknown key or a bad value."""
    from ebraille_sim.base.validation import replace_checked
    from ebraille_sim.physics.params import EstimatorParams
    out = {}
    for item in ([] if settings is None else settings.items() if isinstance(settings, dict) else settings):
        if isinstance(item, str):
            key, sep, text = item.partition("=")
            if not sep or not key.strip():
                raise ValueError(f"estimator setting {item!r} must be KEY=VALUE")
            low = text.strip().lower()
            if low in ("true", "false"):
                value = low == "true"
            else:
                try:
                    value = float(text)
                except ValueError:
                    value = text.strip()
            item = (key.strip(), value)
        out[str(item[0])] = item[1]
    replace_checked(EstimatorParams(), **out)
    if "model" in out:
        check_estimator_model(out)
    return dict(sorted(out.items()))


def check_estimator_model(settings: dict) -> None:
    """Load the estimator model of ``settings`` and check it against the rates of every suite
    scenario's device, so that a model no episode can use is refused before any runs
    (one-line ``ValueError``)."""
    from ebraille_sim.base.validation import replace_checked
    from ebraille_sim.estimation.registry import load_estimator
    from ebraille_sim.plant.lumped import check_sensor_rates
    from ebraille_sim.scenarios.spec import load_scenario
    model = load_estimator(str(settings["model"]))
    seen = set()
    for suite in SUITES.values():
        for sc in suite.scenarios:
            if sc.scenario in seen:
                continue
            seen.add(sc.scenario)
            device = load_scenario(sc.scenario).device
            device = dataclasses.replace(device, estimator=replace_checked(device.estimator, **settings))
            try:
                check_sensor_rates(device, model)
            except ValueError as exc:
                raise ValueError(f"model {settings['model']!r} does not suit scenario {sc.scenario}: {exc}") from None


def run_episode(task) -> list[dict]:
    """Run one ``(controller, BenchScenario, reader, readers, estimator items)`` task; rows of
    kept metrics.

    ``actuator_bound`` episodes also give the ``sensor_bound`` row, except in fault scenarios
    (a failed sensor's error is not an estimation error); ``hysteresis_bound`` runs on the
    reader's own FSR and gives no row in fault scenarios.  The estimator items (pairs of
    :class:`~ebraille_sim.physics.params.EstimatorParams` fields and values) replace the
    device's estimator settings.
    """
    from ebraille_sim.base.validation import replace_checked
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.tools.report import latched_fault
    from ebraille_sim.tools.sweep import READER_COLUMNS
    ctrl, sc, reader, n, est = task[:5]
    pop = task[5] if len(task) > 5 else None
    spec = scenario_spec(sc)
    device = scenario_devices(sc, n, pop)[reader]
    if est:
        device = dataclasses.replace(device, estimator=replace_checked(device.estimator, **dict(est)))
    seed = episode_seed(spec, reader, pop)
    base = {"scenario": sc.key, "reader": reader, "seed": seed,
            **{col: float(get(device)) for col, get in READER_COLUMNS.items()}}
    controller = ctrl
    if ctrl == "hysteresis_bound":
        if sc.fault:
            return []
        from controllers.bounds import make_hysteresis_bound
        controller = make_hysteresis_bound(device.fsr)
    try:
        res = run_scenario(spec, controller=controller, seed=seed, device=device)
    except (ValueError, FloatingPointError) as exc:
        return [dict(base, controller=ctrl, error=str(exc).splitlines()[0])]
    latch = latched_fault(res)
    rows = [dict(base, controller=ctrl, **{k: _num(res.metrics.get(k)) for k in KEPT}, **latch)]
    if ctrl == "actuator_bound" and not sc.fault:
        m = sensor_bound_metrics(res)
        rows.append(dict(base, controller="sensor_bound", **{k: _num(m.get(k)) for k in KEPT},
                         **dict(latch, supervisor_fault=None, supervisor_fault_s=None)))
    return rows


def _num(v):
    return None if v is None or not math.isfinite(float(v)) else float(v)


@dataclass
class BenchmarkResult:
    """Rows of a benchmark run and how it was run."""
    suite: Suite
    controllers: list
    readers: int
    rows: list
    wall_s: float
    jobs: int
    estimator: dict = dataclasses.field(default_factory=dict)


def run_benchmark(controllers, suite: str | Suite = "standard", readers: int | None = None, jobs: int = 1,
                  bounds: bool = True, progress=None, estimator=None, scheduler=None,
                  population_seed: int | None = None) -> BenchmarkResult:
    """Run ``controllers`` (and the bounds) on a suite.

    Parameters
    ----------
    controllers : list of str
        Registered names, gains files or ``policy:PATH``; each is checked by building it once.
    suite : str or Suite
    readers : int, optional
        Readers per scenario (nominal + drawn), default the suite's.
    jobs : int
        Local worker processes (1: this process).  The numbers do not depend on it.
    scheduler : str or dask.distributed.Client, optional
        A Dask scheduler address (or a connected client): the episodes run on that cluster
        (``jobs`` is then ignored; the numbers are the same).
    bounds : bool
        Also run ``actuator_bound`` (which gives ``sensor_bound``) and ``hysteresis_bound``.
    progress : callable, optional
        ``progress(done, total)`` after each episode.
    estimator : dict or list of str, optional
        Estimator settings of every device, the bounds' included (:func:`estimator_settings`):
        a firmware variant, such as ``{"hysteresis_compensation": True}``.
    population_seed : int, optional
        Draw every reader from this seed (:func:`scenario_devices`, no nominal reader; episode
        seeds :func:`episode_seed`) instead of the benchmark's: validation readers, apart from
        the benchmark's, for choosing among candidates.
    """
    import controllers as ctrl_mod
    est = estimator_settings(estimator)
    suite = get_suite(suite) if isinstance(suite, str) else suite
    names = list(dict.fromkeys(str(c) for c in controllers))
    if not names:
        raise ValueError("give at least one controller")
    for c in names:
        if c in BOUNDS:
            raise ValueError(f"{c!r} is a bound the benchmark adds itself; give controllers to compare")
        ctrl_mod.make(c)
    if bounds:
        names += ["actuator_bound", "hysteresis_bound"]
    n = reader_count(suite, readers)
    tasks = [(c, suite.scenarios[i], r, n, tuple(est.items())) + (() if population_seed is None else (int(population_seed),))
             for c, i, r in plan_episodes(names, suite, n)]
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    jobs = min(int(jobs), max(1, len(tasks)))          # no idle workers
    t0 = time.perf_counter()
    rows: list = []
    if scheduler is not None:
        from dask.distributed import as_completed

        from ebraille_sim.tools.sweep import dask_client, dask_threads
        with dask_client(scheduler) as client:
            futs = {client.submit(run_episode, t, pure=False): k for k, t in enumerate(tasks)}
            parts = [None] * len(tasks)
            for done, f in enumerate(as_completed(futs), start=1):
                parts[futs[f]] = f.result()
                if progress:
                    progress(done, len(tasks))
            jobs = dask_threads(client)
        rows = [r for part in parts for r in part]
    elif jobs == 1:
        for k, t in enumerate(tasks):
            rows.extend(run_episode(t))
            if progress:
                progress(k + 1, len(tasks))
    else:
        from concurrent.futures import ProcessPoolExecutor

        from ebraille_sim.tools.parallel import process_context
        with ProcessPoolExecutor(max_workers=jobs, mp_context=process_context()) as ex:
            for k, out in enumerate(ex.map(run_episode, tasks, chunksize=1)):
                rows.extend(out)
                if progress:
                    progress(k + 1, len(tasks))
    return BenchmarkResult(suite, names + (["sensor_bound"] if bounds else []), n, rows,
                           time.perf_counter() - t0, jobs, est)


def summarise(result: BenchmarkResult) -> dict:
    """``{controller: {"score", "scenarios": {key: stats}, ...}}`` (module docstring)."""
    out = {}
    for c in result.controllers:
        per, tracking, over, total, errors, faults = {}, [], 0, 0, 0, 0
        for sc in result.suite.scenarios:
            rows = [r for r in result.rows if r["controller"] == c and r["scenario"] == sc.key]
            ok = [r for r in rows if not r.get("error")]
            errors += len(rows) - len(ok)
            st = {"episodes": len(rows), "errors": len(rows) - len(ok), "fault": sc.fault,
                  "supervisor_faults": sum(1 for r in ok if r.get("supervisor_fault"))}
            for m in FRACTIONS:
                vals = [r[m] for r in ok if r[m] is not None]
                st[f"{m}_median"] = float(np.median(vals)) if vals else None
                st[f"{m}_cvar10"] = cvar_low(vals) if vals else None
            peaks = [r["peak_force_n"] for r in ok if r["peak_force_n"] is not None]
            st["peak_force_n_max"] = max(peaks) if peaks else None
            for m in ("energy_j", "legible_char_fraction"):
                vals = [r[m] for r in ok if r[m] is not None]
                st[f"{m}_median"] = float(np.median(vals)) if vals else None
            over += sum(1 for p in peaks if p > TACTILE_FORCE_MAX_N) + (len(rows) - len(ok))
            total += len(rows)
            if not sc.fault:
                faults += st["supervisor_faults"]
                a, b = st["in_band_fraction_cvar10"], st["char_in_band_fraction_cvar10"]
                tracking.append(0.5 * ((a or 0.0) + (b or 0.0)))
            per[sc.key] = st
        score = 100.0 * float(np.mean(tracking)) - 100.0 * (over / total if total else 0.0)
        out[c] = {"score": round(score, 3), "bound": c in BOUNDS, "errors": errors,
                  "over_force_fraction": over / total if total else 0.0, "tracking_faults": faults,
                  "scenarios": per}
    return out


def population(result: BenchmarkResult, worst: int = 3) -> list[dict]:
    """The population report per scenario and controller
    (:func:`ebraille_sim.tools.report.population_summary`): the share of readers meeting each
    criterion, latched faults and false trips (also per reading-hour), the worst readers
    with their drawn parameters."""
    from ebraille_sim.tools.report import population_scenario, population_summary
    from ebraille_sim.tools.sweep import READER_COLUMNS
    scenarios = {sc.key: population_scenario(scenario_spec(sc)) for sc in result.suite.scenarios}
    return population_summary(result.rows, scenarios, list(READER_COLUMNS), group=("scenario", "controller"),
                              worst=worst)


def format_population(summary: list[dict]) -> str:
    """Terminal text of :func:`population`; the worst readers are listed for the controllers,
    not for the bounds."""
    from ebraille_sim.tools.report import format_population as fmt
    from ebraille_sim.tools.sweep import READER_COLUMNS
    return fmt(summary, list(READER_COLUMNS), worst_for=lambda g: g["controller"] not in BOUNDS)


def _ranked(summary: dict) -> list:
    return sorted(summary, key=lambda c: (summary[c]["bound"] is False, -summary[c]["score"], c))


def _f(v, fmt="{:.3f}"):
    return "-" if v is None else fmt.format(v)


def _firmware(result: BenchmarkResult) -> str:
    """``", estimator k=v, ..."`` when the run changed the devices' estimator settings."""
    if not result.estimator:
        return ""
    return ", estimator " + ", ".join(f"{k}={str(v).lower() if isinstance(v, bool) else v}"
                                      for k, v in result.estimator.items())


def _faults(entry: dict) -> str:
    """Episodes of the tracking scenarios that ended in a latched supervisor fault ("-" in a
    results file written before the count was kept)."""
    n = entry.get("tracking_faults")
    return "-" if n is None else str(n)


def format_leaderboard(result: BenchmarkResult, summary: dict | None = None) -> str:
    """The leaderboard and the per-scenario worst-case table as terminal text (the column
    ``faults`` counts the tracking scenarios' episodes that ended in a latched supervisor fault)."""
    s = summarise(result) if summary is None else summary
    order = _ranked(s)
    w = max(14, *(len(c) for c in order))
    lines = [f"suite {result.suite.name} v{SUITE_VERSION}: {len(result.suite.scenarios)} scenarios x "
             f"{result.readers} readers{_firmware(result)}", score_formula(), "",
             f"{'controller':<{w}}  {'score':>7}  {'peak N':>6}  {'>3N':>5}  {'faults':>6}"]
    for c in order:
        peak = max((v["peak_force_n_max"] or 0.0) for v in s[c]["scenarios"].values())
        tag = "  (bound)" if s[c]["bound"] else ""
        lines.append(f"{c:<{w}}  {s[c]['score']:7.2f}  {peak:6.2f}  {s[c]['over_force_fraction']:5.2f}"
                     f"  {_faults(s[c]):>6}{tag}")
    lines += ["", "CVaR10 in_band / char_in_band per scenario (median in_band in brackets):"]
    cw = max(17, *(len(c) for c in order))
    lines.append(f"{'scenario':<18}" + "".join(f"  {c:>{cw}}" for c in order))
    for sc in result.suite.scenarios:
        cells = []
        for c in order:
            st = s[c]["scenarios"][sc.key]
            cells.append(f"{_f(st['in_band_fraction_cvar10'], '{:.2f}')}/"
                         f"{_f(st['char_in_band_fraction_cvar10'], '{:.2f}')} "
                         f"({_f(st['in_band_fraction_median'], '{:.2f}')})")
        lines.append(f"{sc.key:<18}" + "".join(f"  {x:>{cw}}" for x in cells))
    return "\n".join(lines)


def format_markdown(result: BenchmarkResult, summary: dict | None = None) -> str:
    """The leaderboard and one table per statistic as Markdown."""
    s = summarise(result) if summary is None else summary
    order = _ranked(s)
    out = [f"Suite `{result.suite.name}` v{SUITE_VERSION}: {len(result.suite.scenarios)} scenarios x "
           f"{result.readers} readers{_firmware(result)}.  `{score_formula()}`", "",
           "| controller | score | max peak force (N) | share of episodes > 3 N | latched faults, tracking scenarios |",
           "|---|---:|---:|---:|---:|"]
    for c in order:
        peak = max((v["peak_force_n_max"] or 0.0) for v in s[c]["scenarios"].values())
        name = f"*{c}* (bound)" if s[c]["bound"] else f"`{c}`"
        out.append(f"| {name} | {s[c]['score']:.2f} | {peak:.2f} | {s[c]['over_force_fraction']:.2f} | "
                   f"{_faults(s[c])} |")
    for title, key, fmt in (("CVaR10 in_band_fraction", "in_band_fraction_cvar10", "{:.3f}"),
                            ("median in_band_fraction", "in_band_fraction_median", "{:.3f}"),
                            ("CVaR10 char_in_band_fraction", "char_in_band_fraction_cvar10", "{:.3f}"),
                            ("median char_in_band_fraction", "char_in_band_fraction_median", "{:.3f}"),
                            ("max peak force, N", "peak_force_n_max", "{:.2f}"),
                            ("median energy, J", "energy_j_median", "{:.3f}"),
                            ("median legible fraction", "legible_char_fraction_median", "{:.3f}")):
        out += ["", f"**{title}**", "", "| scenario | " + " | ".join(order) + " |",
                "|---|" + "---:|" * len(order)]
        for sc in result.suite.scenarios:
            out.append(f"| {sc.key} | " + " | ".join(_f(s[c]["scenarios"][sc.key][key], fmt) for c in order) + " |")
    return "\n".join(out) + "\n"


def results_document(result: BenchmarkResult, summary: dict | None = None) -> dict:
    """The JSON results document (a later run compares against it)."""
    s = summarise(result) if summary is None else summary
    return {"suite": result.suite.name, "suite_version": SUITE_VERSION, "readers": result.readers,
            "population_seed": POPULATION_SEED, "score_formula": score_formula(),
            "scenarios": [dataclasses.asdict(sc) for sc in result.suite.scenarios],
            "controllers": result.controllers, "ranking": _ranked(s), "summary": s,
            "estimator": dict(result.estimator), "population": population(result),
            "rows": result.rows, "wall_s": round(result.wall_s, 3), "jobs": result.jobs}


RESULT_FILES = ("benchmark.json", "leaderboard.md", "population.png")
"""What :func:`write_results` writes into its folder."""


def write_results(result: BenchmarkResult, out, summary: dict | None = None) -> list:
    """Write ``benchmark.json``, ``leaderboard.md`` and ``population.png`` (the in-band share of
    the controllers' readers against the drawn parameters that separate the failing ones,
    :func:`ebraille_sim.tools.report.plot_population`) into folder ``out``; return the paths.

    Each file is replaced whole (:func:`ebraille_sim.tools.outputs.write_file`); a symbolic
    link, FIFO, device or folder of either name is refused, never written through.
    """
    from ebraille_sim.tools.outputs import write_file
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = results_document(result, summary)
    p_json, p_md = out / "benchmark.json", out / "leaderboard.md"
    doc = dict(doc, rows=[{k: round(v, 6) if isinstance(v, float) else v for k, v in r.items()}
                          for r in doc["rows"]])
    write_file(p_json, json.dumps(doc, separators=(",", ":"), allow_nan=False, default=float) + "\n", "--out entry")
    write_file(p_md, format_markdown(result, doc["summary"]), "--out entry")
    from ebraille_sim.tools.report import plot_population
    from ebraille_sim.tools.sweep import READER_COLUMNS
    rows = [r for r in result.rows if r["controller"] not in BOUNDS]
    pop = [s for s in doc["population"] if s["group"]["controller"] not in BOUNDS]
    p_png = plot_population(rows, pop, out / "population.png", list(READER_COLUMNS))
    return [p_json, p_md, p_png]


def load_results(path) -> dict:
    """A results document written by :func:`write_results`; one-line ValueError if it is not one."""
    from ebraille_sim.base.files import read_json, short
    p = pathlib.Path(path)
    if not os.path.lexists(p):
        raise FileNotFoundError(f"no results file {short(p)}")
    doc = read_json(p, "results file")
    if not isinstance(doc, dict) or not {"suite", "suite_version", "summary"} <= set(doc):
        raise ValueError(f"{short(p)}: not a benchmark results file (needs suite, suite_version and summary)")
    _check_results_types(doc, short(p))
    return doc


def _check_results_types(doc: dict, shown: str) -> None:
    """The parts of a results document :func:`compare` reads, of the types it reads them as."""
    from ebraille_sim.base.files import short

    def bad(where, want):
        raise ValueError(f"{shown}: not a benchmark results file ({where} must be {want})")

    def number(v):
        return v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))

    if not isinstance(doc["suite"], str):
        bad("suite", "a name")
    if not isinstance(doc["suite_version"], (int, str)) or isinstance(doc["suite_version"], bool):
        bad("suite_version", "a version")
    if not isinstance(doc["summary"], dict):
        bad("summary", "an object")
    for c, s in doc["summary"].items():
        if not isinstance(s, dict) or not number(s.get("score")) or s.get("score") is None:
            bad(f"summary[{short(c, 40)}].score", "a number")
        if not isinstance(s.get("scenarios"), dict):
            bad(f"summary[{short(c, 40)}].scenarios", "an object")
        for key, st in s["scenarios"].items():
            if not isinstance(st, dict) or not all(number(st.get(m)) for m in COMPARED):
                bad(f"summary[{short(c, 40)}].scenarios[{short(key, 40)}]",
                    "an object of numbers (" + ", ".join(COMPARED) + ")")


COMPARED = ("in_band_fraction_median", "in_band_fraction_cvar10", "char_in_band_fraction_median",
            "char_in_band_fraction_cvar10", "peak_force_n_max")


def compare(new: dict, old: dict) -> dict:
    """Deltas ``new - old`` of the score and the per-scenario statistics, for the controllers
    and scenarios both documents hold.

    Raises
    ------
    ValueError
        When the suites (name or version) differ.
    """
    if (new["suite"], new["suite_version"]) != (old["suite"], old["suite_version"]):
        raise ValueError(f"cannot compare suite {new['suite']} v{new['suite_version']} with "
                         f"{old['suite']} v{old['suite_version']}")
    out = {}
    for c, s in new["summary"].items():
        if c not in old["summary"]:
            continue
        o = old["summary"][c]
        d = {"score": round(s["score"] - o["score"], 6), "scenarios": {}}
        for key, st in s["scenarios"].items():
            if key not in o["scenarios"]:
                continue
            d["scenarios"][key] = {m: (None if st.get(m) is None or o["scenarios"][key].get(m) is None
                                       else round(st[m] - o["scenarios"][key][m], 6)) for m in COMPARED}
        out[c] = d
    return out


def format_compare(deltas: dict) -> str:
    """Terminal text of :func:`compare`: score deltas, then the scenarios that moved."""
    if not deltas:
        return "no controller in common with the compared results"
    lines = ["change against the compared results (new - old):"]
    for c, d in deltas.items():
        lines.append(f"  {c}: score {d['score']:+.2f}")
        for key, st in d["scenarios"].items():
            moved = {m: v for m, v in st.items() if v}
            if moved:
                lines.append(f"    {key}: " + ", ".join(f"{m} {v:+.3f}" for m, v in moved.items()))
    return "\n".join(lines)
