"""force.png drawn from plain data, here or in a helper process started ahead of time.

:func:`draw_force_figure` builds the figure of a run from :func:`~ebraille_sim.tools.report.figure_data`
(arrays and texts only), with Matplotlib's ``Figure`` and the Agg canvas (no pyplot, no
global figure state).

:class:`ForcePlotter` is the helper process ``run`` starts before it simulates: the process
imports Matplotlib (a third of a second) while this one imports Numba and simulates, waits
for the figure data, draws the figure and hands back the PNG bytes, which this process
writes.  The helper never touches the file system and runs in a session of its own, so
Ctrl-C reaches only this process, which ends the helper when it stops.  This module imports
nothing beyond the standard library at import time, so the helper starts with the
interpreter, NumPy and Matplotlib only.
"""
from __future__ import annotations

import io
import os
import pickle
import subprocess
import sys
import threading

__all__ = ["draw_force_figure", "png_bytes", "ForcePlotter", "serve", "DPI", "MAX_START_LINES"]

DPI = 110
"""Resolution of force.png, dots per inch (11 x 6 inches: 1210 x 660 pixels)."""

MAX_START_LINES = 400
"""Character starts drawn as vertical lines when there are at most this many (none when more)."""

_MARGINS = {"left": 0.07, "right": 0.986, "top": 0.94, "bottom": 0.0975, "hspace": 0.1}
"""Subplot margins (figure fractions) of force.png, fixed so that the figure is laid out once."""

_HEADER = 8
"""Bytes of the little-endian payload length that precedes the pickled figure data on the pipe."""

_TIMEOUT_S = 300.0
"""Longest wait for the helper to take the data, and again for its PNG, before it is ended
and the figure is drawn here instead."""


def _new_figure():
    """The empty figure of force.png: two axes sharing time, their fixed labels and margins,
    at :data:`DPI` on an Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(11, 6), dpi=DPI)
    FigureCanvasAgg(fig)
    ax, ax2 = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.set_ylabel("contact force (N)")
    ax2.set_ylabel("command (V)")
    ax2.set_xlabel("time (s)")
    fig.subplots_adjust(**_MARGINS)
    return fig


def draw_force_figure(data: dict, fig=None):
    """The figure of force.png: true and estimated force against the setpoint band, and the command.

    Parameters
    ----------
    data : dict
        :func:`ebraille_sim.tools.report.figure_data`: ``t_s``, ``setpoint_n``,
        ``force_est_n``, ``force_true_n``, ``command_v`` (arrays of one length),
        ``starts_s`` (character starts up to the last sample), ``band_fraction``,
        ``reading_start_s`` and ``title``.
    fig : matplotlib.figure.Figure, optional
        An empty figure of :func:`_new_figure` to draw into (the helper process makes and
        draws it once while it waits for the data, which loads the fonts); default: a new one.

    Returns
    -------
    matplotlib.figure.Figure
        Thin grey vertical lines mark the start of each braille character (up to
        :data:`MAX_START_LINES` of them; none when there are more), the green line the start of
        reading.
    """
    import numpy as np
    fig = _new_figure() if fig is None else fig
    ax, ax2 = fig.axes
    t, sp = np.asarray(data["t_s"]), np.asarray(data["setpoint_n"])
    band = data["band_fraction"]
    keep = _corners(sp)
    ax.fill_between(t[keep], sp[keep] * (1 - band), sp[keep] * (1 + band), color="0.9", label=f"band +/-{band:.0%}")
    ax.plot(t[keep], sp[keep], "k--", lw=1, label="setpoint")
    ax.plot(t, data["force_est_n"], color="tab:orange", lw=0.8, label="estimated (Wiener)")
    ax.plot(t, data["force_true_n"], color="tab:blue", lw=1.0, label="true (finger)")
    starts = data["starts_s"]
    if len(starts) <= MAX_START_LINES:
        for i, s in enumerate(starts):
            ax.axvline(s, color="0.75", lw=0.4, zorder=0, label="character starts" if i == 0 else None)
    ax.axvline(data["reading_start_s"], color="tab:green", lw=1, label="reading starts")
    ax.set_title(data["title"])
    ax.legend(loc="upper right", fontsize=8, ncol=3)
    ax.set_ylim(0, max(1.5 * float(np.max(sp)), float(np.max(data["force_true_n"])) * 1.05))
    ax2.plot(t, data["command_v"], color="tab:red", lw=0.8)
    return fig


def _corners(y):
    """Indices of the samples of ``y`` that are not inside a run of equal values: the polyline
    through them is the polyline through every sample (a setpoint holds for long stretches)."""
    import numpy as np
    y = np.asarray(y)
    keep = np.ones(len(y), dtype=bool)
    if len(y) > 2:
        keep[1:-1] = (y[1:-1] != y[:-2]) | (y[1:-1] != y[2:])
    return np.flatnonzero(keep)


def png_bytes(fig) -> bytes:
    """``fig`` as PNG at :data:`DPI`."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


class ForcePlotter:
    """A helper process that draws force.png (:func:`draw_force_figure`) from data sent later.

    Start it before the work that produces the data; :meth:`send` the data, do other work,
    then take the PNG with :meth:`png`.  :meth:`close` (also the end of a ``with`` block)
    ends the helper if it still runs.  :meth:`png` returns None when the helper failed or
    could not be reached: the caller then draws the figure itself, which raises what went
    wrong.

    Raises
    ------
    OSError
        The process could not be started (:meth:`start` returns None instead).
    """

    def __init__(self):
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        code = (f"import sys; sys.path.insert(0, {root!r}); "
                "from ebraille_sim.tools.forceplot import serve; serve()")
        self._proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      start_new_session=os.name == "posix")
        self._sent = False
        self._writer = None

    @classmethod
    def start(cls) -> ForcePlotter | None:
        """A started helper, or None where no interpreter can be started (no ``sys.executable``, an OS error)."""
        if not sys.executable:
            return None
        try:
            return cls()
        except OSError:
            return None

    def send(self, data: dict) -> None:
        """Hand the figure data (:func:`ebraille_sim.tools.report.figure_data`) to the helper.

        The data go down the pipe from a thread of their own, so this returns at once even
        while the helper is still loading Matplotlib."""
        payload = pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)
        self._writer = threading.Thread(target=self._write, args=(len(payload).to_bytes(_HEADER, "little"), payload),
                                        daemon=True)
        self._writer.start()

    def _write(self, header: bytes, payload: bytes) -> None:
        try:
            self._proc.stdin.write(header)
            self._proc.stdin.write(payload)
            self._proc.stdin.flush()
            self._sent = True
        except (OSError, ValueError):
            self._sent = False

    def png(self) -> bytes | None:
        """The PNG the helper drew from the data sent, or None when it failed (or nothing was sent)."""
        if self._writer is None:
            self.close()
            return None
        self._writer.join(_TIMEOUT_S)
        if self._writer.is_alive() or not self._sent:
            self.close()
            return None
        try:
            out, _ = self._proc.communicate(timeout=_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.close()
            return None
        return out if self._proc.returncode == 0 and out else None

    def close(self) -> None:
        """End the helper (when it still runs) and release its pipes."""
        if self._proc.poll() is None:
            self._proc.kill()
        try:
            self._proc.communicate()
        except (OSError, ValueError):
            self._proc.wait()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _read_payload(stream) -> bytes | None:
    """One length-prefixed payload from ``stream`` (None at the end of the input)."""
    header = stream.read(_HEADER)
    if len(header) != _HEADER:
        return None
    size = int.from_bytes(header, "little")
    payload = stream.read(size)
    return payload if len(payload) == size else None


def serve() -> None:
    """The helper process of :class:`ForcePlotter`: load Matplotlib and draw the empty figure,
    read the figure data from stdin, write the PNG to stdout.  Exit status 1 with the error on stderr when
    drawing fails, 0 without output when the input ends before the data."""
    try:
        fig = _new_figure()
        fig.canvas.draw()                         # loads the fonts and lays out the fixed texts
        payload = _read_payload(sys.stdin.buffer)
        if payload is None:
            os._exit(0)
        png = png_bytes(draw_force_figure(pickle.loads(payload), fig))
        sys.stdout.buffer.write(png)
        sys.stdout.buffer.flush()
    except BaseException as exc:                  # noqa: BLE001 (reported to the parent, which draws again)
        sys.stderr.write(f"{type(exc).__name__}: {exc}\n")
        sys.stderr.flush()
        os._exit(1)
    os._exit(0)
