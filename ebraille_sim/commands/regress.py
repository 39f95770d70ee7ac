"""``ebraille-sim regress``: run every scenario and compare its metrics with the stored baselines."""
from __future__ import annotations

NAME = "regress"
HELP = "run every scenario in scenarios/ and compare the metrics with scenarios/baselines/ (exit 1 if any moved)"


def add_arguments(p):
    p.add_argument("--update", action="store_true", help="rewrite the baselines from this run")
    p.add_argument("--only", nargs="+", metavar="NAME", default=None, help="run only these scenarios")
    p.add_argument("--scenarios", default=None, metavar="DIR",
                   help="folder of scenario files (default: ./scenarios, else the project's)")
    p.add_argument("--baselines", default=None, metavar="DIR", help="folder of baselines (default: DIR/baselines)")
    p.add_argument("--controller", default=None,
                   help="check this controller (name or gains file) against the baselines instead of each scenario's")
    p.add_argument("-j", "--jobs", type=int, default=1, metavar="N", help="scenarios run in parallel (default 1)")
    p.add_argument("-v", "--verbose", action="store_true", help="list every compared metric, not only what moved")


def main(args) -> int:
    import time

    from ebraille_sim.tools.regress import format_report, regress_scenarios

    if args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    if args.update and args.controller:
        raise ValueError("--update writes baselines with each scenario's own controller; drop --controller")
    t0 = time.perf_counter()
    checks = regress_scenarios(args.scenarios, only=args.only, update=args.update, controller=args.controller,
                               baseline_dir=args.baselines, jobs=args.jobs)
    print(format_report(checks, verbose=args.verbose))
    print(f"wall time {time.perf_counter() - t0:.1f} s")
    return 1 if any(c.failed for c in checks) else 0
