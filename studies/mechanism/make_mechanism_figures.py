"""Figures of docs/mechanism.md: the off-centre press, the backend cross-check, a picture.

Run from the repository root::

    python studies/mechanism/make_mechanism_figures.py            # about two minutes on two cores

Writes the PNGs into docs/figures/mechanism/ and the text tables into studies/mechanism/:

* ``offcentre_press.png``: the ``offcentre_press`` scenario on both backends: true and
  estimated force, board tilt, per-rack friction level and bushing side loads;
* ``crosscheck.png``: true-force RMS difference between the backends on every standard
  scenario (full length), next to the lumped plant's own difference between its 10 kHz
  and 20 kHz physics steps;
* ``mechanism.png``: the drawing of the mechanism with the press 9 mm off-centre;
* ``crosscheck.txt``: the numbers of ``crosscheck.png``.
"""
from __future__ import annotations

import dataclasses
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ebraille_sim.plant.pymunk.plant import PymunkPlant  # noqa: E402
from ebraille_sim.plant.pymunk.recording import Recorder  # noqa: E402
from ebraille_sim.scenarios.mechanism_section import load_mechanism_scenario  # noqa: E402
from ebraille_sim.physics.params import DeviceParams  # noqa: E402
from ebraille_sim.scenarios.runner import run_scenario  # noqa: E402
from ebraille_sim.scenarios.spec import load_scenario  # noqa: E402
from ebraille_sim.tools.mechanism_drawing import draw_snapshot  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
OUT = HERE
FIG = HERE.parents[1] / "docs" / "figures" / "mechanism"
STANDARD = ["steady_60wpm", "steady_90wpm", "steady_120wpm", "setpoint_steps", "contact_onset"]


def rms_rel(a, b, sp):
    d = np.asarray(a) - np.asarray(b)
    return float(np.sqrt(np.mean(d ** 2)) / np.mean(sp))


def offcentre_figure():
    spec = load_mechanism_scenario("offcentre_press")
    rec = Recorder(every_s=0.005)
    pm = run_scenario(spec, backend="pymunk", recorder=rec)
    lu = run_scenario(spec)
    fr = rec.frames[1:]
    t = np.array([f["t_s"] for f in fr])
    tilt = np.array([f["tilt_rad"] for f in fr]) * 1e3
    lim = np.array([f["rack_friction_limit_n"] for f in fr])
    side = np.array([f["side_load_n"] for f in fr])
    off = np.array([f["press_offset_m"] for f in fr]) * 1e3

    def smooth(x, n=40):
        x = np.asarray(x, dtype=float)
        padded = np.concatenate([np.full(n // 2, x[0]), x, np.full(n - 1 - n // 2, x[-1])])
        return np.convolve(padded, np.ones(n) / n, mode="valid")

    fig, ax = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    ax[0].plot(lu.trace["t_s"], smooth(lu.trace["force_true_n"], 200), color="0.5", label="lumped, true (0.2 s mean)")
    ax[0].plot(pm.trace["t_s"], smooth(pm.trace["force_true_n"], 200), color="C3", label="pymunk, true (0.2 s mean)")
    ax[0].plot(pm.trace["t_s"], smooth(pm.trace["force_est_n"], 200), color="C0", ls="--",
               label="pymunk, estimate (0.2 s mean)")
    ax[0].axhline(spec.setpoint.force_n, color="k", lw=0.6)
    ax[0].set_ylabel("force, N")
    ax[0].set_ylim(0.85, 1.15)
    ax[0].legend(fontsize=7, loc="lower left", ncol=3)
    ax[1].plot(t, off, color="k")
    ax[1].set_ylabel("press offset, mm")
    ax1b = ax[1].twinx()
    ax1b.plot(t, np.degrees([f["finger_tilt_rad"] for f in fr]), color="C4", ls=":")
    ax1b.set_ylabel("finger tilt, deg", color="C4")
    ax[2].plot(t, tilt, color="C2")
    ax[2].set_ylabel("board tilt, mrad")
    ax[3].plot(t, lim[:, 0], color="C0", label="rack A friction level")
    ax[3].plot(t, lim[:, 1], color="C1", label="rack B friction level")
    ax[3].plot(t, side[:, 0], color="C0", ls=":", label="rack A side load")
    ax[3].plot(t, side[:, 1], color="C1", ls=":", label="rack B side load")
    ax[3].set_ylabel("N")
    ax[3].set_xlabel("time, s")
    ax[3].legend(fontsize=7, ncol=2)
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle("offcentre_press: press moved toward rack B (0, 3, 6, 9 mm), then finger tilted 3 deg")
    fig.tight_layout()
    fig.savefig(FIG / "offcentre_press.png", dpi=110)
    plt.close(fig)
    # numbers for the text: 1 s means at the end of every pose
    rows = []
    for t0, t1, label in [(2.0, 3.0, "centred"), (5.0, 6.0, "3 mm"), (8.0, 9.0, "6 mm"), (11.0, 12.0, "9 mm"),
                          (14.0, 15.0, "centred, tilt 3 deg")]:
        m = (t >= t0) & (t < t1)
        mt = (pm.trace["t_s"] >= t0) & (pm.trace["t_s"] < t1)
        rows.append(f"{label:22s} tilt {tilt[m].mean():6.2f} mrad  friction level A {lim[m, 0].mean():.3f} "
                    f"B {lim[m, 1].mean():.3f} N  side load A {side[m, 0].mean():.3f} B {side[m, 1].mean():.3f} N  "
                    f"true {pm.trace['force_true_n'][mt].mean():.3f} N  estimate {pm.trace['force_est_n'][mt].mean():.3f} N"
                    f"  (lumped true {lu.trace['force_true_n'][mt].mean():.3f} N)")
    (OUT / "offcentre_press.txt").write_text("\n".join(rows) + "\n")


def crosscheck_figure():
    rows, pm_rel, self_rel = [], [], []
    for name in STANDARD:
        spec = load_scenario(name)
        lu = run_scenario(spec)
        pm = run_scenario(spec, backend="pymunk")
        fast = dataclasses.replace(spec.device, rates=dataclasses.replace(spec.device.rates, physics_rate_hz=20000.0))
        lu20 = run_scenario(dataclasses.replace(spec, device=fast))
        r = rms_rel(lu.trace["force_true_n"], pm.trace["force_true_n"], lu.trace["setpoint_n"])
        r0 = rms_rel(lu.trace["force_true_n"], lu20.trace["force_true_n"], lu.trace["setpoint_n"])
        pm_rel.append(100 * r)
        self_rel.append(100 * r0)
        rows.append(f"{name:15s} pymunk vs lumped {100 * r:5.2f} %   lumped 10 kHz vs 20 kHz {100 * r0:5.2f} %   "
                    f"force RMSE lumped {lu.metrics['force_rmse_n']:.4f} N pymunk {pm.metrics['force_rmse_n']:.4f} N")
    (OUT / "crosscheck.txt").write_text("\n".join(rows) + "\n")
    fig, ax = plt.subplots(figsize=(8, 3.6))
    x = np.arange(len(STANDARD))
    ax.bar(x - 0.2, pm_rel, 0.4, label="pymunk vs lumped (10 kHz)")
    ax.bar(x + 0.2, self_rel, 0.4, label="lumped 10 kHz vs lumped 20 kHz", color="0.6")
    ax.axhline(5.0, color="C3", lw=1, label="5 % bound")
    ax.set_xticks(x, STANDARD, fontsize=8)
    ax.set_ylabel("true-force RMS difference,\n% of the mean setpoint")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(FIG / "crosscheck.png", dpi=110)
    plt.close(fig)


def picture():
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_finger(1e-3)
    plant.set_pose(press_offset_m=9e-3)
    import controllers
    ctrl = controllers.make("pid")
    ctrl.reset(force_est_n=float(plant.force_est_n[0]), setpoint_n=1.0, command_v=0.0)
    for _ in range(2000):
        plant.advance(ctrl.update(float(plant.force_est_n[0]), 1.0, plant.control_dt_s,
                                  float(plant.motor_current_a[0])))
    img = draw_snapshot(plant.snapshot(), size_px=(640, 480))
    plt.imsave(FIG / "mechanism.png", img)


def main():
    FIG.mkdir(parents=True, exist_ok=True)
    picture()
    offcentre_figure()
    crosscheck_figure()
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
