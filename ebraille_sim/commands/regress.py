"""``ebraille-sim regress``: run every scenario and compare its metrics with the stored baselines."""
from __future__ import annotations

NAME = "regress"
JSON_FILE = True
HELP = "run every scenario in scenarios/ and compare the metrics with scenarios/baselines/ (exit 1 if any moved)"
EPILOG = ("exit status: 0 when every scenario matches its baseline and criteria, 1 when any moved, "
          "failed a criterion or has no baseline, 2 for bad input (including a baseline file that cannot be read)")


def add_arguments(p):
    from ebraille_sim.commands import MAX_JOBS, whole
    p.add_argument("--update", action="store_true", help="rewrite the baselines from this run")
    p.add_argument("--only", nargs="+", metavar="NAME", default=None,
                   help="run only these scenarios: names (./scenarios first, then the shipped library) or "
                        "scenario file paths (baseline in baselines/ beside the file)")
    p.add_argument("--scenarios", default=None, metavar="DIR",
                   help="folder of scenario files (default: ./scenarios, else the shipped library)")
    p.add_argument("--baselines", default=None, metavar="DIR", help="folder of baselines (default: baselines/ beside each scenario file)")
    p.add_argument("--controller", default=None,
                   help="check this controller (name or gains file) against the baselines instead of each scenario's")
    p.add_argument("-j", "--jobs", type=whole(1, MAX_JOBS), default=1, metavar="N",
                   help=f"scenarios run in parallel, at most {MAX_JOBS} (default 1)")
    p.add_argument("-v", "--verbose", action="store_true", help="list every compared metric, not only what moved")
    p.add_argument("--junit", default=None, metavar="FILE",
                   help="also write JUnit XML: one test case per scenario, failures list the moved metrics")


def _prepare(option: str, path):
    """The report file, checked now (not a folder, its folder writable) so a bad path fails before the runs."""
    from ebraille_sim.commands import UserError
    from ebraille_sim.tools.outputs import check_file
    try:
        return check_file(path, option)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def _check_inputs(args) -> None:
    """Scenario folder, scenarios, baselines folder and controller, checked before any run."""
    import os
    import pathlib

    import controllers

    from ebraille_sim.base.files import short
    from ebraille_sim.commands import UserError, check_out_dir
    from ebraille_sim.tools.regress import scenario_files
    if args.scenarios is not None:
        d = pathlib.Path(args.scenarios)
        if not d.exists():
            raise UserError(f"--scenarios {str(d)!r}: no such folder")
        if not d.is_dir():
            raise UserError(f"--scenarios {str(d)!r} is a file, not a folder")
    if args.baselines is not None:
        b = pathlib.Path(args.baselines)
        if args.update:
            check_out_dir(b, "--baselines")
        elif b.exists() and not b.is_dir():
            raise UserError(f"--baselines {str(b)!r} is a file, not a folder")
    try:
        files = scenario_files(args.scenarios, args.only)
    except (ValueError, FileNotFoundError) as exc:
        raise UserError(str(exc)) from None
    if not files:
        where = args.scenarios if args.scenarios is not None else "the scenario folder"
        raise UserError(f"no scenario files (*.toml) in {short(str(where))}; nothing to check")
    from ebraille_sim.base.files import check_regular, read_json
    from ebraille_sim.tools.regress import baseline_path
    for f in files:                  # a baseline that cannot be read (a FIFO, a device, too large, too deep) is refused before the runs
        b = (pathlib.Path(args.baselines) / f"{pathlib.Path(f).stem}.json" if args.baselines is not None
             else baseline_path(f))
        if os.path.lexists(b):
            try:
                if os.path.islink(b) and args.update:
                    raise ValueError(f"baseline {short(str(b))} is a symbolic link; ebraille-sim replaces only "
                                     f"regular files")
                check_regular(b, "baseline")
                if not args.update:
                    read_json(b, "baseline")
            except (ValueError, FileNotFoundError) as exc:
                raise UserError(str(exc)) from None
    from ebraille_sim.scenarios.spec import load_scenario
    for f in files:                  # every scenario (and the files it reads) is read before the runs
        try:
            load_scenario(f)
        except (ValueError, FileNotFoundError) as exc:
            raise UserError(f"--only: {exc}" if args.only else str(exc)) from None
    if args.controller is not None:
        try:
            controllers.make(args.controller)
        except (ValueError, FileNotFoundError, TypeError) as exc:
            raise UserError(f"--controller {str(args.controller)!r}: {exc}") from None


def main(args) -> int:
    import json
    import time

    from ebraille_sim.commands import console
    from ebraille_sim.tools.outputs import write_file
    from ebraille_sim.tools.regress import format_report, json_document, junit_xml, regress_scenarios

    con = console(args)

    if args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    if args.update and args.controller:
        raise ValueError("--update writes baselines with each scenario's own controller; drop --controller")
    _check_inputs(args)
    junit = _prepare("--junit", args.junit) if args.junit is not None else None
    json_path = _prepare("--json", args.json) if isinstance(args.json, str) else None
    t0 = time.perf_counter()
    checks = regress_scenarios(args.scenarios, only=args.only, update=args.update, controller=args.controller,
                               baseline_dir=args.baselines, jobs=args.jobs)
    doc = json_document(checks)
    con.result(doc)
    con.say(format_report(checks, verbose=args.verbose))
    con.say(f"wall time {time.perf_counter() - t0:.1f} s")
    if junit:
        write_file(junit, junit_xml(checks), "--junit")
        con.say(f"wrote {junit}")
    if json_path:
        write_file(json_path, json.dumps(doc, indent=2, allow_nan=False) + "\n", "--json")
        con.say(f"wrote {json_path}")
    return 1 if any(c.failed for c in checks) else 0
