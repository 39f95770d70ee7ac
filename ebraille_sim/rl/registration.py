"""Registration of the Gymnasium id, without importing the environment itself.

``import ebraille_sim`` calls :func:`register_when_gymnasium_loads`: the id is registered at
once when Gymnasium is already imported, otherwise right after Gymnasium's own import
finishes (a one-shot import hook), so importing the simulator does not import Gymnasium.
The entry points are strings, so the environment, the compiled kernel and SciPy load only
when ``gym.make`` builds an env.
"""
from __future__ import annotations

import sys

__all__ = ["ENV_ID", "RESIDUAL_ENV_ID", "register_envs", "register_when_gymnasium_loads"]

ENV_ID = "EBraille/ContactForce-v0"
RESIDUAL_ENV_ID = "EBraille/ContactForceResidual-v0"
"""The residual env (:class:`ebraille_sim.rl.residual.ResidualEnv`): a correction on a design's command."""


def register_envs() -> None:
    """Register ``EBraille/ContactForce-v0`` and ``EBraille/ContactForceResidual-v0`` with
    Gymnasium (once per process, silently).

    No ``max_episode_steps`` is registered: the env truncates itself when the excerpt ends,
    which bounds an episode by :meth:`ebraille_sim.rl.env.EnvConfig.max_episode_steps` at
    whatever control rate it is made with (one registered step count would cut a 1 kHz
    episode after 1.4 s).
    """
    import gymnasium as gym
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="ebraille_sim.rl.env:ContactForceEnv",
                     vector_entry_point="ebraille_sim.rl.vector_env:ContactForceVectorEnv")
    if RESIDUAL_ENV_ID not in gym.registry:
        gym.register(id=RESIDUAL_ENV_ID, entry_point="ebraille_sim.rl.residual:ResidualEnv")


class _AfterGymnasium:
    """Import hook: lets Gymnasium import as usual, then registers the id (once) and leaves."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname != "gymnasium":
            return None
        import importlib.machinery
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None:
            return spec
        exec_module = spec.loader.exec_module

        def exec_then_register(module):
            exec_module(module)
            register_envs()

        spec.loader.exec_module = exec_then_register
        return spec


def register_when_gymnasium_loads() -> None:
    """Register the id now if Gymnasium is imported, else as soon as it is."""
    if "gymnasium" in sys.modules:
        register_envs()
    elif not any(isinstance(f, _AfterGymnasium) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterGymnasium())
