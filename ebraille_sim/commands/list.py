"""``ebraille-sim list``: the shipped scenarios, controllers, firmware presets, designs, device presets and
estimator models."""
from __future__ import annotations

import pathlib

NAME = "list"
HELP = "list scenarios, controllers, firmware presets, designs, device presets and estimator models"


def add_arguments(p):
    """``--designs PATH ...``: your own design files (or folders of them) to list with the
    shipped ones; ``--json`` prints :func:`catalogue`."""
    p.add_argument("--designs", nargs="+", default=[], metavar="PATH",
                   help="also list these design files (.toml/.json), or the design files in these folders; "
                        "the design files in ./designs are always listed")


def catalogue(design_paths=()) -> dict:
    """Everything ``list`` shows, as a JSON-ready dict.

    ``scenarios`` is a list of ``{"name", "description", "file", "from", "error"}`` in the
    order names are looked up: ``from`` is ``"library"`` for the shipped library and
    ``"working folder"`` for your own ``./scenarios``; ``error`` is None for a valid file,
    else the one-line reason it cannot be loaded.  ``designs`` holds the shipped designs
    (``from`` ``"library"``), then your own design files
    (:func:`controllers.designs.design_files`): those of ``./designs`` (``"working folder"``)
    and of ``design_paths`` (``"argument"``); a bad design file raises one line naming it.
    """
    import controllers
    from controllers.designs import design_files, designs
    from ebraille_sim.estimation.paper_models import KINDS, ORDERS
    from ebraille_sim.estimation.presets import firmware_presets
    from ebraille_sim.physics import params
    from ebraille_sim.plant.backends import PLANT_BACKENDS
    from ebraille_sim.scenarios.spec import library_dir, list_scenarios, load_scenario, resolve_scenario_path

    lib = library_dir()
    lib = lib.resolve() if lib is not None else None
    scenarios = []
    for name in list_scenarios():
        path = resolve_scenario_path(name)
        entry = {"name": name, "description": "", "file": str(path),
                 "from": "library" if path.parent.resolve() == lib else "working folder", "error": None}
        try:
            entry["description"] = load_scenario(path).description
        except ValueError as exc:
            entry["error"] = str(exc)
        scenarios.append(entry)
    return {
        "scenarios": scenarios,
        "controllers": list(controllers.available()),
        "plant_backends": list(PLANT_BACKENDS),
        "device_presets": {"motor": list(params.MOTORS), "drivetrain": list(params.DRIVETRAINS),
                           "finger": list(params.FINGERS), "fsr": list(params.FSRS)},
        "estimator_models": [f"paper:{k}:{o}" for k in KINDS for o in ORDERS],
        "firmware": [{"name": f.name, "description": f.description, "score": f.score,
                      "settings": dict(f.estimator), "benchmark": dict(f.benchmark)}
                     for f in firmware_presets().values()],
        "designs": [_design_entry(d, "library") for d in designs().values()]
                   + [_design_entry(_checked(d), _origin(d)) for d in design_files(design_paths)],
    }


def _checked(d):
    """A user's design whose controller is registered and accepts its gains (one line naming the file)."""
    import controllers
    if d.controller not in controllers.available():
        raise ValueError(f"{d.source}: controller {d.controller!r} is not a registered controller; available: "
                         f"{', '.join(controllers.available())}")
    try:
        controllers.make(d.controller, **d.gains)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{d.source}: {str(exc).strip().splitlines()[0]}") from None
    return d


def _origin(d) -> str:
    from controllers.designs import WORKING_FOLDER
    here = pathlib.Path(WORKING_FOLDER).resolve()
    return "working folder" if pathlib.Path(d.source).resolve().parent == here else "argument"


def _design_entry(d, origin: str) -> dict:
    return {"name": d.name, "description": d.description, "score": d.score, "controller": d.controller,
            "firmware": d.firmware, "gains": dict(d.gains), "benchmark": dict(d.benchmark), "file": d.source,
            "from": origin}


def _score(v) -> str:
    return f"{v:6.2f}" if isinstance(v, (int, float)) else "     -"


def main(args) -> int:
    from controllers.policy import shipped_policies
    from ebraille_sim.commands import console

    con = console(args)
    cat = catalogue(getattr(args, "designs", ()))
    con.result(cat)
    if con.json or con.quiet:
        return 0
    print("scenarios:")
    for s in cat["scenarios"]:
        desc = f"(invalid: {s['error']})" if s["error"] else s["description"]
        mark = " [./scenarios]" if s["from"] == "working folder" else ""
        print(f"  {s['name']:<24} {desc}{mark}")
    print("controllers:")
    for name in cat["controllers"]:
        print(f"  {name}")
    print("  (or a gains file: .toml/.json with controller = NAME and a [gains] table,")
    print("   or policy:PATH for a policy saved by 'ebraille-sim train', extra: rl,")
    print("   or policy:NAME for a shipped learned policy: "
          + ", ".join(shipped_policies()) + ")")
    print("firmware presets (score: the best design on it, benchmark points):")
    for f in cat["firmware"]:
        print(f"  {f['name']:<24} {_score(f['score'])}  {f['description']}")
    print("designs (--controller NAME runs one on its firmware; your own: --controller FILE):")
    for d in cat["designs"]:
        mark = "" if d["from"] == "library" else f" [{d['file']}]"
        print(f"  {d['name']:<24} {_score(d['score'])}  {d['controller']} on {d['firmware'] or 'any firmware'}: "
              f"{d['description']}{mark}")
    print("plant backends:")
    print("  " + ", ".join(cat["plant_backends"]))
    print("device presets:")
    for kind, names in cat["device_presets"].items():
        print(f"  {kind + ':':<11} " + ", ".join(names))
    print("estimator models:")
    print("  " + ", ".join(cat["estimator_models"]))
    print("  (or the path of a model saved as JSON)")
    return 0
