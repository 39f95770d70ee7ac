"""ebraille-sim: closed-loop contact-force simulator for a finger-wearable E-Braille reader.

Importing the package registers the Gymnasium environment id ``EBraille/ContactForce-v0``
(when the environment module is present) and has no other side effect.
"""
from __future__ import annotations

__version__ = "0.1.0"

from ebraille_sim.scenarios.runner import RunResult, run_scenario  # noqa: E402
from ebraille_sim.rl.env import register_envs as _register_envs  # noqa: E402

_register_envs()

__all__ = ["run_scenario", "RunResult", "__version__"]
