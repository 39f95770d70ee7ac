"""Injected faults: the ``[[faults]]`` scenario section.

Each entry is a table with a ``kind``, a start time ``start_s`` and a ``duration_s``
(omitted: until the end of the run); the fault is active on ``[start_s, start_s +
duration_s)``.

==================  ===================================================================
kind                effect (plant input or controller)
==================  ===================================================================
fsr_open            ``fsr_fault = OPEN``: the divider reads 0 V (broken FSR lead)
fsr_short           ``fsr_fault = SHORT``: the divider reads the supply (shorted film)
fsr_stuck           ``fsr_fault = STUCK``: the ADC repeats its last code
fsr_value           ``fsr_fault = VALUE``: the divider reads ``value_v`` volts
motor_stall         ``motor_jammed = 1``: the pinion is locked (jammed gearhead)
controller_nan      the controller's command is NaN (a diverged or corrupted controller)
finger_withdrawn    the pulp moves away by ``distance_m`` (default 3 mm) over ``move_s``
                    (default 0.05 s, a smooth cosine ramp), stays away, and comes back over
                    ``move_s`` at the end of the window
==================  ===================================================================

``controller_nan`` is applied by :func:`wrap_controller`: the runner wraps the controller
with every delegate section in the order of :data:`ebraille_sim.scenarios.spec.DELEGATES`
(``faults`` before ``supervisor``), so the NaN comes from *inside* a supervisor, whose
watchdog must catch it.  The faulty wrapper still calls the inner controller every
period (its state evolves as if it were running) and replaces its output.

Examples
--------
>>> v = validate_section("x.toml", [{"kind": "fsr_open", "start_s": 2.0, "duration_s": 1.0}])
>>> import numpy as np
>>> t = np.arange(0, 4, 0.5)
>>> build_inputs(v, t, None, None)["fsr_fault"][1].tolist()
[0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0]
"""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.base.validation import check_choice, check_keys, check_number
from ebraille_sim.physics.fsr import FAULT_OPEN, FAULT_SHORT, FAULT_STUCK, FAULT_VALUE

__all__ = ["KINDS", "validate_section", "driven_inputs", "build_inputs", "wrap_controller", "FaultyController"]

KINDS = {
    "fsr_open": ("fsr_fault", FAULT_OPEN),
    "fsr_short": ("fsr_fault", FAULT_SHORT),
    "fsr_stuck": ("fsr_fault", FAULT_STUCK),
    "fsr_value": ("fsr_fault", FAULT_VALUE),
    "motor_stall": ("motor_jammed", 1.0),
    "controller_nan": (None, None),
    "finger_withdrawn": ("finger_pos_m", None),
}
"""Fault kinds and the plant input each drives (with its value)."""

_COMMON = {"kind", "start_s", "duration_s"}
_EXTRA = {"fsr_value": {"value_v"}, "finger_withdrawn": {"distance_m", "move_s"}}
_RANGES = {"start_s": (0.0, 3600.0, False), "duration_s": (0.0, 3600.0, True), "value_v": (-1.0, 10.0, False),
           "distance_m": (0.0, 0.02, True), "move_s": (0.0, 10.0, True)}
"""``(lo, hi, lo_open)`` of every numeric key."""
KEY_DOCS = {"kind": ("-", "The fault (one of KINDS)."),
            "start_s": ("s", "Time the fault starts."),
            "duration_s": ("s", "How long the fault lasts."),
            "value_v": ("V", "Voltage the divider reads during an fsr_value fault."),
            "distance_m": ("m", "How far the pulp moves away."),
            "move_s": ("s", "Time of the pulp's move away and back.")}
"""``(unit, one-line description)`` of every key (the scenario reference reads them)."""


def validate_section(source: str, value) -> list[dict]:
    """Check a ``[[faults]]`` array of tables; raise ``ScenarioError`` naming the problem."""
    from ebraille_sim.scenarios.spec import ScenarioError
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise ScenarioError(f"{source}: faults must be an array of tables ([[faults]] entries)")
    out = []
    for j, entry in enumerate(value):
        where = f"[[faults]] entry {j + 1}"
        try:
            kind = check_choice(f"{where} kind", entry.get("kind"), KINDS)
            check_keys(f"{where} ({kind})", entry, sorted(_COMMON | _EXTRA.get(kind, set())))
            if "start_s" not in entry:
                raise ValueError(f"{where} ({kind}) needs start_s")
            if kind == "fsr_value" and "value_v" not in entry:
                raise ValueError(f"{where} (fsr_value) needs value_v")
            e = {"kind": kind}
            for key, v in entry.items():
                if key != "kind":
                    lo, hi, lo_open = _RANGES[key]
                    e[key] = check_number(f"{where} {key}", v, lo, hi, lo_open=lo_open)
        except ValueError as exc:
            raise ScenarioError(f"{source}: {exc}") from None
        e.setdefault("duration_s", math.inf)
        if kind == "finger_withdrawn":
            e.setdefault("distance_m", 3e-3)
            e.setdefault("move_s", 0.05)
            if math.isfinite(e["duration_s"]) and 2 * e["move_s"] > e["duration_s"]:
                raise ScenarioError(f"{source}: {where} duration_s must be at least twice move_s")
        out.append(e)
    return out


def _window(t_s: np.ndarray, e: dict) -> np.ndarray:
    return (t_s >= e["start_s"]) & (t_s < e["start_s"] + e["duration_s"])


def _withdraw_profile(t_s: np.ndarray, e: dict) -> np.ndarray:
    """Displacement of the pulp away from the board: cosine ramps out and back."""
    t0, t1, mv, d = e["start_s"], e["start_s"] + e["duration_s"], e["move_s"], e["distance_m"]

    def ramp(x):
        x = np.clip(x, 0.0, 1.0)
        return 0.5 - 0.5 * np.cos(np.pi * x)
    up = ramp((t_s - t0) / mv)
    down = ramp((t_s - (t1 - mv)) / mv) if math.isfinite(t1) else np.zeros_like(t_s)
    return d * (up - down)


def driven_inputs(section: list) -> tuple:
    """The plant inputs :func:`build_inputs` returns for a validated ``[[faults]]`` list."""
    names = []
    for e in section:
        name = KINDS[e["kind"]][0]
        if name is not None:
            names.append(name)
        if e["kind"] == "fsr_value":
            names.append("fsr_fault_value")
    return tuple(dict.fromkeys(names))


def build_inputs(section: list, t_s: np.ndarray, rng, device, out: dict | None = None) -> dict:
    """Per-period plant inputs of the faults: ``{input: ("set" | "add", array)}`` (``out``,
    the rows :data:`~ebraille_sim.scenarios.spec.DELEGATES` modules may write into, is not
    used: these profiles are built whole).

    Later entries override earlier ones where windows of the same input overlap.
    """
    t_s = np.asarray(t_s, float)
    out: dict = {}
    for e in section:
        name, val = KINDS[e["kind"]]
        if name is None:
            continue
        if e["kind"] == "finger_withdrawn":
            prev = out.get(name, ("add", np.zeros_like(t_s)))[1]
            out[name] = ("add", prev + _withdraw_profile(t_s, e))
            continue
        if name in out:
            arr = out[name][1].copy()
        else:
            arr = np.zeros_like(t_s)
        w = _window(t_s, e)
        arr[w] = val
        out[name] = ("set", arr)
        if e["kind"] == "fsr_value":
            v = out.get("fsr_fault_value", ("set", np.zeros_like(t_s)))[1].copy()
            v[w] = e["value_v"]
            out["fsr_fault_value"] = ("set", v)
    return out


class FaultyController:
    """Wraps a controller and returns NaN inside the ``controller_nan`` windows.

    Time is the sum of the ``dt_s`` passed since :meth:`reset`, taken at the start of
    each period (the runner's period ``k`` starts at ``k dt``).
    """

    def __init__(self, inner, windows):
        self.inner = inner
        self.windows = [(float(a), float(b)) for a, b in windows]
        self.name = getattr(inner, "name", type(inner).__name__)
        self.t = 0.0

    def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
        self.t = 0.0
        self.inner.reset(force_est_n=force_est_n, setpoint_n=setpoint_n, command_v=command_v)

    def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
        u = self.inner.update(force_est_n, setpoint_n, dt_s, motor_current_a)
        t = self.t
        self.t += dt_s
        for a, b in self.windows:
            if a <= t < b:
                return math.nan
        return u


def wrap_controller(section: list, controller, dt_s: float, device=None):
    """Apply the ``controller_nan`` entries (other kinds act on the plant inputs; ``device`` is unused)."""
    wins = [(e["start_s"], e["start_s"] + e["duration_s"]) for e in section if e["kind"] == "controller_nan"]
    return FaultyController(controller, wins) if wins else controller
