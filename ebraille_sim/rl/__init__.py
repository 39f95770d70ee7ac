"""Reinforcement-learning layer: the Gymnasium environment, its native vector form and rendering."""
