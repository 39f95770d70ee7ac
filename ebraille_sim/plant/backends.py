"""The plant backends by name, importable without loading any backend (or Numba).

The command line lists these names in its help and checks ``--backend`` against them
before it loads a simulator.
"""
from __future__ import annotations

__all__ = ["PLANT_BACKENDS", "make_plant"]

PLANT_BACKENDS: dict = {"lumped": "ebraille_sim.plant.lumped:Plant",
                        "pymunk": "ebraille_sim.plant.pymunk.plant:PymunkPlant"}
"""Plant classes by backend name, as ``"module:Class"``; each class provides
``from_devices(devices, seeds, board_pos_m=None, models=None)`` and the :class:`Plant`
interface (``advance``, ``set_finger``, ``set_input``, ``state``/``params``/``inputs``); a
backend may take more keywords (the pymunk plant's ``recorder``)."""


def make_plant(devices, seeds, backend: str = "lumped", **kwargs):
    """Build a plant of the named backend (a key of :data:`PLANT_BACKENDS`)."""
    import importlib
    if backend not in PLANT_BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; available: {', '.join(sorted(PLANT_BACKENDS))}")
    mod_name, cls_name = PLANT_BACKENDS[backend].split(":")
    try:
        cls = getattr(importlib.import_module(mod_name), cls_name)
    except (ModuleNotFoundError, AttributeError):
        raise ValueError(f"backend {backend!r} is not available in this installation") from None
    return cls.from_devices(devices, seeds, **kwargs)
