"""Population sweeps: scenarios x reading rates x readers x controllers, run in parallel.

A sweep is planned as a list of :class:`Episode` s, the product of

* scenarios (parsed once in the parent process and shipped to the workers),
* reading rates (``[reading] wpm`` replaced; none given keeps each scenario's rate),
* readers: devices drawn with :func:`ebraille_sim.scenarios.population.sample_devices` around each
  scenario's own device (reader ``k`` is the same draw, child ``k`` of the population
  seed, in every scenario); ``readers = 0`` runs the scenario's own device (reader -1),
* controllers (registered names or gains files),
* replicates.

Seeds.  One master seed.  Episode seeds come from
``SeedSequence(seed, spawn_key=(scenario, rate, reader, replicate))`` and do **not**
depend on the controller: every controller meets the same reader, schedule jitter and
sensor noise (common random numbers), so controller differences are paired.  The
population is drawn from ``seed`` as well.  The rows of a sweep therefore depend only on
the plan, never on how it was executed: serially, on local processes, or on a Dask
cluster (:func:`identical_results` compares two runs, ignoring the wall-clock metric).

Execution.  ``jobs = 1`` runs in this process; ``jobs > 1`` (default: all local cores)
uses a :class:`concurrent.futures.ProcessPoolExecutor` (:func:`process_context`); ``scheduler`` (an address such as
``tcp://10.0.0.5:8786`` or a ``dask.distributed.Client``) sends batches of episodes to a
Dask cluster (``pip install ebraille-sim[dist]``).  A progress bar (tqdm when installed)
counts finished episodes.

Results.  One row per episode: the plan columns (``rate_wpm`` is the nominal rate; the
metric ``wpm`` is the realised one), the reader's drawn parameters, every metric of the
run, the supervisor's latched fault (``supervisor_fault``, its time ``supervisor_fault_s``;
empty without a latch), the reading time ``reading_s``, and ``error`` (a one-line message
when the episode failed, e.g. a diverged simulation; its metrics are then empty).
:func:`write_results` writes ``results.csv`` (and ``results.parquet`` when pyarrow is
installed), ``summary.txt`` (the loss table and the population report, :func:`population`)
and figures (metric distributions, worst cases, CVaR, the in-band share against the drawn
parameters that separate the failing readers).

Risk.  For a loss ``L`` (a metric where lower is better, or ``1 - metric`` for the
fractions where higher is better), ``CVaR_alpha`` is the mean of the worst
``ceil(alpha n)`` episodes: the expected loss in the worst ``alpha`` tail
(Rockafellar & Uryasev 2000).

Examples
--------
>>> plan = plan_sweep(["contact_onset"], rates=[60, 120], readers=2, controllers=["pid"], seed=0,
...                   duration_s=3.0)
>>> len(plan.episodes)
4
>>> rows = run_sweep(plan, jobs=1, progress=False).rows
>>> len(rows)
4
"""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import math
import os
import pathlib
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ebraille_sim.scenarios.spec import DEFAULT_DESIGN
from ebraille_sim.tools.parallel import process_context

__all__ = ["Episode", "SweepPlan", "SweepResult", "plan_sweep", "run_sweep", "run_episode", "cvar", "loss_values",
           "summarise", "population", "format_population", "identical_results", "write_results", "READER_COLUMNS", "PLAN_COLUMNS"]

PLAN_COLUMNS = ["episode", "scenario", "rate_wpm", "reader", "controller", "replicate", "seed"]
READER_COLUMNS = {
    "finger_b_n_per_m": lambda d: d.finger.stiffness_b_n_per_m,
    "finger_m_per_m": lambda d: d.finger.exponent_m_per_m,
    "relax_c0": lambda d: d.finger.relax_weight_inf,
    "fsr_k_ohm": lambda d: d.fsr.resistance_at_1n_ohm,
    "fsr_exponent": lambda d: d.fsr.exponent,
    "fsr_hysteresis": lambda d: d.fsr.hysteresis_fraction,
    "fsr_creep_per_decade": lambda d: d.fsr.creep_per_decade,
    "r2_ohm": lambda d: d.circuit.r2_ohm,
    "gear_efficiency": lambda d: d.drivetrain.gear_efficiency,
    "guide_coulomb_n": lambda d: d.drivetrain.guide_coulomb_n,
    "backlash_m": lambda d: d.drivetrain.backlash_m,
}
"""Reader/device parameters written beside each episode (for worst-case analysis)."""

WALL_CLOCK_COLUMNS = ("real_time_factor",)


@dataclass(frozen=True)
class Episode:
    """One run of a sweep.  ``wpm`` None keeps the scenario's rate; ``reader`` -1 its device."""
    index: int
    scenario: str
    wpm: float | None
    reader: int
    controller: str
    replicate: int
    seed: int


@dataclass
class SweepPlan:
    """Everything a worker needs: parsed scenarios, drawn devices, the episodes."""
    specs: dict
    devices: dict
    episodes: list
    duration_s: float | None = None
    seed: int = 0


@dataclass
class SweepResult:
    """Rows (one dict per episode, in episode order), their columns and the wall time."""
    rows: list
    columns: list
    wall_s: float
    executor: str = "local"
    plan: SweepPlan | None = field(default=None, repr=False)


def _episode_seed(seed: int, key: tuple) -> int:
    ss = np.random.SeedSequence(seed, spawn_key=key)
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(12))


def plan_sweep(scenarios, rates=(), readers: int = 0, controllers=(DEFAULT_DESIGN,), seed: int = 0, replicates: int = 1,
               duration_s: float | None = None, population=None) -> SweepPlan:
    """Plan a sweep (see the module docstring).

    Parameters
    ----------
    scenarios : list of str, path or ScenarioSpec
    rates : list of float
        Reading rates, wpm; empty keeps each scenario's.
    readers : int
        Devices drawn per scenario (0: the scenario's own device).
    controllers : list of str
        Registered controller names, designs or gains files (default: the scenarios' default
        design, :data:`~ebraille_sim.scenarios.spec.DEFAULT_DESIGN`).
    seed : int
        Master seed (population and episodes).
    replicates : int
        Episodes per (scenario, rate, reader, controller) with different seeds.
    duration_s : float, optional
        Overrides every scenario's duration (short episodes for large sweeps).
    population : PopulationSpec, optional
        Distributions of the readers (default :class:`~ebraille_sim.scenarios.population.PopulationSpec`).
    """
    import controllers as _controllers

    from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
    from ebraille_sim.scenarios.spec import ScenarioSpec, load_scenario
    if not scenarios:
        raise ValueError("a sweep needs at least one scenario")
    if not controllers:
        raise ValueError("a sweep needs at least one controller")
    for name, v in (("readers", readers), ("replicates", replicates)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise ValueError(f"{name} must be a whole number >= 0, got {v!r}")
    if replicates < 1:
        raise ValueError(f"replicates must be >= 1, got {replicates}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be a positive finite number, got {duration_s}")
    for w in rates:
        if not (isinstance(w, (int, float)) and math.isfinite(w) and 0 < w <= 1000):
            raise ValueError(f"reading rate {w!r} must be a number in (0, 1000] wpm")
    for c in controllers:
        _controllers.make(c)        # fail early on an unknown name or a bad gains file
    population = population or PopulationSpec()
    specs, devices = {}, {}
    for s in scenarios:
        spec = s if isinstance(s, ScenarioSpec) else load_scenario(s)
        if spec.name in specs:
            raise ValueError(f"scenario {spec.name!r} is listed twice")
        length = spec.duration_s if duration_s is None else duration_s
        if length is not None and length <= spec.reading.start_s:
            raise ValueError(f"episodes of {length:g} s end before scenario {spec.name!r} starts reading at "
                             f"{spec.reading.start_s:g} s (no force metric could be computed); use a duration "
                             f"above {spec.reading.start_s:g} s")
        specs[spec.name] = spec
        drawn = dataclasses.replace(population, calibrate=population.calibrate and spec.calibrated)
        devices[spec.name] = sample_devices(seed, readers, drawn, base=spec.device) if readers else []
    rate_list = list(rates) or [None]
    reader_list = list(range(readers)) or [-1]
    episodes = []
    for si, name in enumerate(specs):
        for ri, wpm in enumerate(rate_list):
            for di, reader in enumerate(reader_list):
                for rep in range(replicates):
                    ep_seed = _episode_seed(seed, (si, ri, di, rep))
                    for ctrl in controllers:
                        episodes.append(Episode(len(episodes), name, None if wpm is None else float(wpm), reader,
                                                str(ctrl), rep, ep_seed))
    return SweepPlan(specs, devices, episodes, duration_s, seed)


def _episode_run(plan: SweepPlan, ep: Episode) -> tuple[dict, dict]:
    """The row's plan and reader columns, and the keyword arguments of its run."""
    spec = plan.specs[ep.scenario]
    if ep.wpm is not None:
        spec = dataclasses.replace(spec, reading=dataclasses.replace(spec.reading, wpm=ep.wpm))
    device = plan.devices[ep.scenario][ep.reader] if ep.reader >= 0 else spec.device
    row = {"episode": ep.index, "scenario": ep.scenario, "rate_wpm": spec.reading.wpm, "reader": ep.reader,
           "controller": ep.controller, "replicate": ep.replicate, "seed": ep.seed}
    for col, get in READER_COLUMNS.items():
        row[col] = float(get(device))
    return row, {"scenario": spec, "controller": ep.controller, "seed": ep.seed, "duration_s": plan.duration_s,
                 "device": device}


def _complete(row: dict, res) -> dict:
    """Add a run's metrics (or its one-line error) to its row."""
    if isinstance(res, Exception):
        row["error"] = (str(res).strip().splitlines() or [type(res).__name__])[0]
        return row
    from ebraille_sim.tools.report import latched_fault
    row.update(res.metrics)
    row.update(latched_fault(res))
    row["error"] = ""
    return row


def run_episode(plan: SweepPlan, ep: Episode) -> dict:
    """Run one episode on its own; returns its row (metrics empty and ``error`` set if it failed)."""
    from ebraille_sim.scenarios.runner import run_scenario
    row, kw = _episode_run(plan, ep)
    try:
        res = run_scenario(**kw)
    except (ValueError, FloatingPointError, FileNotFoundError) as exc:
        res = exc
    return _complete(row, res)


def _run_batch(plan: SweepPlan, batch: list) -> list:
    """Rows of several episodes, their plants advanced together
    (:func:`ebraille_sim.scenarios.runner.run_batch`; the same rows as :func:`run_episode`)."""
    from ebraille_sim.scenarios.runner import run_batch
    rows = []
    for j in range(0, len(batch), SERIAL_BATCH):
        # a worker's task runs as batches of SERIAL_BATCH: the inputs of one batch are held at a time
        pairs = [_episode_run(plan, ep) for ep in batch[j:j + SERIAL_BATCH]]
        results = run_batch([kw for _, kw in pairs], keep_traces=False)
        rows += [_complete(row, res) for (row, _), res in zip(pairs, results)]
    return rows


_WORKER_PLAN: SweepPlan | None = None


def _init_worker(plan: SweepPlan) -> None:
    global _WORKER_PLAN
    _WORKER_PLAN = plan


def _run_batch_in_worker(batch: list) -> list:
    return _run_batch(_WORKER_PLAN, batch)


class _Progress:
    """tqdm when installed, else a line on stderr every 10 %."""

    def __init__(self, total: int, enabled: bool, desc: str):
        self.total, self.n, self.enabled, self._bar, self._next = total, 0, enabled, None, 0.1
        if enabled:
            try:
                from tqdm import tqdm
                tqdm.monitor_interval = 0          # no monitor thread: worker processes can fork
                self._bar = tqdm(total=total, desc=desc, unit="ep", file=sys.stderr, smoothing=0.1)
            except ImportError:
                print(f"{desc}: 0/{total}", file=sys.stderr)

    def update(self, k: int) -> None:
        self.n += k
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(k)
        elif self.n >= self._next * self.total or self.n == self.total:
            print(f"  {self.n}/{self.total} episodes", file=sys.stderr)
            self._next = math.floor(self.n / self.total * 10 + 1) / 10

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


SERIAL_BATCH = 256
"""Episodes per batch in this process (``jobs = 1``): advanced together, a progress update each."""

TASKS_PER_WORKER = 2
"""Batches per worker process or Dask thread (default): enough to balance the load, few
enough that each batch advances many episodes per compiled call."""


def _batches(episodes: list, n_batches: int) -> list:
    size = max(1, math.ceil(len(episodes) / max(1, n_batches)))
    return [episodes[i:i + size] for i in range(0, len(episodes), size)]


def _columns(rows: list) -> list:
    cols = list(PLAN_COLUMNS) + list(READER_COLUMNS)
    for r in rows:
        for k in r:
            if k not in cols and k != "error":
                cols.append(k)
    return cols + ["error"]


def run_sweep(plan: SweepPlan, jobs: int | None = None, scheduler=None, progress: bool = True,
              batch_size: int | None = None) -> SweepResult:
    """Execute a plan.

    Parameters
    ----------
    plan : SweepPlan
    jobs : int, optional
        Local worker processes (default: ``os.cpu_count()``); 1 runs in this process.
        Ignored with ``scheduler``.
    scheduler : str or dask.distributed.Client, optional
        Dask scheduler address (or a connected client): run on that cluster.
    progress : bool
        Show a progress bar on stderr.
    batch_size : int, optional
        Episodes per task (default: :data:`TASKS_PER_WORKER` tasks per worker; in this
        process :data:`SERIAL_BATCH` episodes).  The episodes of a task that share a
        scenario and a duration are advanced together in one compiled call per control
        period (:func:`ebraille_sim.scenarios.runner.run_batch`); the rows do not depend on
        the batching.

    Returns
    -------
    SweepResult
        Rows in episode order; identical for the same plan whatever the executor.
    """
    eps = plan.episodes
    t0 = time.perf_counter()
    bar = _Progress(len(eps), progress, "sweep")
    rows: list = []
    try:
        if scheduler is not None:
            rows, executor = _run_dask(plan, scheduler, bar, batch_size), "dask"
        else:
            jobs = jobs or os.cpu_count() or 1
            if jobs < 1:
                raise ValueError(f"jobs must be >= 1, got {jobs}")
            jobs = min(jobs, max(1, len(eps)))          # no idle workers
            if jobs == 1 or len(eps) <= 1:
                for b in _batches(eps, math.ceil(len(eps) / (batch_size or SERIAL_BATCH))):
                    part = _run_batch(plan, b)
                    rows.extend(part)
                    bar.update(len(part))
                executor = "serial"
            else:
                rows, executor = _run_local(plan, jobs, bar, batch_size), f"local x{jobs}"
    finally:
        bar.close()
    rows.sort(key=lambda r: r["episode"])
    return SweepResult(rows, _columns(rows), time.perf_counter() - t0, executor, plan)


def _run_local(plan, jobs, bar, batch_size):
    from concurrent.futures import ProcessPoolExecutor, as_completed
    batches = _batches(plan.episodes, len(plan.episodes) // batch_size if batch_size else jobs * TASKS_PER_WORKER)
    rows = []
    ctx = process_context()
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_init_worker,
                             initargs=(plan,)) as ex:
        futs = [ex.submit(_run_batch_in_worker, b) for b in batches]
        for f in as_completed(futs):
            part = f.result()
            rows.extend(part)
            bar.update(len(part))
    return rows


@contextlib.contextmanager
def dask_client(scheduler):
    """A ``dask.distributed.Client`` for ``scheduler``: an address (connected here and closed on
    leaving) or a connected client (left open).  One-line ValueError when dask.distributed is
    not installed or the scheduler cannot be reached."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise ValueError("running on a Dask cluster needs dask.distributed: pip install 'ebraille-sim[dist]'") from None
    if isinstance(scheduler, Client):
        yield scheduler
        return
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        msg = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"cannot connect to the Dask scheduler {scheduler!r}: {msg}") from None
    try:
        yield client
    finally:
        client.close()


def dask_threads(client) -> int:
    """The threads of a Dask cluster's workers (at least 1)."""
    return max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))


def _run_dask(plan, scheduler, bar, batch_size):
    from dask.distributed import as_completed
    with dask_client(scheduler) as client:
        batches = _batches(plan.episodes, len(plan.episodes) // batch_size if batch_size
                           else dask_threads(client) * TASKS_PER_WORKER)
        plan_f = client.scatter(plan, broadcast=True)
        futs = [client.submit(_run_batch, plan_f, b, pure=False) for b in batches]
        rows = []
        for f in as_completed(futs):
            part = f.result()
            rows.extend(part)
            bar.update(len(part))
        return rows


# --------------------------------------------------------------------------------------
# analysis
# --------------------------------------------------------------------------------------

def identical_results(a: SweepResult, b: SweepResult, ignore=WALL_CLOCK_COLUMNS) -> bool:
    """True when two sweeps have the same rows, exactly, apart from wall-clock columns."""
    if len(a.rows) != len(b.rows):
        return False
    for ra, rb in zip(a.rows, b.rows):
        ka = {k: v for k, v in ra.items() if k not in ignore}
        kb = {k: v for k, v in rb.items() if k not in ignore}
        if ka != kb:
            return False
    return True


def _better(metric: str) -> str:
    from ebraille_sim.tools.regress import DEFAULT_TOLERANCE, TOLERANCES
    return TOLERANCES.get(metric, DEFAULT_TOLERANCE).better or "lower"


def loss_values(rows: list, metric: str) -> np.ndarray:
    """Loss per row for ``metric``: the metric if lower is better, ``1 - metric`` otherwise.

    Failed episodes (and None metrics) count as the worst possible: ``inf`` for a
    lower-is-better metric, 1 for a fraction.
    """
    higher = _better(metric) == "higher"
    out = []
    for r in rows:
        v = r.get(metric)
        if r.get("error") or v is None:
            out.append(1.0 if higher else math.inf)
        else:
            out.append(1.0 - v if higher else float(v))
    return np.asarray(out, dtype=float)


def cvar(losses, alpha: float) -> float:
    """Mean of the worst ``ceil(alpha n)`` losses (conditional value at risk).

    >>> cvar([0.0, 1.0, 2.0, 3.0], 0.5)
    2.5
    """
    x = np.sort(np.asarray(losses, dtype=float))[::-1]
    if x.size == 0:
        return math.nan
    if not 0 < alpha <= 1:
        raise ValueError(f"alpha must lie in (0, 1], got {alpha}")
    k = max(1, math.ceil(alpha * x.size - 1e-9))
    return float(np.mean(x[:k]))


def _groups(rows: list) -> dict:
    out: dict = {}
    for r in rows:
        out.setdefault((r["scenario"], r["controller"], r["rate_wpm"]), []).append(r)
    return out


def summarise(result: SweepResult, loss: str = "force_rmse_n", alpha: float = 0.1) -> list[dict]:
    """Per (scenario, controller, rate_wpm): episodes, failures, mean/median/worst loss and CVaR."""
    out = []
    for (scen, ctrl, wpm), rows in _groups(result.rows).items():
        L = loss_values(rows, loss)
        fin = L[np.isfinite(L)]
        out.append({"scenario": scen, "controller": ctrl, "rate_wpm": wpm, "episodes": len(rows),
                    "failed": sum(1 for r in rows if r.get("error")),
                    "loss": loss if _better(loss) == "lower" else f"1 - {loss}",
                    "mean": float(np.mean(fin)) if fin.size else math.nan,
                    "median": float(np.median(fin)) if fin.size else math.nan,
                    "worst": float(np.max(L)) if L.size else math.nan,
                    f"cvar_{alpha:g}": cvar(L, alpha)})
    return out


def population(result: SweepResult, worst: int = 5) -> list[dict]:
    """The population report of a sweep per scenario, controller and rate
    (:func:`ebraille_sim.tools.report.population_summary`): the share of readers meeting each
    criterion, the latched faults and false trips, the worst readers."""
    from ebraille_sim.tools.report import population_scenario, population_summary
    scenarios = {name: population_scenario(spec) for name, spec in result.plan.specs.items()}
    return population_summary(result.rows, scenarios, list(READER_COLUMNS),
                              group=("scenario", "controller", "rate_wpm"), worst=worst)


def format_population(summary: list[dict]) -> str:
    """Terminal text of :func:`population` (:func:`ebraille_sim.tools.report.format_population`)."""
    from ebraille_sim.tools.report import format_population as fmt
    return fmt(summary, list(READER_COLUMNS))


def format_summary(summary: list[dict]) -> str:
    """Plain-text table of :func:`summarise`."""
    if not summary:
        return "(no episodes)"
    cols = list(summary[0])
    cells = [[(f"{v:.4g}" if isinstance(v, float) else str(v)) for v in (s[c] for c in cols)] for s in summary]
    w = [max(len(c), *(len(r[i]) for r in cells)) for i, c in enumerate(cols)]
    lines = ["  ".join(c.ljust(x) for c, x in zip(cols, w)), "  ".join("-" * x for x in w)]
    lines += ["  ".join(v.ljust(x) for v, x in zip(r, w)) for r in cells]
    return "\n".join(lines)


def write_csv(result: SweepResult, path) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=result.columns, extrasaction="ignore")
        w.writeheader()
        for r in result.rows:
            w.writerow({k: ("" if r.get(k) is None else (repr(r[k]) if isinstance(r.get(k), float) else r.get(k)))
                        for k in result.columns})


def write_parquet(result: SweepResult, path) -> bool:
    """Write ``results.parquet``; False (nothing written) when pyarrow is not installed."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return False
    table = pa.Table.from_pylist([{k: r.get(k) for k in result.columns} for r in result.rows])
    pq.write_table(table, path)
    return True


def write_results(result: SweepResult, out_dir, loss: str = "force_rmse_n", alpha: float = 0.1,
                  figures: bool = True) -> list:
    """Write results.csv (+ .parquet), summary.txt and the figures into ``out_dir``; returns the paths."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "results.csv"]
    write_csv(result, written[0])
    if write_parquet(result, out / "results.parquet"):
        written.append(out / "results.parquet")
    summ = summarise(result, loss, alpha)
    pop = population(result)
    text = (f"{len(result.rows)} episodes, {result.executor}, wall time {result.wall_s:.1f} s\n"
            f"loss: {summ[0]['loss'] if summ else loss}; CVaR at alpha = {alpha:g}\n\n" + format_summary(summ) + "\n\n"
            + format_population(pop) + "\n")
    (out / "summary.txt").write_text(text, encoding="utf-8")
    written.append(out / "summary.txt")
    if figures:
        from ebraille_sim.tools.report import plot_population
        written += plot_results(result, out / "figures", loss, alpha)
        written.append(plot_population(result.rows, pop, out / "figures" / "population.png", list(READER_COLUMNS)))
    return written


_CONTROLLER_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "*")


def _episode_scatter(fig, ax, rows: list, L: np.ndarray) -> None:
    """Loss of every episode against the reader's pulp stiffness, one marker per controller.

    The colour is the FSR unit's ``k`` (colour bar); the marker shape names the controller
    (legend, one entry per controller in order of first appearance). Episodes with a
    non-finite loss are left out, and so is a controller with none left.
    """
    fin = np.isfinite(L)
    b = np.array([r["finger_b_n_per_m"] for r in rows], dtype=float)
    k_kohm = np.array([r["fsr_k_ohm"] for r in rows], dtype=float) / 1e3
    ctrl = np.array([r["controller"] for r in rows], dtype=object)
    names = list(dict.fromkeys(ctrl.tolist()))
    norm = None
    if fin.any():
        import matplotlib.colors
        norm = matplotlib.colors.Normalize(float(np.min(k_kohm[fin])), float(np.max(k_kohm[fin])))
    sc = None
    for i, name in enumerate(names):
        sel = fin & (ctrl == name)
        if not sel.any():
            continue
        sc = ax.scatter(b[sel], L[sel], c=k_kohm[sel], s=14, cmap="viridis", norm=norm,
                        marker=_CONTROLLER_MARKERS[i % len(_CONTROLLER_MARKERS)], edgecolors="k",
                        linewidths=0.3, label=f"{name} ({int(np.count_nonzero(sel))})")
    ax.set_xscale("log")
    ax.set_xlabel("pulp stiffness b (N/m)")
    ax.set_ylabel("loss")
    ax.set_title("every episode against the reader's pulp and FSR unit")
    if sc is not None:
        leg = ax.legend(title="controller (episodes)", fontsize=7, title_fontsize=7)
        for h in leg.legend_handles:
            h.set_facecolor("0.6")
        fig.colorbar(sc, ax=ax, label="FSR k = R at 1 N (kOhm)")


def plot_results(result: SweepResult, fig_dir, loss: str = "force_rmse_n", alpha: float = 0.1) -> list:
    """Figures: metric distributions, the worst episodes, and CVaR against alpha."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = pathlib.Path(fig_dir)
    d.mkdir(parents=True, exist_ok=True)
    groups = _groups(result.rows)
    labels = [f"{s}\n{c} {w:g} wpm" for (s, c, w) in groups]
    paths = []

    metrics = [m for m in ("force_rmse_n", "in_band_fraction", "char_in_band_fraction", "legible_char_fraction_cv")
               if m in result.columns]
    fig, axes = plt.subplots(len(metrics), 1, figsize=(max(6, 1.1 * len(groups) + 2), 2.3 * len(metrics)),
                             squeeze=False)
    for ax, m in zip(axes[:, 0], metrics):
        data = [[r[m] for r in rows if r.get(m) is not None and not r.get("error")] for rows in groups.values()]
        ax.boxplot(data, whis=(5, 95), showfliers=True, flierprops={"markersize": 2})
        ax.set_ylabel(m, fontsize=8)
        ax.set_xticks(range(1, len(labels) + 1), labels if ax is axes[-1, 0] else [""] * len(labels), fontsize=7)
        ax.grid(axis="y", lw=0.3)
    axes[0, 0].set_title(f"metric distributions over {len(result.rows)} episodes (whiskers 5-95 %)")
    fig.tight_layout()
    paths.append(d / "distributions.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    L = loss_values(result.rows, loss)
    order = np.argsort(-np.where(np.isfinite(L), L, np.finfo(float).max))[:12]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.2))
    ylab = [f"{result.rows[i]['scenario']} {result.rows[i]['rate_wpm']:g}wpm r{result.rows[i]['reader']} "
            f"{result.rows[i]['controller']}" for i in order]
    vals = [L[i] if np.isfinite(L[i]) else 0.0 for i in order]
    ax1.barh(range(len(order))[::-1], vals, color="tab:red")
    ax1.set_yticks(range(len(order))[::-1], ylab, fontsize=7)
    ax1.set_xlabel(f"loss ({'1 - ' if _better(loss) == 'higher' else ''}{loss})")
    ax1.set_title("worst episodes")
    _episode_scatter(fig, ax2, result.rows, L)
    fig.tight_layout()
    paths.append(d / "worst_cases.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    alphas = np.linspace(0.01, 1.0, 100)
    for lab, rows in zip(labels, groups.values()):
        Lg = loss_values(rows, loss)
        Lg = np.where(np.isfinite(Lg), Lg, np.nan)
        if np.all(np.isnan(Lg)):
            continue
        Lg = np.where(np.isnan(Lg), np.nanmax(Lg), Lg)
        ax.plot(alphas, [cvar(Lg, a) for a in alphas], label=lab.replace("\n", " "))
    ax.axvline(alpha, color="0.6", lw=0.8, ls="--")
    ax.set_xlabel("alpha (tail fraction)")
    ax.set_ylabel(f"CVaR of {'1 - ' if _better(loss) == 'higher' else ''}{loss}")
    ax.set_title("conditional value at risk (alpha = 1: the mean)")
    ax.legend(fontsize=7)
    ax.grid(lw=0.3)
    fig.tight_layout()
    paths.append(d / "cvar.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths
