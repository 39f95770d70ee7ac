"""Run outputs: summary table, metrics.json, the trace (trace.csv or trace.parquet) and force.png;
population reports of sweeps and benchmarks (:func:`population_summary`).

Files are written into a staging folder beside the target and moved into place only
when all of them are complete (:func:`ebraille_sim.tools.outputs.staged`), so an
interrupted or failed run leaves nothing half-way.  A run folder holds one run: outputs
of an earlier run that this one does not write (a force.png under ``--no-plot``, a trace
of another format, an animation) are removed.
"""
from __future__ import annotations

import dataclasses
import json
import math
import pathlib
from dataclasses import dataclass

import numpy as np

from ebraille_sim.scenarios.metrics import evaluate_criteria
from ebraille_sim.scenarios.runner import TRACE_COLUMNS, RunResult

_FMT = {"force_rmse_n": "{:.4f}", "force_mae_n": "{:.4f}", "in_band_fraction": "{:.3f}",
        "char_in_band_fraction": "{:.3f}", "peak_force_n": "{:.3f}", "onset_overshoot_fraction": "{:.3f}",
        "settling_time_s": "{:.3f}", "estimate_rmse_n": "{:.4f}", "energy_j": "{:.3f}",
        "real_time_factor": "{:.0f}", "wpm": "{:.1f}",
        "legible_char_fraction": "{:.3f}", "legible_char_fraction_cv": "{:.3f}"}


def _is_design_name(controller_file) -> bool:
    """Whether ``controller_file`` names a shipped design rather than a gains or design file."""
    return controller_file is not None and not str(controller_file).lower().endswith((".toml", ".json"))


def controller_label(result: RunResult, controller_file=None) -> str:
    """The run's controller name, with the gains file or the shipped design it came from when
    there is one (``controller_file``: a path, or a design's name)."""
    if not controller_file:
        return result.controller_name
    return result.controller_name + (f" (design {controller_file})" if _is_design_name(controller_file)
                                     else f" (gains {controller_file})")


def controller_gains(controller) -> dict | None:
    """A controller's configuration dataclass as a dict (``None`` when it has none)."""
    cfg = getattr(controller, "config", None)
    if not dataclasses.is_dataclass(cfg) or isinstance(cfg, type):
        return None
    return dataclasses.asdict(cfg)


def summary_table(result: RunResult, controller_file=None) -> str:
    """A plain-text table of the run's metrics (``controller_file``: the gains file, if any)."""
    m = result.metrics
    lines = [f"scenario {result.spec.name}  controller {controller_label(result, controller_file)}  "
             f"seed {result.seed}",
             f"{'metric':<26} value"]
    lines.append("-" * 40)
    for k, v in m.items():
        if v is None:
            s = "n/a"
        elif isinstance(v, float):
            s = _FMT.get(k, "{:.4g}").format(v)
        else:
            s = str(v)
        lines.append(f"{k:<26} {s}")
    for key, c in evaluate_criteria(result.spec.criteria, m).items():
        op = "<=" if key.endswith("max") or key.endswith("max_n") else ">="
        lines.append(f"criterion {c['metric']} {op} {c['limit']:g}: {'pass' if c['passed'] else 'FAIL'}")
    lines.extend(supervisor_lines(result))
    return "\n".join(lines)


def supervisor_lines(result: RunResult) -> list[str]:
    """The safety supervisor's state for the summary: on/off and why, its fault and events."""
    sup = result.supervisor or {}
    if not sup:
        return []
    lines = [f"supervisor {sup['source']}"]
    if sup.get("fault"):
        lines.append(f"supervisor fault {sup['fault']}")
    for t, text in sup.get("events", ()):
        lines.append(f"supervisor event at {t:.3f} s: {text}")
    return lines


def metrics_document(result: RunResult, controller=None, controller_file=None) -> dict:
    """The JSON document written as metrics.json.

    With ``controller`` (the controller object run) it records ``controller_gains``, its
    configuration dataclass as a dict; with ``controller_file`` the gains file it came from.
    """
    doc = {"scenario": result.spec.name, "controller": result.controller_name, "seed": result.seed,
           "band_fraction": result.spec.setpoint.band_fraction, "reading_start_s": result.spec.reading.start_s,
           "metrics": result.metrics, "criteria": evaluate_criteria(result.spec.criteria, result.metrics),
           "supervisor": result.supervisor}
    if controller_file is not None:
        doc["design" if _is_design_name(controller_file) else "controller_file"] = str(controller_file)
    if controller is not None:
        doc["controller_gains"] = controller_gains(controller)
    return doc


def _csv_field(text: str) -> str:
    """``text`` as the ``csv`` module's default dialect writes one field (quoted when needed)."""
    if any(ch in text for ch in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def write_trace_csv(path, trace: dict) -> None:
    """Write the trace columns :data:`TRACE_COLUMNS` as CSV (the ``csv`` module's default
    dialect, ``\\r\\n`` line ends; numbers with 9 significant digits, ``char_index`` as an
    integer), with the bytes the row-by-row ``csv.writer`` gives.  As with the rows of
    ``zip``, the shortest column sets the number of rows.

    The rows are formatted in compiled code (:func:`ebraille_sim.tools.csvformat.csv_body`,
    the bytes of ``"%.9g" % v``), the braille characters once per distinct character.  A
    trace holding a number that code does not cover (``|v| >= 1e9``, ``0 < |v| < 1e-19``)
    is formatted in Python instead: one ``%`` operation of the row format repeated once per
    row over the cells in row order, a float column that repeats its values formatted once
    per distinct bit pattern.
    """
    from ebraille_sim.tools.csvformat import FLOAT, INT, TEXT, csv_body
    cols = TRACE_COLUMNS
    arrays = [np.asarray(trace[c]) for c in cols]
    n = min((len(a) for a in arrays), default=0)
    columns = []
    for c, arr in zip(cols, arrays):
        arr = arr[:n]
        if c == "char_index":
            columns.append((INT, arr.astype(np.int64)))
        elif c == "character":
            distinct, index = np.unique(arr.astype(str), return_inverse=True)
            columns.append((TEXT, (index.reshape(-1), [_csv_field(v) for v in distinct.tolist()])))
        else:
            columns.append((FLOAT, arr.astype(float)))
    body = csv_body(columns) if columns else b""
    header = ",".join(_csv_field(c) for c in cols) + "\r\n"
    with open(path, "wb") as fh:
        fh.write(header.encode("utf-8"))
        fh.write(body if body is not None else _python_body(columns, n).encode("utf-8"))


def _python_body(columns: list, n: int) -> str:
    """The rows of :func:`ebraille_sim.tools.csvformat.csv_body` 's ``columns``, formatted in Python."""
    from ebraille_sim.tools.csvformat import FLOAT, INT
    cells = np.empty((n, len(columns)), dtype=object)
    fmts = []
    for j, (kind, values) in enumerate(columns):
        if kind == INT:
            cells[:, j] = values
            fmts.append("%d")
        elif kind == FLOAT:
            if n > 1 and np.count_nonzero(values[1:] != values[:-1]) < n // 2:
                cells[:, j] = _distinct_texts(values.view(np.int64), _format_bits)
                fmts.append("%s")
            else:
                cells[:, j] = values
                fmts.append("%.9g")
        else:
            index, texts = values
            cells[:, j] = np.array(texts, dtype=object)[index]
            fmts.append("%s")
    return (",".join(fmts) + "\r\n") * n % tuple(cells.ravel().tolist())


def _format_bits(bits: list) -> list[str]:
    """``format(v, ".9g")`` of the floats whose int64 bit patterns are ``bits``."""
    values = np.array(bits, dtype=np.int64).view(np.float64).tolist()
    return ("%.9g\n" * len(values) % tuple(values)).split("\n")[:-1]


def _distinct_texts(keys: np.ndarray, texts) -> np.ndarray:
    """The text of every element of ``keys`` as an object array, with ``texts`` (a function of
    the list of distinct keys returning their texts) called once per distinct key."""
    distinct, index = np.unique(keys, return_inverse=True)
    return np.array(texts(distinct.tolist()), dtype=object)[index.reshape(-1)]


def figure_data(result: RunResult, controller_file=None, backend: str | None = None) -> dict:
    """What force.png shows, as plain arrays and texts (:func:`ebraille_sim.tools.forceplot.draw_force_figure`).

    Parameters
    ----------
    result : RunResult
    controller_file : path, optional
        The gains file the controller came from, named in the title.
    backend : str, optional
        The plant backend the run used (``"lumped"``, ``"pymunk"``), named in the title.
    """
    tr = result.trace
    t = np.asarray(tr["t_s"])
    starts = result.schedule.boundaries_s()
    title = f"{result.spec.name}: controller {controller_label(result, controller_file)}"
    if backend is not None:
        title += f", {backend} backend"
    return {"t_s": t, "setpoint_n": np.asarray(tr["setpoint_n"]), "force_est_n": np.asarray(tr["force_est_n"]),
            "force_true_n": np.asarray(tr["force_true_n"]), "command_v": np.asarray(tr["command_v"]),
            "starts_s": starts[starts <= t[-1]], "band_fraction": result.spec.setpoint.band_fraction,
            "reading_start_s": result.spec.reading.start_s, "title": f"{title}, seed {result.seed}"}


def force_figure(result: RunResult, controller_file=None, backend: str | None = None):
    """The figure of force.png: true and estimated force against the setpoint, and the command.

    The parameters are those of :func:`figure_data`.

    Returns
    -------
    matplotlib.figure.Figure
        Drawn by :func:`ebraille_sim.tools.forceplot.draw_force_figure` on an Agg canvas (not
        a pyplot figure): thin grey vertical lines mark the start of each braille character
        (up to 400 of them; none when there are more), the green line the start of reading.
    """
    from ebraille_sim.tools.forceplot import draw_force_figure
    return draw_force_figure(figure_data(result, controller_file, backend))


def plot_force(result: RunResult, path, controller_file=None, backend: str | None = None) -> None:
    """Write :func:`force_figure` to ``path``."""
    from ebraille_sim.tools.forceplot import png_bytes
    pathlib.Path(path).write_bytes(png_bytes(force_figure(result, controller_file, backend)))


RUN_OUTPUTS = ("metrics.json", "trace.csv", "trace.parquet", "force.png", "animation.gif", "animation")
"""The names a run writes into its folder (``animation`` is the PNG-frame folder drawn without Pillow)."""

RUN_OWNED = {name: ("frame_*.png" if name == "animation" else None) for name in RUN_OUTPUTS}
""":data:`RUN_OUTPUTS` for :func:`ebraille_sim.tools.outputs.staged`: of the frame folder a run owns only the frames."""

TRACE_FORMATS = ("csv", "parquet", "none")


def existing_outputs(out_dir) -> list[pathlib.Path]:
    """The run outputs (:data:`RUN_OUTPUTS`) already present in ``out_dir``."""
    out = pathlib.Path(out_dir)
    if not out.is_dir():
        return []
    return [out / n for n in RUN_OUTPUTS if (out / n).exists()]


def remove_output(path) -> None:
    """Remove one run output: a file, or the frame folder's ``frame_*.png`` (and the folder once empty)."""
    from ebraille_sim.tools.outputs import remove_owned
    remove_owned(path, RUN_OWNED)


def have_parquet() -> bool:
    """Whether pyarrow is installed (``trace.parquet`` needs it)."""
    import importlib.util
    return importlib.util.find_spec("pyarrow") is not None


def write_trace_parquet(path, trace: dict) -> None:
    """The trace as a Parquet table (needs pyarrow), same columns as trace.csv."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ValueError("trace format 'parquet' needs pyarrow, which is not installed; use 'csv'") from None
    cols = {}
    for c in TRACE_COLUMNS:
        v = np.asarray(trace[c])
        cols[c] = (v.astype(np.int64) if c == "char_index" else
                   [str(x) for x in v] if c == "character" else v.astype(np.float64))
    pq.write_table(pa.table(cols), path)


def write_run_files(result: RunResult, folder, plot: bool = True, trace: str = "csv", controller=None,
                    controller_file=None, backend: str | None = None, plotter=None) -> list[str]:
    """Write metrics.json, the trace and force.png straight into ``folder`` (which must exist).

    The arguments are those of :func:`write_outputs`; returns the names written.  With
    ``plotter`` (a started :class:`ebraille_sim.tools.forceplot.ForcePlotter`) force.png is
    drawn by that process while this one writes the other files; where it fails, the figure
    is drawn here.
    """
    if trace not in TRACE_FORMATS:
        raise ValueError(f"trace format must be one of {', '.join(TRACE_FORMATS)}, got {trace!r}")
    folder = pathlib.Path(folder)
    if plot and plotter is not None:
        plotter.send(figure_data(result, controller_file, backend))
    (folder / "metrics.json").write_text(json.dumps(
        metrics_document(result, controller, controller_file), indent=2) + "\n")
    if trace == "csv":
        write_trace_csv(folder / "trace.csv", result.trace)
    elif trace == "parquet":
        write_trace_parquet(folder / "trace.parquet", result.trace)
    if plot:
        png = plotter.png() if plotter is not None else None
        if png is None:
            plot_force(result, folder / "force.png", controller_file, backend)
        else:
            (folder / "force.png").write_bytes(png)
    return [n for n in RUN_OUTPUTS if (folder / n).exists()]


def write_outputs(result: RunResult, out_dir, plot: bool = True, trace: str = "csv",
                  clear_stale: bool = True, controller=None, controller_file=None,
                  backend: str | None = None) -> list[pathlib.Path]:
    """Write metrics.json, the trace and force.png into ``out_dir`` (created if needed), all at once.

    The files are written into a staging folder and moved into place together
    (:func:`ebraille_sim.tools.outputs.staged`): an error or an interrupt leaves
    ``out_dir`` as it was.

    Parameters
    ----------
    result : RunResult
    out_dir : path
    plot : bool
        Draw force.png.
    trace : {"csv", "parquet", "none"}
        trace.csv, trace.parquet (pyarrow) or no trace.
    clear_stale : bool
        Remove the outputs of :data:`RUN_OUTPUTS` this run does not write.
    controller, controller_file : optional
        The controller object run and the gains file it came from (:func:`metrics_document`).
    backend : str, optional
        The plant backend the run used, named in force.png's title.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    from ebraille_sim.tools.outputs import staged
    if trace not in TRACE_FORMATS:
        raise ValueError(f"trace format must be one of {', '.join(TRACE_FORMATS)}, got {trace!r}")
    out = pathlib.Path(out_dir)
    with staged(out, RUN_OWNED if clear_stale else ()) as folder:
        names = write_run_files(result, folder, plot, trace, controller, controller_file, backend)
    return [out / n for n in names]


# --------------------------------------------------------------------------------------
# population reports (sweep and benchmark)
# --------------------------------------------------------------------------------------

IN_BAND_MIN = 0.9
"""In-band share a reader of a tracking scenario must hold when the scenario names no
``in_band_min`` of its own (on a refresh scenario: the characters' in-band share, the hold
windows, :data:`POPULATION_CRITERIA` ``char_in_band_min``)."""

POPULATION_CRITERIA = {"char_in_band_min": ("char_in_band_fraction", "ge")}
"""Criteria of population reports besides a scenario's ``[criteria]`` keys
(:data:`ebraille_sim.scenarios.metrics.CRITERIA`): the metric each bounds and how."""

CRITERIA_LABELS = {"in_band_min": "in_band>={:g}", "char_in_band_min": "char_in_band>={:g}",
                   "peak_force_max_n": "peak<={:g}N", "onset_overshoot_max": "overshoot<={:g}"}


@dataclass(frozen=True)
class PopulationScenario:
    """What a population report knows of one scenario.

    Attributes
    ----------
    criteria : dict
        ``[criteria]`` keys and limits every reader is checked against
        (:func:`population_scenario`).
    fault : bool
        The scenario injects a fault (a ``[faults]`` section): a latched supervisor fault is
        its detection there, on any other scenario a false trip.
    """
    criteria: dict
    fault: bool


def population_scenario(spec) -> PopulationScenario:
    """The criteria of a scenario's readers: its own ``[criteria]`` on top of the in-band share
    :data:`IN_BAND_MIN` (tracking scenarios; of the characters' hold windows on a refresh
    scenario, whose lift phases lie out of the band by design) and the tactile range's top
    (:data:`~ebraille_sim.physics.params.TACTILE_FORCE_MAX_N`, every scenario)."""
    from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N
    fault = "faults" in spec.sections
    in_band = "char_in_band_min" if spec.reading.mode == "refresh" else "in_band_min"
    criteria = {} if fault else {in_band: IN_BAND_MIN}
    criteria["peak_force_max_n"] = TACTILE_FORCE_MAX_N
    criteria.update(spec.criteria)
    return PopulationScenario(criteria, fault)


def latched_fault(result) -> dict:
    """Row columns of a run's latched supervisor fault: ``supervisor_fault`` (its name, None
    without a latch), ``supervisor_fault_s`` (the time it latched, s) and ``reading_s`` (the
    reading time of the run, s: from the reading's start to the run's end)."""
    sup = result.supervisor or {}
    name = sup.get("fault")
    t = next((float(t_ev) for t_ev, text in sup.get("events", ()) if name and text.startswith(f"fault {name}:")),
             None)
    spec = result.spec
    end = spec.duration_s if spec.duration_s is not None else result.schedule.t_end_s
    return {"supervisor_fault": name or None, "supervisor_fault_s": t,
            "reading_s": max(0.0, float(end) - spec.reading.start_s)}


def _fails(row: dict, criteria: dict) -> list:
    """The criteria ``row`` fails (all of them when its episode failed)."""
    from ebraille_sim.scenarios.metrics import CRITERIA
    if row.get("error"):
        return list(criteria)
    out = []
    for key, limit in criteria.items():
        metric, how = CRITERIA[key] if key in CRITERIA else POPULATION_CRITERIA[key]
        v = row.get(metric)
        if v is None or not (v <= limit if how == "le" else v >= limit):
            out.append(key)
    return out


def separating_parameters(rows: list, failed, params) -> list[tuple[str, float]]:
    """Drawn parameters ordered by how well they separate the failing readers from the others.

    The measure is the area under the ROC curve of the parameter as a failure score (the
    Mann-Whitney statistic over the two groups, ties counted half): 0.5 does not separate,
    1 (0) puts every failing reader above (below) every other.  Returned as ``(name, auc)``,
    the largest ``|auc - 0.5|`` first; empty when either group is empty.

    >>> rows = [{"h": 0.05}, {"h": 0.07}, {"h": 0.14}, {"h": 0.15}]
    >>> separating_parameters(rows, [False, False, True, True], ["h"])
    [('h', 1.0)]
    """
    from scipy.stats import rankdata
    failed = np.asarray(failed, dtype=bool)
    n1, n0 = int(failed.sum()), int((~failed).sum())
    if n1 == 0 or n0 == 0:
        return []
    out = []
    for p in params:
        x = np.array([r.get(p, np.nan) for r in rows], dtype=float)
        if not np.all(np.isfinite(x)):
            continue
        ranks = rankdata(x)
        auc = (ranks[failed].sum() - n1 * (n1 + 1) / 2) / (n1 * n0)
        out.append((p, float(auc)))
    return sorted(out, key=lambda pa: (-abs(pa[1] - 0.5), pa[0]))


def population_summary(rows: list, scenarios: dict, params, group=("scenario", "controller"),
                       worst: int = 5) -> list[dict]:
    """Per group of rows (default: scenario and controller): the share of readers meeting each
    criterion and all of them, the latches, the false trips and the worst readers.

    Parameters
    ----------
    rows : list of dict
        Episode rows: the metrics, ``error``, the columns of :func:`latched_fault` and the
        drawn parameters ``params``.
    scenarios : dict
        :class:`PopulationScenario` per value of the rows' ``scenario``.
    params : list of str
        The drawn parameters shown beside the worst readers and tested for separation.
    worst : int
        Worst readers kept per group: those failing the most criteria, then (tracking
        scenarios) the lowest in-band share or (fault scenarios) the highest peak force.

    Returns
    -------
    list of dict
        ``group`` (the group's values), ``readers``, ``errors``, ``fault`` (a fault
        scenario), ``criteria`` (key -> limit), ``shares`` (key -> share meeting it, plus
        ``all``), ``latched`` (episodes ending in a latch), ``false_trips`` (latches on a
        scenario without a fault), ``false_trip_rate`` (their share of the readers),
        ``reading_h`` (reading hours), ``false_trips_per_h``, ``worst`` (rows) and
        ``separating`` (:func:`separating_parameters` of the readers failing a criterion).
    """
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[g] for g in group), []).append(r)
    out = []
    for key, rs in groups.items():
        sc = scenarios[rs[0]["scenario"]]
        fails = [_fails(r, sc.criteria) for r in rs]
        latched = [bool(r.get("supervisor_fault")) for r in rs]
        failed = [bool(f) or (lat and not sc.fault) for f, lat in zip(fails, latched)]
        n = len(rs)
        shares = {k: sum(k not in f for f in fails) / n for k in sc.criteria}
        if not sc.fault:
            shares["no_latch"] = sum(not x for x in latched) / n
        shares["all"] = sum(not x for x in failed) / n
        hours = sum(float(r.get("reading_s") or 0.0) for r in rs) / 3600.0
        trips = 0 if sc.fault else sum(latched)

        def badness(i):
            r = rs[i]
            v = r.get("peak_force_n") if sc.fault else r.get(_in_band_metric(sc.criteria))
            v = (math.inf if sc.fault else -math.inf) if v is None or r.get("error") else float(v)
            return (-len(fails[i]) - (latched[i] and not sc.fault), -v if sc.fault else v, i)

        order = sorted(range(n), key=badness)[:worst]
        out.append({"group": dict(zip(group, key)), "readers": n, "errors": sum(1 for r in rs if r.get("error")),
                    "fault": sc.fault, "criteria": dict(sc.criteria), "shares": shares, "latched": sum(latched),
                    "false_trips": trips, "false_trip_rate": trips / n, "reading_h": hours,
                    "false_trips_per_h": trips / hours if hours > 0 else None,
                    "worst": [dict(rs[i], failed_criteria=fails[i]) for i in order],
                    "separating": separating_parameters(rs, failed, params)})
    return out


def _in_band_metric(criteria: dict) -> str:
    """The in-band metric a group's criteria check (the characters' on a refresh scenario)."""
    return "char_in_band_fraction" if "char_in_band_min" in criteria else "in_band_fraction"


def _pct(x: float) -> str:
    return f"{100 * x:.1f}%"


def format_population(summary: list[dict], params, worst_for=None) -> str:
    """The population report as terminal text: one line per group (share of readers meeting
    each criterion and all of them, false trips and their rate per reading-hour; on a fault
    scenario the latches are detections), then the worst readers with their drawn parameters
    and the parameters that separate the failing readers.  ``worst_for(group)`` (default: every
    group) chooses the groups whose worst readers are listed."""
    if not summary:
        return "(no episodes)"
    lines = [f"population report: share of readers meeting each criterion (the scenario's [criteria], else "
             f"in_band >= {IN_BAND_MIN:g}, of the characters on a refresh scenario, and peak <= limit); a latched "
             f"supervisor fault on a scenario without [faults] is a false trip"]
    gw = max(len(" ".join(str(v) for v in s["group"].values())) for s in summary)
    for s in summary:
        name = " ".join(str(v) for v in s["group"].values())
        crit = "  ".join(f"{CRITERIA_LABELS.get(k, k + '{:g}').format(v)} {_pct(s['shares'][k])}"
                         for k, v in s["criteria"].items())
        if s["fault"]:
            tail = f"latched {s['latched']}/{s['readers']} (fault scenario)"
        else:
            tail = (f"no latch {_pct(s['shares']['no_latch'])}  false trips {s['false_trips']}/{s['readers']} "
                    f"({_pct(s['false_trip_rate'])}, {_num(s['false_trips_per_h'], '{:.3g}')} per reading-hour)")
        err = f"  errors {s['errors']}" if s["errors"] else ""
        lines.append(f"  {name:<{gw}}  readers {s['readers']:>4}  {crit}  all {_pct(s['shares']['all'])}  "
                     f"{tail}{err}")
    for s in summary:
        if worst_for is not None and not worst_for(s["group"]):
            continue
        name = " ".join(str(v) for v in s["group"].values())
        sep = ", ".join(f"{p} {'high' if a > 0.5 else 'low'} (AUC {a:.2f})" for p, a in s["separating"][:3])
        lines.append(f"worst readers of {name}" + (f"; failures separated by {sep}" if sep else "") + ":")
        for r in s["worst"]:
            fault = (f"latched {r['supervisor_fault']} at {r['supervisor_fault_s']:.3f} s"
                     if r.get("supervisor_fault") and r.get("supervisor_fault_s") is not None
                     else f"latched {r['supervisor_fault']}" if r.get("supervisor_fault") else "no latch")
            if r.get("error"):
                what = f"error: {r['error']}"
            else:
                what = (f"in_band {_num(r.get('in_band_fraction'), '{:.3f}')}  char_in_band "
                        f"{_num(r.get('char_in_band_fraction'), '{:.3f}')}  peak "
                        f"{_num(r.get('peak_force_n'), '{:.2f}')} N  {fault}")
            failed = ",".join(r["failed_criteria"]) or "-"
            drawn = " ".join(f"{p}={r[p]:.4g}" for p in params if r.get(p) is not None)
            lines.append(f"    reader {r['reader']:>4} seed {r['seed']}: {what}  fails {failed}  {drawn}")
    return "\n".join(lines)


def _num(v, fmt: str) -> str:
    return "-" if v is None else fmt.format(v)


def plot_population(rows: list, summary: list[dict], path, params, panels: int = 3, groups: int = 6):
    """The in-band share of the readers against the drawn parameters that separate the failing
    ones (:func:`separating_parameters`; without failures the first of ``params``): one row of
    panels per tracking group (those with the most failing readers first, at most ``groups``),
    ``panels`` parameters each.  Every reader is a point (red: fails a criterion, a cross: a
    false trip); the line is the share of readers at ``in_band >=`` the group's limit per
    quintile of the parameter.  Returns ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    tracking = [s for s in summary if not s["fault"]]
    tracking.sort(key=lambda s: s["shares"]["all"])
    tracking = tracking[:groups]
    if not tracking:
        tracking = summary[:1]
    fig, axes = plt.subplots(len(tracking), panels, figsize=(4.0 * panels, 2.8 * len(tracking)), squeeze=False)
    for row_axes, s in zip(axes, tracking):
        rs = [r for r in rows if all(r.get(k) == v for k, v in s["group"].items())]
        metric = _in_band_metric(s["criteria"])
        limit = s["criteria"].get("char_in_band_min", s["criteria"].get("in_band_min", IN_BAND_MIN))
        chosen = [p for p, _ in s["separating"]][:panels]
        chosen += [p for p in params if p not in chosen][:panels - len(chosen)]
        y = np.array([np.nan if r.get("error") or r.get(metric) is None else r[metric] for r in rs], dtype=float)
        bad = np.array([bool(_fails(r, s["criteria"])) for r in rs])
        trip = np.array([bool(r.get("supervisor_fault")) for r in rs])
        auc = dict(s["separating"])
        name = " ".join(str(v) for v in s["group"].values())
        for ax, p in zip(row_axes, chosen):
            x = np.array([r.get(p, np.nan) for r in rs], dtype=float)
            ok = ~bad & ~trip
            ax.scatter(x[ok], y[ok], s=8, color="tab:blue", label="meets every criterion")
            ax.scatter(x[bad & ~trip], y[bad & ~trip], s=10, color="tab:red", label="fails a criterion")
            ax.scatter(x[trip], np.nan_to_num(y[trip]), s=22, marker="x", color="k", label="latched fault")
            edges = np.unique(np.quantile(x[np.isfinite(x)], np.linspace(0, 1, 6))) if np.isfinite(x).any() else []
            if len(edges) > 1:
                idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
                share = [np.mean(np.nan_to_num(y[idx == i], nan=-1.0) >= limit) if np.any(idx == i) else np.nan
                         for i in range(len(edges) - 1)]
                ax.step(edges, share + share[-1:], where="post", color="tab:green", lw=1.2,
                        label=f"share at >= {limit:g}")
            ax.set_xlabel(p + (f" (AUC {auc[p]:.2f})" if p in auc else ""), fontsize=8)
            ax.set_ylim(-0.05, 1.05)
            ax.grid(lw=0.3)
        row_axes[0].set_ylabel(f"{name}\n{metric}", fontsize=8)
    axes[0, 0].legend(fontsize=6, loc="lower left")
    fig.suptitle("in-band share against the drawn parameters that separate the failing readers", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
