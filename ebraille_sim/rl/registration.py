"""Registration of the Gymnasium id, without importing the environment itself.

``import ebraille_sim`` calls :func:`register_envs`; the entry points are strings, so the
environment, the compiled kernel and SciPy load only when ``gym.make`` builds an env.
"""
from __future__ import annotations

__all__ = ["ENV_ID", "register_envs"]

ENV_ID = "EBraille/ContactForce-v0"


def register_envs() -> None:
    """Register ``EBraille/ContactForce-v0`` with Gymnasium (once per process, silently).

    No ``max_episode_steps`` is registered: the env truncates itself when the excerpt ends,
    which bounds an episode by :meth:`ebraille_sim.rl.env.EnvConfig.max_episode_steps` at
    whatever control rate it is made with (one registered step count would cut a 1 kHz
    episode after 1.4 s).
    """
    import gymnasium as gym
    if ENV_ID in gym.registry:
        return
    gym.register(id=ENV_ID, entry_point="ebraille_sim.rl.env:ContactForceEnv",
                 vector_entry_point="ebraille_sim.rl.vector_env:ContactForceVectorEnv")
