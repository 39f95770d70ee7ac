"""ebraille-sim: closed-loop contact-force simulator for a finger-wearable E-Braille reader.

Importing the package registers the Gymnasium environment id ``EBraille/ContactForce-v0``
(at once if Gymnasium is loaded, else when it is: the package does not import it) and has
no other side effect.  ``run_scenario`` and ``RunResult`` are loaded on first use,
so ``import ebraille_sim`` stays light.
"""
from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["run_scenario", "RunResult", "__version__"]


def __getattr__(name):
    if name in ("run_scenario", "RunResult"):
        from ebraille_sim.scenarios import runner
        return getattr(runner, name)
    raise AttributeError(f"module 'ebraille_sim' has no attribute {name!r}")


from ebraille_sim.rl.registration import register_when_gymnasium_loads as _register  # noqa: E402

_register()
