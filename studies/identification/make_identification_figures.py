"""Figures and tables of docs/identification.md.

Runs the virtual bench (seed 0), the DMA (ideal and realistic instruments), the 30-minute
hold, the identification of all 16 models with the default options, a recovery check on a
known Wiener system, and a 10-second closed-loop check of an identified estimator.  Writes
the PNG figures into ``docs/figures/identification/`` and ``results.md`` (every table quoted
in the document) and the identified model files into ``studies/identification/``.  About two
minutes on two cores.

Run:  python studies/identification/make_identification_figures.py
"""
from __future__ import annotations

import dataclasses
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ebraille_sim.identification import bench as B  # noqa: E402
from ebraille_sim.identification import dma as D  # noqa: E402
from ebraille_sim.identification import sysid  # noqa: E402
from ebraille_sim.estimation.blockmodels import BlockModel, LinearBF, PiecewiseLinear  # noqa: E402
from ebraille_sim.commands.identify import best_model, identify_all, plot_fit  # noqa: E402
from ebraille_sim.physics.fsr import static_voltage  # noqa: E402
from ebraille_sim.estimation.paper_models import paper_model_table  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
OUT = HERE
FIG = HERE.parents[1] / "docs" / "figures" / "identification"
SEED = 0
KIND_TITLE = {"linear": "Linear", "hammerstein": "Hammerstein", "wiener": "Wiener",
              "hammerstein-wiener": "Hammerstein-Wiener"}


def fig_records(records):
    fig, axes = plt.subplots(3, 2, figsize=(11, 7.5))
    for ax, (name, rec) in zip(axes.ravel(), records.items()):
        ax.plot(rec.time_s, rec.force_n, color="tab:blue", lw=0.7)
        ax.set_ylabel("force - preload (N)", color="tab:blue", fontsize=8)
        ax2 = ax.twinx()
        ax2.plot(rec.time_s, rec.voltage_v, color="tab:red", lw=0.7)
        ax2.set_ylabel("voltage - offset (V)", color="tab:red", fontsize=8)
        ax.set_title(B.PROFILE_LABELS[name], fontsize=9)
        ax.set_xlabel("time (s)", fontsize=8)
        for a in (ax, ax2):
            a.tick_params(labelsize=7)
    fig.suptitle("Virtual bench records (detrended, content above 40 Hz removed), seed 0", fontsize=10)
    fig.tight_layout()
    fig.savefig(FIG / "bench_records.png", dpi=100)
    plt.close(fig)


def fig_dma(ideal, real):
    f_t = np.array(B.TABLE3_FREQUENCIES_HZ)
    f = np.linspace(0.05, 1.0, 300)
    inside = (f >= f_t[0]) & (f <= f_t[-1])
    film = B.FilmParams()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    ax = axes[0]
    for t, m in ((0, "o"), (1, "s")):
        ax.plot(f_t, np.array(B.TABLE3_STIFFNESS_N_PER_M[t]) / 1e3, m, mfc="none", color="k", label=f"Table 3, test {t + 1}")
    ax.plot(f[inside], np.polyval(B.EQ4_STIFFNESS_COEFFS, f[inside]) / 1e3, "k--", lw=0.8, label="eq. 4")
    ax.plot(f, film.stiffness_n_per_m(f) / 1e3, color="tab:blue", lw=1, label="bench film (causal solid)")
    ax.plot(ideal.frequencies_hz, ideal.stiffness_n_per_m / 1e3, "x", color="tab:green", ms=8, label="virtual DMA, ideal")
    ax.errorbar(real.frequencies_hz, real.stiffness_n_per_m / 1e3,
                yerr=[p.stiffness_se_n_per_m / 1e3 for p in real.points], fmt="+", color="tab:red", ms=8,
                label="virtual DMA, realistic")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("stiffness k (kN/m)")
    ax.legend(fontsize=7)
    ax = axes[1]
    for t, m in ((0, "o"), (1, "s")):
        ax.plot(f_t, B.TABLE3_DAMPING_N_S_PER_M[t], m, mfc="none", color="k", label=f"Table 3, test {t + 1}")
    ax.plot(f[inside], np.polyval(B.EQ3_DAMPING_COEFFS, f[inside]), "k--", lw=0.8, label="eq. 3")
    ax.plot(f, np.polyval(B.EQ3_DAMPING_COEFFS, f), ":", color="0.5", lw=0.8, label="eq. 3 extrapolated")
    ax.plot(f, film.damping_n_s_per_m(f), color="tab:blue", lw=1, label="bench film")
    ax.plot(ideal.frequencies_hz, ideal.damping_n_s_per_m, "x", color="tab:green", ms=8, label="virtual DMA, ideal")
    ax.set_yscale("log")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("damping c (N s/m, log scale)")
    ax.legend(fontsize=7)
    ax = axes[2]
    ax.errorbar(real.frequencies_hz, real.damping_n_s_per_m, yerr=[p.damping_se_n_s_per_m for p in real.points],
                fmt="+", color="tab:red", ms=8, capsize=3, label="virtual DMA, realistic (+/- 1 s.e.)")
    ax.plot(f_t, np.mean(B.TABLE3_DAMPING_N_S_PER_M, axis=0), "o", mfc="none", color="k", label="Table 3 (mean)")
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("damping c (N s/m)")
    ax.legend(fontsize=7)
    ax.set_title("realistic instruments", fontsize=9)
    fig.tight_layout()
    fig.savefig(FIG / "dma.png", dpi=100)
    plt.close(fig)


def fig_creep(creep):
    t = creep["time_s"]
    r = creep["resistance_ohm"]
    win = 100
    rs = np.convolve(r, np.ones(win) / win, mode="valid")
    ts = t[win // 2: win // 2 + rs.size]
    fig, ax = plt.subplots(figsize=(6.5, 3.5))
    ax.semilogx(ts, 100 * (rs / rs[0] - 1), color="tab:blue", lw=1)
    ax.axhline(6.0, color="k", ls="--", lw=0.8, label="paper: about +6 % in 30 min")
    ax.set_xlabel("time into the hold (s)")
    ax.set_ylabel("resistance change (%)")
    ax.set_title(f"30-minute hold at 1.6 N: {100 * creep['creep_fraction']:+.2f} %", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIG / "creep.png", dpi=100)
    plt.close(fig)


def fig_fitness(table):
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.4), sharey=True)
    orders = list(sysid.ORDERS)
    for ax, kind in zip(axes, sysid.KINDS):
        for prof, color in (("chirp", "tab:blue"), ("triangle_0.1hz", "tab:red")):
            ax.plot(orders, [table[kind][o][prof] for o in orders], "o-", color=color,
                    label=f"{B.PROFILE_LABELS[prof]}, this bench")
            ax.plot(orders, [sysid.PAPER_FITNESS[kind][o][prof] for o in orders], "s--", mfc="none", color=color,
                    label=f"{B.PROFILE_LABELS[prof]}, paper")
        ax.set_title(KIND_TITLE[kind], fontsize=10)
        ax.set_xlabel("order")
        ax.set_xticks(orders)
    axes[0].set_ylabel("fitness (%)")
    axes[0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(FIG / "fitness_vs_paper.png", dpi=100)
    plt.close(fig)


def fig_static_maps(models, bench, offsets):
    dev = bench.device
    f = np.linspace(0.2, 3.0, 100)
    v = np.array([static_voltage(x, dev.fsr, dev.circuit) for x in f])
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.plot(v - offsets["voltage"], f - offsets["force"], "k", lw=2, label="FSR 402 model, static (central branch)")
    u = np.linspace(0.0, v[-1] - offsets["voltage"], 100)
    for kind, order, style in (("wiener", 5, "-"), ("hammerstein", 3, "--"), ("linear", 5, ":")):
        ax.plot(u, models[(kind, order)].steady_state(u), style, label=f"identified {kind} {order}")
    ax.plot(u, sysid.paper_model("wiener", 5).steady_state(u), "-.", color="0.5", label="paper's Wiener 5")
    ax.set_xlabel("detrended voltage (V)")
    ax.set_ylabel("detrended force (N)")
    ax.set_title("Steady-state maps of the estimators", fontsize=10)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(FIG / "static_maps.png", dpi=100)
    plt.close(fig)


def pole_axes(ax, ylabel: bool = True) -> None:
    """Draw the unit circle and label the axes of a pole plot in the z-plane."""
    th = np.linspace(0, 2 * np.pi, 200)
    ax.plot(np.cos(th), np.sin(th), color="0.7", lw=0.8, label="unit circle")
    ax.axhline(0.0, color="0.85", lw=0.5, zorder=0)
    ax.axvline(0.0, color="0.85", lw=0.5, zorder=0)
    ax.set_xlabel("Re z")
    if ylabel:
        ax.set_ylabel("Im z")
    ax.set_aspect("equal")


def recovery_example():
    poles = np.array([0.92, 0.7 + 0.5j, 0.7 - 0.5j, -0.5 + 0.3j, -0.5 - 0.3j])
    lin = LinearBF((1.0, -0.6, 0.4, -0.2, 0.3), tuple(np.real(np.poly(poles))[1:]), nk=1)
    g = lin.dc_gain()
    truth = BlockModel(lin, None, PiecewiseLinear((0.0, 0.35 * g, 0.7 * g, g), (0.0, 0.6, 1.6, 3.0)), dt_s=0.01)
    rng = np.random.default_rng(1)
    u = np.repeat(rng.uniform(0.0, 1.2, 6000), rng.integers(1, 6, 6000))[:6000]
    y = sysid.simulate(truth, u)
    y = y + 0.002 * np.std(y) * np.random.default_rng(2).standard_normal(y.size)
    rep = sysid.fit_report("wiener", u, y, 5, seed=SEED)
    rng = np.random.default_rng(99)
    uv = np.repeat(rng.uniform(0.0, 1.2, 3000), rng.integers(1, 6, 3000))[:3000]
    val = sysid.fitness(sysid.simulate(truth, uv), sysid.simulate(rep.model, uv))
    dist = sysid.match_poles(rep.model.linear.poles(), poles)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    pole_axes(axes[0])
    axes[0].plot(poles.real, poles.imag, "o", mfc="none", ms=10, color="k", label="true poles")
    p = rep.model.linear.poles()
    axes[0].plot(p.real, p.imag, "x", color="tab:red", ms=8, label="identified")
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"poles: largest distance {dist:.4f}", fontsize=10)
    ux = np.linspace(0.0, 1.2, 100)
    axes[1].plot(ux, truth.steady_state(ux), "k", lw=2, label="true static map")
    axes[1].plot(ux, rep.model.steady_state(ux), "--", color="tab:red", label="identified")
    axes[1].set_xlabel("input")
    axes[1].set_ylabel("steady output")
    axes[1].legend(fontsize=8)
    axes[1].set_title(f"validation fitness {val:.2f} %, nk found {rep.nk}", fontsize=10)
    fig.tight_layout()
    fig.savefig(FIG / "recovery.png", dpi=100)
    plt.close(fig)
    return {"validation_fitness": val, "pole_distance": dist, "nk": rep.nk, "estimation_fitness": rep.fitness_pct}


def fig_paper_poles():
    rows = paper_model_table()
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.8), sharey=True)
    for ax, kind in zip(axes, sysid.KINDS):
        pole_axes(ax, ylabel=ax is axes[0])
        for r in rows:
            if r["kind"] != kind:
                continue
            p = np.array(r["poles"])
            ax.plot(p.real, p.imag, "x", ms=7, label=f"order {r['order']}" + ("" if r["usable"] else " (unusable)"))
        ax.set_title(f"paper, {KIND_TITLE[kind]}", fontsize=10)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(FIG / "paper_poles.png", dpi=100)
    plt.close(fig)


def closed_loop_check(device_model_path, raw_model_path):
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.scenarios.spec import load_scenario

    spec = load_scenario("steady_60wpm")
    out = {}
    for label, model in (("paper:wiener:5", "paper:wiener:5"), ("identified wiener 5 (device)", str(device_model_path)),
                         ("identified wiener 5 (as identified, no shift)", str(raw_model_path))):
        dev = dataclasses.replace(spec.device, estimator=dataclasses.replace(spec.device.estimator, model=model))
        res = run_scenario(spec, duration_s=10.0, device=dev)
        out[label] = {k: res.metrics[k] for k in ("estimate_rmse_n", "force_rmse_n", "in_band_fraction")}
    return out


def _c(x, ref=None):
    """A damping in N s/m: one decimal for Table 3's magnitudes, none for the causal film's.

    ``ref`` (the estimate a standard error belongs to) sets the format instead of ``x``.
    """
    return f"{x:.1f}" if abs(x if ref is None else ref) < 100 else f"{x:.0f}"


def md_table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def main():
    FIG.mkdir(parents=True, exist_ok=True)
    bench = B.BenchParams()
    ss_bench, ss_hold, ss_dma = np.random.SeedSequence(SEED).spawn(3)
    records = B.run_profiles(B.PAPER_PROFILES.values(), bench, ss_bench)
    hold = B.run_profile(B.HOLD_PROFILE, bench, ss_hold)
    creep = B.hold_creep(hold, bench)
    ss_ideal, ss_real = ss_dma.spawn(2)
    ideal = D.dma_test(D.ideal_instruments(bench), cycles=10, seed=ss_ideal)
    real = D.dma_test(bench, cycles=10, seed=ss_real)
    fig_records(records)
    fig_dma(ideal, real)
    fig_creep(creep)
    fig_paper_poles()
    print("identifying 16 models ...", file=sys.stderr)
    models, table, info = identify_all(records, "chirp", sysid.KINDS, sysid.ORDERS,
                                       {"seed": SEED, "n_starts": 4, "n_delay_candidates": 2, "max_nfev": 200},
                                       log=lambda s: print(s, file=sys.stderr))
    fig_fitness(table)
    est = records["chirp"]
    fig_static_maps(models, bench, {"voltage": est.voltage_offset_v, "force": est.force_offset_n})
    plot_fit(models[("wiener", 5)], records, B.PROFILE_LABELS, FIG / "wiener5_fit.png")
    plot_fit(models[("hammerstein", 3)], records, B.PROFILE_LABELS, FIG / "hammerstein3_fit.png")
    rec = recovery_example()
    v0 = static_voltage(0.0, bench.device.fsr, bench.device.circuit)
    dev_model = sysid.shift_operating_point(models[("wiener", 5)], est.voltage_offset_v - v0, est.force_offset_n)
    dev_path = OUT / "wiener5_device.json"
    dev_model.save(dev_path)
    raw_path = OUT / "wiener5.json"
    models[("wiener", 5)].save(raw_path)
    loop = closed_loop_check(dev_path, raw_path)

    eq6_model = D.fit_second_order(records["chirp"], ideal.damping_coeffs, ideal.stiffness_coeffs)
    eq6 = D.second_order_table(records, eq6_model)
    parts = ["# Results quoted in docs/identification.md", "",
             f"Generated by studies/identification/make_identification_figures.py (seed {SEED}).", ""]
    rows = []
    for r, q in zip(D.table3_comparison(ideal), D.table3_comparison(real)):
        rows.append([f"{r['frequency_hz']:.3f}", f"{r['k_test1'] / 1e3:.2f} / {r['k_test2'] / 1e3:.2f}",
                     f"{r['k_virtual'] / 1e3:.2f}", f"{q['k_virtual'] / 1e3:.2f} +/- {q['k_se'] / 1e3:.2f}",
                     f"{r['c_test1']:.3f} / {r['c_test2']:.3f}", _c(r['c_virtual']),
                     f"{_c(q['c_virtual'])} +/- {_c(q['c_se'], q['c_virtual'])}",
                     f"{100 * max(abs(r[k]) for k in ('k_rel_test1', 'k_rel_test2')):.1f}"])
    parts += ["## DMA", "", md_table(["f (Hz)", "k Table 3 (kN/m)", "k ideal", "k realistic", "c Table 3 (N s/m)",
                                      "c ideal", "c realistic", "k ideal: largest diff. (%)"], rows), ""]
    bound = D.causal_stiffness_rise_bound_n_per_m(B.TABLE3_FREQUENCIES_HZ,
                                                  np.mean(B.TABLE3_DAMPING_N_S_PER_M, axis=0))
    rise = float(np.diff(np.mean(B.TABLE3_STIFFNESS_N_PER_M, axis=0)[[0, -1]])[0])
    parts += [f"Causality: a spring-plus-Maxwell material with Table 3's damping (mean of the tests) can stiffen by "
              f"at most {bound:.1f} N/m between {B.TABLE3_FREQUENCIES_HZ[0]:g} and {B.TABLE3_FREQUENCIES_HZ[-1]:g} Hz; "
              f"Table 3 stiffens by {rise / 1e3:.2f} kN/m", ""]
    parts += [f"Eqs. 3-4 refitted to the ideal DMA: c = {ideal.damping_coeffs[0]:.2f} f^2 "
              f"{ideal.damping_coeffs[1]:+.2f} f {ideal.damping_coeffs[2]:+.2f}; k = "
              f"{ideal.stiffness_coeffs[0] / 1e3:.2f} f {ideal.stiffness_coeffs[1] / 1e3:+.2f} kN/m", ""]
    implied = D.implied_damping_n_s_per_m(B.TABLE3_FREQUENCIES_HZ, np.mean(B.TABLE3_STIFFNESS_N_PER_M, axis=0))
    parts += ["Damping implied by the stiffness dispersion (pi/2 rule), N s/m: "
              + ", ".join(f"{f:g} Hz: {c:.0f}" for f, c in zip(B.TABLE3_FREQUENCIES_HZ, implied)), ""]
    parts += ["## Eq. 6", "", f"A fitted on the chirp: {eq6_model.amplitude:.4g} (paper {D.PAPER_A:.4g})", "",
              md_table(["Profile", "this bench", "paper (Table 4)"],
                       [[B.PROFILE_LABELS[n], f"{v:.2f}", f"{D.TABLE4_FITNESS[n]:.2f}"] for n, v in eq6.items()]), ""]
    parts += ["## Creep", "", f"30-minute hold: {100 * creep['creep_fraction']:+.2f} % "
              f"({creep['resistance_start_ohm']:.0f} -> {creep['resistance_end_ohm']:.0f} ohm)", ""]
    parts += ["## Fitness (this bench, paper in parentheses)", ""]
    for kind in sysid.KINDS:
        rows = []
        for prof in sysid.PAPER_PROFILE_ORDER:
            vals = [table[kind][o][prof] for o in sysid.ORDERS]
            top = max(vals)
            rows.append([B.PROFILE_LABELS[prof]] + [
                (f"**{v:.2f}**" if v == top else f"{v:.2f}") + f" ({sysid.PAPER_FITNESS[kind][o][prof]:.2f})"
                for v, o in zip(vals, sysid.ORDERS)])
        parts += [f"### {KIND_TITLE[kind]}", "", md_table(["Profile"] + [f"Order {o}" for o in sysid.ORDERS], rows), ""]
    kind, order, mean = best_model(table)
    means = {f"{k}-{o}": float(np.mean(list(table[k][o].values()))) for k in sysid.KINDS for o in sysid.ORDERS}
    parts += [f"Best by mean fitness: {kind} {order} ({mean:.2f} %). Means: "
              + ", ".join(f"{k} {v:.2f}" for k, v in means.items()), ""]
    def left_poles(key):
        kind_, order_ = key.rsplit("-", 1)
        p = [z for z in models[(kind_, int(order_))].linear.poles() if z.real < 0 and z.imag >= -5e-4]
        return ", ".join(f"{z.real:.3f}" + (f" +/- {z.imag:.3f}j" if abs(z.imag) > 5e-4 else "")
                         for z in sorted(p, key=lambda z: z.real)) or "-"

    rows = [[k, f"{v['nk']}", f"{v['max_abs_pole']:.4f}", left_poles(k), f"{v['estimation_fitness']:.2f}",
             f"{v['seconds']:.1f}"] for k, v in info.items()]
    parts += ["## Identified models", "", md_table(["model", "nk", "max abs pole", "poles with Re z < 0",
                                                   "estimation fit (%)", "time (s)"], rows), ""]
    rows = []
    for r in paper_model_table():
        p = ", ".join(f"{z.real:.3f}" + (f"{z.imag:+.3f}j" if abs(z.imag) > 5e-4 else "") for z in r["poles"])
        force = "-" if not r["usable"] else f"{r['steady_force_N'][0]:.2f} to {r['steady_force_N'][1]:.2f}"
        rows.append([KIND_TITLE[r["kind"]], r["order"], p, f"{r['max_abs_pole']:.3f}", "yes" if r["stable"] else "no",
                     r["unit_roots_cancelled"], "yes" if r["usable"] else "no", force, r["reason"]])
    parts += ["## Paper's appendix models", "",
              md_table(["kind", "order", "poles (after cancellation)", "max abs pole", "stable", "z=1 factors cancelled",
                        "usable", "steady force 0-1.19 V (N)", "note"], rows), ""]
    parts += ["## Recovery of a known fifth-order Wiener system", "",
              f"validation fitness {rec['validation_fitness']:.2f} %, largest pole distance {rec['pole_distance']:.4f}, "
              f"nk found {rec['nk']}", ""]
    parts += ["## Closed loop, steady_60wpm, 10 s", "",
              md_table(["estimator", "estimate RMSE (N)", "force RMSE (N)", "in band"],
                       [[k, f"{v['estimate_rmse_n']:.4f}", f"{v['force_rmse_n']:.4f}", f"{v['in_band_fraction']:.3f}"]
                        for k, v in loop.items()]), ""]
    text = "\n".join(parts)
    (OUT / "results.md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
