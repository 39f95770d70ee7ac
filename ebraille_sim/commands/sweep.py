"""``ebraille-sim sweep``: scenarios x rates x readers x controllers, in parallel, with risk figures."""
from __future__ import annotations

NAME = "sweep"
HELP = "run scenarios over reading rates, drawn readers and controllers (local cores or a Dask cluster)"


def add_arguments(p):
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help="scenario files or shipped scenario names")
    p.add_argument("--rates", nargs="+", type=float, default=[], metavar="WPM",
                   help="reading rates (default: each scenario's own)")
    p.add_argument("--readers", type=int, default=10, metavar="N",
                   help="readers/FSR units drawn from the population per scenario (0: the scenario's device; default 10)")
    p.add_argument("--controllers", nargs="+", default=["pid"], metavar="CTRL",
                   help="controller names or gains files (default: pid)")
    p.add_argument("--replicates", type=int, default=1, metavar="R", help="seeds per combination (default 1)")
    p.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="episode length, s (default: each scenario's)")
    p.add_argument("-j", "--jobs", type=int, default=None, metavar="N", help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler address (e.g. tcp://host:8786): run on that cluster")
    p.add_argument("--out", default="runs/sweep", metavar="DIR", help="output folder (default runs/sweep)")
    p.add_argument("--loss", default="force_rmse_n", metavar="METRIC",
                   help="metric for the worst cases and CVaR (fractions are taken as 1 - value; default force_rmse_n)")
    p.add_argument("--alpha", type=float, default=0.1, help="CVaR tail fraction (default 0.1)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")


def main(args) -> int:
    from ebraille_sim.commands import check_out_dir, console
    from ebraille_sim.tools.sweep import format_summary, plan_sweep, run_sweep, summarise, write_results

    con = console(args)
    if args.jobs is not None and args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    if not 0 < args.alpha <= 1:
        raise ValueError(f"--alpha must lie in (0, 1], got {args.alpha}")
    plan = plan_sweep(args.scenarios, rates=args.rates, readers=args.readers, controllers=args.controllers,
                      seed=args.seed, replicates=args.replicates, duration_s=args.duration)
    known = set(_metric_names())
    if args.loss not in known:
        raise ValueError(f"unknown --loss metric {args.loss!r}; metrics: {', '.join(sorted(known))}")
    out = check_out_dir(args.out)
    result = run_sweep(plan, jobs=args.jobs, scheduler=args.scheduler,
                       progress=con.progress and not args.no_progress)
    paths = write_results(result, out, loss=args.loss, alpha=args.alpha, figures=not args.no_figures)
    summary = summarise(result, args.loss, args.alpha)
    failed = sum(1 for r in result.rows if r.get("error"))
    con.result({"episodes": len(result.rows), "failed": failed, "executor": result.executor,
                "wall_s": round(result.wall_s, 3), "loss": args.loss, "alpha": args.alpha, "summary": summary,
                "out": str(out), "files": [str(p) for p in paths]})
    con.say(format_summary(summary))
    con.say(f"\n{len(result.rows)} episodes ({failed} failed) on {result.executor} in {result.wall_s:.1f} s")
    con.say("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _metric_names():
    from ebraille_sim.scenarios.legibility import METRIC_NAMES as LEG
    from ebraille_sim.scenarios.metrics import METRIC_NAMES
    return list(METRIC_NAMES) + list(LEG)
