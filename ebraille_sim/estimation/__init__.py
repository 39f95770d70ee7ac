"""Estimation layer: what the device's microcontroller runs to turn volts back into newtons.

``blockmodels`` (linear, Hammerstein, Wiener models), ``firmware`` (the on-device chain
between the ADC and the estimator), ``paper_models`` (the seed paper's 16 models as data),
``registry`` (estimators by name), ``resample`` (re-discretisation), ``calibration`` (divider
calibration and static error).  Imports physics and base only.
"""
