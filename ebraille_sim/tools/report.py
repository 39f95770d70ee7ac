"""Run outputs: summary table, metrics.json, the trace (trace.csv or trace.parquet) and force.png.

Files are written into a staging folder beside the target and moved into place only
when all of them are complete (:func:`ebraille_sim.tools.outputs.staged`), so an
interrupted or failed run leaves nothing half-way.  A run folder holds one run: outputs
of an earlier run that this one does not write (a force.png under ``--no-plot``, a trace
of another format, an animation) are removed.
"""
from __future__ import annotations

import dataclasses
import json
import pathlib

import numpy as np

from ebraille_sim.scenarios.metrics import evaluate_criteria
from ebraille_sim.scenarios.runner import TRACE_COLUMNS, RunResult

_FMT = {"force_rmse_n": "{:.4f}", "force_mae_n": "{:.4f}", "in_band_fraction": "{:.3f}",
        "char_in_band_fraction": "{:.3f}", "peak_force_n": "{:.3f}", "onset_overshoot_fraction": "{:.3f}",
        "settling_time_s": "{:.3f}", "estimate_rmse_n": "{:.4f}", "energy_j": "{:.3f}",
        "real_time_factor": "{:.0f}", "wpm": "{:.1f}",
        "legible_char_fraction": "{:.3f}", "legible_char_fraction_cv": "{:.3f}"}


def controller_label(result: RunResult, controller_file=None) -> str:
    """The run's controller name, with the gains file it came from when there is one."""
    return result.controller_name + (f" (gains {controller_file})" if controller_file else "")


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
        doc["controller_file"] = str(controller_file)
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
