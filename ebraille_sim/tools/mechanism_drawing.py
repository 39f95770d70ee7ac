"""Pictures and animations of the pymunk mechanism, drawn from its snapshots.

:func:`draw_snapshot` draws one plain-float snapshot
(:meth:`ebraille_sim.plant.pymunk.plant.PymunkPlant.snapshot`, or a frame of a
:class:`~ebraille_sim.plant.pymunk.recording.Recorder`) with Matplotlib's ``Figure`` and the
Agg canvas; :func:`write_animation` writes recorded frames as a GIF (or PNG frames without
Pillow); ``run --backend pymunk --animate`` uses both.  Matplotlib is imported inside the
functions that draw.

Examples
--------
>>> from ebraille_sim.physics.params import DeviceParams
>>> from ebraille_sim.plant.pymunk.plant import PymunkPlant
>>> plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
>>> draw_mechanism(plant, size_px=(320, 240)).shape
(240, 320, 3)
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ebraille_sim.physics.params import DeviceParams
    from ebraille_sim.plant.pymunk.geometry import MechanismParams
    from ebraille_sim.plant.pymunk.plant import PymunkPlant

__all__ = ["PAD_RADIUS_MM", "draw_snapshot", "draw_mechanism", "write_animation"]

PAD_RADIUS_MM = 8.0
"""Fingertip pad radius used for drawing, mm [E] (as in the Hertz estimate of contact_width_m)."""


def _gear_outline(cx, cy, r, teeth, angle, depth):
    t = np.linspace(0.0, 2.0 * np.pi, teeth * 8 + 1)
    rr = r + depth * 0.5 * np.sign(np.sin(teeth * (t - angle)))
    return cx + rr * np.cos(t), cy + rr * np.sin(t)


def draw_snapshot(snap: dict, size_px=(480, 360), tilt_gain: float = 20.0) -> np.ndarray:
    """Draw one mechanism snapshot; returns an RGB uint8 array (height, width, 3).

    Lengths are drawn to scale in millimetres, except the board tilt, which is magnified
    ``tilt_gain`` times (it is a few milliradians) and labelled so.
    """
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon, Rectangle
    geo: MechanismParams = snap["geometry"]
    dev: DeviceParams = snap["device"]
    mm = 1e3
    w_px, h_px = size_px
    fig = Figure(figsize=(w_px / 100.0, h_px / 100.0), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.02, 0.1, 0.96, 0.88))
    s = geo.rod_spacing_m * mm
    travel = (dev.drivetrain.travel_max_m - dev.drivetrain.travel_min_m) * mm
    y0 = dev.drivetrain.travel_min_m * mm
    # frame and rods
    ax.add_patch(Rectangle((-0.5 * s - 3, y0 - geo.rack_length_m * mm - 4), s + 6, 1.5, color="0.35"))
    for x in (-0.5 * s, 0.5 * s):
        ax.plot([x, x], [y0 - geo.rack_length_m * mm - 2.5, y0 + travel + 1.5], color="0.55", lw=2)
    # racks
    cmap = matplotlib.colormaps["viridis"]
    fmax = max(1e-9, 0.3)
    for i, (x, yr) in enumerate(zip((-0.5 * s, 0.5 * s), snap["rack_y_m"])):
        yr *= mm
        fric = snap["rack_friction_n"][i]
        ax.add_patch(Rectangle((x - 0.5 * geo.rack_width_m * mm, yr - geo.rack_length_m * mm),
                               geo.rack_width_m * mm, geo.rack_length_m * mm,
                               color=cmap(min(abs(fric) / fmax, 1.0)), ec="k", lw=0.6))
        ax.text(x, yr - geo.rack_length_m * mm - 1.2, f"{fric:.2f} N", ha="center", va="top", fontsize=7)
    # pinion (drawn on the shaft, rotated by its travel / r)
    r = dev.drivetrain.pinion_radius_m * mm
    yc = y0 - 0.5 * geo.rack_length_m * mm
    ang = snap["pinion_y_m"] * mm / r
    gx, gy = _gear_outline(0.0, yc, r, 16, ang, 0.35)
    ax.fill(gx, gy, color="#c9a227", ec="k", lw=0.6)
    ax.plot([0.0, r * 0.8 * math.cos(ang)], [yc, yc + r * 0.8 * math.sin(ang)], color="k", lw=1)
    ax.plot([-0.5 * s + 0.5 * geo.rack_width_m * mm, -r], [yc, yc], color="0.4", lw=0.8, ls=":")
    ax.plot([r, 0.5 * s - 0.5 * geo.rack_width_m * mm], [yc, yc], color="0.4", lw=0.8, ls=":")
    # board (tilt magnified)
    th = snap["tilt_rad"] * tilt_gain
    bx, by = snap["board_x_m"] * mm, snap["board_y_m"] * mm
    wb, tb = geo.board_width_m * mm, geo.board_thickness_m * mm
    c, sn = math.cos(th), math.sin(th)
    corners = [(-0.5 * wb, 0.0), (0.5 * wb, 0.0), (0.5 * wb, -tb), (-0.5 * wb, -tb)]
    pts = [(bx + c * px - sn * py, by + sn * px + c * py) for px, py in corners]
    ax.add_patch(Polygon(pts, closed=True, color="#2e7d32", ec="k", lw=0.6))
    for col in (-0.5, 0.5):                         # display electrodes (two columns)
        px = col * 2.34
        ax.add_patch(Circle((bx + c * px, by + sn * px + 0.25), 0.72, color="#ffb300", ec="k", lw=0.4))
    # finger: a pad of radius PAD_RADIUS_MM about the press centre, flattened where the board presses it
    fy = snap["finger_y_m"] * mm
    xc = snap["press_offset_m"] * mm
    tt = math.tan(snap["finger_tilt_rad"])
    xs = np.linspace(xc - 9.0, xc + 9.0, 121)
    free = fy + (xs - xc) * tt + (xs - xc) ** 2 / (2.0 * PAD_RADIUS_MM)
    board_top = by + (xs - bx) * math.tan(th)
    on_board = np.abs(xs - bx) <= 0.5 * wb
    surf = np.where(on_board, np.maximum(free, board_top), free)
    ax.fill_between(xs, surf, fy + 9.0, color="#f4c7a1", ec="#a0522d", lw=0.8)
    fmax_c = max(max(snap["contact_force_n"]), 1e-9)
    for xcj, fj in zip(snap["contact_x_m"], snap["contact_force_n"]):
        xcj *= mm
        if fj > 0:
            y_c = by + (xcj - bx) * math.tan(th)
            ax.annotate("", xy=(xcj, y_c), xytext=(xcj, y_c + 0.8 + 3.0 * fj / fmax_c),
                        arrowprops=dict(arrowstyle="->", color="#b71c1c", lw=1.2))
    ax.set_xlim(-0.5 * s - 6, 0.5 * s + 6)
    ax.set_ylim(y0 - geo.rack_length_m * mm - 5, y0 + travel + 10)
    ax.set_aspect("equal")
    ax.axis("off")
    label = (f"t {snap['t_s']:.3f} s   F {snap.get('force_true_n', sum(snap['contact_force_n'])):.2f} N"
             f"   est {snap.get('force_est_n', float('nan')):.2f} N   tilt {snap['tilt_rad'] * 1e3:.2f} mrad"
             f" (drawn x{tilt_gain:g})")
    fig.text(0.02, 0.03, label, fontsize=7)
    canvas.draw()
    buf = np.asarray(canvas.buffer_rgba())
    return np.ascontiguousarray(buf[:, :, :3])


def draw_mechanism(plant: PymunkPlant, k: int = 0, size_px=(480, 360)) -> np.ndarray:
    """RGB picture, uint8 array of shape (height, width, 3), of device ``k`` of a :class:`PymunkPlant`."""
    return draw_snapshot(plant.snapshot(k), size_px=size_px)


def write_animation(frames: list, path, fps: float = 25.0, size_px=(480, 360), progress=None):
    """Write recorded snapshots as a GIF (Pillow) or, without Pillow, as numbered PNG frames.

    Parameters
    ----------
    frames : list of dict
        Snapshots recorded by a :class:`~ebraille_sim.plant.pymunk.recording.Recorder`.
    path : path
        The GIF; without Pillow, the folder ``path`` without its suffix receives
        ``frame_00000.png`` ... (earlier ``frame_*.png`` there are removed first).
    fps : float
        Frames per second of the GIF.
    size_px : (int, int)
        Width and height of a frame, px.
    progress : callable, optional
        Called as ``progress(done, total)`` after each frame is drawn.

    Returns
    -------
    pathlib.Path
        The path written (the GIF, or the folder of PNG frames).
    """
    import pathlib
    path = pathlib.Path(path)
    if not frames:
        raise ValueError("no frames to animate")
    try:
        import PIL  # noqa: F401
        have_pillow = True
    except ModuleNotFoundError:
        have_pillow = False
    images = []
    for f in frames:
        images.append(draw_snapshot(f, size_px=size_px))
        if progress is not None:
            progress(len(images), len(frames))
    path.parent.mkdir(parents=True, exist_ok=True)
    if have_pillow:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.animation as animation
        import matplotlib.pyplot as plt
        fig = plt.figure(figsize=(size_px[0] / 100.0, size_px[1] / 100.0), dpi=100)
        ax = fig.add_axes((0, 0, 1, 1))
        ax.axis("off")
        im = ax.imshow(images[0])

        def update(i):
            im.set_data(images[i])
            return (im,)
        anim = animation.FuncAnimation(fig, update, frames=len(images), blit=True)
        out = path if path.suffix.lower() == ".gif" else path.with_suffix(".gif")
        anim.save(str(out), writer=animation.PillowWriter(fps=fps))
        plt.close(fig)
        return out
    import matplotlib.image as mpimg
    folder = path.with_suffix("")
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("frame_*.png"):
        old.unlink()
    for i, img in enumerate(images):
        mpimg.imsave(folder / f"frame_{i:05d}.png", img)
    return folder
