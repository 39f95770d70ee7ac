"""Figures and numbers of docs/tuning.md.

Run from the repository root (takes about 10 minutes on 2 cores)::

    python docs/make_tuning_figures.py

Writes PNGs and ``results.json`` into ``docs/figures/tuning/``.  Every number quoted in
docs/tuning.md comes from ``results.json``.
"""
from __future__ import annotations

import dataclasses
import json
import pathlib
import sys
import time

import control
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import controllers  # noqa: E402
from controllers.lqg import LQG  # noqa: E402
from controllers.pid import DEFAULT_PID, PID  # noqa: E402
from controllers.robust import (evaluate, linearisation_points, population_ms, robust_tune,  # noqa: E402
                                scenario_setpoints, summarise, tuning_population)
from controllers.schedule import ScheduleConfig, ScheduledPID  # noqa: E402
from controllers.tuning import (analyse_loop, continuous_model, linearize, plot_bode,  # noqa: E402
                                plot_nyquist, simc_pid)
from ebraille_sim.loop import Plant  # noqa: E402
from ebraille_sim.params import DeviceParams  # noqa: E402
from ebraille_sim.runner import run_scenario  # noqa: E402
from ebraille_sim.scenario import load_scenario  # noqa: E402

OUT = ROOT / "docs" / "figures" / "tuning"
POP_SEED, POP_N = 0, 6


def step_match(results):
    """Linear vs nonlinear response to a 0.1 V command step at 1 N."""
    base = DeviceParams()
    coulomb = dataclasses.replace(base, motor=dataclasses.replace(base.motor, breakaway_ratio=1.0),
                                  drivetrain=dataclasses.replace(base.drivetrain, guide_breakaway_ratio=1.0))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    out = {}
    for ax, (label, dev) in zip(axes, (("pure Coulomb friction", coulomb), ("default device (stiction)", base))):
        P, op = linearize(dev, 1.0, return_point=True)
        pl = Plant.from_devices([dev], seeds=[1])
        pl.set_finger(1e-3)
        for _ in range(15000):
            pl.advance(op.command_v)
        f0, e0 = pl.contact_force_n[0], pl.force_est_n[0]
        n, dv = 1500, 0.1
        fe, ft = np.zeros(n), np.zeros(n)
        for k in range(n):
            pl.advance(op.command_v + dv)
            fe[k], ft[k] = pl.force_est_n[0], pl.contact_force_n[0]
        # linearise at the force the nonlinear plant actually holds
        P, op2 = linearize(dev, float(f0), return_point=True)
        t = np.arange(n // 10) * 0.01
        y_lin = np.asarray(control.forced_response(P, T=t, U=np.full(len(t), dv)).outputs).ravel()
        y_nl = np.concatenate([[0.0], fe[9::10][:len(t) - 1] - e0])
        ct = continuous_model(dev, op2)
        tt = np.arange(n + 1) * 1e-3
        y_ct = np.asarray(control.forced_response(ct[0, 0], T=tt, U=np.full(n + 1, dv)).outputs).ravel()[1:]
        ax.plot(tt[1:], ft - f0, color="tab:blue", lw=1, label="true force, nonlinear")
        ax.plot(tt[1:], y_ct, "--", color="tab:blue", lw=1, label="true force, linear (continuous)")
        ax.plot(t, y_nl, ".", color="tab:orange", ms=3, label="estimate, nonlinear (100 Hz)")
        ax.plot(t, y_lin, "-", color="tab:orange", lw=1, label="estimate, linear (sampled)")
        ax.set_title(f"{label}: hold {f0:.3f} N, +{dv} V")
        ax.set_xlabel("time after the step (s)")
        out[label] = {"hold_force_n": float(f0),
                      "estimate_max_error_rel": float(np.max(np.abs(y_nl - y_lin)) / abs(y_lin[-1])),
                      "true_max_error_rel": float(np.max(np.abs(ft - f0 - y_ct)) / abs(y_ct[-1]))}
    axes[0].set_ylabel("force change (N)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "step_match.png", dpi=110)
    plt.close(fig)
    results["step_match"] = out


def loop_figures(results):
    forces = (0.6, 1.2, 2.0)
    sched = ScheduledPID(ScheduleConfig())
    an_d = [analyse_loop(DEFAULT_PID, force_n=f) for f in forces]
    an_s = [analyse_loop(sched.pid_config_at(f), force_n=f) for f in forces]
    plot_bode(an_d, OUT / "bode_default.png", "default PID (kp 2, ki 8), nominal reader")
    plot_nyquist(an_d, OUT / "nyquist_default.png", "default PID, nominal reader")
    plot_bode(an_s, OUT / "bode_scheduled.png", "gain-scheduled PID, nominal reader")
    plot_nyquist(an_s, OUT / "nyquist_scheduled.png", "gain-scheduled PID, nominal reader")
    simc = simc_pid(force_n=1.0)
    an_simc = [analyse_loop(simc, force_n=f) for f in forces]
    results["loops"] = {"default_pid": [a.summary() for a in an_d], "scheduled_pid": [a.summary() for a in an_s],
                        "simc": {"gains": {"kp_v_per_n": simc.kp_v_per_n, "ki_v_per_ns": simc.ki_v_per_ns},
                                 "loops": [a.summary() for a in an_simc]}}
    P = linearize(force_n=1.0)
    results["plant_1n"] = {"dc_gain_n_per_v": float(np.real(control.dcgain(P))),
                           "slowest_pole_abs": float(np.max(np.abs(P.poles()))),
                           "states": P.state_labels}


def ms_map(results, pop, spec):
    forces = scenario_setpoints(spec)
    pts = linearisation_points(pop, forces)
    sched = ScheduledPID(ScheduleConfig())
    ms_d = population_ms(DEFAULT_PID, pts).reshape(len(pop), len(forces))
    ms_s = population_ms(sched.pid_config_at, pts).reshape(len(pop), len(forces))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, ms, title in ((axes[0], ms_d, "default PID"), (axes[1], ms_s, "gain-scheduled PID")):
        shown = np.where(np.isfinite(ms), ms, 10.0)
        im = ax.imshow(shown, aspect="auto", cmap="RdYlGn_r", vmin=1.0, vmax=3.0)
        for i in range(ms.shape[0]):
            for j in range(ms.shape[1]):
                ax.text(j, i, "unst." if not np.isfinite(ms[i, j]) else f"{ms[i, j]:.2f}", ha="center",
                        va="center", fontsize=7)
        ax.set_xticks(range(len(forces)))
        ax.set_xticklabels([f"{f:g} N" for f in forces])
        ax.set_title(f"Ms, {title}")
    axes[0].set_yticks(range(len(pop)))
    axes[0].set_yticklabels([lab for lab, _ in pop], fontsize=8)
    fig.colorbar(im, ax=axes, shrink=0.8)
    fig.savefig(OUT / "ms_map.png", dpi=110)
    plt.close(fig)
    ms_l = population_ms(LQG().statespace(), pts).reshape(len(pop), len(forces))
    results["ms_map"] = {"forces_n": forces, "labels": [lab for lab, _ in pop], "unstable": -1,
                         "default_pid": np.where(np.isfinite(ms_d), ms_d, -1).tolist(),
                         "scheduled_pid": np.where(np.isfinite(ms_s), ms_s, -1).tolist(),
                         "lqg": np.where(np.isfinite(ms_l), ms_l, -1).tolist()}


def tuning(results, pop, spec):
    out = {}
    for family in ("pid", "pid_scheduled"):
        t0 = time.perf_counter()
        res = robust_tune(spec, pop, family=family, max_evaluations=24)
        rep = res.report()
        rep["wall_s"] = time.perf_counter() - t0
        rep["gains_file"] = res.gains_file()
        out[family] = rep
        print(f"tuned {family}: {rep['gains_file']}  worst in-band {rep['tuned']['metrics']['in_band_fraction']}"
              f" default {rep['default']['metrics']['in_band_fraction']}  ({rep['wall_s']:.0f} s)")
    results["tuning"] = out
    return out


def comparison(results, pop, tuned):
    makers = {
        "pid (default)": lambda: PID(DEFAULT_PID),
        "pid (robust-tuned)": lambda: controllers.make("pid", **tuned["pid"]["gains_file"]["gains"]),
        "pid_scheduled (tuned)": lambda: controllers.make("pid_scheduled", **tuned["pid_scheduled"]["gains_file"]["gains"]),
        "pid_scheduled (defaults)": lambda: controllers.make("pid_scheduled"),
        "pid_scheduled + map": lambda: ScheduledPID(ScheduleConfig(reference_map=True)),
        "pid_feedforward": lambda: controllers.make("pid_feedforward"),
        "lqg": lambda: LQG(),
    }
    scen = {"setpoint_steps": None, "steady_90wpm": 12.0, "contact_onset": None}
    table = {}
    for sname, dur in scen.items():
        spec = load_scenario(sname)
        table[sname] = {}
        for cname, mk in makers.items():
            table[sname][cname] = summarise(evaluate(mk, pop, spec, duration_s=dur))
            print(sname, cname, table[sname][cname]["in_band_fraction"])
    results["comparison"] = table
    names = list(makers)
    fig, axes = plt.subplots(1, len(scen), figsize=(15, 4.5), sharey=True)
    for ax, sname in zip(axes, scen):
        med = [table[sname][c]["in_band_fraction"]["median"] for c in names]
        worst = [table[sname][c]["in_band_fraction"]["worst"] for c in names]
        y = np.arange(len(names))
        ax.barh(y + 0.2, med, height=0.4, label="median")
        ax.barh(y - 0.2, worst, height=0.4, label="worst case")
        ax.set_title(sname)
        ax.set_xlim(0, 1.02)
        ax.set_xlabel("in-band fraction (true force within 10 %)")
    axes[0].set_yticks(np.arange(len(names)))
    axes[0].set_yticklabels(names, fontsize=8)
    axes[0].legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(OUT / "comparison.png", dpi=110)
    plt.close(fig)


def fault_figure(results):
    names = ["fault_fsr_open", "fault_fsr_short", "fault_fsr_stuck", "fault_motor_stall", "fault_controller_nan",
             "fault_finger_withdrawn"]
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 13), sharex=True)
    out = {}
    for ax, name in zip(axes, names):
        spec = load_scenario(name)
        tr = run_scenario(spec).trace
        bare = dataclasses.replace(spec, sections={k: v for k, v in spec.sections.items() if k != "supervisor"})
        try:
            tb = run_scenario(bare).trace
            peak_bare = float(tb["force_true_n"].max())
        except ValueError:
            tb, peak_bare = None, None
        t = tr["t_s"]
        if tb is not None:
            ax.plot(t, tb["force_true_n"], color="0.6", lw=0.8, label="true force, no supervisor")
        ax.plot(t, tr["force_true_n"], color="tab:blue", lw=1, label="true force, supervised")
        ax.plot(t, tr["setpoint_n"], "k--", lw=0.8, label="setpoint")
        ax.axhline(3.5, color="tab:red", lw=0.8, ls=":", label="3.5 N limit")
        ax2 = ax.twinx()
        ax2.plot(t, tr["board_pos_m"] * 1e3, color="tab:green", lw=0.8, label="board position (mm)")
        ax2.set_ylabel("board (mm)", fontsize=8)
        ax.set_ylim(0, 4.5)
        ax.set_ylabel("force (N)")
        ax.set_title(name, fontsize=9)
        out[name] = {"peak_true_force_n": float(tr["force_true_n"].max()), "peak_without_supervisor_n": peak_bare,
                     "final_board_pos_mm": float(tr["board_pos_m"][-1] * 1e3),
                     "final_force_n": float(tr["force_true_n"][-1])}
    axes[0].legend(fontsize=7, loc="upper left", ncol=4)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(OUT / "faults.png", dpi=100)
    plt.close(fig)
    results["faults"] = out


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    results = {"population": {"seed": POP_SEED, "n_random": POP_N}}
    t0 = time.perf_counter()
    step_match(results)
    loop_figures(results)
    spec = load_scenario("setpoint_steps")
    pop = tuning_population(POP_N, seed=POP_SEED)
    results["population"]["labels"] = [lab for lab, _ in pop]
    ms_map(results, pop, spec)
    fault_figure(results)
    tuned = tuning(results, pop, spec)
    comparison(results, pop, tuned)
    results["wall_s"] = time.perf_counter() - t0
    (OUT / "results.json").write_text(json.dumps(results, indent=1, default=float) + "\n")
    print(f"wrote {OUT} in {results['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
