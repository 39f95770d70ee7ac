"""``ebraille-sim benchmark``: controllers on a fixed suite x reader population, with bounds and a score."""
from __future__ import annotations

NAME = "benchmark"
HELP = ("rank controllers on a fixed scenario suite over a reader population, beside the actuator, "
        "hysteresis and sensor bounds")
EPILOG = ("score = 100 * mean over tracking scenarios of (CVaR10(in_band) + CVaR10(char_in_band)) / 2 "
          "- 100 * fraction of episodes with peak force > 3 N.  CVaR10 is the mean of the worst 10 % of "
          "the readers.  actuator_bound: a controller fed the true force; hysteresis_bound: the same "
          "controller fed the true force through the FSR's hysteresis and its exact inverse; sensor_bound: "
          "the actuator bound's force shifted by the estimator error (docs/benchmark.md).  The same command gives the same numbers.  "
          "Exit status: 0 when every episode ran, 1 when one failed (one line on stderr), 2 for bad input.")


SUITE_NAMES = ("quick", "standard")
"""The names of :data:`ebraille_sim.tools.benchmark.SUITES` (kept here so that the help
loads no simulator; a test checks they agree)."""


def add_arguments(p):
    from ebraille_sim.commands import MAX_JOBS, whole
    from ebraille_sim.commands.sweep import MAX_READERS
    p.add_argument("controllers", nargs="+", metavar="CONTROLLER",
                   help="registered names, gains files (.toml/.json) or policy:PATH")
    p.add_argument("--suite", default="standard", metavar="NAME",
                   help=f"scenario suite: {', '.join(SUITE_NAMES)} (default standard)")
    p.add_argument("--readers", type=whole(1, MAX_READERS), default=None, metavar="N",
                   help=f"readers per scenario: the nominal device and N-1 drawn ones, at most {MAX_READERS} "
                        "(default: the suite's, 64 for standard)")
    p.add_argument("-j", "--jobs", type=whole(1, MAX_JOBS), default=1, metavar="N",
                   help=f"local worker processes, at most {MAX_JOBS} and at most one per episode (default 1)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler address (e.g. tcp://host:8786): run on that cluster")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="write benchmark.json (the results file), leaderboard.md and population.png into DIR")
    p.add_argument("--compare", default=None, metavar="RESULTS.json",
                   help="print the changes against an earlier benchmark.json of the same suite")
    p.add_argument("--no-bounds", action="store_true", help="skip actuator_bound, hysteresis_bound and sensor_bound")
    p.add_argument("--estimator", action="append", default=[], metavar="KEY=VALUE",
                   help="an estimator setting of every device, bounds included (repeatable), e.g. "
                        "hysteresis_compensation=true; the [estimator] keys of a scenario file")


def main(args) -> int:
    import contextlib

    from ebraille_sim.commands import FrameProgress, UserError, check_out_dir, claim_out_dir, console
    from ebraille_sim.tools import benchmark as bm

    con = console(args)
    suite = bm.get_suite(args.suite)
    try:
        estimator = bm.estimator_settings(args.estimator)
    except (ValueError, FileNotFoundError) as exc:
        raise UserError(f"--estimator: {exc}") from None
    from ebraille_sim.commands.sweep import MAX_EPISODES
    readers = suite.readers if args.readers is None else args.readers
    episodes = (len(set(args.controllers)) + (0 if args.no_bounds else 2)) * len(suite.scenarios) * readers
    if episodes > MAX_EPISODES:
        raise UserError(f"this benchmark has {episodes} episodes (controllers and bounds x {len(suite.scenarios)} "
                        f"scenarios x {readers} readers), more than the {MAX_EPISODES} one run holds; "
                        f"give fewer --readers")
    out = check_out_dir(args.out, owned=bm.RESULT_FILES) if args.out is not None else None
    old = bm.load_results(args.compare) if args.compare is not None else None
    if old is not None and (old["suite"], old["suite_version"]) != (suite.name, bm.SUITE_VERSION):
        raise UserError(f"--compare {args.compare}: suite {old['suite']} v{old['suite_version']}, "
                        f"this run is {suite.name} v{bm.SUITE_VERSION}")
    progress = FrameProgress("episodes", enabled=con.progress and not con.json)
    with (claim_out_dir(out, bm.RESULT_FILES) if out is not None else contextlib.nullcontext()) as target:
        result = bm.run_benchmark(args.controllers, suite, readers=args.readers, jobs=args.jobs,
                                  bounds=not args.no_bounds, progress=progress, estimator=estimator,
                                  scheduler=args.scheduler)
        progress.close()
        summary = bm.summarise(result)
        doc = bm.results_document(result, summary)
        deltas = bm.compare(doc, old) if old is not None else None
        files = []
        if target is not None:
            with target.staged() as folder:
                files = [out / p.name for p in bm.write_results(result, folder, summary)]
    con.result({**{k: v for k, v in doc.items() if k != "rows"}, "compare": deltas,
                "files": [str(f) for f in files]})
    con.say(bm.format_leaderboard(result, summary))
    con.say("")
    con.say(bm.format_population(doc["population"]))
    if deltas is not None:
        con.say("")
        con.say(bm.format_compare(deltas))
    con.say(f"\n{len(result.rows)} episode rows in {result.wall_s:.1f} s on {result.jobs} process(es)")
    if files:
        con.say("wrote " + ", ".join(str(f) for f in files))
    failed = [r for r in result.rows if r.get("error")]
    if failed:
        import sys
        print(f"episodes failed: {len(failed)} of {len(result.rows)} (first: {failed[0]['controller']} on "
              f"{failed[0]['scenario']}: {str(failed[0]['error'])[:160]})", file=sys.stderr)
        return 1
    return 0
