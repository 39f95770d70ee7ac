"""Figures and numbers of docs/scenarios.md: python studies/scenarios/make_scenario_figures.py

Writes docs/figures/scenarios/*.png and, into studies/scenarios/, summary.json (every number
quoted on the page; the prose's own measurements under "numbers"), metrics_table.md (the library table of the page) and disturbance_parameters.md (the
disturbance parameter table, from ebraille_sim.scenarios.disturbances.parameter_table).
"""
from __future__ import annotations

import json
import pathlib
import shutil
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.signal import butter, sosfiltfilt  # noqa: E402

from ebraille_sim.scenarios import disturbances as D  # noqa: E402
from ebraille_sim.scenarios import legibility as L  # noqa: E402
from ebraille_sim.tools import sweep as S  # noqa: E402
from ebraille_sim.scenarios.reading import mean_dwell_s  # noqa: E402
from ebraille_sim.scenarios.runner import refresh_phases, run_scenario  # noqa: E402
from ebraille_sim.scenarios.spec import DEFAULT_DESIGN, list_scenarios, load_scenario, parse_scenario  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
OUT = HERE
FIG = HERE.parents[1] / "docs" / "figures" / "scenarios"
PAPER_FIRMWARE = "paper_100hz"     # the paper's 100 Hz estimator path, for the PID comparisons of the prose
TABLE_METRICS = ["force_rmse_n", "in_band_fraction", "char_in_band_fraction", "peak_force_n", "contact_loss_count",
                 "estimate_rmse_n", "legible_char_fraction", "legible_char_fraction_cv", "wpm"]


def disturbance_inputs(spec, t):
    """The disturbance profiles of a run, drawn from the runner's input stream."""
    rng = np.random.default_rng(np.random.SeedSequence(spec.seed).spawn(3)[2])
    return D.build_inputs(spec.sections["disturbances"], t, rng, spec.device)


def force_panel(ax, res, t0=None, t1=None, est=True):
    tr = res.trace
    t = tr["t_s"]
    sel = np.ones(len(t), bool) if t0 is None else (t >= t0) & (t <= t1)
    band = res.spec.setpoint.band_fraction
    sp = tr["setpoint_n"][sel]
    ax.fill_between(t[sel], sp * (1 - band), sp * (1 + band), color="0.88", lw=0, label=f"band +/-{band:.0%}")
    ax.plot(t[sel], sp, "k--", lw=0.8, label="setpoint")
    if est:
        ax.plot(t[sel], tr["force_est_n"][sel], color="tab:orange", lw=0.7, label="estimated")
    ax.plot(t[sel], tr["force_true_n"][sel], color="tab:blue", lw=0.9, label="true")
    ax.set_ylabel("force (N)")
    ax.grid(lw=0.3)


def fig_disturbances(summary):
    rows = [("tremor_90wpm", "finger_pos_m", 1e6, "pulp position (um)", (10.0, 12.0)),
            ("pressing_90wpm", "finger_pos_m", 1e3, "pulp position (mm)", None),
            ("strap_slip", "finger_pos_m", 1e3, "pulp position (mm)", None),
            ("orientation_change", "gravity_along_m_per_s2", 1.0, "g along travel (m/s^2)", None),
            ("warm_fsr", "fsr_temp_offset_k", 1.0, "FSR T - T_cal (K)", None),
            ("long_session_drift", "fsr_temp_offset_k", 1.0, "equivalent T input (K)", None),
            ("battery_sag", "driver_supply_v", 1.0, "H-bridge supply (V)", None)]
    fig, axes = plt.subplots(len(rows), 2, figsize=(13, 2.1 * len(rows)), gridspec_kw={"width_ratios": [1, 1.6]})
    for (name, inp, scale, label, win), (a1, a2) in zip(rows, axes):
        spec = load_scenario(name)
        res = run_scenario(spec)
        summary["scenarios"][name] = res.metrics
        t = res.trace["t_s"] - 1e-3
        prof = disturbance_inputs(spec, t)
        mode, arr = prof[inp]
        x = arr * scale
        sel = np.ones(len(t), bool) if win is None else (t >= win[0]) & (t <= win[1])
        a1.plot(t[sel], x[sel], color="tab:green", lw=0.8)
        a1.set_ylabel(label, fontsize=8)
        a1.set_title(f"{name}: {inp} ({mode})", fontsize=9)
        a1.grid(lw=0.3)
        force_panel(a2, res, *(win or (None, None)))
        m = res.metrics
        a2.set_title(f"in band {m['in_band_fraction']:.3f}, char in band {m['char_in_band_fraction']:.3f}, "
                     f"RMSE {m['force_rmse_n'] * 1e3:.0f} mN, legible (CV) {m['legible_char_fraction_cv']:.3f}",
                     fontsize=9)
    axes[0, 1].legend(fontsize=7, ncol=4, loc="lower right")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(FIG / "disturbances.png", dpi=100)
    plt.close(fig)


def fig_refresh(summary):
    fig, axes = plt.subplots(2, 1, figsize=(11, 6))
    for ax, name in zip(axes, ("refresh_60wpm", "refresh_120wpm")):
        res = run_scenario(name)
        summary["scenarios"][name] = res.metrics
        spec = res.spec
        t = res.trace["t_s"]
        win = (5.0, 6.2)
        force_panel(ax, res, *win)
        _, hold = refresh_phases(spec, res.schedule, t)
        sel = (t >= win[0]) & (t <= win[1])
        ax.fill_between(t[sel], 0, 1.6, where=hold[sel], color="tab:green", alpha=0.12, lw=0, label="hold (window)")
        for s in res.schedule.boundaries_s():
            if win[0] <= s <= win[1]:
                ax.axvline(s, color="0.6", lw=0.5)
        m = res.metrics
        ax.set_ylim(0, 1.6)
        ax.set_title(f"{name}: dwell {mean_dwell_s(spec.reading.wpm) * 1e3:.0f} ms, press within "
                     f"{spec.reading.refresh_press_fraction:.0%}; char_in_band_fraction = "
                     f"{m['char_in_band_fraction']:.3f} ({m['characters']} characters)", fontsize=9)
    axes[0].legend(fontsize=7, ncol=5, loc="lower right")
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(FIG / "refresh.png", dpi=100)
    plt.close(fig)

    grid = {}
    misses = {f"lift_{lift:g}N": {} for lift in (0.1, 0.4, 0.7)}
    rates = [60, 75, 90, 105, 120]
    fig, ax = plt.subplots(figsize=(7, 4))
    for lift in (0.1, 0.4, 0.7):
        vals = []
        for wpm in rates:
            spec = parse_scenario({"name": "refresh_grid", "seed": 18, "duration_s": 12.0,
                                   "reading": {"wpm": wpm, "mode": "refresh", "refresh_lift_force_n": lift},
                                   "setpoint": {"force_n": 1.0}, "finger": {"gap_m": 1e-3}})
            res = run_scenario(spec)
            vals.append(res.metrics["char_in_band_fraction"])
            misses[f"lift_{lift:g}N"][str(wpm)] = _refresh_misses(res)
        grid[f"lift_{lift:g}N"] = dict(zip(map(str, rates), vals))
        ax.plot(rates, vals, "o-", label=f"lift/release to {lift:g} N")
    ax.set_xlabel("reading rate (wpm)")
    ax.set_ylabel("char_in_band_fraction (hold windows)")
    ax.set_title(f"per-character refresh with the default design {DEFAULT_DESIGN} (press within 30 % of the dwell)",
                 fontsize=9)
    ax.set_ylim(-0.03, 1.03)
    ax.grid(lw=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIG / "refresh_grid.png", dpi=100)
    plt.close(fig)
    summary["refresh_grid"] = grid
    summary["refresh_grid_misses"] = misses


def fig_legibility(summary):
    f = np.linspace(0.05, 3.0, 400)
    cc, cv = L.DEFAULT, L.CONSTANT_VOLTAGE
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    a = L.contact_radius_m(f) * 1e3
    cov = L.coverage(f)
    axes[0].plot(f, a, "k", label="contact radius")
    axes[0].set_ylabel("contact radius (mm)")
    axes[0].set_xlabel("contact force (N)")
    axes[0].set_title("contact patch and electrode coverage", fontsize=9)
    cov_ax = axes[0].twinx()
    cov_ax.plot(f, cov[:, 1], color="tab:blue", label="dots 2, 5 (1.2 mm from centre)")
    cov_ax.plot(f, cov[:, 0], color="tab:orange", label="dots 1, 3, 4, 6 (2.7 mm)")
    cov_ax.set_ylabel("electrode area in contact (fraction)")
    cov_ax.set_ylim(0, 1.05)
    cov_ax.legend(fontsize=7, loc="lower right")
    axes[1].plot(f, L.impedance_ohm(f) / 1e3)
    axes[1].set_xlabel("contact force (N)")
    axes[1].set_ylabel("Z per electrode (kOhm)")
    axes[1].set_title("Z(F) = Z_inf + Z_sc (p_ref / p(F))^k", fontsize=9)
    lo, hi = cc.band
    for p, name in ((cc, "constant current"), (cv, "constant voltage")):
        r = L.relative_intensity(f, 1.0, p)
        axes[2].plot(f, r[:, 0], label=f"{name}, corner dot")
        axes[2].plot(f, r[:, 1], "--", label=f"{name}, centre dot")
    axes[2].axhspan(lo, hi, color="tab:green", alpha=0.12, label=f"legible band [{lo:.2f}, {hi:.2f}]")
    axes[2].set_xlabel("contact force (N), setpoint 1 N")
    axes[2].set_ylabel("current density / nominal")
    axes[2].set_ylim(0, 2.5)
    axes[2].set_title("stimulation intensity", fontsize=9)
    axes[2].legend(fontsize=7)
    for ax in axes:
        ax.grid(lw=0.3)
    fig.tight_layout()
    fig.savefig(FIG / "legibility_model.png", dpi=100)
    plt.close(fig)
    band_cv = [float(f[i]) for i in np.nonzero((L.relative_intensity(f, 1.0, cv)[:, 1] >= lo) &
                                               (L.relative_intensity(f, 1.0, cv)[:, 1] <= hi))[0][[0, -1]]]
    r_cc = L.relative_intensity(f, 1.0, cc)
    ok_cc = np.all((r_cc >= lo) & (r_cc <= hi), axis=1)
    summary["legibility"] = {"contact_radius_mm_at_1N": float(L.contact_radius_m(1.0) * 1e3),
                             "cv_legible_force_range_n": band_cv,
                             "cc_all_dots_legible_above_n": float(f[np.argmax(ok_cc)]),
                             "band": [lo, hi]}


def fig_jitter(summary):
    steady = run_scenario("steady_90wpm", duration_s=60.0)
    jit = run_scenario("jittered_reading")
    summary["scenarios"]["jittered_reading"] = jit.metrics
    fig, ax = plt.subplots(figsize=(7, 3.6))
    bins = np.linspace(0, 1.0, 60)
    ax.hist(steady.schedule.dwell_s, bins=bins, alpha=0.6, label="steady_90wpm (no jitter)")
    ax.hist(jit.schedule.dwell_s, bins=bins, alpha=0.6, label="jittered_reading (15 %, pauses)")
    ax.set_yscale("log")
    ax.set_xlabel("dwell per cell (s)")
    ax.set_ylabel("cells")
    ax.set_title(f"realised rate {jit.metrics['wpm']:.1f} wpm for 90 wpm nominal", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIG / "jittered_reading.png", dpi=100)
    plt.close(fig)


def fig_library(summary):
    names = list_scenarios()
    for n in names:
        if n not in summary["scenarios"]:
            summary["scenarios"][n] = run_scenario(n).metrics
    ms = summary["scenarios"]
    fig, ax = plt.subplots(figsize=(9, 0.32 * len(names) + 1.5))
    y = np.arange(len(names))
    for k, (m, c) in enumerate((("in_band_fraction", "tab:blue"), ("char_in_band_fraction", "tab:orange"),
                                ("legible_char_fraction_cv", "tab:green"))):
        vals = [ms[n][m] if ms[n][m] is not None else 0.0 for n in names]
        ax.barh(y + (k - 1) * 0.27, vals, height=0.27, color=c, label=m)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.grid(axis="x", lw=0.3)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("scenario library, each with its own controller and seed", fontsize=9)
    fig.tight_layout()
    fig.savefig(FIG / "library_metrics.png", dpi=100)
    plt.close(fig)
    lines = ["| scenario | " + " | ".join(TABLE_METRICS) + " |", "|---" * (len(TABLE_METRICS) + 1) + "|"]
    for n in names:
        cells = []
        for m in TABLE_METRICS:
            v = ms[n][m]
            cells.append("n/a" if v is None else (f"{v:.3f}" if isinstance(v, float) else str(v)))
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    (OUT / "metrics_table.md").write_text("\n".join(lines) + "\n")


def fig_sweep(summary):
    plan = S.plan_sweep(["steady_90wpm", "tremor_90wpm", "strap_slip"], rates=[60, 90, 120], readers=16,
                        controllers=[DEFAULT_DESIGN], seed=7, duration_s=10.0)
    res = S.run_sweep(plan, jobs=1, progress=False)
    with tempfile.TemporaryDirectory() as tmp:
        for p in S.plot_results(res, tmp, loss="char_in_band_fraction", alpha=0.1):
            shutil.copy(p, FIG / f"sweep_{pathlib.Path(p).name}")
    summary["sweep"] = {"episodes": len(res.rows), "failed": sum(1 for r in res.rows if r["error"]),
                        "summary": S.summarise(res, "char_in_band_fraction", 0.1)}


def write_parameter_table():
    lines = ["| sub-table | key | default | unit | range | source |", "|---|---|---|---|---|---|"]
    for kind, key, default, unit, rng, source in D.parameter_table():
        if isinstance(default, tuple):
            shown = "[" + ", ".join(f"{v:g}" for v in default) + "]"
        elif default is None:
            shown = "(none)"
        else:
            shown = f"{default:g}"
        lines.append(f"| {kind} | {key} | {shown} | {unit} | {rng} | {source} |")
    (OUT / "disturbance_parameters.md").write_text("\n".join(lines) + "\n")


def _dwell_extremes(res):
    """Per-character highest and lowest true force over each dwell of the reading, N."""
    tr, sch = res.trace, res.schedule
    t, f = tr["t_s"], tr["force_true_n"]
    hi, lo = [], []
    for s, d in zip(sch.start_s, sch.dwell_s):
        sel = (t >= s) & (t < s + d)
        if sel.any():
            hi.append(float(f[sel].max()))
            lo.append(float(f[sel].min()))
    return np.array(hi), np.array(lo)


def _refresh_climbs(res):
    """Per press, the time from the start of the press phase until the true force first reaches
    the band's lower edge within the dwell, s (presses that never reach it are left out)."""
    spec, tr, sch = res.spec, res.trace, res.schedule
    edge = spec.setpoint.force_n * (1.0 - spec.setpoint.band_fraction)
    t, f = tr["t_s"], tr["force_true_n"]
    climb = []
    for s, d in zip(sch.start_s, sch.dwell_s):
        tp = s + spec.reading.refresh_lift_fraction * d
        sel = (t >= tp) & (t < s + d) & (f >= edge)
        if sel.any():
            climb.append(float(t[sel][0] - tp))
    return climb


def _refresh_misses(res):
    """Characters out of band for more than a tenth of their hold, split by where the force was
    outside the band longer: above its upper edge or below its lower edge."""
    spec, tr, sch = res.spec, res.trace, res.schedule
    t, f = tr["t_s"], tr["force_true_n"]
    _, hold = refresh_phases(spec, sch, t)
    sp, band = tr["setpoint_n"], spec.setpoint.band_fraction
    above_n = below_n = 0
    for s, d in zip(sch.start_s, sch.dwell_s):
        sel = hold & (t >= s) & (t < s + d)
        if not sel.any():
            continue
        above = float(np.mean(f[sel] > sp[sel] * (1 + band)))
        below = float(np.mean(f[sel] < sp[sel] * (1 - band)))
        if above + below > 0.1:
            above_n += above >= below
            below_n += above < below
    return {"missed_above_band": int(above_n), "missed_below_band": int(below_n)}


def page_numbers(summary):
    """The numbers the prose of docs/scenarios.md quotes beyond the metrics (summary["numbers"])."""
    import controllers
    out = {}
    refresh = {}
    for name in ("refresh_60wpm", "refresh_120wpm", "refresh_160wpm", "refresh_200wpm"):
        res = run_scenario(name)
        hi, lo = _dwell_extremes(res)
        climb = _refresh_climbs(res)
        refresh[name] = {"median_dwell_max_n": float(np.median(hi)), "median_dwell_min_n": float(np.median(lo)),
                         "fraction_reaching_0.9N": float(np.mean(hi >= 0.9)),
                         "median_climb_to_band_s": float(np.median(climb)) if climb else None,
                         "climbs_reached": len(climb), "dwells": len(hi), **_refresh_misses(res)}
    out["refresh"] = refresh
    # The PID (its default gains, then kp raised) on the paper's 100 Hz path, the configuration
    # the refresh prose compares the default design with.
    paper = {}
    for name in ("refresh_60wpm", "refresh_120wpm"):
        res = run_scenario(name, controller="pid", firmware=PAPER_FIRMWARE)
        climb = _refresh_climbs(res)
        paper[name] = {"char_in_band_fraction": res.metrics["char_in_band_fraction"],
                       "median_climb_to_band_s": float(np.median(climb)) if climb else None,
                       "climbs_reached": len(climb), **_refresh_misses(res)}
    out["refresh_pid_paper_100hz"] = paper
    high_gain = {"controller": "pid", "firmware": PAPER_FIRMWARE}
    for kp in (4.0, 6.0):
        res = run_scenario("refresh_120wpm", controller=controllers.make("pid", kp_v_per_n=kp),
                           firmware=PAPER_FIRMWARE)
        high_gain[f"kp_{kp:g}"] = {k: res.metrics[k] for k in ("peak_force_n", "contact_loss_count",
                                                               "char_in_band_fraction", "force_rmse_n")}
    out["refresh_120wpm_high_kp"] = high_gain
    # Tremor and pressing under the default design, the PID on the paper's path, the default
    # design on the paper's path, and (pressing) the default's gains without the wide-error integral.
    band = butter(4, [7.0, 13.0], btype="band", fs=1000.0, output="sos")
    configurations = {"default": {}, "pid/paper_100hz": {"controller": "pid", "firmware": PAPER_FIRMWARE},
                      f"{DEFAULT_DESIGN}/paper_100hz": {"controller": DEFAULT_DESIGN, "firmware": PAPER_FIRMWARE}}
    tremor = {}
    for label, kw in configurations.items():
        res = run_scenario("tremor_90wpm", **kw)
        tr = res.trace
        sel = tr["t_s"] >= res.spec.reading.start_s + 1.0
        tremor[label] = {"in_band_fraction": res.metrics["in_band_fraction"],
                         "char_in_band_fraction": res.metrics["char_in_band_fraction"],
                         **{f"{k}_7_13hz_rms": float(np.sqrt(np.mean(sosfiltfilt(band, tr[k][sel]) ** 2)))
                            for k in ("force_true_n", "force_est_n", "command_v")}}
    out["tremor_90wpm"] = tremor
    pressing = {}
    for label, kw in {**configurations, "dob_hold_1khz/fast_1khz_centred":
                      {"controller": "dob_hold_1khz", "firmware": "fast_1khz_centred"}}.items():
        m = run_scenario("pressing_90wpm", **kw).metrics
        pressing[label] = {k: m[k] for k in ("in_band_fraction", "char_in_band_fraction", "force_rmse_n")}
    out["pressing_90wpm"] = pressing
    # Other shipped designs on the scenarios the prose compares them on (each on its own firmware).
    out["other_designs"] = {
        "mixed_reader/dob_100hz/in_band_fraction":
            run_scenario("mixed_reader", controller="dob_100hz").metrics["in_band_fraction"],
        "refresh_120wpm/dob_100hz/char_in_band_fraction":
            run_scenario("refresh_120wpm", controller="dob_100hz").metrics["char_in_band_fraction"],
        "refresh_120wpm_1khz/dob_hold_1khz/char_in_band_fraction":
            run_scenario("refresh_120wpm_1khz", controller="dob_hold_1khz").metrics["char_in_band_fraction"]}
    res = run_scenario("strap_slip")
    tr, t = res.trace, res.trace["t_s"]
    f = tr["force_true_n"]
    slips = res.spec.sections["disturbances"]["strap_slip"].at_s
    t0 = float(slips[0])
    before = float(np.mean(f[(t >= t0 - 0.2) & (t < t0)]))
    during = float(f[(t >= t0) & (t < t0 + 0.03 + 1e-9)].min())
    win = (t >= t0) & (t < t0 + 1.5)
    tw, fw = t[win], f[win]
    k_min = int(np.argmin(fw))
    k_pk = k_min + int(np.argmax(fw[k_min:]))
    peak = float(fw[k_pk])
    later = np.nonzero(np.abs(fw[k_pk:] - 1.0) <= 0.05)[0]
    back = [float(tw[k_pk + later[0]] - t0)] if len(later) else []
    est = tr["force_est_n"]
    est_before = float(np.mean(est[(t >= t0 - 0.2) & (t < t0)]))
    est_min = float(est[win].min())
    # the supervisor's drop rule on the estimate: the fall within drop_window_s, and what it keeps
    from controllers.supervisor.config import SupervisorPolicy
    policy = SupervisorPolicy()
    lag = int(round(policy.drop_window_s / float(t[1] - t[0])))
    drop_rule = []
    for ts in slips:
        k = np.arange(int(np.searchsorted(t, float(ts))), int(np.searchsorted(t, float(ts) + 0.3)))
        fall, kept = est[k - lag] - est[k], est[k] / est[k - lag]
        drop_rule.append({"largest_fall_in_window_n": float(fall.max()),
                          "least_kept_fraction_when_fall_above_drop_n":
                              float(kept[fall > policy.drop_n].min()) if (fall > policy.drop_n).any() else None})
    unsupervised = run_scenario("strap_slip", supervised=False)
    out["strap_slip"] = {"force_before_n": before, "drop_within_slip_n": before - during,
                         "estimate_before_n": est_before, "estimate_min_after_slip_n": est_min,
                         "estimate_drop_n": est_before - est_min,
                         "drop_rule_per_slip": drop_rule, "drop_n": policy.drop_n,
                         "drop_keep_fraction": policy.drop_keep_fraction,
                         "char_in_band_fraction_supervisor_off": unsupervised.metrics["char_in_band_fraction"],
                         "contact_loss_count_supervisor_off": unsupervised.metrics["contact_loss_count"],
                         "overshoot_peak_n": peak, "overshoot_peak_after_s": float(tw[k_pk] - t0),
                         "back_within_5pct_after_s": back[0] if back else None,
                         "mean_true_between_slips_n": float(np.mean(f[(t >= float(slips[1]) - 3.0) &
                                                                      (t < float(slips[1]))]))}
    for name in ("orientation_change", "warm_fsr", "long_session_drift"):
        res = run_scenario(name)
        tr, t = res.trace, res.trace["t_s"]
        read = t >= res.spec.reading.start_s + 1.0
        ft, fe = tr["force_true_n"][read], tr["force_est_n"][read]
        tr_read = t[read]
        out[name] = {"mean_true_n": float(np.mean(ft)), "mean_estimate_n": float(np.mean(fe)),
                     "mean_true_first_10s_n": float(np.mean(ft[tr_read < tr_read[0] + 10.0])),
                     "mean_true_last_10s_n": float(np.mean(ft[tr_read > tr_read[-1] - 10.0])),
                     "estimate_over_true": float(np.mean(fe) / np.mean(ft)),
                     "min_true_n": float(ft.min()), "max_true_n": float(ft.max()),
                     "force_rmse_n": res.metrics["force_rmse_n"]}
    cmd = {}
    for name in ("tremor_90wpm", "pressing_90wpm", "strap_slip", "orientation_change", "warm_fsr",
                 "long_session_drift", "battery_sag", "steady_90wpm"):
        res = run_scenario(name)
        tr, t = res.trace, res.trace["t_s"]
        read = t >= res.spec.reading.start_s
        if "battery" in res.spec.sections.get("disturbances", {}):   # before the protection cut-off
            supplied = disturbance_inputs(res.spec, t - 1e-3)["driver_supply_v"][1] > 0.5
            out["battery_cutoff_s"] = None if supplied.all() else float(t[np.argmin(supplied)])
            read &= supplied
        cmd[name] = float(tr["command_v"][read].max())
    res = run_scenario("contact_onset")
    tr, t = res.trace, res.trace["t_s"]
    cmd["contact_onset_approach"] = float(tr["command_v"][t < res.spec.reading.start_s].max())
    out["max_command_v"] = cmd
    read = t >= res.spec.reading.start_s
    out["contact_onset"] = {"mean_true_reading_n": float(np.mean(tr["force_true_n"][read])),
                            "mean_estimate_reading_n": float(np.mean(tr["force_est_n"][read]))}
    summary["numbers"] = out


def main():
    FIG.mkdir(parents=True, exist_ok=True)
    summary = {"scenarios": {}}
    write_parameter_table()
    fig_legibility(summary)
    fig_disturbances(summary)
    fig_refresh(summary)
    fig_jitter(summary)
    fig_sweep(summary)
    fig_library(summary)
    page_numbers(summary)
    for m in summary["scenarios"].values():
        m.pop("real_time_factor", None)
    (OUT / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")


if __name__ == "__main__":
    main()
