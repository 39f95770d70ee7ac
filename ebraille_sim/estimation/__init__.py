"""Estimation layer: what the device's microcontroller runs to turn volts back into newtons.

``blockmodels`` (linear, Hammerstein, Wiener models), ``paper_models`` (the seed paper's 16
models as data), ``models`` (estimators by name), ``calibration`` (divider calibration and
static error).  Imports physics and base only.
"""
