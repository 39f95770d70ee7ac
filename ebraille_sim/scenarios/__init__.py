"""Scenario layer: what a reading session is, and running one in closed loop.

``spec`` (scenario files), ``braille``/``passages``/``reading`` (text to cells to a
schedule), ``disturbances``, ``faults``, ``supervision`` and ``mechanism_section`` (optional
sections), ``population`` (drawn devices), ``runner`` (the closed-loop run), ``metrics`` and
``legibility`` (what is measured on the true force).
"""
