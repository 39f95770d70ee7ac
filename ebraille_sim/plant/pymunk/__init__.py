"""The pymunk backend: the device as a 2-D mechanism (rack, board tilt, off-centre press).

One concept per module:

- ``geometry``: :class:`~ebraille_sim.plant.pymunk.geometry.MechanismParams` (the mechanism's
  geometry and model options) and the step check of its stiffest explicit mode;
- ``model``: :class:`~ebraille_sim.plant.pymunk.model.Mechanism`, the pymunk space of one
  device (bodies, joints, the mesh, friction, end stops and pulp laws outside Chipmunk) and its
  control period;
- ``plant``: :class:`~ebraille_sim.plant.pymunk.plant.PymunkPlant`, ``n`` mechanisms behind the
  lumped plant's interface (the backend ``"pymunk"``); its sensor chain is the kernel's;
- ``recording``: :class:`~ebraille_sim.plant.pymunk.recording.Recorder`, snapshots handed to
  the plant as an argument.

Drawing the snapshots is not physics: :mod:`ebraille_sim.tools.mechanism_drawing`.
This package imports nothing itself, so that naming it loads neither pymunk nor Numba.
"""
