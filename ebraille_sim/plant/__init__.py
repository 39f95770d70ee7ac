"""Plant layer: the device simulated one control period at a time.

``layout`` (named slots of the flat state, parameter and input vectors), ``kernel`` (the
compiled control period, composing the physics laws), ``engine`` (the loop engine: the one
closed-loop body), ``loop`` (:class:`Plant`, packing, the backend registry), ``mechanism``
(the 2-D pymunk backend).
"""
