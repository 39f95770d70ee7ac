"""The estimator registry's earlier module name: :mod:`ebraille_sim.estimation.registry`."""
from ebraille_sim.estimation.registry import cached_model, load_estimator

__all__ = ["load_estimator", "cached_model"]
