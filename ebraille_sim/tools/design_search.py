r"""Design search: controller family, gains and firmware preset tuned on the benchmark's own score.

The objective is the benchmark (:mod:`ebraille_sim.tools.benchmark`) run on a *training*
population: the suite's scenarios, durations and score formula, but readers drawn by
:func:`ebraille_sim.scenarios.population.sample_devices` from the search's own seed (never
the benchmark's :data:`~ebraille_sim.tools.benchmark.POPULATION_SEED`) and without the
nominal device, and episode seeds of their own.  The design found is then benchmarked as
the leaderboard does, on the benchmark's readers, which the search never saw: the
*held-out* score, reported beside the training score.

Search space.  A list of *arms*, each a controller family on a firmware preset
(:mod:`ebraille_sim.estimation.presets`) with fixed gains, ranges of the gains searched and
start points (shipped designs or gain tables)::

    [[arm]]
    controller = "pid_dob"
    firmware = "fast_1khz"
    starts = ["dob_hold_1khz", "dob_learn_1khz"]
    [arm.gains]                        # fixed gains
    refresh_learning_lead_s = 0.01
    [arm.ranges]                       # [low, high] or [low, high, "log"]
    kp_v_per_n = [1.0, 5.0]
    q_time_constant_s = [0.0005, 0.01, "log"]

The optimiser sees one coordinate per searched gain of every arm, plus one that picks the arm
when there are several; gains are rounded to :data:`DIGITS` significant digits before a
run, so the design file holds the numbers that were measured.

Optimiser (:data:`OPTIMISERS`).  ``de`` (the default): SciPy's differential evolution
(``rand1bin``, deferred updating: every generation is evaluated as one batch, so the result
does not depend on ``jobs``) from an initial population that holds the start points, the
rest a Latin hypercube of the seed; SciPy's own polish is off.  ``optuna``: Optuna's TPE
sampler (the optional extra ``search``), the start points enqueued as its first trials, one
trial at a time.  The budget is a number of evaluations; the episodes of an evaluation run
over the ``jobs`` processes.

Journal.  Each evaluation is appended to ``journal.jsonl`` as soon as its episodes are done
(the candidate, its training statistic and score).  A rerun with the same settings replays
the optimiser from its seed and takes every evaluation the journal holds instead of running
it: it continues where the earlier run stopped, and gives the design an uninterrupted run
gives.  A journal of other settings is refused in one line.

Validation.  With ``validate`` = K > 0 the K best distinct candidates on the training readers
are run again on *validation* readers, a third population (drawn from
:func:`validation_seed` of the search's seed, never the benchmark's), and the design is the
best of them there.  The best of many candidates on a few readers is the one those readers
flatter most (its training score overstates it); the validation readers did not take part in
the choice that put the K candidates forward, so their statistic ranks the K without that
bias.  The validation runs are journalled too (under their readers' count: a rerun with other
validation settings reuses the search's evaluations).

Examples
--------
>>> space = default_space(["fast_1khz"])
>>> [(a.controller, a.firmware) for a in space.arms]
[('pid_dob', 'fast_1khz'), ('pid_scheduled', 'fast_1khz')]
>>> check_statistic("cvar10_in_band")
'cvar10_in_band'
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
from dataclasses import dataclass, field

__all__ = ["Param", "Arm", "SearchSpace", "STATISTICS", "DIGITS", "check_statistic", "default_space",
           "load_space", "check_space", "training_devices", "Candidate", "DesignSearch", "SearchResult",
           "design_text", "report_markdown", "JOURNAL", "SEARCH_FILES", "OPTIMISERS",
           "check_optimiser", "validation_seed"]

DIGITS = 4
"""Significant digits of a searched gain."""

OPTIMISERS = {"de": "SciPy's differential evolution",
              "optuna": "Optuna's TPE sampler (pip install 'ebraille-sim[search]')"}
"""The optimisers of the search by name."""

JOURNAL = "journal.jsonl"
"""The journal's file name in the output folder."""

SEARCH_FILES = ("design.toml", "report.md", "report.json", JOURNAL)
"""What ``ebraille-sim tune --search`` writes into its output folder."""

STATISTICS = {
    "score": "the benchmark's score (CVaR10 of in-band and char-in-band, less the share of episodes over 3 N)",
    "cvar10_in_band": "100 x mean over tracking scenarios of CVaR10(in_band_fraction)",
    "cvar10_char_in_band": "100 x mean over tracking scenarios of CVaR10(char_in_band_fraction)",
    "median_in_band": "100 x mean over tracking scenarios of the median in_band_fraction",
    "median_char_in_band": "100 x mean over tracking scenarios of the median char_in_band_fraction",
}
"""Objective statistics (higher is better), computed over the training population."""

_STAT_KEYS = {"cvar10_in_band": "in_band_fraction_cvar10", "cvar10_char_in_band": "char_in_band_fraction_cvar10",
              "median_in_band": "in_band_fraction_median", "median_char_in_band": "char_in_band_fraction_median"}


def check_statistic(name: str) -> str:
    """``name`` if it is one of :data:`STATISTICS` (one-line ``ValueError`` naming them otherwise)."""
    if name not in STATISTICS:
        raise ValueError(f"unknown statistic {name!r}; statistics: {', '.join(STATISTICS)}")
    return name


def check_optimiser(name: str) -> str:
    """``name`` if it is one of :data:`OPTIMISERS` and importable (one-line ``ValueError``)."""
    if name not in OPTIMISERS:
        raise ValueError(f"unknown optimiser {name!r}; optimisers: {', '.join(OPTIMISERS)}")
    if name == "optuna":
        try:
            import optuna  # noqa: F401
        except ImportError:
            raise ValueError("optimiser 'optuna' needs Optuna: pip install 'ebraille-sim[search]'") from None
    return name


@dataclass(frozen=True)
class Param:
    """One searched gain: its name, range and scale (``log``: searched on its logarithm)."""
    name: str
    lo: float
    hi: float
    log: bool = False

    def value(self, u: float) -> float:
        """The gain at the coordinate ``u`` in [0, 1], rounded to :data:`DIGITS` digits."""
        u = min(1.0, max(0.0, float(u)))
        v = math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo))) if self.log else \
            self.lo + u * (self.hi - self.lo)
        return float(f"{v:.{DIGITS}g}")

    def coordinate(self, v: float) -> float:
        """The coordinate in [0, 1] of gain ``v`` (clipped into the range)."""
        v = min(self.hi, max(self.lo, float(v)))
        if self.log:
            return (math.log(v) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (v - self.lo) / (self.hi - self.lo)


@dataclass(frozen=True)
class Arm:
    """A controller family on a firmware preset: fixed gains, searched ranges, start points."""
    controller: str
    firmware: str | None
    params: tuple = ()
    gains: dict = field(default_factory=dict)
    starts: tuple = ()

    @property
    def label(self) -> str:
        return f"{self.controller}@{self.firmware or 'scenario firmware'}"


@dataclass(frozen=True)
class SearchSpace:
    """Arms of a search (see the module docstring)."""
    arms: tuple

    @property
    def dimensions(self) -> int:
        return (1 if len(self.arms) > 1 else 0) + sum(len(a.params) for a in self.arms)

    def decode(self, x) -> "Candidate":
        """The candidate at the optimiser's point ``x`` (coordinates in [0, 1])."""
        x = [float(v) for v in x]
        k = 0
        if len(self.arms) > 1:
            k = min(len(self.arms) - 1, int(x[0] * len(self.arms)))
            x = x[1:]
        off = sum(len(a.params) for a in self.arms[:k])
        arm = self.arms[k]
        gains = dict(arm.gains)
        gains.update({p.name: p.value(x[off + i]) for i, p in enumerate(arm.params)})
        return Candidate(arm.controller, arm.firmware, dict(sorted(gains.items())))

    def encode(self, arm_index: int, gains: dict) -> list:
        """The point of arm ``arm_index`` at ``gains`` (other arms' coordinates at their middles)."""
        x = [(arm_index + 0.5) / len(self.arms)] if len(self.arms) > 1 else []
        for k, arm in enumerate(self.arms):
            for p in arm.params:
                x.append(p.coordinate(gains.get(p.name, 0.5 * (p.lo + p.hi))) if k == arm_index else 0.5)
        return x

    def describe(self) -> list:
        """The space as plain data (for the journal's header and the report)."""
        return [{"controller": a.controller, "firmware": a.firmware, "gains": a.gains,
                 "ranges": {p.name: [p.lo, p.hi] + (["log"] if p.log else []) for p in a.params},
                 "starts": [s if isinstance(s, str) else dict(s) for s in a.starts]} for a in self.arms]


@dataclass(frozen=True)
class Candidate:
    """A point of the space: controller family, firmware preset and every gain given."""
    controller: str
    firmware: str | None
    gains: dict

    def key(self) -> str:
        return json.dumps([self.controller, self.firmware, self.gains], sort_keys=True)


_PID_DOB_RANGES = {
    "kp_v_per_n": (0.5, 6.0, False), "ki_v_per_ns": (0.5, 12.0, False),
    "compensation_fraction": (0.2, 1.0, False), "q_time_constant_s": (0.0005, 0.02, True),
    "hold_damping_v_per_v": (0.0, 1.5, False),
}
_LEARNING_RANGES = {"refresh_learning_gain": (0.0, 0.5, False), "refresh_hold_damping_v_per_v": (0.0, 3.0, False)}
_SCHEDULED_RANGES = {"kp_v_per_n": (0.2, 4.0, True), "ki_v_per_ns": (0.2, 12.0, True),
                     "kd_vs_per_n": (0.0, 0.02, False)}


def _params(ranges: dict) -> tuple:
    return tuple(Param(n, lo, hi, log) for n, (lo, hi, log) in ranges.items())


def default_space(firmwares=None) -> SearchSpace:
    """The default space on the firmware presets ``firmwares`` (default: every shipped preset).

    For each preset: ``pid_dob`` (PID with the current-based disturbance observer and hold
    damping; on a 1 kHz preset also refresh learning) started from the shipped designs of that
    firmware, and ``pid_scheduled`` started from its default gains.
    """
    from controllers.designs import designs
    from ebraille_sim.estimation.presets import firmware_presets
    names = sorted(firmware_presets()) if firmwares is None else list(firmwares)
    arms = []
    for fw in names:
        shipped = sorted(d.name for d in designs().values() if d.firmware == fw and d.controller == "pid_dob")
        learning = any("refresh_learning_gain" in designs()[d].gains for d in shipped)
        ranges = dict(_PID_DOB_RANGES, **(_LEARNING_RANGES if learning else {}))
        fixed = {}
        for d in shipped:                       # the shipped designs' other gains stay as they are
            fixed.update({k: v for k, v in designs()[d].gains.items() if k not in ranges})
        arms.append(Arm("pid_dob", fw, _params(ranges), fixed, tuple(shipped)))
        arms.append(Arm("pid_scheduled", fw, _params(_SCHEDULED_RANGES), {}, ({},)))
    return check_space(SearchSpace(tuple(arms)))


def _range(where: str, name: str, value) -> Param:
    ok = isinstance(value, list) and len(value) in (2, 3) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value[:2])
    if not ok or (len(value) == 3 and value[2] != "log"):
        raise ValueError(f"{where}: range {name} must be [low, high] or [low, high, \"log\"], got {value!r}")
    return Param(name, float(value[0]), float(value[1]), len(value) == 3)


def load_space(path) -> SearchSpace:
    """The search space of a TOML/JSON file (module docstring); one-line ``ValueError``."""
    from ebraille_sim.base.validation import check_keys, read_table
    p = os.fspath(path)
    data = read_table(p, "search space")
    check_keys(p, data, ("arm",))
    arms = data.get("arm")
    if not isinstance(arms, list) or not arms:
        raise ValueError(f"{p}: the search space is empty (give at least one [[arm]])")
    out = []
    for i, a in enumerate(arms):
        where = f"{p} arm {i + 1}"
        if not isinstance(a, dict):
            raise ValueError(f"{where}: must be a table")
        check_keys(where, a, ("controller", "firmware", "gains", "ranges", "starts"))
        if not isinstance(a.get("controller"), str):
            raise ValueError(f"{where}: 'controller' must name a controller family")
        ranges, gains, starts = a.get("ranges", {}), a.get("gains", {}), a.get("starts", [])
        if not isinstance(ranges, dict) or not isinstance(gains, dict) or not isinstance(starts, list):
            raise ValueError(f"{where}: [ranges] and [gains] must be tables, 'starts' a list")
        out.append(Arm(a["controller"], a.get("firmware"), tuple(_range(where, n, v) for n, v in ranges.items()),
                       dict(gains), tuple(starts)))
    return check_space(SearchSpace(tuple(out)), p)


def check_space(space: SearchSpace, where: str = "search space") -> SearchSpace:
    """Refuse an empty space, an empty or inverted range, a log range through zero, an unknown
    firmware or controller, or gains a family does not take (one-line ``ValueError``)."""
    import controllers
    from controllers.designs import get_design
    from ebraille_sim.estimation.presets import get_firmware
    if not space.arms:
        raise ValueError(f"{where}: the search space is empty (no arm)")
    if space.dimensions == 0:
        raise ValueError(f"{where}: the search space is empty (no range and a single arm)")
    for arm in space.arms:
        for p in arm.params:
            if not (math.isfinite(p.lo) and math.isfinite(p.hi)):
                raise ValueError(f"{where}: {arm.label} range {p.name} [{p.lo:g}, {p.hi:g}] must be finite")
            if p.hi < p.lo:
                raise ValueError(f"{where}: {arm.label} range {p.name} [{p.lo:g}, {p.hi:g}] is inverted")
            if p.hi == p.lo:
                raise ValueError(f"{where}: {arm.label} range {p.name} [{p.lo:g}, {p.hi:g}] is empty")
            if p.log and p.lo <= 0:
                raise ValueError(f"{where}: {arm.label} log range {p.name} must be above 0, got {p.lo:g}")
        if arm.firmware is not None:
            try:
                get_firmware(arm.firmware)
            except (ValueError, FileNotFoundError) as exc:
                raise ValueError(f"{where}: {arm.label}: {exc}") from None
        for s in arm.starts:
            if isinstance(s, str):
                d = get_design(s)
                if d.controller != arm.controller:
                    raise ValueError(f"{where}: {arm.label}: start {s!r} is a {d.controller} design")
            elif not isinstance(s, dict):
                raise ValueError(f"{where}: {arm.label}: a start must be a design name or a gains table")
        lo = {p.name: p.lo for p in arm.params}
        try:
            controllers.make(arm.controller, **dict(arm.gains, **lo))
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{where}: {arm.label}: {str(exc).splitlines()[0]}") from None
    return space


def training_devices(scenario: str, seed: int, n: int):
    """``n`` training readers of a suite scenario: drawn around its device from ``seed`` (which
    must differ from the benchmark's reader seed), without the nominal device."""
    from ebraille_sim.scenarios.population import sample_devices
    from ebraille_sim.scenarios.spec import load_scenario
    from ebraille_sim.tools.benchmark import POPULATION_SEED
    if seed == POPULATION_SEED:
        raise ValueError(f"seed {seed} is the benchmark's reader seed: the held-out readers would be trained on; "
                         "give another seed")
    return sample_devices(seed, n, base=load_scenario(scenario).device)


VALIDATION_SEED_STEP = 1_000_003
"""The validation readers' seed is the search's seed plus this (one more when that is the
benchmark's reader seed)."""


def validation_seed(seed: int) -> int:
    """The seed of the validation readers of a search of ``seed``: neither the search's own nor
    the benchmark's reader seed.

    >>> validation_seed(0)
    1000003
    """
    from ebraille_sim.tools.benchmark import POPULATION_SEED
    v = (int(seed) + VALIDATION_SEED_STEP) % (2 ** 63)
    return v + 1 if v == POPULATION_SEED else v


def _scenario_spec(sc):
    """The spec of one suite scenario, as the benchmark builds it."""
    from ebraille_sim.tools.benchmark import scenario_spec
    return scenario_spec(sc)


def _episode(task) -> dict:
    """One training episode: ``(candidate, BenchScenario, device, seed, reader)`` -> a benchmark row."""
    import controllers
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.tools.benchmark import KEPT
    cand, sc, device, seed, reader = task
    base = {"controller": "candidate", "scenario": sc.key, "reader": reader, "seed": seed}
    try:
        res = run_scenario(_scenario_spec(sc), controller=controllers.make(cand.controller, **cand.gains),
                           seed=seed, device=device, firmware=cand.firmware)
    except (ValueError, FloatingPointError) as exc:
        return dict(base, error=str(exc).splitlines()[0])
    num = {k: res.metrics.get(k) for k in KEPT}
    return dict(base, **{k: None if v is None or not math.isfinite(float(v)) else float(v) for k, v in num.items()},
                supervisor_fault=(res.supervisor or {}).get("fault"))


def _statistic(summary: dict, statistic: str, suite) -> float:
    if statistic == "score":
        return float(summary["score"])
    vals = [summary["scenarios"][sc.key][_STAT_KEYS[statistic]] for sc in suite.scenarios if not sc.fault]
    return round(100.0 * sum(v or 0.0 for v in vals) / len(vals), 3)


@dataclass
class SearchResult:
    """What a search found: the best candidate, its training statistic and score, the history;
    with validation, the candidates validated (training and validation statistic and score,
    best on the validation readers first) and the chosen one's validation statistic."""
    best: Candidate
    train_value: float
    train_score: float
    evaluations: int
    cached: int
    history: list
    starts: list
    validated: list = field(default_factory=list)
    validation_value: float | None = None


class DesignSearch:
    """A search over ``space`` with the objective of the module docstring.

    Parameters
    ----------
    space : SearchSpace
    suite : str
        The benchmark suite whose scenarios, durations and score the objective uses.
    statistic : str
        One of :data:`STATISTICS`.
    readers : int
        Training readers per scenario (drawn, see :func:`training_devices`).
    seed : int
        Seed of the training readers, the episode seeds and the optimiser.
    evaluations : int
        Budget: candidates evaluated (the starts included).
    jobs : int
        Local worker processes; the result does not depend on it.
    optimiser : str
        One of :data:`OPTIMISERS`.
    validate : int
        Candidates (the best distinct ones on the training readers) run again on the
        validation readers, the design the best of them there; 0 (default) chooses on the
        training readers.
    validation_readers : int, optional
        Validation readers per scenario (default: twice ``readers``), drawn from
        :func:`validation_seed`.
    journal : path, optional
        The journal file (module docstring); None keeps no journal.
    """

    def __init__(self, space: SearchSpace, suite: str = "standard", statistic: str = "score", readers: int = 4,
                 seed: int = 0, evaluations: int = 60, jobs: int = 1, journal=None, progress=None,
                 optimiser: str = "de", validate: int = 0, validation_readers: int | None = None):
        from ebraille_sim.tools.benchmark import get_suite
        check_statistic(statistic)
        self.optimiser = check_optimiser(optimiser)
        if isinstance(evaluations, bool) or not isinstance(evaluations, int) or evaluations < 1:
            raise ValueError(f"the budget must be at least 1 evaluation, got {evaluations!r}")
        if isinstance(readers, bool) or not isinstance(readers, int) or readers < 1:
            raise ValueError(f"training readers must be at least 1, got {readers!r}")
        if jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {jobs}")
        if isinstance(validate, bool) or not isinstance(validate, int) or validate < 0:
            raise ValueError(f"validate must be a whole number of candidates >= 0, got {validate!r}")
        validation_readers = 2 * readers if validation_readers is None else validation_readers
        if isinstance(validation_readers, bool) or not isinstance(validation_readers, int) or validation_readers < 1:
            raise ValueError(f"validation readers must be at least 1, got {validation_readers!r}")
        self.validate, self.validation_readers = validate, validation_readers
        self.space, self.suite, self.statistic = space, get_suite(suite), statistic
        self.readers, self.seed, self.evaluations, self.jobs = readers, int(seed), evaluations, int(jobs)
        self.progress = progress
        self.devices = {sc.key: training_devices(sc.scenario, self.seed, readers) for sc in self.suite.scenarios}
        self.validation_devices = {} if not validate else {
            sc.key: training_devices(sc.scenario, validation_seed(self.seed), validation_readers)
            for sc in self.suite.scenarios}
        self.journal = None if journal is None else pathlib.Path(journal)
        self.cache: dict = {}
        self.history: list = []
        self.ran = 0

    def header(self) -> dict:
        """What a journal's first line records: a rerun continues only under the same settings."""
        from ebraille_sim.tools.benchmark import SUITE_VERSION
        head = {"journal": "ebraille-sim design search", "suite": self.suite.name, "suite_version": SUITE_VERSION,
                "statistic": self.statistic, "readers": self.readers, "seed": self.seed,
                "optimiser": self.optimiser,
                "space": self.space.describe()}
        return head

    def check_journal(self) -> list:
        """The entries of the journal, refused (one-line ``ValueError``) when it is not this
        search's; an empty list when there is none yet."""
        if self.journal is None or not self.journal.exists():
            return []
        if self.journal.is_symlink() or not self.journal.is_file():
            raise ValueError(f"{self.journal} is not a regular file")
        lines = self.journal.read_text(encoding="utf-8").splitlines()
        if not lines or lines[0] != json.dumps(self.header(), sort_keys=True):
            raise ValueError(f"{self.journal} is the journal of another search (suite, statistic, readers, seed, "
                             "optimiser or space differ); give another --out or remove it")
        out = []
        for line in lines[1:]:
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:        # a line cut by a kill: that evaluation runs again
                continue
        return out

    def _open_journal(self) -> None:
        if self.journal is None:
            return
        entries = self.check_journal()
        if self.journal.exists():
            self.cache.update({e["key"]: e for e in entries})
        else:
            self.journal.parent.mkdir(parents=True, exist_ok=True)
            self.journal.write_text(json.dumps(self.header(), sort_keys=True) + "\n", encoding="utf-8")

    def _tasks(self, cand: Candidate, validation: bool = False) -> list:
        devices, seed = (self.validation_devices, validation_seed(self.seed)) if validation else (self.devices, self.seed)
        out = []
        for i, sc in enumerate(self.suite.scenarios):
            base = _scenario_spec(sc).seed + 1_000_003 * (seed % 1_000_000_007 + 1) + 7919 * (i + 1)
            out += [(cand, sc, dev, (base + 101 * r) % (2 ** 63), r) for r, dev in enumerate(devices[sc.key])]
        return out

    def _summary(self, rows: list, readers: int) -> dict:
        from ebraille_sim.tools.benchmark import BenchmarkResult, summarise
        return summarise(BenchmarkResult(self.suite, ["candidate"], readers, rows, 0.0, self.jobs))["candidate"]

    def _run_entries(self, cands: list, validation: bool = False) -> None:
        """Run the candidates of ``cands`` that the cache does not hold (on the validation readers
        when ``validation``, cached and journalled under :meth:`_validation_prefix` and their key)."""
        prefix = self._validation_prefix() if validation else ""
        by_key = {prefix + c.key(): c for c in cands}
        todo = [k for k in by_key if k not in self.cache]
        tasks = [t for k in todo for t in self._tasks(by_key[k], validation)]
        per = len(tasks) // max(1, len(todo))
        if not tasks:
            return
        readers = self.validation_readers if validation else self.readers
        for k, rows in zip(todo, self._rows(tasks, per, todo)):
            s = self._summary(rows, readers)
            e = {"key": k, "value": _statistic(s, self.statistic, self.suite), "score": s["score"],
                 "errors": s["errors"]}
            self.cache[k] = e
            self.ran += 0 if validation else 1
            if self.journal is not None:
                with open(self.journal, "a", encoding="utf-8") as f:
                    f.write(json.dumps(e, sort_keys=True) + "\n")

    def _evaluate(self, cands: list) -> list:
        """Statistics of ``cands`` (journal entries where held, else run), in order."""
        self._run_entries(cands)
        out = []
        for c in cands:
            e = self.cache[c.key()]
            self.history.append({"controller": c.controller, "firmware": c.firmware, "gains": c.gains,
                                 "value": e["value"], "score": e["score"]})
            if self.progress:
                self.progress(min(len(self.history), self.evaluations), self.evaluations)
            out.append(e["value"])
        return out

    def _rows(self, tasks: list, per: int, todo: list):
        """Run ``tasks`` (``per`` for each candidate of ``todo``, in order); yield each candidate's
        rows as soon as they are all done, so that the journal keeps what finished."""
        def chunks(stream):
            buf = []
            for row in stream:
                buf.append(row)
                if len(buf) == per:
                    yield buf
                    buf = []
        jobs = min(self.jobs, len(tasks))
        if jobs == 1:
            yield from chunks(map(_episode, tasks))
            return
        from concurrent.futures import ProcessPoolExecutor

        from ebraille_sim.tools.parallel import process_context
        with ProcessPoolExecutor(max_workers=jobs, mp_context=process_context()) as ex:
            yield from chunks(ex.map(_episode, tasks, chunksize=1))

    def _population(self, size: int):
        """The initial population: the start points, then a Latin hypercube of the seed."""
        import numpy as np
        from scipy.stats import qmc

        from controllers.designs import get_design
        starts = []
        self.start_labels = []
        for k, arm in enumerate(self.space.arms):
            for s in arm.starts:
                self.start_labels.append(s if isinstance(s, str) else f"{arm.controller} at the given gains")
                gains = dict(_defaults(arm), **(get_design(s).gains if isinstance(s, str) else dict(s)))
                if "refresh_hold_damping_v_per_v" in {p.name for p in arm.params} and \
                        "refresh_hold_damping_v_per_v" not in gains:
                    gains = dict(gains, refresh_hold_damping_v_per_v=gains.get("hold_damping_v_per_v", 0.0))
                starts.append(self.space.encode(k, gains))
        lhs = qmc.LatinHypercube(d=self.space.dimensions, seed=np.random.default_rng(self.seed)).random(size)
        pop = np.clip(lhs, 0.0, 1.0)
        for i, x in enumerate(starts[:size]):
            pop[i] = x
        return pop, len(starts)

    def run(self) -> SearchResult:
        """Search; the best candidate over every evaluation (the starts included), or with
        ``validate`` the best on the validation readers of the best on the training readers."""
        import numpy as np
        from scipy.optimize import differential_evolution
        self._open_journal()
        d = self.space.dimensions
        size = max(5, min(16, d + 4, self.evaluations))
        pop, n_starts = self._population(size)
        if self.optimiser == "optuna":
            self._run_optuna(pop[:n_starts])
        elif self.evaluations < 5 or self.evaluations <= size:
            self._evaluate([self.space.decode(x) for x in pop[:self.evaluations]])
        else:
            generations = self.evaluations // size - 1

            def batch_map(_func, xs):
                return self._evaluate([self.space.decode(x) for x in xs])

            differential_evolution(lambda x: 0.0, [(0.0, 1.0)] * d, init=pop, maxiter=generations, popsize=1,
                                   seed=np.random.default_rng(self.seed + 1), polish=False, tol=0.0, atol=0.0,
                                   updating="deferred", workers=_NegatedMap(batch_map), mutation=(0.5, 1.0),
                                   recombination=0.7)
            rest = self.evaluations - len(self.history)
            if rest > 0:            # the budget's remainder: a last partial generation around the best
                rng = np.random.default_rng(self.seed + 2)
                best = self._best_point()
                xs = [np.clip(self.space.encode(*best) + rng.normal(0.0, 0.05, d), 0.0, 1.0) for _ in range(rest)]
                self._evaluate([self.space.decode(x) for x in xs])
        return self._result(n_starts)

    def _validation_prefix(self) -> str:
        """The journal key's prefix of a validation run: the validation readers' count, so that a
        rerun with other validation settings reuses every search evaluation and no other count's
        validation."""
        return f"validation/{self.validation_readers}:"

    def _validated(self) -> list:
        """The ``validate`` best distinct candidates on the training readers (ties: the earlier),
        run on the validation readers: history entries with ``validation_value`` and
        ``validation_score``, the best on the validation readers first (ties: the better
        training statistic)."""
        order = sorted(range(len(self.history)), key=lambda j: (-self.history[j]["value"], j))
        top, seen = [], set()
        for j in order:
            h = self.history[j]
            cand = Candidate(h["controller"], h["firmware"], h["gains"])
            if cand.key() not in seen:
                seen.add(cand.key())
                top.append((j, cand))
            if len(top) == self.validate:
                break
        self._run_entries([c for _, c in top], validation=True)
        out = []
        for rank, (j, cand) in enumerate(top):
            e = self.cache[self._validation_prefix() + cand.key()]
            out.append(dict(self.history[j], validation_value=e["value"], validation_score=e["score"],
                            training_rank=rank + 1))
        return sorted(out, key=lambda h: (-h["validation_value"], -h["value"], h["training_rank"]))

    def _run_optuna(self, starts) -> None:
        import optuna
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        study = optuna.create_study(direction="maximize", sampler=optuna.samplers.TPESampler(seed=self.seed))
        names = [f"x{i}" for i in range(self.space.dimensions)]
        for x in starts:
            study.enqueue_trial(dict(zip(names, (float(v) for v in x))))
        for _ in range(self.evaluations):
            trial = study.ask()
            x = [trial.suggest_float(n, 0.0, 1.0) for n in names]
            study.tell(trial, self._evaluate([self.space.decode(x)])[0])

    def _best_point(self):
        h = max(self.history, key=lambda e: e["value"])
        k = next(i for i, a in enumerate(self.space.arms)
                 if (a.controller, a.firmware) == (h["controller"], h["firmware"]))
        return k, h["gains"]

    def _result(self, n_starts: int) -> SearchResult:
        evaluations = len(self.history)
        validated = self._validated() if self.validate else []
        if validated:
            h = validated[0]
        else:
            h = self.history[max(range(len(self.history)), key=lambda j: (self.history[j]["value"], -j))]
        starts = [dict(e, start=label) for e, label in zip(self.history[:n_starts], self.start_labels)]
        return SearchResult(Candidate(h["controller"], h["firmware"], h["gains"]), h["value"], h["score"],
                            evaluations, evaluations - self.ran, list(self.history), starts,
                            validated, h.get("validation_value"))


def _defaults(arm: Arm) -> dict:
    """The family's own values of the searched gains, where its configuration holds them."""
    import controllers
    cfg = getattr(controllers.make(arm.controller, **arm.gains), "config", None)
    if cfg is None or not dataclasses.is_dataclass(cfg):
        return {}
    return {p.name: getattr(cfg, p.name) for p in arm.params if getattr(cfg, p.name, None) is not None}


class _NegatedMap:
    """The map SciPy calls on a generation: statistics negated (SciPy minimises)."""

    def __init__(self, batch):
        self.batch = batch

    def __call__(self, func, xs):
        return [-v for v in self.batch(func, list(xs))]


def design_text(name: str, description: str, cand: Candidate, benchmark: dict) -> str:
    """A design file (:mod:`controllers.designs`) of ``cand`` with its ``[benchmark]`` table."""
    from ebraille_sim.analysis.robust import toml_value
    lines = [f"name = {toml_value(name)}", f"description = {toml_value(description)}",
             f"controller = {toml_value(cand.controller)}"]
    if cand.firmware is not None:
        lines.append(f"firmware = {toml_value(cand.firmware)}")
    lines += ["", "[gains]"] + [f"{k} = {toml_value(v)}" for k, v in cand.gains.items() if v is not None]
    lines += ["", "[benchmark]"] + [f"{k} = {toml_value(v)}" for k, v in benchmark.items() if v is not None]
    return "\n".join(lines) + "\n"


def report_markdown(rep: dict, held_out_tables: str) -> str:
    """``report.md`` of a search: the design, training beside held-out score, the best candidates."""
    d = rep["design"]
    ref = rep.get("reference")
    out = [f"# Design search: {rep['name']}", "",
           f"Suite `{rep['suite']}`, statistic `{rep['statistic']}`, {rep['training_readers']} training readers per "
           f"scenario drawn from seed {rep['seed']} (the benchmark draws its readers from {_population_seed()}), "
           f"{rep['evaluations']} evaluations ({rep['from_journal']} read from the journal), search "
           f"{rep['wall_s']['search']:.0f} s, held-out check {rep['wall_s']['held_out']:.0f} s.", "",
           "| | training (search readers) | held-out (benchmark readers) |", "|---|---:|---:|",
           f"| score | {rep['training_score']:.2f} | {rep['held_out_score']:.2f} |"]
    if rep.get("validated"):
        out += ["", f"Chosen on {rep['validation_readers']} validation readers per scenario (seed "
                f"{validation_seed(rep['seed'])}) among the {len(rep['validated'])} best on the training readers:", "",
                "| training rank | controller | firmware | training score | validation score |", "|---:|---|---|---:|---:|"]
        out += [f"| {h['training_rank']} | {h['controller']} | {h['firmware']} | {h['score']:.2f} | "
                f"{h['validation_score']:.2f} |" for h in rep["validated"]]
    if ref is not None and ref.get("score") is not None:
        out += ["", f"Best shipped design on `{d['firmware']}`: `{ref['design']}`, {ref['score']:.2f} "
                f"({ref['source']}); the found design reaches {100 * rep['ratio_to_reference']:.1f} % of it."]
    out += ["", f"## Design: `{d['controller']}` on `{d['firmware']}`", "", "| gain | value |", "|---|---:|"]
    out += [f"| {k} | {v:g} |" for k, v in d["gains"].items() if isinstance(v, (int, float))]
    same = [h["start"] for h in rep["starts"] if (h["controller"], h["firmware"], h["gains"]) ==
            (d["controller"], d["firmware"], d["gains"])]
    if same:
        out += ["", f"No candidate beat the start point `{same[0]}` on the training readers: the design is that start."]
    out += ["", "## Start points (training)", "", "| start | controller | firmware | training score |",
            "|---|---|---|---:|"]
    out += [f"| {h['start']} | {h['controller']} | {h['firmware']} | {h['score']:.2f} |" for h in rep["starts"]]
    top = sorted(rep["history"], key=lambda h: -h["value"])[:10]
    head = "score" if rep["statistic"] == "score" else f"{rep['statistic']} | score"
    out += ["", "## Best candidates (training)", "", f"| controller | firmware | {head} |",
            "|---|---|---:|" + ("" if rep["statistic"] == "score" else "---:|")]
    out += [f"| {h['controller']} | {h['firmware']} | " + (f"{h['score']:.2f} |" if rep["statistic"] == "score" else
                                                            f"{h['value']:.2f} | {h['score']:.2f} |") for h in top]
    out += ["", "## Held-out benchmark", "", held_out_tables]
    return "\n".join(out) + "\n"


def _population_seed() -> int:
    from ebraille_sim.tools.benchmark import POPULATION_SEED
    return POPULATION_SEED
