"""The ``[supervisor]`` scenario section: wraps the run's controller in the safety supervisor."""
from __future__ import annotations

from controllers.supervisor import ENVELOPE_KEYS, POLICY_KEYS, Supervisor, SupervisorConfig
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.scenarios.spec import ScenarioError, check_section_table


def validate_section(source: str, value) -> dict:
    """Check a ``[supervisor]`` table (the :class:`~controllers.supervisor.SupervisorPolicy`);
    raise ``ScenarioError`` naming a bad key or value.  A drive envelope constant
    (:data:`~controllers.supervisor.ENVELOPE_KEYS`) is refused: it comes from ``[device]``."""
    if isinstance(value, dict):
        for k in value:
            if k in ENVELOPE_KEYS:
                raise ScenarioError(f"{source}: [supervisor] {k} is not a setting: the supervisor derives it from "
                                    f"[device] (datasheet and calibration)")
    check_section_table(source, "supervisor", value, sorted(POLICY_KEYS))
    try:
        SupervisorConfig(**value)
    except ValueError as exc:
        raise ScenarioError(f"{source}: [supervisor] {exc}") from None
    return dict(value)


def wrap_controller(section: dict, controller, dt_s: float, device: DeviceParams | None = None):
    """Wrap ``controller`` in a :class:`Supervisor` configured by the ``[supervisor]`` section.

    The drive envelope comes from ``device`` (:meth:`SupervisorConfig.for_device`; the nominal
    device when None); the section sets the policy.
    """
    return Supervisor(controller, SupervisorConfig.for_device(device or DeviceParams(), **section))
