"""The body-motion axis of the fault matrix: the wearer's own motion relative to the board.

Each cell is a scenario built from the public API: a firmware (``default``: the 100 Hz
estimator and the default PID; ``1khz``: the firmware preset and design of the shipped scenario
``refresh_120wpm_1khz``), an FSR preset on a device calibrated for the nominal unit, a reader
(the nominal and stiff presets and drawn readers), a setpoint (1, 2 or 3 N; the supervisor caps
the setpoint to leave room for a strap slip) and one body motion from :func:`motions`.  The
contract inside the relative-motion budget of docs/safety.md (section 6): the true force stays
at or below 3.5 N.  ``studies/body_motion/matrix.py`` runs the whole matrix; the tests run the
sample :func:`cells` gives with ``quick=True``.
"""
from __future__ import annotations

import dataclasses
import itertools
import sys
import time

import numpy as np

from ebraille_sim.physics.params import FINGERS, FSRS
from ebraille_sim.scenarios.disturbances import body_motion_budget
from ebraille_sim.scenarios.population import sample_devices
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import parse_scenario

SAFE_N = 3.5
DURATION_S = 2.5
MOTION_AT_S = 1.6
SETPOINTS_N = (1.0, 2.0, 3.0)
FSR_PRESETS = ("nominal", "low_k", "high_k")
FIRMWARES = ("default", "1khz")
READER_SEED = 2207
"""Master seed of the drawn readers (:func:`ebraille_sim.scenarios.population.sample_devices`)."""


def _budget():
    return body_motion_budget()


def motions() -> dict:
    """Body motions by name: ``(section, entry, inside_budget)``; ``section`` is
    ``"disturbances"`` (a sub-table) or ``"faults"`` (a ``finger_withdrawn`` entry: a partial lift).

    Tremor is the finger's tremor at the strapped frame's transmission (its worst over the
    8-12 Hz band, :func:`~ebraille_sim.scenarios.disturbances.body_motion_budget`), at
    15-45 um RMS and at the budget's worst finger tremor (200 um); 15-45 um with transmission 1
    (a frame that does not follow the finger) are outside the budget.  Lifts (a
    ``finger_withdrawn`` entry held 0.1 s) of 0.1-3 mm moving in 2-50 ms, in refresh reading;
    strap slips of 0.1-1 mm toward the board and of the budget's largest away from it in the
    budget's fastest time; pressing at the budget's largest and at 0.1 and 0.5 mm RMS (a frame
    that does not follow the finger).
    """
    b = _budget()
    out = {}
    for rms in (15e-6, 30e-6, 45e-6, b["tremor_rms_max_m"]):
        name = f"tremor_{rms * 1e6:.0f}um"
        out[name] = ("disturbances", {"tremor": {"rms_m": rms, "transmission": b["tremor_transmission_max"]}}, True)
        if rms <= 45e-6:
            out[name + "_t1"] = ("disturbances", {"tremor": {"rms_m": rms, "transmission": 1.0}}, False)
    for depth in (0.1e-3, 0.3e-3, 1e-3, 3e-3):
        for move in (2e-3, 10e-3, 50e-3):
            inside = depth <= b["lift_depth_max_m"] and move >= b["lift_move_min_s"]
            out[f"lift_{depth * 1e3:g}mm_{move * 1e3:g}ms"] = (
                "faults", {"kind": "finger_withdrawn", "distance_m": depth, "move_s": move,
                           "duration_s": 2 * move + 0.1}, inside)
    for d in (0.1e-3, 0.3e-3, 0.5e-3, 1e-3):
        inside = d <= b["slip_toward_max_m"]
        out[f"slip_{d * 1e3:g}mm"] = ("disturbances", {"strap_slip": {
            "at_s": [MOTION_AT_S], "displacement_m": -d, "duration_s": b["slip_duration_min_s"],
            "max_offset_m": 1e-3}}, inside)
    d = b["slip_depth_max_m"]
    out[f"slip_away_{d * 1e3:g}mm"] = ("disturbances", {"strap_slip": {
        "at_s": [MOTION_AT_S], "displacement_m": d, "duration_s": b["slip_duration_min_s"], "max_offset_m": 1e-3}},
        True)
    out["pressing_budget"] = ("disturbances", {"pressing": {"rms_m": b["pressing_rms_max_m"]}}, True)
    for rms in (0.1e-3, 0.5e-3):
        out[f"pressing_{rms * 1e6:.0f}um"] = ("disturbances", {"pressing": {"rms_m": rms}}, False)
    return out


def _firmware_sections(firmware: str) -> dict:
    """``default``: the scenario defaults; ``1khz``: the firmware preset and the design of the
    shipped scenario ``refresh_120wpm_1khz`` (``fast_1khz``, ``dob_learn_1khz``)."""
    if firmware == "default":
        return {}
    return {"estimator": {"firmware": "fast_1khz"}, "controller": {"name": "dob_learn_1khz"}}


def cell_spec(motion: str, firmware: str, setpoint_n: float, seed: int = 7, supervisor: dict | None = None,
              duration_s: float = DURATION_S):
    """The scenario of one cell (the device is set by :func:`run_cell`); ``supervisor``: the
    ``[supervisor]`` section (default: the supervisor's defaults)."""
    section, entry, _ = motions()[motion]
    refresh = motion.startswith("lift")
    reading = {"passage": "default", "wpm": 120, "start_s": 0.8}
    if refresh:
        reading.update({"mode": "refresh", "refresh_lift_fraction": 0.10, "refresh_press_fraction": 0.30,
                        "refresh_release_fraction": 0.15, "refresh_lift_force_n": 0.4})
    data = {"name": "body_motion_cell", "description": "body-motion matrix cell", "seed": seed,
            "duration_s": duration_s, "reading": reading,
            "setpoint": {"force_n": setpoint_n, "band_fraction": 0.1},
            "finger": {"gap_m": 0.001}, "supervisor": dict(supervisor or {}),
            **_firmware_sections(firmware)}
    if section == "disturbances":
        data["disturbances"] = entry
    else:
        data["faults"] = [{**entry, "start_s": MOTION_AT_S}]
    return parse_scenario(data)


def readers(n_drawn: int = 2) -> dict:
    """Reader devices by name: the nominal and stiff presets and ``n_drawn`` drawn readers."""
    spec = parse_scenario({"name": "r"})
    base = spec.device
    out = {"nominal": base, "stiff": dataclasses.replace(base, finger=FINGERS["stiff"])}
    for k, dev in enumerate(sample_devices(READER_SEED, n_drawn)):
        out[f"drawn{k}"] = dev
    return out


def run_cell(motion, firmware, setpoint_n, fsr, device, supervised=True, supervisor=None,
             duration_s: float = DURATION_S) -> dict:
    """Peak true force, time above 3.5 N and the supervisor's fault of one cell."""
    spec = cell_spec(motion, firmware, setpoint_n, supervisor=supervisor, duration_s=duration_s)
    dev = dataclasses.replace(device, fsr=FSRS[fsr]) if fsr != "nominal" else device
    res = run_scenario(dataclasses.replace(spec, device=dev), supervised=supervised)
    f = res.trace["force_true_n"]
    dt = float(res.trace["t_s"][1] - res.trace["t_s"][0])
    late = res.trace["t_s"] >= MOTION_AT_S - 0.5
    return {"peak_n": float(f[late].max()), "above_s": float(np.sum(f > SAFE_N) * dt),
            "fault": res.supervisor.get("fault") if isinstance(res.supervisor, dict) else None}


def cells(quick: bool = False):
    """The cells ``(motion, firmware, setpoint, fsr, reader)`` of the matrix (``quick``: the CI
    sample, every motion inside the budget on both firmwares at 3 N asked, with the under-reading
    high-k unit on the stiff reader)."""
    ms = motions()
    if quick:
        names = [n for n, (_, _, inside) in ms.items() if inside]
        return list(itertools.product(names, FIRMWARES, (3.0,), ("high_k",), ("stiff",)))
    return list(itertools.product(ms, FIRMWARES, SETPOINTS_N, FSR_PRESETS, readers()))
