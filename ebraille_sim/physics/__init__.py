"""Physics layer: one module per physical law of the device and reader, and their parameters.

``params`` (sourced parameter dataclasses and presets), ``motor``, ``drivetrain``,
``fingertip``, ``fsr``, ``noise``.  Each law is a plain function, compiled with Numba, that
every path calls: the compiled kernel, the pymunk backend, the linearisation and the static
helpers.  Imports only :mod:`ebraille_sim.base`.
"""
