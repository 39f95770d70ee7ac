"""``ebraille-sim run SCENARIO``: simulate a reading scenario in closed loop and report."""
from __future__ import annotations

NAME = "run"
HELP = "simulate a scenario in closed loop; print the metrics, write metrics.json, trace.csv, force.png"
EPILOG = ("exit status: 0 when the run meets every [criteria] limit of the scenario, 1 when one fails "
          "(one 'criterion failed: ...' line per limit on stderr), 2 for bad input (also an --out folder "
          "that already holds a run, without --force)")

ANIMATION_NAME = "animation.gif"
"""File name of ``--animate`` without a path, inside the run folder."""

PLOT_PROCESS = True
"""Draw force.png in a helper process started before the simulation
(:class:`ebraille_sim.tools.forceplot.ForcePlotter`), so that Matplotlib loads while Numba
loads and the run simulates, and the figure is drawn while the trace is written.  It is
used when Matplotlib is not loaded in this process yet; False draws the figure here."""


class _Backends:
    """The names of :data:`ebraille_sim.plant.backends.PLANT_BACKENDS`, read when argparse asks."""

    def _names(self) -> list:
        from ebraille_sim.plant.backends import PLANT_BACKENDS
        return list(PLANT_BACKENDS)

    def __iter__(self):
        return iter(self._names())

    def __contains__(self, name) -> bool:
        return name in self._names()

    def __len__(self) -> int:
        return len(self._names())


def add_arguments(p):
    from ebraille_sim.commands import number, seed
    p.add_argument("scenario", help="scenario file or the name of a shipped scenario (see 'list')")
    p.add_argument("--controller", default=None,
                   help="controller name (see 'list') or a gains file (.toml/.json); default: the scenario's")
    p.add_argument("--seed", type=seed, default=None, help="master seed, in [0, 2**63) (default: the scenario's)")
    p.add_argument("--duration", type=number(0, None, lo_open=True), default=None, metavar="S",
                   help="override the duration, s (at most what 2 GB of run arrays hold: "
                        "about 2 h at the default 1 kHz control rate)")
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default: runs/SCENARIO)")
    p.add_argument("--force", action="store_true",
                   help="overwrite the outputs of an earlier run in --out (refused otherwise)")
    p.add_argument("--backend", default="lumped", choices=_Backends(),
                   help="plant model: %(choices)s (default: %(default)s)")
    p.add_argument("--trace", default="csv", choices=("csv", "parquet", "none"),
                   help="trace file: trace.csv (default), trace.parquet (needs pyarrow) or none")
    p.add_argument("--trace-rate", type=number(0, None, lo_open=True), default=None, metavar="HZ",
                   help="samples per second kept in the trace and the plot (default: every control period); "
                        "must divide the control rate; the metrics always use every period")
    p.add_argument("--no-plot", action="store_true", help="skip force.png")
    p.add_argument("--no-supervisor", action="store_true",
                   help="run without the safety supervisor (on by default; the choice is printed and "
                        "recorded in metrics.json)")
    p.add_argument("--animate", nargs="?", const="", default=None, metavar="PATH",
                   help=f"with --backend pymunk: draw the mechanism as a GIF (PNG frames without Pillow), "
                        f"25 frames per simulated second; default PATH: {ANIMATION_NAME} in the run folder")


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


def trace_every(spec, args) -> int | None:
    """Control periods per kept trace sample from ``--trace-rate`` (None: no trace is needed,
    ``--trace none`` with ``--no-plot``).

    Raises
    ------
    UserError
        The rate is above the control rate or does not divide it.
    """
    from ebraille_sim.commands import UserError
    if args.trace == "none" and args.no_plot:
        return None
    if args.trace_rate is None:
        return 1
    control_hz = float(spec.device.rates.control_rate_hz)
    ratio = control_hz / args.trace_rate
    duration = args.duration if args.duration is not None else spec.duration_s
    if duration is not None:
        periods, length = max(1, round(duration * control_hz)), f"the run's {duration:g} s"
    else:
        from ebraille_sim.scenarios.inputs import BYTES_PER_CONTROL_SAMPLE, MAX_RUN_BYTES
        periods = MAX_RUN_BYTES // BYTES_PER_CONTROL_SAMPLE
        length = f"the longest run ({periods / control_hz:g} s)"
    if ratio > periods:
        raise UserError(f"--trace-rate {args.trace_rate:g} Hz keeps one sample every {1.0 / args.trace_rate:g} s, "
                        f"longer than {length}: no sample would be kept; give at least "
                        f"{control_hz / periods:g} Hz")
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * ratio:
        raise UserError(f"--trace-rate {args.trace_rate:g} Hz must divide the scenario's control rate "
                        f"{control_hz:g} Hz (e.g. {control_hz:g}, {control_hz / 10:g} or {control_hz / 100:g} Hz)")
    return int(k)


def _targets(args, spec):
    """The run folder and the animation path, checked before any simulation."""
    import pathlib

    from ebraille_sim.commands import UserError, check_out_dir
    from ebraille_sim.tools.outputs import check_file
    from ebraille_sim.tools.report import RUN_OWNED

    out = check_out_dir(args.out if args.out is not None else pathlib.Path("runs") / spec.name, owned=RUN_OWNED)
    anim = None
    if args.animate is not None:
        anim = pathlib.Path(args.animate) if args.animate else out / ANIMATION_NAME
        if args.animate:
            if anim.is_dir():
                raise UserError(f"--animate {str(anim)!r} is a folder; give a file name such as press.gif")
            try:
                check_file(anim, "--animate")
            except ValueError as exc:
                raise UserError(str(exc)) from None
    _not_overwriting(args, out, anim)
    return out, anim


def _not_overwriting(args, out, anim) -> None:
    """Refuse an --out folder that holds a run (or an --animate file that exists) without --force."""
    from ebraille_sim.base.files import short
    from ebraille_sim.commands import UserError
    from ebraille_sim.tools.report import existing_outputs
    if not args.force:
        old = [p.name for p in existing_outputs(out)]
        if old:
            raise UserError(f"run folder {short(out)} already holds a run ({', '.join(old)}); "
                            "pass --force to overwrite it or choose another --out")
        if anim is not None and anim.exists():
            raise UserError(f"--animate {short(anim)} exists; pass --force to overwrite it")


def _draw(frames, path, con):
    """Draw the recorded frames to ``path``; returns the file (or frame folder) written."""
    from ebraille_sim.commands import FrameProgress
    from ebraille_sim.tools.mechanism_drawing import write_animation
    bar = FrameProgress("drawing frames", enabled=con.progress)
    try:
        return write_animation(frames, path, fps=25.0, progress=bar)
    finally:
        bar.close()


def _start_plotter(args):
    """The helper process that draws force.png (None: the figure is drawn here, or not at all)."""
    import sys
    if args.no_plot or not PLOT_PROCESS or "matplotlib.figure" in sys.modules:
        return None
    from ebraille_sim.tools.forceplot import ForcePlotter
    return ForcePlotter.start()


def main(args) -> int:
    plotter = _start_plotter(args)
    try:
        return _run(args, plotter)
    finally:
        if plotter is not None:
            plotter.close()


def _run(args, plotter) -> int:
    import sys

    import pathlib

    from ebraille_sim.commands import UserError, check_duration, claim_out_dir, console
    from ebraille_sim.scenarios.runner import make_controller, run_scenario
    from ebraille_sim.scenarios.spec import load_scenario
    from ebraille_sim.tools.report import (RUN_OWNED, have_parquet, metrics_document, summary_table,
                                           write_run_files)

    con = console(args)
    if args.seed is not None and args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if args.animate is not None and args.backend != "pymunk":
        raise ValueError(f"--animate draws the pymunk mechanism; use it with --backend pymunk, not {args.backend!r}")
    if args.trace == "parquet" and not have_parquet():
        raise UserError("--trace parquet needs pyarrow, which is not installed; use --trace csv or none")
    spec = load_scenario(args.scenario)
    check_duration(spec, args.duration)
    every = trace_every(spec, args)
    out, anim = _targets(args, spec)
    try:
        from ebraille_sim.scenarios.runner import on_controller_firmware
        spec, firmware, applied = on_controller_firmware(spec, args.controller)   # a design on its own firmware
        ctrl = make_controller(spec, args.controller)
    except (ValueError, FileNotFoundError, TypeError) as exc:
        if args.controller is None:
            raise
        raise UserError(f"--controller {str(args.controller)!r}: {exc}") from None
    from controllers.designs import designs
    named = spec.controller.name if args.controller is None else str(args.controller)
    gains_file = args.controller if (args.controller is not None
                                     and str(args.controller).lower().endswith((".toml", ".json"))) else None
    if named in designs():                              # named in the report as the design it is
        gains_file = named
    from ebraille_sim.scenarios.runner import supervisor_choice
    sup_on, sup_source = supervisor_choice(spec, not args.no_supervisor)
    if not sup_on:
        print(f"warning: safety supervisor {sup_source}", file=sys.stderr)

    def simulate(recorder=None):
        return run_scenario(spec, controller=ctrl, seed=args.seed, duration_s=args.duration,
                            backend=args.backend, supervised=not args.no_supervisor, trace_every=every,
                            recorder=recorder)

    frames = None
    inside = anim is not None and not args.animate           # the default: animation.gif in the run folder
    drawn = None
    with claim_out_dir(out, RUN_OWNED) as target:
        _not_overwriting(args, out, anim)
        if anim is not None:
            from ebraille_sim.plant.pymunk.recording import Recorder
            rec = Recorder(every_s=1.0 / 25.0)
            result = simulate(rec)
            frames = rec.frames
        else:
            result = simulate()
        with target.staged() as folder:
            names = write_run_files(result, folder, plot=not args.no_plot, trace=args.trace, controller=ctrl,
                                    controller_file=gains_file, backend=args.backend, plotter=plotter)
            if inside:
                drawn = _draw(frames, folder / anim.name, con)
    written = [out / n for n in names]
    if drawn is not None:
        written.append(out / pathlib.Path(drawn).relative_to(folder))
    elif frames is not None:
        from ebraille_sim.tools.outputs import staged_file
        with staged_file(anim, "--animate") as tmp:
            _draw(frames, tmp, con)
        written.append(anim)
    doc = metrics_document(result, ctrl, gains_file)
    doc["firmware"] = firmware
    doc["out"] = str(out)
    doc["files"] = [str(p) for p in written]
    con.result(doc)
    con.say(summary_table(result, gains_file))
    if applied is not None:
        con.say(applied)
    con.say("\nwrote " + ", ".join(str(p) for p in written)
            + (f" ({len(frames)} frames)" if frames is not None else ""))
    failures = failed_criteria(result)
    for line in failures:
        print(line, file=sys.stderr)
    return 1 if failures else 0
