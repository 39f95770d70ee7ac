"""``ebraille-sim list``: the shipped scenarios, controllers, presets and estimator models."""
from __future__ import annotations

NAME = "list"
HELP = "list scenarios, controllers, device presets and estimator models"


def add_arguments(p):
    pass


def main(args) -> int:
    import controllers

    from ebraille_sim.physics import params
    from ebraille_sim.estimation.paper_models import KINDS, ORDERS
    from ebraille_sim.scenarios.spec import list_scenarios, load_scenario

    print("scenarios:")
    for name in list_scenarios():
        try:
            desc = load_scenario(name).description
        except ValueError as exc:
            desc = f"(invalid: {exc})"
        print(f"  {name:<24} {desc}")
    print("controllers:")
    for name in controllers.available():
        print(f"  {name}")
    print("  (or a gains file: .toml/.json with controller = NAME and a [gains] table,")
    print("   or policy:PATH for a policy saved by 'ebraille-sim train', extra: rl)")
    print("plant backends:")
    from ebraille_sim.plant.loop import PLANT_BACKENDS
    print("  " + ", ".join(PLANT_BACKENDS))
    print("device presets:")
    print("  motor:      " + ", ".join(params.MOTORS))
    print("  drivetrain: " + ", ".join(params.DRIVETRAINS))
    print("  finger:     " + ", ".join(params.FINGERS))
    print("  fsr:        " + ", ".join(params.FSRS))
    print("estimator models:")
    print("  " + ", ".join(f"paper:{k}:{o}" for k in KINDS for o in ORDERS))
    print("  (or the path of a model saved as JSON)")
    return 0
