"""``ebraille-sim sweep``: scenarios x rates x readers x controllers, in parallel, with risk figures."""
from __future__ import annotations

NAME = "sweep"
HELP = "run scenarios over reading rates, drawn readers and controllers (local cores or a Dask cluster)"
EPILOG = ("exit status: 0 when every episode ran, 1 when one failed (its row in results.csv holds the "
          "error, one line on stderr), 2 for bad input")

MAX_READERS = 10_000
"""Most readers drawn per scenario (``--readers``) and seeds per combination (``--replicates``)."""

MAX_EPISODES = 100_000
"""Most episodes of one sweep: their result rows are held in memory until the end."""

SWEEP_OWNED = {"results.csv": None, "results.parquet": None, "summary.txt": None, "figures": "*.png"}
"""What a sweep writes into its folder (of ``figures/`` only the PNG files)."""


def add_arguments(p):
    from ebraille_sim.commands import MAX_JOBS, number, seed, whole
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help="scenario files or shipped scenario names")
    p.add_argument("--rates", nargs="+", type=number(0, 1000, lo_open=True), default=[], metavar="WPM",
                   help="reading rates in (0, 1000] wpm (default: each scenario's own)")
    p.add_argument("--readers", type=whole(0, MAX_READERS), default=10, metavar="N",
                   help="readers/FSR units drawn from the population per scenario (0: the scenario's device; "
                        f"default 10, at most {MAX_READERS})")
    p.add_argument("--controllers", nargs="+", default=None, metavar="CTRL",
                   help="controller names, designs or gains files (default: the scenarios' default design)")
    p.add_argument("--replicates", type=whole(1, MAX_READERS), default=1, metavar="R",
                   help="seeds per combination (default 1)")
    p.add_argument("--seed", type=seed, default=0, help="master seed, in [0, 2**63) (default 0)")
    p.add_argument("--duration", type=number(0, None, lo_open=True), default=None, metavar="S",
                   help="episode length, s (default: each scenario's; at most what 2 GB of run arrays hold)")
    p.add_argument("-j", "--jobs", type=whole(1, MAX_JOBS), default=None, metavar="N",
                   help=f"local worker processes, at most {MAX_JOBS} (default: all cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler address (e.g. tcp://host:8786): run on that cluster")
    p.add_argument("--out", default="runs/sweep", metavar="DIR", help="output folder (default runs/sweep)")
    p.add_argument("--loss", default="force_rmse_n", metavar="METRIC",
                   help="metric for the worst cases and CVaR (fractions are taken as 1 - value; default force_rmse_n)")
    p.add_argument("--alpha", type=number(0, 1, lo_open=True), default=0.1,
                   help="CVaR tail fraction, in (0, 1] (default 0.1)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")


def main(args) -> int:
    import controllers

    from ebraille_sim.commands import UserError, check_duration, check_out_dir, claim_out_dir, console
    from ebraille_sim.scenarios.spec import DEFAULT_DESIGN
    from ebraille_sim.tools.sweep import (format_population, format_summary, plan_sweep, population, run_sweep,
                                         summarise, write_results)

    con = console(args)
    if args.controllers is None:
        args.controllers = [DEFAULT_DESIGN]
    if args.jobs is not None and args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    if not 0 < args.alpha <= 1:
        raise ValueError(f"--alpha must lie in (0, 1], got {args.alpha}")
    episodes = (len(args.scenarios) * max(1, len(args.rates)) * max(1, args.readers) * len(args.controllers)
                * args.replicates)
    if episodes > MAX_EPISODES:
        raise UserError(f"this sweep has {episodes} episodes (scenarios x rates x readers x controllers x "
                        f"replicates), more than the {MAX_EPISODES} one sweep holds; split it")
    known = set(_metric_names())
    if args.loss not in known:
        raise ValueError(f"unknown --loss metric {args.loss!r}; metrics: {', '.join(sorted(known))}")
    out = check_out_dir(args.out, owned=SWEEP_OWNED)
    for c in args.controllers:
        try:
            controllers.make(c)
        except (ValueError, FileNotFoundError, TypeError) as exc:
            raise UserError(f"--controllers {str(c)!r}: {exc}") from None
    plan = plan_sweep(args.scenarios, rates=args.rates, readers=args.readers, controllers=args.controllers,
                      seed=args.seed, replicates=args.replicates, duration_s=args.duration)
    for spec in plan.specs.values():
        check_duration(spec, args.duration)
    with claim_out_dir(out, SWEEP_OWNED) as target:
        result = run_sweep(plan, jobs=args.jobs, scheduler=args.scheduler,
                           progress=con.progress and not args.no_progress)
        with target.staged() as folder:
            names = [p.relative_to(folder) for p in write_results(result, folder, loss=args.loss, alpha=args.alpha,
                                                                  figures=not args.no_figures)]
    paths = [out / n for n in names]
    summary = summarise(result, args.loss, args.alpha)
    pop = population(result)
    failed = sum(1 for r in result.rows if r.get("error"))
    con.result({"episodes": len(result.rows), "failed": failed, "executor": result.executor,
                "wall_s": round(result.wall_s, 3), "loss": args.loss, "alpha": args.alpha, "summary": summary,
                "population": pop, "out": str(out), "files": [str(p) for p in paths]})
    con.say(format_summary(summary))
    con.say("")
    con.say(format_population(pop))
    con.say(f"\n{len(result.rows)} episodes ({failed} failed) on {result.executor} in {result.wall_s:.1f} s")
    con.say("wrote " + ", ".join(str(p) for p in paths))
    if failed:
        import sys
        first = next(r for r in result.rows if r.get("error"))
        print(f"episodes failed: {failed} of {len(result.rows)} (first: {str(first['error'])[:160]})",
              file=sys.stderr)
        return 1
    return 0


def _metric_names():
    from ebraille_sim.scenarios.legibility import METRIC_NAMES as LEG
    from ebraille_sim.scenarios.metrics import METRIC_NAMES
    return list(METRIC_NAMES) + list(LEG)
