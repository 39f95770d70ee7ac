"""Pictures of the device for the Gymnasium env's ``render_mode="rgb_array"``.

A frame has three panels, drawn with Matplotlib's Agg canvas (no window, no pyplot
state):

* the device in side view, to scale along the travel axis: gearmotor and pinion, the two
  racks, the board with the 3x2 display, and the reading finger whose pulp is flattened by
  the board (board travel and pulp compression in mm);
* the true contact force (what the finger feels), the microcontroller's estimate and the
  setpoint over the last seconds, with the safe-force limit;
* the Braille cell on the display, raised dots filled.

Examples
--------
>>> import numpy as np
>>> snap = RenderSnapshot(time_s=1.0, board_pos_m=1.2e-3, finger_pos_m=1.0e-3, travel_max_m=6e-3,
...                       force_true_n=0.9, force_est_n=0.85, setpoint_n=1.0, safe_force_n=3.0,
...                       command_v=0.6, dots=np.zeros((3, 2), bool), character="")
>>> img = Renderer().draw(snap)
>>> img.shape, img.dtype
((360, 720, 3), dtype('uint8'))
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RenderSnapshot", "Renderer", "RenderedEnv", "snapshot_from"]

WIDTH_PX, HEIGHT_PX, DPI = 720, 360, 100
HISTORY_S = 3.0


@dataclass(frozen=True)
class RenderSnapshot:
    """What one frame shows (SI units).

    ``dots`` is the (3, 2) boolean grid of the displayed cell (all False between cells);
    ``history`` is None or a dict of equal-length sequences ``t_s``, ``force_true_n``,
    ``force_est_n``, ``setpoint_n``.
    """
    time_s: float
    board_pos_m: float
    finger_pos_m: float
    travel_max_m: float
    force_true_n: float
    force_est_n: float
    setpoint_n: float
    safe_force_n: float
    command_v: float
    dots: np.ndarray
    character: str
    history: dict | None = None


def snapshot_from(state_row, input_row, episode, step: int, dt_s: float, safe_force_n: float,
                  history=None) -> RenderSnapshot:
    """Snapshot of one env at step ``step`` from its packed plant state and input rows and its
    :class:`~ebraille_sim.rl.env.Episode`."""
    from ebraille_sim.scenarios.braille import dots_grid
    from ebraille_sim.plant.layout import S, U
    time_s = step * dt_s
    k = episode.schedule.index_at(time_s)
    if k >= 0:
        cell = episode.schedule.cells[k]
        dots, char = dots_grid(cell), cell.unicode
    else:
        dots, char = np.zeros((3, 2), bool), ""
    return RenderSnapshot(time_s=float(time_s), board_pos_m=float(state_row[S.board_pos_m]),
                          finger_pos_m=float(input_row[U.finger_pos_m]),
                          travel_max_m=float(episode.device.drivetrain.travel_max_m),
                          force_true_n=float(state_row[S.contact_force_n]),
                          force_est_n=float(state_row[S.force_est_n]),
                          setpoint_n=float(episode.setpoint_n[min(step, episode.n_steps)]),
                          safe_force_n=float(safe_force_n), command_v=float(input_row[U.command_v]),
                          dots=dots, character=char, history=history)


class Renderer:
    """Draws :class:`RenderSnapshot` frames into RGB arrays of shape (360, 720, 3), uint8."""

    def __init__(self, width_px: int = WIDTH_PX, height_px: int = HEIGHT_PX):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        self.fig = Figure(figsize=(width_px / DPI, height_px / DPI), dpi=DPI)
        self.canvas = FigureCanvasAgg(self.fig)
        gs = self.fig.add_gridspec(2, 3, width_ratios=[1.15, 1.7, 0.75], height_ratios=[1, 1],
                                   left=0.04, right=0.98, top=0.84, bottom=0.13, wspace=0.3, hspace=0.5)
        self.ax_dev = self.fig.add_subplot(gs[:, 0])
        self.ax_force = self.fig.add_subplot(gs[:, 1])
        self.ax_cell = self.fig.add_subplot(gs[0, 2])
        self.ax_text = self.fig.add_subplot(gs[1, 2])

    def draw(self, snap: RenderSnapshot) -> np.ndarray:
        """Render one frame; returns a new array of shape (height, width, 3), uint8."""
        self._device(snap)
        self._force(snap)
        self._cell(snap)
        self._text(snap)
        self.fig.suptitle(f"E-Braille contact force   t = {snap.time_s:6.2f} s", fontsize=10)
        self.canvas.draw()
        rgba = np.asarray(self.canvas.buffer_rgba())
        return np.array(rgba[:, :, :3])

    def close(self) -> None:
        self.fig.clear()

    # -- panels --------------------------------------------------------------------------------
    def _device(self, snap):
        from matplotlib.patches import Circle, Ellipse, Rectangle
        ax = self.ax_dev
        ax.clear()
        ax.set_title("device (mm)", fontsize=8)
        xb = snap.board_pos_m * 1e3
        xf = snap.finger_pos_m * 1e3
        top = snap.travel_max_m * 1e3
        y0 = -4.0                                   # frame base, mm below the retracted board
        ax.add_patch(Rectangle((-6, y0 - 1), 12, 1, color="0.55"))
        ax.add_patch(Rectangle((-5.5, y0), 2.6, 3.2, color="0.35"))          # gearmotor
        ax.add_patch(Circle((-2.2, y0 + 2.2), 0.9, color="0.2"))              # pinion
        for x in (-1.2, 3.6):                                                  # racks
            ax.add_patch(Rectangle((x, xb - 3.5), 0.8, 3.5, color="#b08040"))
        ax.add_patch(Rectangle((-1.5, xb - 0.6), 5.6, 0.6, color="#3060a0"))  # board
        for r in range(3):
            for c in range(2):
                raised = bool(snap.dots[r, c])
                ax.add_patch(Circle((0.0 + 1.2 * r, xb + 0.12), 0.22,
                                    color="#ffd030" if raised else "#203050"))
        comp = max(0.0, xb - xf)
        pulp = Ellipse((1.3, xf + 3.2), 7.0, 6.4, color="#e8b8a0")            # undeformed pulp: bottom at xf
        ax.add_patch(pulp)
        if comp > 0:                                                          # flattened by the board
            keep = Rectangle((-6.5, xb), 13.0, top + 10.0, transform=ax.transData)
            pulp.set_clip_path(keep)
            ax.add_patch(Rectangle((-1.5, xb), 5.6, 0.08, color="#c06040"))
        arrow = 1.5 * snap.force_true_n
        ax.annotate("", xy=(5.4, xb), xytext=(5.4, xb + max(arrow, 1e-3)),
                    arrowprops={"arrowstyle": "->", "color": "#c03030", "lw": 1.5})
        ax.text(5.0, xb + arrow + 0.3, "F", color="#c03030", fontsize=7)
        ax.text(-5.8, top + 4.8, f"board {xb:5.2f}\npulp  {xf:5.2f}\ncompression {comp:4.2f}", fontsize=6,
                family="monospace", va="top")
        ax.set_xlim(-6.5, 6.5)
        ax.set_ylim(y0 - 1.5, top + 5.0)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.tick_params(labelsize=6)

    def _force(self, snap):
        ax = self.ax_force
        ax.clear()
        ax.set_title("contact force (N)", fontsize=8)
        h = snap.history
        if h and len(h["t_s"]) > 1:
            t = np.asarray(h["t_s"])
            sel = t >= snap.time_s - HISTORY_S
            ax.plot(t[sel], np.asarray(h["setpoint_n"])[sel], color="0.4", lw=1.0, ls="--", label="setpoint")
            ax.plot(t[sel], np.asarray(h["force_est_n"])[sel], color="#3060c0", lw=1.0, label="estimated")
            ax.plot(t[sel], np.asarray(h["force_true_n"])[sel], color="#c03030", lw=1.2, label="true")
            ax.set_xlim(max(0.0, snap.time_s - HISTORY_S), max(snap.time_s, 0.1))
        else:
            names = ["setpoint", "estimated", "true"]
            vals = [snap.setpoint_n, snap.force_est_n, snap.force_true_n]
            ax.barh(names, vals, color=["0.6", "#3060c0", "#c03030"])
            ax.set_xlim(0, snap.safe_force_n * 1.1)
        ax.axhline(snap.safe_force_n, color="k", lw=0.8) if h and len(h["t_s"]) > 1 else \
            ax.axvline(snap.safe_force_n, color="k", lw=0.8)
        if h and len(h["t_s"]) > 1:
            ax.set_ylim(0, snap.safe_force_n * 1.1)
            ax.legend(fontsize=6, loc="upper left")
            ax.set_xlabel("time (s)", fontsize=7)
        ax.tick_params(labelsize=6)

    def _cell(self, snap):
        ax = self.ax_cell
        ax.clear()
        ax.set_title("cell on display", fontsize=8)
        for r in range(3):
            for c in range(2):
                raised = bool(snap.dots[r, c])
                ax.scatter([c], [2 - r], s=180, c="#202020" if raised else "white", edgecolors="#202020")
        ax.set_xlim(-0.8, 1.8)
        ax.set_ylim(-0.8, 2.8)
        ax.set_aspect("equal")
        ax.axis("off")

    def _text(self, snap):
        ax = self.ax_text
        ax.clear()
        ax.axis("off")
        ax.text(0.0, 1.0, f"true   {snap.force_true_n:5.2f} N\nest.   {snap.force_est_n:5.2f} N\n"
                f"setpt  {snap.setpoint_n:5.2f} N\nmotor  {snap.command_v:+5.2f} V",
                fontsize=7, family="monospace", va="top", transform=ax.transAxes)


class RenderedEnv:
    """``render()`` and ``close()`` of the envs (``render_mode="rgb_array"``): the display, the board
    and the finger at the current step.  An env sets ``render_mode``, ``episode``, ``plant``, ``config``
    and ``_k``; :meth:`_render_history` gives the recorded history the frame draws (none by default)."""

    _renderer = None

    def _render_history(self):
        return None

    def render(self):
        """The display, the board and the finger now, an RGB array (``render_mode="rgb_array"``)."""
        if self.render_mode is None:
            import gymnasium as gym
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self.episode is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            self._renderer = Renderer()
        snap = snapshot_from(self.plant.state[0], self.plant.inputs[0], self.episode, self._k,
                             self.config.dt_s, self.config.safe_force_n, self._render_history())
        return self._renderer.draw(snap)

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
