"""Snapshots of a pymunk plant at a fixed interval of simulated time, for drawing.

A :class:`Recorder` is handed to the plant it records, explicitly:
``PymunkPlant.from_devices(..., recorder=rec)``, or ``run_scenario(..., backend="pymunk",
recorder=rec)``, which passes it on.  The plant calls :meth:`Recorder.attach` when it is
built and :meth:`Recorder.after_step` after every control period; the recorder keeps the
plain-float snapshots (:meth:`~ebraille_sim.plant.pymunk.plant.PymunkPlant.snapshot`) that
:func:`ebraille_sim.tools.mechanism_drawing.write_animation` draws.  Recording reads the
plant and changes nothing in it.

Examples
--------
>>> from ebraille_sim.scenarios.runner import run_scenario
>>> rec = Recorder(every_s=0.05)
>>> _ = run_scenario("contact_onset", backend="pymunk", duration_s=1.0, recorder=rec)
>>> len(rec.frames)
21
"""
from __future__ import annotations

import math
import operator

from ebraille_sim.plant.layout import S

__all__ = ["Recorder"]


class Recorder:
    """Snapshots of device ``device_index`` of one plant, every ``every_s`` of simulated time.

    Parameters
    ----------
    every_s : float
        Interval between snapshots, s (> 0).  The first snapshot is the plant as built; the
        next is taken at the end of the first control period that reaches ``every_s``.
    device_index : int
        The device of the plant to record.

    Attributes
    ----------
    frames : list of dict
        The snapshots, in time order.
    plant
        The plant recorded: the last one the recorder was attached to (a plant built later
        with the same recorder takes its place; its snapshots follow the earlier ones).
    """

    def __init__(self, every_s: float = 0.04, device_index: int = 0):
        try:
            every = float(every_s)
        except (TypeError, ValueError):
            every = math.nan
        if isinstance(every_s, bool) or not (math.isfinite(every) and every > 0):
            raise ValueError(f"recording interval must be a positive number of seconds, got {every_s!r}")
        try:
            k = operator.index(device_index)
        except TypeError:
            k = -1
        if isinstance(device_index, bool) or k < 0:
            raise ValueError(f"recorded device_index must be a whole number >= 0, got {device_index!r}")
        self.every_s = every
        self.device_index = k
        self.frames: list[dict] = []
        self.plant = None
        self._next = 0.0

    def attach(self, plant) -> None:
        """Record ``plant`` from now on: its first snapshot is taken here."""
        if self.device_index >= plant.n:
            raise ValueError(f"recorded device_index {self.device_index} is out of range for a plant of "
                             f"{plant.n} device(s)")
        self.plant = plant
        self.frames.append(plant.snapshot(self.device_index))
        self._next = self.every_s

    def after_step(self, plant) -> None:
        """Take a snapshot of ``plant`` if its time has reached the next one due."""
        if plant is not self.plant:
            return
        t = plant.state[self.device_index, S.time_s]
        if t >= self._next - 1e-12:
            self.frames.append(plant.snapshot(self.device_index))
            self._next += self.every_s
