"""The ``[supervisor]`` scenario section: wraps the run's controller in the safety supervisor."""
from __future__ import annotations

import dataclasses

from controllers.supervisor import Supervisor, SupervisorConfig
from ebraille_sim.scenarios.spec import ScenarioError

def validate_section(source: str, value) -> dict:
    """Check a ``[supervisor]`` table; raise ``ScenarioError`` naming a bad key or value."""
    if not isinstance(value, dict):
        raise ScenarioError(f"{source}: [supervisor] must be a table")
    names = [f.name for f in dataclasses.fields(SupervisorConfig)]
    for key in value:
        if key not in names:
            raise ScenarioError(f"{source}: unknown key {key!r} in [supervisor]; allowed: {', '.join(sorted(names))}")
    try:
        SupervisorConfig(**value)
    except ValueError as exc:
        msg = str(exc)
        msg = msg[len("supervisor "):] if msg.startswith("supervisor ") else msg
        raise ScenarioError(f"{source}: [supervisor] {msg}") from None
    return dict(value)


def wrap_controller(section: dict, controller, dt_s: float):
    """Wrap ``controller`` in a :class:`Supervisor` configured by the ``[supervisor]`` section."""
    return Supervisor(controller, SupervisorConfig(**section))
