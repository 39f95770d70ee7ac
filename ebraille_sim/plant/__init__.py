"""Plant layer: the device simulated one control period at a time.

``layout`` (named slots of the flat state, parameter and input vectors), ``kernel`` (the
compiled control period, composing the physics laws), ``engine`` (the loop engine: the one
closed-loop body), ``lumped`` (the lumped plant: :class:`~ebraille_sim.plant.lumped.Plant`,
packing), ``backends`` (the plant backends by name), ``pymunk`` (the 2-D pymunk backend, a
package).
"""
