"""The ``[supervisor]`` scenario section: wraps the run's controller in the safety supervisor."""
from __future__ import annotations

import dataclasses

from controllers.supervisor import Supervisor, SupervisorConfig
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.scenarios.spec import ScenarioError, check_section_table

_NAMES = sorted(f.name for f in dataclasses.fields(SupervisorConfig))


def validate_section(source: str, value) -> dict:
    """Check a ``[supervisor]`` table; raise ``ScenarioError`` naming a bad key or value."""
    check_section_table(source, "supervisor", value, _NAMES)
    try:
        SupervisorConfig(**value)
    except ValueError as exc:
        raise ScenarioError(f"{source}: [supervisor] {exc}") from None
    return dict(value)


def wrap_controller(section: dict, controller, dt_s: float, device: DeviceParams | None = None):
    """Wrap ``controller`` in a :class:`Supervisor` configured by the ``[supervisor]`` section.

    The motor limits come from ``device`` (:meth:`SupervisorConfig.for_device`; the nominal
    device when None); the section's keys override them.
    """
    return Supervisor(controller, SupervisorConfig.for_device(device or DeviceParams(), **section))
