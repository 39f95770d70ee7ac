"""Figures and numbers of docs/tuning.md.

Run from the repository root (14 minutes measured on the 2-core development machine shared
with other jobs, about 12 of them the four robust tunings, two at a time, 5-6 minutes each)::

    python studies/tuning/make_tuning_figures.py            # everything
    python studies/tuning/make_tuning_figures.py --reuse    # keep the tunings (gains_*.toml), redo the rest (2.3 min of the full run)
    python studies/tuning/make_tuning_figures.py --loops-only   # redo only the loop analyses and Bode/Nyquist figures (10 s)

Writes the PNGs into ``docs/figures/tuning/`` and ``results.json`` and the gains files into
``studies/tuning/``.  Every number quoted in docs/tuning.md comes from ``results.json``.
"""
from __future__ import annotations

import dataclasses
import json
import pathlib
import sys
import time
import tomllib

import control
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

from ebraille_sim.analysis.design import make_lqg, simc_pid  # noqa: E402
from controllers.pid import DEFAULT_PID, PID  # noqa: E402
from ebraille_sim.analysis.robust import (evaluate, friction_band_v, gains_toml, linearisation_points,  # noqa: E402
                                          population_ms, robust_tune, standard_scenarios, summarise,
                                          tuning_population, unramped)
from controllers.schedule import HAND, MS_1_6, RECOMMENDED, ScheduleConfig, ScheduledPID  # noqa: E402
from controllers.friction import FRICTION_GAINS  # noqa: E402
from ebraille_sim.analysis.margins import analyse_loop  # noqa: E402
from ebraille_sim.analysis.plant_model import continuous_model, operating_point  # noqa: E402
from ebraille_sim.analysis.plots import plot_bode, plot_nyquist  # noqa: E402
from ebraille_sim.analysis.sampled import linearize, sampled_front  # noqa: E402
from ebraille_sim.plant.lumped import Plant  # noqa: E402
from ebraille_sim.physics.params import DeviceParams  # noqa: E402
from ebraille_sim.scenarios.runner import run_scenario  # noqa: E402
from ebraille_sim.scenarios.spec import load_scenario  # noqa: E402

OUT = HERE
FIG = ROOT / "docs" / "figures" / "tuning"
POP_SEED, POP_N = 0, 6
HELDOUT_SEED, HELDOUT_N = 1, 8
FORCES = [0.6, 0.8, 1.0, 1.2, 1.5, 2.0]
"""Every setpoint of the tuning scenarios (setpoint steps, steady reading, contact onset)."""
TUNINGS = {
    "ms1.6": {"ms_max": 1.6, "ms_gain": 1.0, "label": "Ms <= 1.6, sliding model (the robustness target)"},
    "ms2.0": {"ms_max": 2.0, "ms_gain": 1.0, "label": "Ms <= 2.0, sliding model"},
    "friction": {"ms_max": 1.6, "ms_gain": 0.5, "label": "Ms <= 1.6 on the loop x 0.5 (friction-band DF)"},
    "free": {"ms_max": float("inf"), "ms_gain": 1.0, "label": "no Ms bound (simulation only)"},
}
EVALUATIONS = 36


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
    fig.savefig(FIG / "step_match.png", dpi=110)
    plt.close(fig)
    results["step_match"] = out


REC = "recommended (pid_scheduled default)"
"""``controllers.schedule.RECOMMENDED``: the "ms2.0" tuning, rounded to three significant digits."""
EARLIER = "earlier RECOMMENDED (kp 0.81, ki 1.8)"
"""What ``RECOMMENDED`` was before the "ms2.0" tuning replaced it (the earlier model's
friction-relaxation tuning, rounded; ``pid_friction`` keeps these gains)."""
EARLIER_CONFIG = ScheduleConfig(**FRICTION_GAINS)
TUNE_DEFAULT = "Ms <= 1.6 (MS_1_6)"
"""``controllers.schedule.MS_1_6``: the "ms1.6" tuning (what ``tune`` gives by default), rounded."""


def _slim(obj, key=None):
    """results.json without per-device rows of the tuning reports, floats to 5 digits."""
    if isinstance(obj, dict):
        return {k: _slim(v, k) for k, v in obj.items() if k not in ("per_device", "play_model")}
    if isinstance(obj, (list, tuple)):
        return [_slim(v) for v in obj]
    if isinstance(obj, float):
        return float(f"{obj:.5g}")
    return obj


def _write(results):
    import re
    text = json.dumps(_slim(results), indent=1, default=float)
    # lists of plain numbers on one line
    text = re.sub(r"\[[-0-9.eE,\s]*\]", lambda m: " ".join(m.group(0).split()), text)
    # innermost objects (e.g. median / worst / cvar25) on one line
    text = re.sub(r"\{[^{}\[\]]*\}", lambda m: " ".join(m.group(0).split()), text)
    (OUT / "results.json").write_text(text + "\n")


def _ms_grid(ms):
    return np.where(np.isfinite(ms), ms, -1).tolist()


def loop_figures(results, recommended):
    forces = (0.6, 1.2, 2.0)
    sched = ScheduledPID(recommended)
    an_d = [analyse_loop(DEFAULT_PID, force_n=f) for f in forces]
    an_s = [analyse_loop(sched.pid_config_at(f), force_n=f) for f in forces]
    plot_bode(an_d, FIG / "bode_default.png", "default PID (kp 2, ki 8), nominal reader")
    plot_nyquist(an_d, FIG / "nyquist_default.png", "default PID, nominal reader")
    plot_bode(an_s, FIG / "bode_scheduled.png", "recommended scheduled PID, nominal reader (sliding model)")
    plot_nyquist(an_s, FIG / "nyquist_scheduled.png", "recommended scheduled PID, nominal reader (sliding model)")
    simc = simc_pid(force_n=1.0)
    an_simc = [analyse_loop(simc, force_n=f) for f in forces]
    results["loops"] = {"default_pid": [a.summary() for a in an_d], "scheduled_pid": [a.summary() for a in an_s],
                        "simc": {"gains": {"kp_v_per_n": simc.kp_v_per_n, "ki_v_per_ns": simc.ki_v_per_ns},
                                 "loops": [a.summary() for a in an_simc]}}
    # the default PID at 1 N: the frequency-response margins against control.stability_margins
    a1 = analyse_loop(DEFAULT_PID, force_n=1.0)
    gm, pm, _, _, wgc, _ = control.stability_margins(a1.loop)
    results["loops"]["default_pid_1n_margins"] = {
        "loop_margins": a1.summary(),
        "control_stability_margins": {"version": control.__version__, "gain_margin": float(gm),
                                      "phase_margin_deg": float(pm), "gain_crossover_hz": float(wgc) / (2 * np.pi)}}
    P = linearize(force_n=1.0)
    results["plant_1n"] = {"dc_gain_n_per_v": float(np.real(control.dcgain(P))),
                           "slowest_pole_abs": float(np.max(np.abs(P.poles()))),
                           "states": P.state_labels}


def ms_maps(results, pop, designs):
    """Ms of each design at every device and setpoint (sliding model, the shipped estimator's delay
    nk = 1; tune's check adds nk = 0), figure of three of them."""
    pts = linearisation_points(pop, FORCES, delays=False)
    maps = {}
    for name, ctrl in designs.items():
        maps[name] = population_ms(ctrl, pts).reshape(len(pop), len(FORCES))
    shown_names = [n for n in ("default PID", "hand design", TUNE_DEFAULT, REC) if n in maps]
    fig, axes = plt.subplots(1, len(shown_names), figsize=(4.6 * len(shown_names), 4.5), sharey=True)
    for ax, name in zip(axes, shown_names):
        ms = maps[name]
        shown = np.where(np.isfinite(ms), ms, 10.0)
        im = ax.imshow(shown, aspect="auto", cmap="RdYlGn_r", vmin=1.0, vmax=3.0)
        for i in range(ms.shape[0]):
            for j in range(ms.shape[1]):
                ax.text(j, i, "unst." if not np.isfinite(ms[i, j]) else f"{ms[i, j]:.2f}", ha="center",
                        va="center", fontsize=6)
        ax.set_xticks(range(len(FORCES)))
        ax.set_xticklabels([f"{f:g} N" for f in FORCES], fontsize=8)
        ax.set_title(f"Ms (sliding), {name}", fontsize=8)
    axes[0].set_yticks(range(len(pop)))
    axes[0].set_yticklabels([lab for lab, _ in pop], fontsize=8)
    fig.colorbar(im, ax=axes, shrink=0.8)
    fig.savefig(FIG / "ms_map.png", dpi=110)
    plt.close(fig)
    results["ms_map"] = {"forces_n": FORCES, "labels": [lab for lab, _ in pop], "unstable": -1,
                         **{name: _ms_grid(ms) for name, ms in maps.items()}}
    return maps


def _linear_estimate(front, est, u, n=10):
    """The sampled-data linear model's estimate for a command ``u`` given at the control rate.

    ``front`` runs at the control rate; the estimator reads every ``n``-th of its outputs
    (samples ``n - 1, 2 n - 1, ...``).  With the estimator's creep compensation ``front`` has
    a second input, the estimate the firmware holds: the sample the estimator reads still
    holds the previous estimate, the ones after it the new one (as ``analysis.sampled._lift``).
    """
    A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (front.A, front.B, front.C, front.D))
    Ae, Be, Ce, De = (np.atleast_2d(np.asarray(m, float)) for m in (est.A, est.B, est.C, est.D))
    comp = front.ninputs == 2
    x, xe, held = np.zeros(A.shape[0]), np.zeros(Ae.shape[0]), 0.0
    out = []
    for k, uk in enumerate(u):
        v = np.array([uk, held]) if comp else np.array([uk])
        if k % n == n - 1:
            y = C @ x + D @ v
            e = float((Ce @ xe + De @ y)[0])
            xe = Ae @ xe + Be @ y
            out.append(e)
            x = A @ x + B @ v
            held = e
        else:
            x = A @ x + B @ v
    return np.array(out)


def describing_function(results):
    """Measured describing function of the drive around the pressing equilibrium at 1 N.

    The nominal device (and the same with pure Coulomb friction) is brought to the pressing
    equilibrium with the operating command held 15 s; a sinusoid of amplitude A is added to
    the command for 4 s and the fundamental of the estimate over the last 2 s (detrended)
    is divided by the sampled-data linear model's response to the same input.
    """
    base = DeviceParams()
    coulomb = dataclasses.replace(base, motor=dataclasses.replace(base.motor, breakaway_ratio=1.0),
                                  drivetrain=dataclasses.replace(base.drivetrain, guide_breakaway_ratio=1.0))
    amps = [0.1, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.6, 2.4]
    freqs = [2.0, 8.0]
    band = friction_band_v(base, 1.0)
    out = {"friction_band_v": band, "amplitudes_v": amps, "frequencies_hz": freqs, "measured": {}}

    def fund(y, tt, f, t_end):
        m = tt >= t_end - 2.0
        A = np.vstack([np.sin(2 * np.pi * f * tt[m]), np.cos(2 * np.pi * f * tt[m]), np.ones(m.sum()), tt[m]]).T
        c = np.linalg.lstsq(A, y[m], rcond=None)[0]
        return complex(c[0], c[1])

    for dname, dev in (("default device", base), ("pure Coulomb friction", coulomb)):
        op = operating_point(dev, 1.0)
        front, est = sampled_front(dev, op)
        for f in freqs:
            vals = []
            for a in amps:
                pl = Plant.from_devices([dev], seeds=[1])
                pl.set_finger(1e-3)
                for _ in range(15000):
                    pl.advance(op.command_v)
                e0 = pl.force_est_n[0]
                T = 4.0
                n = int(T * 1000)
                t = np.arange(n) * 1e-3
                u = a * np.sin(2 * np.pi * f * t)
                fe = np.zeros(n)
                for k in range(n):
                    pl.advance(op.command_v + u[k])
                    fe[k] = pl.force_est_n[0]
                y_lin = _linear_estimate(front, est, u)
                te = t[9::10]
                N = fund(fe[9::10] - e0, te, f, T) / fund(y_lin, te, f, T)
                vals.append([abs(N), float(np.degrees(np.angle(N)))])
            out["measured"][f"{dname}, {f:g} Hz"] = vals
    # play (backlash) describing function of half-width b = band/2
    b = band / 2
    aa_ = np.linspace(b * 1.001, max(amps) * 1.2, 300)
    r = b / aa_
    re = 0.5 + (np.arcsin(1 - 2 * r) + 2 * (1 - 2 * r) * np.sqrt(r * (1 - r))) / np.pi
    im = -4 * r * (1 - r) / np.pi
    out["play_model"] = {"amplitude_v": aa_.tolist(), "gain": np.hypot(re, im).tolist(),
                         "phase_deg": np.degrees(np.arctan2(im, re)).tolist()}
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for key, vals in out["measured"].items():
        v = np.array(vals)
        a1.plot(amps, v[:, 0], "o-", label=key)
        a2.plot(amps, v[:, 1], "o-", label=key)
    a1.plot(aa_, np.hypot(re, im), "k--", label=f"play of width {band:.2f} V (formula)")
    a2.plot(aa_, np.degrees(np.arctan2(im, re)), "k--", label="play (formula)")
    a1.axvline(b, color="0.6", lw=0.8)
    a1.set_xlabel("command amplitude A (V)")
    a2.set_xlabel("command amplitude A (V)")
    a1.set_ylabel("|N(A)| (nonlinear / sliding model)")
    a2.set_ylabel("phase of N(A) (deg)")
    a2.set_ylim(-100, 30)
    a1.legend(fontsize=7)
    a1.set_title("describing function of the drive at 1 N (estimate out)", fontsize=9)
    fig.tight_layout()
    fig.savefig(FIG / "describing_function.png", dpi=110)
    plt.close(fig)
    results["describing_function"] = out
    print("describing function done")


def _tune_one(name):
    t = TUNINGS[name]
    spec = load_scenario("setpoint_steps")
    pop = tuning_population(POP_N, seed=POP_SEED)
    t0 = time.perf_counter()
    res = robust_tune(spec, pop, family="pid_scheduled", ms_max=t["ms_max"], ms_gain=t["ms_gain"],
                      max_evaluations=EVALUATIONS, scenarios=standard_scenarios(spec))
    rep = res.report()
    rep["wall_s"] = time.perf_counter() - t0
    rep["gains_file"] = res.gains_file()
    rep["label"] = t["label"]
    return name, rep


def tuning(results):
    """The four tunings of TUNINGS, two at a time (one per core)."""
    from concurrent.futures import ProcessPoolExecutor
    out = {}
    with ProcessPoolExecutor(max_workers=2) as ex:
        for name, rep in ex.map(_tune_one, list(TUNINGS)):
            g = rep["gains_file"]["gains"]
            print(f"tuned [{name}]: kp {g['kp_v_per_n']:.3g} ki {g['ki_v_per_ns']:.3g} kd {g['kd_vs_per_n']:.3g} "
                  f"cost {rep['tuned']['cost']:.3f} (hand {rep['hand']['cost']:.3f}) ({rep['wall_s']:.0f} s)", flush=True)
            out[name] = rep
    results["tuning"] = out
    return out


def _tuned_config(rep):
    g = rep["gains_file"]["gains"]
    return ScheduleConfig(**g)


EVAL_SCENARIOS = [("steady_60wpm", 12.0), ("steady_90wpm", 12.0), ("steady_120wpm", 12.0), ("contact_onset", None),
                  ("setpoint_steps", None), ("setpoint_steps_unramped", None), ("strap_slip", 20.0),
                  ("tremor_90wpm", 12.0)]
DESIGN_KEYS = {"tuned, Ms <= 1.6": "ms1.6", "tuned, Ms <= 2.0": "ms2.0", "tuned, friction DF": "friction",
               "tuned, no Ms bound": "free"}


def _load(name):
    if name.endswith("_unramped"):
        return unramped(load_scenario(name[: -len("_unramped")]))
    return load_scenario(name)


def comparison(results, pops, makers):
    """Worst case, CVaR25 and median of each metric, every controller x scenario x population."""
    table = {}
    for pname, pop in pops.items():
        table[pname] = {}
        for sname, dur in EVAL_SCENARIOS:
            spec = _load(sname)
            table[pname][sname] = {}
            for cname, mk in makers.items():
                rows = evaluate(mk, pop, spec, duration_s=dur)
                table[pname][sname][cname] = summarise(rows)
                table[pname][sname][cname]["in_band_per_device"] = [r["in_band_fraction"] for r in rows]
            print(pname, sname, {c: round(v["in_band_fraction"]["worst"], 3) for c, v in table[pname][sname].items()},
                  flush=True)
    results["comparison"] = {"scenarios": EVAL_SCENARIOS, "populations": {k: [lab for lab, _ in p]
                                                                           for k, p in pops.items()},
                             "table": table}
    names = list(makers)
    tab = table["tuning population"]
    fig, axes = plt.subplots(1, len(EVAL_SCENARIOS), figsize=(20, 5), sharey=True)
    for ax, (sname, _) in zip(axes, EVAL_SCENARIOS):
        med = [tab[sname][c]["in_band_fraction"]["median"] for c in names]
        worst = [tab[sname][c]["in_band_fraction"]["worst"] for c in names]
        y = np.arange(len(names))
        ax.barh(y + 0.2, med, height=0.4, label="median")
        ax.barh(y - 0.2, worst, height=0.4, label="worst case")
        ax.set_title(sname, fontsize=9)
        ax.set_xlim(0, 1.02)
        ax.set_xlabel("in-band fraction", fontsize=8)
    axes[0].set_yticks(np.arange(len(names)))
    axes[0].set_yticklabels(names, fontsize=8)
    axes[0].legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(FIG / "comparison.png", dpi=110)
    plt.close(fig)


def fragility(results, pop):
    """Worst case on setpoint_steps of MS_1_6 and of the same gains rounded to two digits."""
    spec = load_scenario("setpoint_steps")
    out = {}
    for name, c in (("MS_1_6", MS_1_6), ("kp 0.53, ki 1.15, kd 0", dataclasses.replace(
            MS_1_6, kp_v_per_n=0.53, ki_v_per_ns=1.15, kd_vs_per_n=0.0))):
        rows = evaluate(lambda: ScheduledPID(c), pop, spec)
        out[name] = {r["label"]: r["in_band_fraction"] for r in rows}
    results["fragility_setpoint_steps"] = out


def step_traces(results, makers, names):
    """Nominal reader, setpoint steps with and without the ramp, a few controllers."""
    fig, axes = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    out = {}
    for ax, sname in zip(axes, ("setpoint_steps", "setpoint_steps_unramped")):
        spec = _load(sname)
        out[sname] = {}
        for j, cname in enumerate(names):
            r = run_scenario(spec, controller=makers[cname]())
            tr = r.trace
            if j == 0:
                ax.plot(tr["t_s"], tr["setpoint_n"], "k--", lw=0.8, label="setpoint")
                ax.fill_between(tr["t_s"], 0.9 * tr["setpoint_n"], 1.1 * tr["setpoint_n"], color="0.9")
            ax.plot(tr["t_s"], tr["force_true_n"], lw=0.9, label=cname)
            out[sname][cname] = {"in_band_fraction": r.metrics["in_band_fraction"],
                                 "peak_force_n": r.metrics["peak_force_n"]}
        ax.set_title(f"{sname}, nominal reader (true force)", fontsize=9)
        ax.set_ylabel("force (N)")
    axes[0].legend(fontsize=8, ncol=3)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(FIG / "steps.png", dpi=110)
    plt.close(fig)
    results["step_traces"] = out


def fault_figure(results):
    names = ["fault_fsr_open", "fault_fsr_short", "fault_fsr_stuck", "fault_motor_stall", "fault_controller_nan",
             "fault_finger_withdrawn"]
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 13), sharex=True)
    out = {}
    for ax, name in zip(axes, names):
        spec = load_scenario(name)
        tr = run_scenario(spec).trace
        # the supervisor runs by default in every scenario: the comparison run turns it off
        try:
            tb = run_scenario(spec, supervised=False).trace
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
    fig.savefig(FIG / "faults.png", dpi=100)
    plt.close(fig)
    results["faults"] = out


def main():
    reuse = "--reuse" in sys.argv[1:]
    FIG.mkdir(parents=True, exist_ok=True)
    if "--loops-only" in sys.argv[1:]:
        results = json.loads((OUT / "results.json").read_text())
        loop_figures(results, RECOMMENDED)
        _write(results)
        print(f"rewrote the loop analyses of {OUT / 'results.json'} and the Bode/Nyquist figures")
        return
    old = json.loads((OUT / "results.json").read_text()) if reuse else {}
    results = {"population": {"seed": POP_SEED, "n_random": POP_N},
               "heldout_population": {"seed": HELDOUT_SEED, "n_random": HELDOUT_N}}
    t0 = time.perf_counter()
    pop = tuning_population(POP_N, seed=POP_SEED)
    results["population"]["labels"] = [lab for lab, _ in pop]
    if reuse and "tuning" in old:
        tuned = results["tuning"] = old["tuning"]
        # results.json keeps 5 digits; the gains files written with it keep the tuner's floats
        for key, rep in tuned.items():
            path = OUT / f"gains_{key}.toml"
            if path.exists():
                rep["gains_file"] = tomllib.loads(path.read_text())
    else:
        tuned = tuning(results)
        # saved at once, so that a later step can be redone with --reuse
        _write(results)
        if "--tuning-only" in sys.argv[1:]:
            return
    cfg = {name: _tuned_config(rep) for name, rep in tuned.items()}
    results["recommended"] = {"config": dataclasses.asdict(RECOMMENDED), "from_tuning": "ms2.0",
                              "ms_1_6": dataclasses.asdict(MS_1_6), "hand": dataclasses.asdict(HAND)}
    step_match(results)
    loop_figures(results, RECOMMENDED)
    describing_function(results)
    simc = simc_pid(force_n=1.0)
    designs = {"default PID": DEFAULT_PID, "SIMC": simc, "hand design": ScheduledPID(HAND).pid_config_at,
               **{label: ScheduledPID(cfg[key]).pid_config_at for label, key in DESIGN_KEYS.items()},
               TUNE_DEFAULT: ScheduledPID(MS_1_6).pid_config_at, REC: ScheduledPID(RECOMMENDED).pid_config_at,
               EARLIER: ScheduledPID(EARLIER_CONFIG).pid_config_at, "LQG": make_lqg().statespace()}
    ms_maps(results, pop, designs)
    pts = linearisation_points(pop, FORCES, delays=False)
    results["ms_map_friction_0.5"] = {name: _ms_grid(population_ms(c, pts, 0.5).reshape(len(pop), len(FORCES)))
                                      for name, c in designs.items() if name != "LQG"}
    for label, key in DESIGN_KEYS.items():
        (OUT / f"gains_{key}.toml").write_text(gains_toml(tuned[key]["gains_file"]))
    (OUT / "gains_hand.toml").write_text(gains_toml({"controller": "pid_scheduled",
                                                "gains": {k: v for k, v in dataclasses.asdict(HAND).items()
                                                          if v is not None}}))
    makers = {
        "default PID": lambda: PID(DEFAULT_PID),
        "SIMC": lambda: PID(simc),
        "hand design": lambda: ScheduledPID(HAND),
        **{name: (lambda c: (lambda: ScheduledPID(c)))(cfg[key]) for name, key in DESIGN_KEYS.items()},
        "hand + feedforward": lambda: ScheduledPID(dataclasses.replace(HAND, feedforward=True),
                                                   name="pid_feedforward"),
        TUNE_DEFAULT: lambda: ScheduledPID(MS_1_6),
        REC: lambda: ScheduledPID(RECOMMENDED),
        EARLIER: lambda: ScheduledPID(EARLIER_CONFIG),
        "LQG": lambda: make_lqg(),
    }
    pops = {"tuning population": pop,
            "held-out draws": [(f"heldout_{k}", d) for k, d in
                               enumerate(__import__("ebraille_sim.scenarios.population", fromlist=["x"]).sample_devices(
                                   HELDOUT_SEED, HELDOUT_N))]}
    comparison(results, pops, makers)
    fragility(results, pop)
    step_traces(results, makers, ["default PID", "hand design", TUNE_DEFAULT, REC])
    fault_figure(results)
    results["wall_s"] = time.perf_counter() - t0
    _write(results)
    print(f"wrote {OUT} and {FIG} in {results['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
