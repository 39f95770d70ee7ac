"""``ebraille-sim tune SCENARIO``: robust PID tuning over a population and several scenarios.

Writes into ``--out`` (default ``runs/tune-SCENARIO``):

* ``gains.toml``: the tuned controller, accepted by ``ebraille-sim run --controller``
  (for a scheduled family ``controller = "pid_scheduled"`` or ``"pid_feedforward"`` with
  every :class:`~controllers.schedule.ScheduleConfig` field); when the shipped controller
  of the family beats the Ms-bounded optimum on SCENARIO, the shipped controller, with the
  reason in a comment line, and the optimum in ``gains_tuned.toml``;
* ``gains_hand.toml`` (scheduled families): the family at the hand-tuned default gains,
  the reference the tuned gains are compared with;
* ``report.md`` and ``report.json``: gains, Ms at every linearisation point, median,
  CVaR25 and worst-case metrics per scenario of the tuned controller, the hand-tuned
  default PID, the SIMC rule and the family at the default gains, per device and, for an
  estimator that is a paper model at its own rate, under both readings of the paper's input
  delay (nk = 0 and 1); the phase and gain margins and Ms of the tuned loop on the nominal
  reader at each setpoint, and those of gains.toml and of the default PID under both readings;
* ``bode.png``, ``nyquist.png`` (tuned loop on the nominal reader at each setpoint) and
  ``population.png`` (worst-case in-band fraction per scenario for each controller).

``ebraille-sim tune --search [SPACE]``: the design search of
:mod:`ebraille_sim.tools.design_search` (controller family, gains and firmware preset scored
by the benchmark on training readers, then benchmarked on the held-out readers).  Writes into
``--out`` (default ``runs/tune-search``): ``design.toml`` (a design file that ``run
--controller`` and ``benchmark`` take, with the held-out score and the command that
reproduces it), ``report.md``, ``report.json`` and ``journal.jsonl`` (every evaluation: a
rerun into the same folder continues the search).
"""
from __future__ import annotations

import math

NAME = "tune"
HELP = ("tune PID gains over a population of readers and several scenarios (Ms <= 1.6 by default), or "
        "with --search find a design (family, gains, firmware) on the benchmark's score; write gains or a design")


MAX_POPULATION = 1000
"""Most random devices of ``--population``."""

MAX_EVALUATIONS = 10_000
"""Most cost evaluations of ``--evaluations``."""

ROBUST_DEFAULTS = {"population": 8, "family": "pid_scheduled", "scenarios": "standard", "ms_max": 1.6, "ms_gain": 1.0}
SEARCH_DEFAULTS = {"suite": "standard", "statistic": "score", "readers": 4, "jobs": 1, "optimiser": "de", "validate": 0}

TUNE_OWNED = ("gains.toml", "gains_tuned.toml", "gains_hand.toml", "report.md", "report.json", "bode.png",
              "nyquist.png", "population.png")
"""What ``tune`` writes into its folder."""


def add_arguments(p):
    from ebraille_sim.commands import MAX_JOBS, number, seed, whole
    p.add_argument("scenario", nargs="?", default=None,
                   help="scenario file or the name of a shipped scenario (see 'list'); not with --search")
    p.add_argument("--population", type=whole(0, MAX_POPULATION), default=None, metavar="N",
                   help=f"random devices drawn besides the 5 presets (default 8, at most {MAX_POPULATION})")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder (default runs/tune-SCENARIO, with --search runs/tune-search)")
    p.add_argument("--seed", type=seed, default=0,
                   help="population seed, in [0, 2**63) (default 0); with --search also the optimiser's and the "
                        "training readers' seed (not the benchmark's 2026)")
    p.add_argument("--family", default=None, choices=["pid", "pid_scheduled", "pid_feedforward"],
                   help="fixed PID gains, gains scheduled on force with the reference map (default), "
                        "or that plus the friction-band feedforward")
    p.add_argument("--scenarios", default=None, metavar="LIST",
                   help="'standard' (default: SCENARIO plus steady_90wpm shortened, contact_onset, "
                        "setpoint_steps, setpoint_steps without its ramp and strap_slip shortened), "
                        "'single' (SCENARIO alone), "
                        "or a comma-separated list of scenarios added to SCENARIO "
                        "(NAME_unramped takes NAME's steps at once); every scenario runs with "
                        "SCENARIO's [estimator] settings")
    p.add_argument("--evaluations", type=whole(1, MAX_EVALUATIONS), default=None, metavar="N",
                   help=f"cost evaluations, in [4, {MAX_EVALUATIONS}] (default 30); with --search candidates "
                        f"evaluated, start points included, in [1, {MAX_EVALUATIONS}] (default 60)")
    p.add_argument("--duration", type=number(0, None, lo_open=True), default=None, metavar="S",
                   help="override the duration of SCENARIO, s (steady scenarios default to 12 s in 'standard')")
    p.add_argument("--ms-max", type=number(1, None, lo_open=True, allow_inf=True), default=None,
                   help="bound on the sensitivity peak at every device and setpoint (default 1.6; 'inf' for none)")
    p.add_argument("--ms-gain", type=number(0, 100, lo_open=True), default=None,
                   help="describing-function factor in (0, 100] applied to the loop in the Ms check (default 1: the "
                        "sliding linearisation; e.g. 0.5 for the friction-band relaxation of docs/tuning.md)")
    g = p.add_argument_group("design search (--search)")
    g.add_argument("--search", nargs="?", const="default", default=None, metavar="SPACE",
                   help="search designs instead: over the default space (every firmware preset, pid_dob from the "
                        "shipped designs and pid_scheduled) or the arms of the search-space file SPACE")
    g.add_argument("--suite", default=None, metavar="NAME",
                   help="benchmark suite of the objective and of the held-out check: quick, standard (default)")
    g.add_argument("--statistic", default=None, metavar="NAME",
                   help="objective over the training readers: score (default, the benchmark's), cvar10_in_band, "
                        "cvar10_char_in_band, median_in_band, median_char_in_band")
    g.add_argument("--readers", type=whole(1, MAX_POPULATION), default=None, metavar="N",
                   help=f"training readers per scenario, drawn from --seed (default 4, at most {MAX_POPULATION})")
    g.add_argument("--validate", type=whole(0, MAX_EVALUATIONS), default=None, metavar="K",
                   help="run the K best candidates on the training readers again on validation readers (drawn from "
                        "--seed + 1000003) and keep the best there (default 0: the best on the training readers)")
    g.add_argument("--validation-readers", type=whole(1, MAX_POPULATION), default=None, metavar="N",
                   help=f"validation readers per scenario (default: twice --readers, at most {MAX_POPULATION})")
    g.add_argument("--optimiser", default=None, metavar="NAME",
                   help="de (default: SciPy's differential evolution) or optuna (Optuna's TPE sampler, the optional "
                        "extra 'search')")
    g.add_argument("--firmware", action="append", default=None, metavar="PRESET",
                   help="search the default space on this firmware preset only (repeatable)")
    g.add_argument("--no-starts", action="store_true",
                   help="start from a Latin hypercube alone, not from the shipped designs")
    g.add_argument("--name", default=None, metavar="NAME", help="the design's name (default search_FIRMWARE)")
    g.add_argument("-j", "--jobs", type=whole(1, MAX_JOBS), default=None, metavar="N",
                   help=f"local worker processes, at most {MAX_JOBS} (default 1); the design does not depend on it")


def _fmt_ms(x: float) -> str:
    return "unstable" if (x is None or x < 0 or not math.isfinite(x)) else f"{x:.2f}"


def _loop_cells(a: dict) -> list[str]:
    """Closed-loop state, phase margin, gain margin and Ms of one ``LoopAnalysis.summary()``."""
    if not a["stable"]:
        return ["unstable", "-", "-", "unstable"]
    pm = "none" if math.isinf(a["phase_margin_deg"]) else \
        f"{a['phase_margin_deg']:.1f} deg at {a['gain_crossover_hz']:.2f} Hz"
    gm = "inf" if math.isinf(a["gain_margin"]) else f"{a['gain_margin']:.2f} at {a['phase_crossover_hz']:.2f} Hz"
    return ["stable", pm, gm, _fmt_ms(a["ms"])]


_NAMES = {"tuned": "tuned", "shipped": "shipped", "hand": "family at default gains", "default": "default PID",
          "simc": "SIMC"}
_KEYS = ("tuned", "shipped", "hand", "default", "simc")


def _markdown(spec, rep: dict, n_dev: int) -> str:
    keys = [k for k in _KEYS if k in rep]
    bound = rep["ms_bound"]
    rule = (f"Ms <= {bound:g}" if math.isfinite(bound) else "no Ms bound") + \
        (" on the sliding linearisation" if rep["ms_gain"] == 1.0 else
         f" on the loop scaled by the describing-function factor {rep['ms_gain']:g}") + \
        (" under both readings of the paper's input delay (nk = " + " and ".join(map(str, rep["delays"])) + ")"
         if len(rep.get("delays", ())) > 1 else "")
    out = [f"# Robust tuning: {spec.name}", "",
           f"Population: {n_dev} devices (reader presets, FSR presets, random draws), controller family "
           f"`{rep['family']}`, {rep['evaluations']} cost evaluations, constraint: {rule}.", "",
           "Scenarios of the cost: " + ", ".join(
               f"{n}" + (f" ({d:g} s)" if d else "") for n, d in zip(rep["scenarios"], rep["scenario_durations_s"])),
           "", "| controller | kp (V/N) | ki (V/Ns) | kd (Vs/N) | max Ms | cost |", "|---|---|---|---|---|---|"]
    for key in keys:
        b = rep[key]
        g = b["gains"]
        out.append(f"| {_NAMES[key]} | {g['kp_v_per_n']:.3g} | {g['ki_v_per_ns']:.3g} | {g['kd_vs_per_n']:.3g} | "
                   f"{_fmt_ms(b['ms_max'])} | {b['cost']:.3f} |")
    out += ["", "## In-band fraction per scenario: worst / CVaR25 / median (peak force worst, N)", "",
            "| scenario | " + " | ".join(_NAMES[k] for k in keys) + " |", "|---|" + "---|" * len(keys)]
    for s in rep["scenarios"]:
        cells = []
        for k in keys:
            m = rep[k]["scenarios"][s]["metrics"]
            ib = m["in_band_fraction"]
            cells.append(f"{ib['worst']:.3f} / {ib['cvar25']:.3f} / {ib['median']:.3f} ({m['peak_force_n']['worst']:.2f})")
        out.append(f"| {s} | " + " | ".join(cells) + " |")
    out += ["", "The gains of a scheduled family are its gains at 1 N; they scale with the pulp stiffness "
            "ratio K(1 N)/K(F) at other setpoints.", "",
            "## Ms at every linearisation point (sliding model" +
            ("" if rep["ms_gain"] == 1.0 else f", loop scaled by {rep['ms_gain']:g}") + ")", ""]
    forces = rep["forces_n"]
    for key in keys:
        out += [f"**{_NAMES[key]}**", "", "| device | " + " | ".join(f"{f:g} N" for f in forces) + " |",
                "|---|" + "---|" * len(forces)]
        for lab, row in zip(rep.get("ms_labels") or rep["labels"], rep[key]["ms_table"]):
            out.append(f"| {lab} | " + " | ".join(_fmt_ms(x) for x in row) + " |")
        out.append("")
    if "hand" in rep and rep["hand"]["cost"] < rep["tuned"]["cost"]:
        out += ["**Note.** The family at the hand-tuned default gains has a lower cost than the tuned gains "
                f"({rep['hand']['cost']:.3f} against {rep['tuned']['cost']:.3f}) but does not meet the Ms bound "
                f"(max Ms {_fmt_ms(rep['hand']['ms_max'])}); it is written as gains_hand.toml.  docs/tuning.md "
                "discusses which one to ship.", ""]
    sel = rep.get("selected", "tuned")
    out += ["## Selection", "",
            (f"gains.toml holds the shipped controller `{rep[sel]['controller']}`, better than the optimum: "
             f"{rep['selection_reason']}.  The optimum under the bound is in gains_tuned.toml." if sel != "tuned" else
             "gains.toml holds the tuned optimum (cost on the named scenario "
             f"{rep['named_costs']['tuned']:.3f}; " + ", ".join(
                 f"{_NAMES[k]} {rep['named_costs'][k]:.3f}" for k in keys if k != "tuned") + ")."), ""]
    if rep.get("nominal_loop"):
        out += ["## Loop of gains.toml on the nominal reader (sliding model)", "",
                "Margins from the loop's frequency response (`ebraille_sim.analysis.margins.loop_margins`); "
                "none are given for an unstable closed loop.", "",
                "| setpoint | closed loop | phase margin | gain margin | Ms |", "|---|---|---|---|---|"]
        for a in rep["nominal_loop"]:
            out.append(f"| {a['force_n']:g} N | " + " | ".join(_loop_cells(a)) + " |")
        out.append("")
    if rep.get("delay_margins"):
        out += ["## The paper's input delay: margins on the nominal reader under both readings", "",
                "The paper prints no input delay; nk = 0 reads its notation literally, nk = 1 is MATLAB's "
                "convention (docs/identification.md).  Sliding model, margins from `loop_margins`.", "",
                "| controller | setpoint | nk | closed loop | phase margin | gain margin | Ms |",
                "|---|---|---|---|---|---|---|"]
        for a in rep["delay_margins"]:
            out.append(f"| {a['controller']} | {a['force_n']:g} N | {a['nk']} | " + " | ".join(_loop_cells(a)) + " |")
        out.append("")
    out += ["## Per device (in-band fraction)", ""]
    for s in rep["scenarios"]:
        out += [f"**{s}**", "", "| device | " + " | ".join(_NAMES[k] for k in keys) + " |",
                "|---|" + "---|" * len(keys)]
        for j, lab in enumerate(rep["labels"]):
            out.append(f"| {lab} | " + " | ".join(
                f"{rep[k]['scenarios'][s]['per_device'][j]['in_band_fraction']:.3f}" for k in keys) + " |")
        out.append("")
    out += ["Figures: bode.png, nyquist.png (loop of gains.toml, nominal reader), population.png."]
    return "\n".join(out) + "\n"


def _delay_margins(controllers: dict, device, forces_n) -> list[dict]:
    """Margins of each ``name -> (force -> controller)`` on ``device`` at each force under both
    readings of the paper's input delay (none where the estimator has no delay to choose)."""
    from ebraille_sim.analysis.margins import delay_analyses
    rows = []
    for name, at in controllers.items():
        for f in forces_n:
            for nk, a in delay_analyses(at(f), device, f).items():
                if nk is not None:
                    rows.append({"controller": name, "nk": nk, **a.summary()})
    return rows


def _plot_population(rep: dict, path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    keys = [k for k in _KEYS if k in rep]
    scen = rep["scenarios"]
    x = np.arange(len(scen))
    wdt = 0.8 / len(keys)
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(scen) + 2), 4))
    for j, key in enumerate(keys):
        vals = [rep[key]["scenarios"][s]["metrics"]["in_band_fraction"]["worst"] for s in scen]
        ax.bar(x + (j - (len(keys) - 1) / 2) * wdt, vals, width=wdt, label=_NAMES[key])
    ax.set_xticks(x)
    ax.set_xticklabels(scen, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("worst-case in-band fraction")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _scenarios(arg: str, spec, duration):
    """The scenarios of the cost named by ``--scenarios``; a bad name is one line naming the option."""
    from ebraille_sim.commands import UserError
    if not any(n.strip() for n in arg.split(",")):
        raise UserError(f"--scenarios {arg!r} names no scenario; give 'standard', 'single' or a list of names")
    try:
        return _scenario_list(arg, spec, duration)
    except (ValueError, FileNotFoundError) as exc:
        raise UserError(f"--scenarios {arg!r}: {exc}") from None


def _scenario_list(arg: str, spec, duration):
    from ebraille_sim.analysis.robust import TuneScenario, standard_scenarios, unramped, with_estimator

    from ebraille_sim.scenarios.spec import load_scenario
    if arg == "single":
        return [TuneScenario(spec.name, spec, duration)]
    if arg == "standard":
        out = standard_scenarios(spec)
        if duration is not None:
            out[0] = TuneScenario(out[0].name, out[0].spec, duration)
        return out
    out = [TuneScenario(spec.name, spec, duration)]
    est = spec.device.estimator
    for name in (n.strip() for n in arg.split(",")):
        if not name or name in {s.name for s in out}:
            continue
        if name.endswith("_unramped"):
            out.append(TuneScenario(name, with_estimator(unramped(load_scenario(name[: -len("_unramped")])), est),
                                    None))
        else:
            sp = with_estimator(load_scenario(name), est)
            out.append(TuneScenario(sp.name, sp, 12.0 if sp.name.startswith("steady_") else None))
    return out


def main(args) -> int:
    from ebraille_sim.commands import UserError
    search = args.search is not None
    other, own = (ROBUST_DEFAULTS, SEARCH_DEFAULTS) if search else (SEARCH_DEFAULTS, ROBUST_DEFAULTS)
    given = [k for k in other if getattr(args, k) is not None] + \
        [k for k in ("firmware", "name", "validation_readers") if not search and getattr(args, k) is not None] + \
        (["no_starts"] if not search and args.no_starts else []) + \
        (["duration"] if search and args.duration is not None else [])
    if given:
        opt = "-j" if given[0] == "jobs" else "--" + given[0].replace("_", "-")
        mode = "robust tuning (give a SCENARIO)" if search else "design search (--search)"
        this = "design search" if search else "robust tuning"
        raise UserError(f"{opt} is an option of the {mode}, not of the {this}")
    for k, v in own.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    if search:
        if args.scenario is not None:
            raise UserError(f"--search takes no scenario (the suite's scenarios are the objective), "
                            f"got {args.scenario!r}")
        return _search_main(args)
    if args.scenario is None:
        raise UserError("give a scenario (or --search for the design search)")
    if args.evaluations is None:
        args.evaluations = 30
    return _robust_main(args)


def _robust_main(args) -> int:
    import json
    import pathlib

    from ebraille_sim.analysis.robust import (family_ms_controller, gains_document, gains_toml, robust_tune,
                                              tuning_population)
    from controllers.pid import DEFAULT_PID
    from ebraille_sim.analysis.margins import analyse_loop
    from ebraille_sim.analysis.plots import plot_bode, plot_nyquist

    from ebraille_sim.commands import FrameProgress, check_duration, check_out_dir, claim_out_dir, console
    from ebraille_sim.scenarios.spec import load_scenario

    con = console(args)
    if args.population < 0:
        raise ValueError(f"--population must be >= 0, got {args.population}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.evaluations < 4:
        raise ValueError(f"--evaluations must be >= 4, got {args.evaluations}")
    if args.duration is not None and not args.duration > 0:
        raise ValueError(f"--duration must be > 0, got {args.duration}")
    if not args.ms_max > 1.0:
        raise ValueError(f"--ms-max must be > 1 (or inf), got {args.ms_max}")
    if not (math.isfinite(args.ms_gain) and args.ms_gain > 0):
        raise ValueError(f"--ms-gain must be finite and > 0, got {args.ms_gain}")
    spec = load_scenario(args.scenario)
    check_duration(spec, args.duration)
    scenarios = _scenarios(args.scenarios, spec, args.duration)
    for sc in scenarios:
        end = sc.duration_s if sc.duration_s is not None else sc.spec.duration_s
        if end is not None and end <= sc.spec.reading.start_s:
            raise ValueError(f"scenario {sc.name!r} ends at {end:g} s, before its reading starts at "
                             f"{sc.spec.reading.start_s:g} s; the tuning cost is measured while reading "
                             f"(give a longer --duration)")
    out = check_out_dir(args.out if args.out is not None else pathlib.Path("runs") / f"tune-{spec.name}",
                        owned=TUNE_OWNED)
    with claim_out_dir(out, TUNE_OWNED) as target:
        pop = tuning_population(args.population, seed=args.seed, base=spec.device)
        bar = FrameProgress(f"tune {spec.name}: runs", enabled=con.progress)
        try:
            res = robust_tune(spec, pop, family=args.family, ms_max=args.ms_max, ms_gain=args.ms_gain,
                              max_evaluations=args.evaluations, progress=bar, scenarios=scenarios)
        finally:
            bar.close()
        rep = res.report()
        rep["scenario"] = spec.name
        rep["population"] = [label for label, _ in pop]
        rep["population_seed"] = args.seed
        nominal = dict(pop).get("nominal", pop[0][1])
        cfg_at = family_ms_controller(res.config)
        if not callable(cfg_at):
            cfg_at = (lambda c: (lambda f: c))(cfg_at)
        analyses = [analyse_loop(cfg_at(f), nominal, f) for f in res.forces_n]
        rep["nominal_loop"] = [a.summary() for a in analyses]
        rep["delay_margins"] = _delay_margins({"gains.toml": cfg_at, "default PID": lambda f: DEFAULT_PID},
                                              nominal, res.forces_n)
        with target.staged() as tmp:
            reason = (f"kept the shipped {res.chosen.family}: {res.selection_reason}\n"
                      "the optimum under the bound is in gains_tuned.toml") if res.selected != "tuned" else ""
            (tmp / "gains.toml").write_text(gains_toml(res.gains_file(), reason))
            if res.selected != "tuned":
                (tmp / "gains_tuned.toml").write_text(gains_toml(gains_document(res.tuned.config, args.family)))
            if "hand" in res.references:
                (tmp / "gains_hand.toml").write_text(gains_toml(gains_document(res.references["hand"].config, args.family)))
            (tmp / "report.json").write_text(json.dumps(rep, indent=2, default=float) + "\n")
            (tmp / "report.md").write_text(_markdown(spec, rep, len(pop)))
            plot_bode(analyses, tmp / "bode.png", title=f"gains.toml loop, nominal reader ({spec.name})")
            plot_nyquist(analyses, tmp / "nyquist.png", title=f"gains.toml loop, nominal reader ({spec.name})",
                         ms_limit=args.ms_max if math.isfinite(args.ms_max) else 2.0)
            _plot_population(rep, tmp / "population.png")
        g = res.gains_file()["gains"]
        ship_key = "shipped" if "shipped" in rep else "default"
        files = ["gains.toml"] + (["gains_tuned.toml"] if res.selected != "tuned" else []) + \
            (["gains_hand.toml"] if "hand" in res.references else []) + \
            ["report.md", "report.json", "bode.png", "nyquist.png", "population.png"]
        con.result({
            "scenario": spec.name, "family": args.family, "gains": g, "ms_max": res.ms_max, "ms_bound": args.ms_max,
            "ms_gain": args.ms_gain, "ms_max_tuned": res.tuned.ms_max, "cost": res.cost,
            "selected": res.selected, "selection_reason": res.selection_reason,
            "named_costs": rep["named_costs"],
            "shipped": {"key": ship_key, "controller": rep[ship_key]["controller"], "gains": rep[ship_key]["gains"],
                        "ms_max": rep[ship_key]["ms_max"]},
            "population": len(pop), "population_seed": args.seed,
            "scenarios": {s: {k: {q: rep[k]["scenarios"][s]["metrics"]["in_band_fraction"][q] for q in ("worst", "median")}
                              for k in _KEYS if k in rep}
                          for s in rep["scenarios"]},
            "costs": {k: rep[k]["cost"] for k in ("tuned", "hand", "default", "simc") if k in rep},
            "out": str(out), "files": [str(out / f) for f in files]})
        bound = f"Ms <= {args.ms_max:g}" if math.isfinite(args.ms_max) else "no Ms bound"
        ms_rule = bound + (" (default; --ms-max changes it)" if args.ms_max == 1.6 else "") + \
            (f", loop factor {args.ms_gain:g}" if args.ms_gain != 1.0 else "")
        t = rep["tuned"]["gains"]
        con.say(f"tuned {args.family} under {ms_rule}: kp {t['kp_v_per_n']:.4g}, ki {t['ki_v_per_ns']:.4g}, "
                f"kd {t['kd_vs_per_n']:.4g}; achieved max Ms {_fmt_ms(res.tuned.ms_max)}; cost {res.tuned.cost:.3f}")
        if res.selected != "tuned":
            con.say(f"kept the shipped {res.chosen.family} in gains.toml, better than the optimum: "
                    f"{res.selection_reason}; the optimum is in gains_tuned.toml")
        for s in rep["scenarios"]:
            t = rep["tuned"]["scenarios"][s]["metrics"]["in_band_fraction"]
            d = rep[ship_key]["scenarios"][s]["metrics"]["in_band_fraction"]
            con.say(f"  {s}: in-band worst {t['worst']:.3f} (shipped {rep[ship_key]['controller']} {d['worst']:.3f}), "
                    f"median {t['median']:.3f} (shipped {d['median']:.3f})")
        if "hand" in rep and rep["hand"]["cost"] < rep["tuned"]["cost"]:
            con.say(f"note: the family at the default gains has a lower cost ({rep['hand']['cost']:.3f}) but max Ms "
                  f"{_fmt_ms(rep['hand']['ms_max'])}: written as gains_hand.toml (see report.md)")
        con.say(f"wrote {out / 'gains.toml'}, " + ", ".join(files[1:]))
        return 0


def _search_main(args) -> int:
    import dataclasses
    import json
    import pathlib
    import time

    from controllers.designs import get_design
    from ebraille_sim.commands import FrameProgress, UserError, check_out_dir, claim_out_dir, console
    from ebraille_sim.estimation.presets import check_name, get_firmware
    from ebraille_sim.tools import benchmark as bm
    from ebraille_sim.tools import design_search as ds

    con = console(args)
    evaluations = 60 if args.evaluations is None else args.evaluations
    for opt, check in (("--suite", bm.get_suite), ("--statistic", ds.check_statistic),
                       ("--optimiser", ds.check_optimiser)):
        try:
            check(getattr(args, opt[2:]))
        except ValueError as exc:
            raise UserError(f"{opt}: {exc}") from None
    suite = bm.get_suite(args.suite)
    if args.seed == bm.POPULATION_SEED:
        raise UserError(f"--seed {args.seed} is the benchmark's reader seed: the held-out readers would be "
                        "trained on; give another seed")
    try:
        if args.search == "default":
            space = ds.default_space(args.firmware)
        else:
            if args.firmware is not None:
                raise UserError("--firmware chooses among the default space's presets; a SPACE file names its own")
            space = ds.load_space(args.search)
    except (ValueError, FileNotFoundError) as exc:
        raise UserError(f"--search: {exc}" if args.firmware is None else f"--firmware: {exc}") from None
    if args.no_starts:
        space = dataclasses.replace(space, arms=tuple(dataclasses.replace(a, starts=()) for a in space.arms))
    firmwares = sorted({a.firmware or "" for a in space.arms})
    name = args.name if args.name is not None else "search_" + "_".join(f or "scenario" for f in firmwares)
    try:
        check_name("--name", name)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    from controllers.designs import designs
    if name in designs():
        raise UserError(f"--name {name!r} is a shipped design's name; give another")
    out = check_out_dir(args.out if args.out is not None else pathlib.Path("runs") / "tune-search",
                        owned=ds.SEARCH_FILES)
    journal = out / ds.JOURNAL
    search = ds.DesignSearch(space, suite=suite.name, statistic=args.statistic, readers=args.readers,
                             seed=args.seed, evaluations=evaluations, jobs=args.jobs, journal=journal,
                             optimiser=args.optimiser, validate=args.validate,
                             validation_readers=args.validation_readers)
    if journal.exists():
        try:
            search.check_journal()
        except ValueError as exc:
            raise UserError(str(exc)) from None
    out.mkdir(parents=True, exist_ok=True)          # the journal outlives an interrupted run
    with claim_out_dir(out, ds.SEARCH_FILES) as target:
        bar = FrameProgress("tune --search: evaluations", enabled=con.progress and not con.json)
        search.progress = bar
        t0 = time.perf_counter()
        try:
            res = search.run()
        finally:
            bar.close()
        t_search = time.perf_counter() - t0
        best = res.best
        fw = get_firmware(best.firmware) if best.firmware is not None else None
        ref = fw.benchmark.get("design") if fw is not None else None
        recorded = (fw is not None and fw.benchmark.get("suite") == suite.name
                    and fw.benchmark.get("readers") == suite.readers and fw.score is not None)
        with target.staged() as tmp:
            draft = tmp / "design.toml"
            draft.write_text(ds.design_text(name, "", best, {}))
            bar = FrameProgress("tune --search: held-out episodes", enabled=con.progress and not con.json)
            t1 = time.perf_counter()
            try:
                names = [str(draft)] + ([ref] if ref is not None and not recorded else [])
                val = bm.run_benchmark(names, suite, jobs=args.jobs, bounds=False, progress=bar)
            finally:
                bar.close()
            t_val = time.perf_counter() - t1
            shown = {str(draft): name}                  # the leaderboard names the design, not the staged file
            val = dataclasses.replace(val, controllers=[shown.get(c, c) for c in val.controllers],
                                      rows=[dict(r, controller=shown.get(r["controller"], r["controller"]))
                                            for r in val.rows])
            summary = bm.summarise(val)
            held = summary[name]["score"]
            ref_score = (fw.score if recorded else summary[ref]["score"]) if ref is not None else None
            rel = f"ebraille-sim benchmark {out / 'design.toml'}" + ("" if suite.name == "standard" else
                                                                     f" --suite {suite.name}")
            desc = (f"{best.controller} on {best.firmware or 'the scenario firmware'} found by tune --search "
                    f"(seed {args.seed}, {res.evaluations} evaluations, {args.readers} training readers per "
                    f"scenario, statistic {args.statistic}" +
                    (f", the best of {len(res.validated)} on {search.validation_readers} validation readers"
                     if res.validated else "") + f"): training score {res.train_score:.2f}, held-out "
                    f"score {held:.2f}" + (f" ({100 * held / ref_score:.1f} % of {ref}, {ref_score:.2f})"
                                           if ref_score else "") + ".")
            draft.write_text(ds.design_text(name, desc, best, {"score": held, "suite": suite.name,
                                                               "readers": val.readers, "command": rel}))
            rep = {"name": name, "design": {"controller": best.controller, "firmware": best.firmware,
                                            "gains": best.gains},
                   "suite": suite.name, "statistic": args.statistic, "optimiser": args.optimiser,
                   "training_readers": args.readers,
                   "seed": args.seed, "evaluations": res.evaluations, "from_journal": res.cached,
                   "training_statistic": res.train_value, "training_score": res.train_score,
                   "validate": args.validate, "validation_readers": search.validation_readers if args.validate else None,
                   "validation_statistic": res.validation_value, "validated": res.validated,
                   "held_out_score": held, "held_out_readers": val.readers,
                   "reference": {"design": ref, "score": ref_score,
                                 "source": "recorded in the firmware preset" if recorded else "run with the check"}
                   if ref is not None else None,
                   "ratio_to_reference": held / ref_score if ref_score else None,
                   "wall_s": {"search": round(t_search, 1), "held_out": round(t_val, 1)},
                   "space": space.describe(), "starts": res.starts, "history": res.history,
                   "held_out": {k: v for k, v in bm.results_document(val, summary).items() if k != "rows"}}
            (tmp / "report.json").write_text(json.dumps(rep, indent=2, default=float) + "\n")
            (tmp / "report.md").write_text(ds.report_markdown(rep, bm.format_markdown(val, summary)))
            (tmp / ds.JOURNAL).write_bytes(journal.read_bytes())
    get_design(out / "design.toml")
    con.result({k: rep[k] for k in ("name", "design", "suite", "statistic", "optimiser", "training_readers", "seed",
                                    "evaluations", "from_journal", "training_statistic", "training_score",
                                    "validation_statistic",
                                    "held_out_score", "held_out_readers", "reference", "ratio_to_reference",
                                    "wall_s")} | {"out": str(out), "files": [str(out / f) for f in ds.SEARCH_FILES]})
    con.say(f"searched {res.evaluations} designs ({res.cached} from the journal) in {t_search:.0f} s: "
            f"{best.controller} on {best.firmware}")
    con.say(f"  training {args.statistic} {res.train_value:.2f} (score {res.train_score:.2f}) on {args.readers} "
            f"readers per scenario drawn from seed {args.seed}")
    if res.validated:
        rank = res.validated[0]["training_rank"]
        con.say(f"  validation {args.statistic} {res.validation_value:.2f} on {search.validation_readers} other readers "
                f"per scenario: the best of the {len(res.validated)} best on the training readers (its rank there: "
                f"{rank})")
    con.say(f"  held-out score {held:.2f} on the benchmark's {val.readers} readers ({suite.name} suite)" +
            (f"; {ref} {ref_score:.2f}, ratio {held / ref_score:.3f}" if ref_score else ""))
    same = [h["start"] for h in res.starts if (h["controller"], h["firmware"], h["gains"]) ==
            (best.controller, best.firmware, best.gains)]
    if same:
        con.say(f"  no candidate beat the start point {same[0]} on the training readers: the design is that start")
    con.say(f"wrote {out / 'design.toml'}, report.md, report.json, {ds.JOURNAL}")
    return 0
