"""The ``[mechanism]`` scenario section: pose of the finger on the board for the pymunk backend.

Press offset, finger tilt and hand roll over time become per-period plant inputs
(``press_offset_m``, ``finger_tilt_rad``, ``gravity_lateral_m_per_s2``), which the 2-D
mechanism (:mod:`ebraille_sim.plant.pymunk`) reads; the lumped plant ignores them.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ebraille_sim.base.validation import check_range
from ebraille_sim.physics.params import STANDARD_GRAVITY_M_PER_S2
from ebraille_sim.scenarios.spec import ScenarioError, check_section_table

_SECTION_KEYS = {
    "press_offset_m": (-15e-3, 15e-3),
    "finger_tilt_deg": (-30.0, 30.0),
    "hand_roll_deg": (-180.0, 180.0),
    "pose_steps": None,
    "pose_ramp_s": (0.0, 10.0),
}
KEY_DOCS = {"press_offset_m": ("m", "Lateral offset of the press centre on the board."),
            "finger_tilt_deg": ("deg", "Tilt of the pulp surface relative to the board."),
            "hand_roll_deg": ("deg", "Roll of the hand about the finger axis (lateral gravity g sin(roll))."),
            "pose_steps": ("s, m, deg", "Pose changes as [time_s, press_offset_m, finger_tilt_deg] rows."),
            "pose_ramp_s": ("s", "Ramp time of each pose change (0: a step).")}
"""``(unit, one-line description)`` of every key (the scenario reference reads them)."""


def validate_section(source: str, value) -> dict:
    """Check a ``[mechanism]`` scenario section; raise ScenarioError with one line.

    Keys: ``press_offset_m`` (lateral offset of the press centre, m), ``finger_tilt_deg``
    (pulp surface tilt relative to the board), ``hand_roll_deg`` (roll of the hand about
    the finger axis: lateral gravity ``g sin(roll)``), ``pose_steps`` (list of
    ``[time_s, press_offset_m, finger_tilt_deg]``, times increasing) and ``pose_ramp_s``.
    """
    check_section_table(source, "mechanism", value, sorted(_SECTION_KEYS))
    out = {}
    for key, v in value.items():
        if key == "pose_steps":
            if not isinstance(v, list) or not all(isinstance(r, list) and len(r) == 3 for r in v):
                raise ScenarioError(f"{source}: [mechanism] pose_steps must be a list of "
                                    f"[time_s, press_offset_m, finger_tilt_deg] triples")
            rows = []
            for row in v:
                t_s = _number(source, "pose_steps time", row[0], (0.0, 3600.0))
                off = _number(source, "pose_steps press_offset_m", row[1], _SECTION_KEYS["press_offset_m"])
                tilt = _number(source, "pose_steps finger_tilt_deg", row[2], _SECTION_KEYS["finger_tilt_deg"])
                rows.append((t_s, off, tilt))
            if any(b[0] <= a[0] for a, b in zip(rows, rows[1:])):
                raise ScenarioError(f"{source}: [mechanism] pose_steps times must increase")
            out[key] = tuple(rows)
        else:
            out[key] = _number(source, key, v, _SECTION_KEYS[key])
    return out


def _number(source, key, v, bounds):
    try:
        return check_range(key, v, *bounds)
    except ValueError as exc:
        raise ScenarioError(f"{source}: [mechanism] {exc}") from None


def driven_inputs(section: dict) -> tuple:
    """The plant inputs :func:`build_inputs` returns (a ``[mechanism]`` section drives all three)."""
    return ("press_offset_m", "finger_tilt_rad", "gravity_lateral_m_per_s2")


def build_inputs(section: dict, t_s: np.ndarray, rng, device, out: dict | None = None) -> dict:
    """Per-period inputs of a ``[mechanism]`` section: press offset, finger tilt, lateral gravity
    (``out`` is not used: these profiles are built whole)."""
    off = np.full(len(t_s), section.get("press_offset_m", 0.0))
    tilt = np.full(len(t_s), math.radians(section.get("finger_tilt_deg", 0.0)))
    ramp = section.get("pose_ramp_s", 0.0)
    prev_off, prev_tilt = off[0], tilt[0]
    for t0, o, tdeg in section.get("pose_steps", ()):
        tr = math.radians(tdeg)
        frac = np.clip((t_s - t0) / ramp, 0.0, 1.0) if ramp > 0 else (t_s >= t0).astype(float)
        on = t_s >= t0
        off = np.where(on, prev_off + (o - prev_off) * frac, off)
        tilt = np.where(on, prev_tilt + (tr - prev_tilt) * frac, tilt)
        prev_off, prev_tilt = o, tr
    g_lat = -STANDARD_GRAVITY_M_PER_S2 * math.sin(math.radians(section.get("hand_roll_deg", 0.0)))
    return {"press_offset_m": ("set", off), "finger_tilt_rad": ("set", tilt),
            "gravity_lateral_m_per_s2": ("set", np.full(len(t_s), g_lat))}


def load_mechanism_scenario(path):
    """Load a scenario file whose ``[mechanism]`` section this module validates.

    The section is validated by :func:`validate_section` and attached to the spec's
    delegate sections, so :func:`ebraille_sim.scenarios.runner.run_scenario` applies it through
    :func:`build_inputs`; the rest of the file goes through
    :func:`ebraille_sim.scenarios.spec.parse_scenario` unchanged.
    """
    from ebraille_sim.scenarios.spec import parse_scenario, parse_toml, read_scenario_bytes, resolve_scenario_path
    p = resolve_scenario_path(path)
    data = parse_toml(read_scenario_bytes(p), p.name)
    section = data.pop("mechanism", None)
    spec = parse_scenario(data, source=p.name, base_dir=str(p.parent))
    if section is not None:
        spec = dataclasses.replace(spec, sections={**spec.sections,
                                                   "mechanism": validate_section(p.name, section)})
    return spec
