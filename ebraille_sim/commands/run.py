"""``ebraille-sim run SCENARIO``: simulate a reading scenario in closed loop and report."""
from __future__ import annotations

NAME = "run"
HELP = "simulate a scenario in closed loop; print the metrics, write metrics.json, trace.csv, force.png"
EPILOG = ("exit status: 0 when the run meets every [criteria] limit of the scenario, 1 when one fails "
          "(one 'criterion failed: ...' line per limit on stderr), 2 for bad input")


def add_arguments(p):
    p.add_argument("scenario", help="scenario file or the name of a shipped scenario (see 'list')")
    p.add_argument("--controller", default=None,
                   help="controller name (see 'list') or a gains file (.toml/.json); default: the scenario's")
    p.add_argument("--seed", type=int, default=None, help="master seed (default: the scenario's)")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="override the duration, s")
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default: runs/SCENARIO)")
    p.add_argument("--backend", default="lumped", help="plant model (default: lumped)")
    p.add_argument("--no-plot", action="store_true", help="skip force.png")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON instead of a table")
    p.add_argument("--animate", default=None, metavar="PATH",
                   help="with --backend pymunk: write the mechanism as a GIF (PNG frames without Pillow), "
                        "25 frames per simulated second")


def failed_criteria(result) -> list[str]:
    """One line per ``[criteria]`` limit the run fails (empty when all pass)."""
    from ebraille_sim.scenarios.metrics import CRITERIA, evaluate_criteria
    lines = []
    for key, c in evaluate_criteria(result.spec.criteria, result.metrics).items():
        if not c["passed"]:
            op = "<=" if CRITERIA[key][1] == "le" else ">="
            v = c["value"]
            shown = "None" if v is None else (f"{v:.6g}" if isinstance(v, float) else str(v))
            lines.append(f"criterion failed: {c['metric']} = {shown}, expected {op} {c['limit']:g} "
                         f"([criteria] {key})")
    return lines


def main(args) -> int:
    import json
    import pathlib
    import sys

    from ebraille_sim.tools.report import metrics_document, summary_table, write_outputs
    from ebraille_sim.scenarios.runner import run_scenario
    from ebraille_sim.scenarios.spec import load_scenario

    spec = load_scenario(args.scenario)
    if args.seed is not None and args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.animate is not None and args.backend != "pymunk":
        raise ValueError(f"--animate draws the pymunk mechanism; use it with --backend pymunk, not {args.backend!r}")
    if args.animate is not None:
        from ebraille_sim.plant.mechanism import recording, write_animation
        with recording(every_s=1.0 / 25.0) as rec:
            result = run_scenario(spec, controller=args.controller, seed=args.seed, duration_s=args.duration,
                                  backend=args.backend)
        anim = write_animation(rec.frames, args.animate, fps=25.0)
        print(f"wrote {anim} ({len(rec.frames)} frames)")
    else:
        result = run_scenario(spec, controller=args.controller, seed=args.seed, duration_s=args.duration,
                              backend=args.backend)
    out = pathlib.Path(args.out) if args.out else pathlib.Path("runs") / spec.name
    write_outputs(result, out, plot=not args.no_plot)
    if args.json:
        print(json.dumps(metrics_document(result), indent=2))
    else:
        print(summary_table(result))
        print(f"\nwrote {out / 'metrics.json'}, {out / 'trace.csv'}" + ("" if args.no_plot else f", {out / 'force.png'}"))
    failures = failed_criteria(result)
    for line in failures:
        print(line, file=sys.stderr)
    return 1 if failures else 0
