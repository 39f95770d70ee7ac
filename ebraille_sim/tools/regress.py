"""Regression suite: run every scenario and compare its metrics with stored baselines.

``ebraille-sim regress`` runs each ``scenarios/NAME.toml`` with its own seed and
controller and compares the metrics with ``scenarios/baselines/NAME.json``.  A metric has
*moved* when ``|current - baseline| > abs + rel * |baseline|`` with the tolerances of
:data:`TOLERANCES`; a metric that is None on one side only has moved too.  Any move in
either direction fails (an improvement is a change to review and accept with
``--update``, which rewrites the baselines).  The scenario's own ``[criteria]`` are
checked as well; they fail whatever the baseline says.

The simulation is deterministic (same seed, same trace, exactly), so on one machine an
unchanged tree reproduces every baseline bit for bit.  The tolerances are there for
floating-point differences across platforms and library versions, and are set below what
a reader would notice: one character in 50-100 for the per-character fractions, a few mN
for the force errors.

Tolerances
----------
==========================  =========  ========  =======  ==========================================
metric                      abs        rel       better   reasoning
==========================  =========  ========  =======  ==========================================
force_rmse_n                0.002 N    5 %       lower    2 mN is below the 4 mN ADC step at 1 N
force_mae_n                 0.002 N    5 %       lower    as force_rmse_n
in_band_fraction            0.01       0         higher   1 % of the reading time
char_in_band_fraction       0.02       0         higher   one character in 50
peak_force_n                0.02 N     2 %       lower    20 mN, 2 % of the regulated force
contact_loss_count          0          0         lower    every contact loss counts
onset_overshoot_fraction    0.01       0         lower    1 % of the setpoint
settling_time_s             0.02 s     5 %       lower    20 control periods
estimate_rmse_n             0.002 N    5 %       lower    as force_rmse_n
energy_j                    0.001 J    3 %       lower    energy integrates every transient
characters                  0          0         -        the schedule must not change
wpm                         0.01       0         -        the schedule must not change
legible_char_fraction       0.02       0         higher   one character in 50
legible_char_fraction_cv    0.02       0         higher   one character in 50
(any other metric)          1e-6       1e-3      -        deterministic; tighten or loosen here
real_time_factor            excluded                      wall-clock, not a property of the model
==========================  =========  ========  =======  ==========================================

For CI, :func:`junit_xml` (one test case per scenario, a failure listing what moved) and
:func:`json_document` (every row) give the outcome as files.

Examples
--------
>>> row = compare_metrics({"force_rmse_n": 0.030}, {"force_rmse_n": 0.020})[0]
>>> row.status, round(row.limit, 4)
('moved', 0.003)
"""
from __future__ import annotations

import json
import math
import pathlib
from dataclasses import dataclass

__all__ = ["Tolerance", "TOLERANCES", "DEFAULT_TOLERANCE", "EXCLUDED", "Row", "ScenarioCheck",
           "compare_metrics", "check_criteria", "baseline_path", "read_baseline", "write_baseline",
           "regress_scenarios", "format_report", "scenario_files", "FAILING", "json_document", "junit_xml"]


@dataclass(frozen=True)
class Tolerance:
    """Allowed change of a metric: ``abs + rel * |baseline|``; ``better`` is 'lower', 'higher' or ''."""
    abs: float
    rel: float = 0.0
    better: str = ""

    def limit(self, baseline: float) -> float:
        return self.abs + self.rel * abs(baseline)


TOLERANCES: dict[str, Tolerance] = {
    "force_rmse_n": Tolerance(0.002, 0.05, "lower"),
    "force_mae_n": Tolerance(0.002, 0.05, "lower"),
    "in_band_fraction": Tolerance(0.01, 0.0, "higher"),
    "char_in_band_fraction": Tolerance(0.02, 0.0, "higher"),
    "peak_force_n": Tolerance(0.02, 0.02, "lower"),
    "contact_loss_count": Tolerance(0.0, 0.0, "lower"),
    "onset_overshoot_fraction": Tolerance(0.01, 0.0, "lower"),
    "settling_time_s": Tolerance(0.02, 0.05, "lower"),
    "estimate_rmse_n": Tolerance(0.002, 0.05, "lower"),
    "energy_j": Tolerance(0.001, 0.03, "lower"),
    "characters": Tolerance(0.0, 0.0, ""),
    "wpm": Tolerance(0.01, 0.0, ""),
    "legible_char_fraction": Tolerance(0.02, 0.0, "higher"),
    "legible_char_fraction_cv": Tolerance(0.02, 0.0, "higher"),
}
"""Per-metric tolerances (the module table)."""

DEFAULT_TOLERANCE = Tolerance(1e-6, 1e-3, "")
"""Tolerance of a metric missing from :data:`TOLERANCES`."""

EXCLUDED = {"real_time_factor": "wall-clock"}
"""Metrics never stored or compared, with the reason."""

@dataclass
class Row:
    """One line of the regression report."""
    scenario: str
    metric: str
    baseline: object
    current: object
    limit: float | None
    status: str            # ok | moved | new | removed | criterion | missing | error
    note: str = ""


def _is_num(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def compare_metrics(current: dict, baseline: dict, scenario: str = "", tolerances=None) -> list[Row]:
    """Rows comparing ``current`` with ``baseline`` (excluded metrics skipped).

    A metric present now but absent from the baseline is ``new`` (reported, not a
    failure); one in the baseline but not produced any more is ``removed`` (a failure).
    """
    tol = TOLERANCES if tolerances is None else tolerances
    rows = []
    for k in list(baseline) + [k for k in current if k not in baseline]:
        if k in EXCLUDED:
            continue
        t = tol.get(k, DEFAULT_TOLERANCE)
        if k not in current:
            rows.append(Row(scenario, k, baseline[k], None, None, "removed", "metric no longer produced"))
            continue
        if k not in baseline:
            rows.append(Row(scenario, k, None, current[k], None, "new", "not in the baseline; run --update"))
            continue
        b, c = baseline[k], current[k]
        if b is None or c is None:
            rows.append(Row(scenario, k, b, c, None, "ok" if b is None and c is None else "moved"))
            continue
        if not (_is_num(b) and _is_num(c)):
            rows.append(Row(scenario, k, b, c, None, "ok" if b == c else "moved"))
            continue
        lim = t.limit(b)
        moved = not (math.isfinite(c) and abs(c - b) <= lim * (1 + 1e-12))
        note = ""
        if moved and t.better:
            note = "better" if (c < b) == (t.better == "lower") else "worse"
        rows.append(Row(scenario, k, b, c, lim, "moved" if moved else "ok", note))
    return rows


def check_criteria(metrics: dict, criteria: dict, scenario: str = "") -> list[Row]:
    """Rows for the scenario's ``[criteria]`` (status ``criterion`` when one fails).

    The bounds are evaluated by :func:`ebraille_sim.scenarios.metrics.evaluate_criteria`.
    """
    from ebraille_sim.scenarios.metrics import CRITERIA, evaluate_criteria
    rows = []
    for key, c in evaluate_criteria(criteria, metrics).items():
        op = "<=" if CRITERIA[key][1] == "le" else ">="
        rows.append(Row(scenario, c["metric"], f"{op} {c['limit']:g}", c["value"], None,
                        "ok" if c["passed"] else "criterion", f"[criteria] {key}"))
    return rows


def baseline_path(scenario_file) -> pathlib.Path:
    """``scenarios/baselines/NAME.json`` beside ``scenarios/NAME.toml``."""
    p = pathlib.Path(scenario_file)
    return p.parent / "baselines" / f"{p.stem}.json"


def read_baseline(path) -> dict:
    """The stored document ``{"scenario", "seed", "controller", "metrics"}``."""
    from ebraille_sim.base.files import read_json, short
    p = pathlib.Path(path)
    doc = read_json(p, "baseline")
    if not isinstance(doc, dict) or not isinstance(doc.get("metrics"), dict):
        raise ValueError(f"baseline {short(p)} has no 'metrics' table")
    return doc


def write_baseline(path, result) -> None:
    """Write the baseline document of a :class:`~ebraille_sim.scenarios.runner.RunResult`."""
    from ebraille_sim.tools.outputs import write_file
    doc = {"scenario": result.spec.name, "seed": result.seed, "controller": result.controller_name,
           "metrics": {k: v for k, v in result.metrics.items() if k not in EXCLUDED}}
    write_file(path, json.dumps(doc, indent=2, sort_keys=False) + "\n", "baseline")


def scenario_files(scenario_dir=None, only=None) -> list[pathlib.Path]:
    """The scenario files to check.

    Parameters
    ----------
    scenario_dir : path, optional
        Folder of scenario files.  Without it, all scenarios means every ``*.toml`` of
        ``./scenarios`` when that folder exists, else of the shipped library.
    only : list of str, optional
        Scenarios to check instead of all: names or scenario file paths.  A path is taken as
        it is (its baseline is ``baselines/NAME.json`` beside it).  A name is looked up in
        ``scenario_dir`` when given, else in ``./scenarios`` and then in the shipped library
        (see :func:`ebraille_sim.scenarios.spec.scenario_dirs`), so your own folder never
        hides a shipped scenario it does not contain.

    Raises
    ------
    ValueError
        For an unknown name or a scenario file that does not exist (one line naming it and,
        for a name, the scenarios available).
    FileNotFoundError
        For a scenario folder that does not exist.
    """
    from ebraille_sim.scenarios.spec import resolve_scenario_path, scenario_dirs
    d = None
    if scenario_dir is not None:
        d = pathlib.Path(scenario_dir)
        if not d.is_dir():
            raise FileNotFoundError(f"scenario folder {str(d)!r} not found")
    if not only:
        if d is None:
            dirs = scenario_dirs()
            if not dirs:
                raise FileNotFoundError("no scenarios/ folder found in the working folder or the installation")
            d = dirs[0]
        return sorted(d.glob("*.toml"))
    if d is None:
        return [resolve_scenario_path(entry) for entry in only]
    files = []
    for entry in only:
        p = pathlib.Path(entry)
        if p.suffix == "" and len(p.parts) == 1:
            p = d / f"{entry}.toml"
            if not p.is_file():
                names = ", ".join(f.stem for f in sorted(d.glob("*.toml"))) or "none"
                raise ValueError(f"unknown scenario {entry!r} in {str(d)!r}; available: {names}")
        elif not p.is_file():
            raise ValueError(f"scenario file {str(entry)!r} not found")
        files.append(p)
    return files


FAILING = ("moved", "removed", "criterion", "missing", "error")
"""Row statuses that fail a scenario."""


@dataclass
class ScenarioCheck:
    """Outcome of one scenario: its report rows, the wall time of its run and its files."""
    name: str
    rows: list
    wall_s: float
    updated: bool = False
    source: str = ""
    baseline: str = ""

    @property
    def failed(self) -> bool:
        return any(r.status in FAILING for r in self.rows)


def _check_one(path, update: bool, controller, baseline_dir) -> ScenarioCheck:
    import time

    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.scenarios.spec import load_scenario
    t0 = time.perf_counter()
    name = pathlib.Path(path).stem
    bpath = (pathlib.Path(baseline_dir) / f"{name}.json") if baseline_dir else baseline_path(path)

    def done(rows, updated=False):
        return ScenarioCheck(name, rows, time.perf_counter() - t0, updated, str(path), str(bpath))

    try:
        spec = load_scenario(path)
        result = run_scenario(spec, controller=controller)
    except (ValueError, FileNotFoundError, FloatingPointError) as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return done([Row(name, "-", None, None, None, "error", msg)])
    rows = check_criteria(result.metrics, spec.criteria, name)
    if update:
        write_baseline(bpath, result)
        return done(rows, updated=True)
    if not bpath.exists():
        rows.insert(0, Row(name, "-", None, None, None, "missing", f"no baseline {bpath.name}; run with --update"))
        return done(rows)
    try:
        doc = read_baseline(bpath)
    except (ValueError, FileNotFoundError) as exc:
        rows.insert(0, Row(name, "-", None, None, None, "error", str(exc)))
        return done(rows)
    return done(compare_metrics(result.metrics, doc["metrics"], name) + rows)


def regress_scenarios(scenario_dir=None, only=None, update: bool = False, controller=None, baseline_dir=None,
                      jobs: int = 1) -> list[ScenarioCheck]:
    """Run and check the scenarios; with ``update``, rewrite their baselines.

    Parameters
    ----------
    scenario_dir : path, optional
        Folder of scenario files (default :func:`scenario_files`' choice).
    only : list of str, optional
        Scenario names or scenario file paths to run (default: all; see :func:`scenario_files`).
    update : bool
        Rewrite the baselines instead of comparing.
    controller : str, path or Controller, optional
        Replaces every scenario's controller (to check a candidate against the baselines).
    baseline_dir : path, optional
        Folder of the baseline files (default ``baselines/`` beside each scenario file).
    jobs : int
        Scenarios run in parallel processes (1: in this process).

    Returns
    -------
    list of ScenarioCheck, in scenario order.
    """
    files = scenario_files(scenario_dir, only)
    if jobs <= 1 or len(files) <= 1:
        return [_check_one(f, update, controller, baseline_dir) for f in files]
    from concurrent.futures import ProcessPoolExecutor

    from ebraille_sim.tools.parallel import process_context
    with ProcessPoolExecutor(max_workers=jobs, mp_context=process_context()) as ex:
        futs = [ex.submit(_check_one, f, update, controller, baseline_dir) for f in files]
        return [f.result() for f in futs]


def _fmt(v):
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def format_report(checks: list[ScenarioCheck], verbose: bool = False) -> str:
    """A plain-text table of what moved (all rows with ``verbose``) and a summary line."""
    rows = [r for c in checks for r in c.rows if verbose or r.status not in ("ok",)]
    out = []
    if rows:
        head = ("scenario", "metric", "baseline", "current", "change", "allowed", "status")
        table = []
        for r in rows:
            change = ""
            if _is_num(r.baseline) and _is_num(r.current):
                change = f"{r.current - r.baseline:+.4g}"
            allowed = f"{r.limit:.3g}" if r.limit is not None else ""
            status = r.status + (f" ({r.note})" if r.note else "")
            table.append((r.scenario, r.metric, _fmt(r.baseline), _fmt(r.current), change, allowed, status))
        widths = [max(len(head[i]), *(len(t[i]) for t in table)) for i in range(len(head))]
        out.append("  ".join(h.ljust(w) for h, w in zip(head, widths)))
        out.append("  ".join("-" * w for w in widths))
        out.extend("  ".join(v.ljust(w) for v, w in zip(t, widths)) for t in table)
        out.append("")
    n_fail = sum(c.failed for c in checks)
    n_upd = sum(c.updated for c in checks)
    wall = sum(c.wall_s for c in checks)
    if n_upd:
        out.append(f"updated {n_upd} baseline(s); {n_fail} scenario(s) failing their criteria or not running; "
                   f"{wall:.1f} s of runs")
    else:
        out.append(f"{len(checks) - n_fail} of {len(checks)} scenario(s) match their baselines; "
                   f"{n_fail} failed; {wall:.1f} s of runs")
    return "\n".join(out)


def _plain(v):
    """A JSON-safe value: non-finite floats become their text ('nan', 'inf')."""
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return v


def json_document(checks: list[ScenarioCheck]) -> dict:
    """The outcome as a JSON-ready dict: a summary and, per scenario, every report row."""
    scenarios = []
    for c in checks:
        scenarios.append({
            "name": c.name, "file": c.source, "baseline": c.baseline, "passed": not c.failed,
            "updated": c.updated, "wall_s": round(c.wall_s, 3),
            "rows": [{"metric": r.metric, "baseline": _plain(r.baseline), "current": _plain(r.current),
                      "limit": _plain(r.limit), "status": r.status, "note": r.note} for r in c.rows]})
    n_fail = sum(c.failed for c in checks)
    return {"passed": n_fail == 0, "scenarios_checked": len(checks), "scenarios_failed": n_fail,
            "wall_s": round(sum(c.wall_s for c in checks), 3), "scenarios": scenarios}


def _row_line(r: Row) -> str:
    if r.status in ("missing", "error"):
        return f"{r.status}: {r.note}"
    if r.status == "criterion":
        return f"{r.metric} = {_fmt(r.current)}, expected {r.baseline} ({r.note})"
    text = f"{r.metric}: baseline {_fmt(r.baseline)}, current {_fmt(r.current)}"
    if _is_num(r.baseline) and _is_num(r.current):
        text += f", change {r.current - r.baseline:+.4g}"
    if r.limit is not None:
        text += f", allowed {r.limit:.3g}"
    return text + f" ({r.status}{', ' + r.note if r.note else ''})"


def junit_xml(checks: list[ScenarioCheck], suite: str = "ebraille-sim regress") -> str:
    """The outcome as JUnit XML: one ``testcase`` per scenario.

    A scenario that could not run (or whose baseline is unreadable) gets an ``error``
    element; one whose metrics moved, were removed, miss a baseline or fail a criterion
    gets a ``failure`` element whose message names the metrics and whose text has one line
    per metric (baseline, current, change, allowed).
    """
    import xml.etree.ElementTree as ET
    n_err = sum(any(r.status == "error" for r in c.rows) for c in checks)
    n_fail = sum(c.failed for c in checks) - n_err
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(checks)), failures=str(n_fail),
                       errors=str(n_err), skipped="0", time=f"{sum(c.wall_s for c in checks):.3f}")
    for c in checks:
        tc = ET.SubElement(ts, "testcase", classname="ebraille_sim.regress", name=c.name, time=f"{c.wall_s:.3f}",
                           file=c.source)
        bad = [r for r in c.rows if r.status in FAILING]
        if not bad:
            continue
        kind = "error" if any(r.status == "error" for r in bad) else "failure"
        metrics = [r.metric for r in bad if r.metric != "-"]
        if metrics:
            statuses = {r.status for r in bad}
            verb = ("moved" if statuses <= {"moved", "removed"} else
                    "failed a criterion" if statuses == {"criterion"} else "moved or failed a criterion")
            message = f"{len(metrics)} metric(s) {verb}: {', '.join(metrics)}"
        else:
            message = bad[0].note
        el = ET.SubElement(tc, kind, message=message, type=bad[0].status)
        el.text = "\n".join(_row_line(r) for r in bad)
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
