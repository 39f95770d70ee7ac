"""Scenario files: TOML, loaded with ``tomllib`` and validated strictly.

A scenario names a reading passage and rate, a force setpoint profile, the device
(presets plus field overrides), the rates, the estimator, the reader's finger and the
controller.  Every table accepts only the keys in :data:`SCHEMA`; an unknown key is an
error that names it and lists the allowed ones, a value out of range names the value and
the range.  See ``docs/scenarios.md`` for the full reference.

Example (``scenarios/steady_90wpm.toml``)::

    name = "steady_90wpm"
    seed = 1
    [reading]
    passage = "default"
    wpm = 90
    [setpoint]
    force_n = 1.0

Examples
--------
>>> spec = parse_scenario({"name": "x", "reading": {"wpm": 90}}, source="inline")
>>> spec.reading.wpm
90.0
>>> parse_scenario({"name": "x", "reading": {"wmp": 90}}, source="inline")
Traceback (most recent call last):
...
ebraille_sim.scenarios.spec.ScenarioError: inline: unknown key 'wmp' in [reading]; allowed: ...
"""
from __future__ import annotations

import dataclasses
import math
import pathlib
from dataclasses import dataclass, field
from typing import Any

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

from ebraille_sim.physics import params as _params


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message is one line naming the problem."""


def _num(lo=None, hi=None, lo_open=False, hi_open=False, integer=False):
    return {"type": "int" if integer else "float", "lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open}


_STR = {"type": "str"}
_BOOL = {"type": "bool"}

DELEGATES: dict[str, str] = {
    "disturbances": "ebraille_sim.scenarios.disturbances",
    "faults": "ebraille_sim.scenarios.faults",
    "supervisor": "ebraille_sim.scenarios.supervision",
    "mechanism": "ebraille_sim.scenarios.mechanism_section",
}
"""Top-level scenario sections validated and applied by their own module.

Each module provides ``validate_section(source, value) -> object`` (raising
:class:`ScenarioError` with a one-line message) and is used by the runner through
``build_inputs(section, t_s, rng, device) -> dict`` (per-period plant inputs) and/or
``wrap_controller(section, controller, dt_s) -> Controller``.  Wrappers are applied in
the order of this dict, so an injected controller fault (``faults``) always sits inside
the safety supervisor (``supervisor``)."""

SCHEMA: dict[str, dict[str, Any]] = {
    "": {
        "name": _STR, "description": _STR, "seed": _num(0, 2**52, integer=True),
        "duration_s": _num(0, 3600, lo_open=True),
        "reading": "table", "setpoint": "table", "device": "table", "rates": "table",
        "estimator": "table", "finger": "table", "controller": "table", "criteria": "table",
        **{k: "delegate" for k in DELEGATES},
    },
    "reading": {
        "passage": _STR, "text": _STR, "file": _STR,
        "wpm": _num(0, 1000, lo_open=True), "start_s": _num(0, 600),
        "jitter_fraction": _num(0, 0.5), "word_pause_s": _num(0, 5), "line_pause_s": _num(0, 10),
        "max_characters": _num(1, 10**6, integer=True),
        # per-character refresh mode (see ebraille_sim.scenarios.runner.refresh_phases)
        "mode": {"type": "choice", "choices": ["continuous", "refresh"]},
        "refresh_lift_fraction": _num(0, 1), "refresh_press_fraction": _num(0, 1),
        "refresh_release_fraction": _num(0, 1), "refresh_lift_force_n": _num(0, 3.0),
    },
    "setpoint": {
        "force_n": _num(0, 3.0, lo_open=True), "band_fraction": _num(0, 1, lo_open=True),
        "steps": {"type": "steps"}, "ramp_s": _num(0, 10),
    },
    "device": {
        "motor": {"type": "choice", "choices": sorted(_params.MOTORS)},
        "drivetrain": {"type": "choice", "choices": sorted(_params.DRIVETRAINS)},
        "finger": {"type": "choice", "choices": sorted(_params.FINGERS)},
        "fsr": {"type": "choice", "choices": sorted(_params.FSRS)},
        "driver_supply_v": _num(0, 48, lo_open=True),
        "hand_orientation_deg": _num(-180, 180),
        "motor_overrides": "overrides", "drivetrain_overrides": "overrides",
        "finger_overrides": "overrides", "fsr_overrides": "overrides", "circuit_overrides": "overrides",
    },
    "rates": {
        "control_hz": _num(0, 1e6, lo_open=True), "sensor_hz": _num(0, 1e6, lo_open=True),
        "physics_hz": _num(0, 1e7, lo_open=True),
    },
    "estimator": {
        "model": _STR, "antialias_cutoff_hz": _num(0, 1e5, lo_open=True), "tare_at_start": _BOOL,
        "clamp_nonnegative": _BOOL, "nyquist_average": _BOOL,
    },
    "finger": {
        "gap_m": _num(-0.01, 0.01),
    },
    "controller": {
        "name": _STR, "gains": "free",
    },
    "criteria": {
        "onset_overshoot_max": _num(0, 10), "in_band_min": _num(0, 1), "peak_force_max_n": _num(0, 100),
    },
}

_OVERRIDE_TARGET = {
    "motor_overrides": _params.MotorParams, "drivetrain_overrides": _params.DriveTrainParams,
    "finger_overrides": _params.FingerParams, "fsr_overrides": _params.FSRParams,
    "circuit_overrides": _params.CircuitParams,
}


@dataclass(frozen=True)
class ReadingSpec:
    passage: str = "default"
    text: str | None = None
    file: str | None = None
    wpm: float = 90.0
    start_s: float = 1.5
    jitter_fraction: float = 0.0
    word_pause_s: float = 0.0
    line_pause_s: float = 0.0
    max_characters: int | None = None
    # per-character refresh: each dwell is lift | press | hold | release, as fractions of
    # the dwell; the setpoint is refresh_lift_force_n while lifted or released and the
    # force setpoint from the press on; only the hold part counts as the character's window
    mode: str = "continuous"
    refresh_lift_fraction: float = 0.10
    refresh_press_fraction: float = 0.30
    refresh_release_fraction: float = 0.15
    refresh_lift_force_n: float = 0.1

    def __post_init__(self):
        if self.mode == "refresh":
            used = self.refresh_lift_fraction + self.refresh_press_fraction + self.refresh_release_fraction
            if not used < 1.0:
                raise ScenarioError(f"[reading] refresh_lift_fraction + refresh_press_fraction + "
                                    f"refresh_release_fraction = {used:g} leaves no hold time; it must be < 1")


@dataclass(frozen=True)
class SetpointSpec:
    force_n: float = 1.0
    band_fraction: float = 0.10
    steps: tuple[tuple[float, float], ...] = ()
    ramp_s: float = 0.0


@dataclass(frozen=True)
class ControllerSpec:
    name: str = "pid"
    gains: dict = field(default_factory=dict)


@dataclass(frozen=True)
class FingerSpec:
    gap_m: float = 1.0e-3


@dataclass(frozen=True)
class ScenarioSpec:
    """A validated scenario.  ``device`` is the fully resolved :class:`DeviceParams`."""
    name: str
    description: str
    seed: int
    duration_s: float | None
    reading: ReadingSpec
    setpoint: SetpointSpec
    device: _params.DeviceParams
    finger: FingerSpec
    controller: ControllerSpec
    criteria: dict
    sections: dict = field(default_factory=dict)
    source: str = ""
    base_dir: str = "."


def _fmt_range(s):
    lo = "(" if s["lo_open"] else "["
    hi = ")" if s["hi_open"] else "]"
    a = "-inf" if s["lo"] is None else f"{s['lo']:g}"
    b = "inf" if s["hi"] is None else f"{s['hi']:g}"
    return f"{lo}{a}, {b}{hi}"


def _check_value(src, table, key, value, rule):
    where = f"[{table}] {key}" if table else key
    t = rule["type"]
    if t == "str":
        if not isinstance(value, str):
            raise ScenarioError(f"{src}: {where} must be a string, got {value!r}")
        return value
    if t == "bool":
        if not isinstance(value, bool):
            raise ScenarioError(f"{src}: {where} must be true or false, got {value!r}")
        return value
    if t == "choice":
        if value not in rule["choices"]:
            raise ScenarioError(f"{src}: {where} = {value!r} is not one of: {', '.join(rule['choices'])}")
        return value
    if t == "steps":
        if not isinstance(value, list) or not all(isinstance(r, list) and len(r) == 2 for r in value):
            raise ScenarioError(f"{src}: {where} must be a list of [time_s, force_n] pairs")
        out = []
        for t_s, f_n in value:
            t_s = _check_value(src, table, key + " time", t_s, _num(0, 3600))
            f_n = _check_value(src, table, key + " force", f_n, _num(0, 3.0, lo_open=True))
            out.append((t_s, f_n))
        if any(b[0] <= a[0] for a, b in zip(out, out[1:])):
            raise ScenarioError(f"{src}: {where} times must increase")
        return tuple(out)
    # numbers
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f"{src}: {where} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ScenarioError(f"{src}: {where} must be finite, got {value}")
    if t == "int" and int(value) != value:
        raise ScenarioError(f"{src}: {where} must be a whole number, got {value}")
    lo, hi = rule["lo"], rule["hi"]
    bad = (lo is not None and (value < lo or (rule["lo_open"] and value == lo))) or \
          (hi is not None and (value > hi or (rule["hi_open"] and value == hi)))
    if bad:
        raise ScenarioError(f"{src}: {where} = {value:g} is out of range {_fmt_range(rule)}")
    return int(value) if t == "int" else float(value)


def _check_table(src, name, data):
    allowed = SCHEMA[name]
    if not isinstance(data, dict):
        raise ScenarioError(f"{src}: [{name}] must be a table")
    out = {}
    for key, value in data.items():
        if key not in allowed:
            where = f"[{name}]" if name else "the top level"
            raise ScenarioError(f"{src}: unknown key {key!r} in {where}; allowed: {', '.join(sorted(allowed))}")
        rule = allowed[key]
        if rule == "table":
            out[key] = _check_table(src, key, value)
        elif rule == "overrides":
            out[key] = _check_overrides(src, f"{name}.{key}", value, _OVERRIDE_TARGET[key])
        elif rule == "delegate":
            import importlib
            try:
                mod = importlib.import_module(DELEGATES[key])
            except ModuleNotFoundError:
                raise ScenarioError(f"{src}: section [{key}] is not available in this installation") from None
            out[key] = mod.validate_section(src, value)
        elif rule == "free":
            if not isinstance(value, dict):
                raise ScenarioError(f"{src}: [{name}.{key}] must be a table")
            out[key] = dict(value)
        else:
            out[key] = _check_value(src, name, key, value, rule)
    return out


def _check_overrides(src, where, data, cls):
    if not isinstance(data, dict):
        raise ScenarioError(f"{src}: [{where}] must be a table")
    names = {f.name: f for f in dataclasses.fields(cls) if f.name not in ("name", "sources")}
    for key, value in data.items():
        if key not in names:
            raise ScenarioError(f"{src}: unknown key {key!r} in [{where}]; allowed: {', '.join(sorted(names))}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{src}: [{where}] {key} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ScenarioError(f"{src}: [{where}] {key} must be finite, got {value}")
    return dict(data)


def _build_device(src, dev: dict, rates: dict, est: dict, base_dir: str = ".") -> _params.DeviceParams:
    try:
        motor = _params.MOTORS[dev.get("motor", "faulhaber_0816_006sr")]
        drivetrain = _params.DRIVETRAINS[dev.get("drivetrain", "planetary_64")]
        finger = _params.FINGERS[dev.get("finger", "nominal")]
        fsr = _params.FSRS[dev.get("fsr", "nominal")]
        circuit = _params.CircuitParams()
        motor = _params.replace_checked(motor, **dev.get("motor_overrides", {}))
        drivetrain = _params.replace_checked(drivetrain, **dev.get("drivetrain_overrides", {}))
        finger = _params.replace_checked(finger, **dev.get("finger_overrides", {}))
        fsr = _params.replace_checked(fsr, **dev.get("fsr_overrides", {}))
        circuit = _params.replace_checked(circuit, **dev.get("circuit_overrides", {}))
        r = _params.RateParams(
            control_rate_hz=rates.get("control_hz", 1000.0),
            sensor_rate_hz=rates.get("sensor_hz", 1000.0),
            physics_rate_hz=rates.get("physics_hz", 10000.0))
        e = _params.replace_checked(_params.EstimatorParams(), **{
            k2: est[k1] for k1, k2 in (("model", "model"), ("antialias_cutoff_hz", "antialias_cutoff_hz"),
                                       ("tare_at_start", "tare_at_start"),
                                       ("clamp_nonnegative", "clamp_nonnegative"),
                                       ("nyquist_average", "nyquist_average")) if k1 in est})
        if "model" in est and not est["model"].startswith("paper:"):
            mp = pathlib.Path(est["model"])
            if not mp.is_absolute():
                mp = pathlib.Path(base_dir) / mp
            if not mp.exists():
                raise ScenarioError(f"{src}: [estimator] model file {str(mp)!r} not found")
            e = _params.replace_checked(e, model=str(mp))
        angle = math.radians(dev.get("hand_orientation_deg", 0.0))
        g = _params.STANDARD_GRAVITY_M_PER_S2 * math.cos(angle)
        return _params.DeviceParams(motor=motor, drivetrain=drivetrain, finger=finger, fsr=fsr,
                                    circuit=circuit, estimator=e, rates=r,
                                    driver_supply_v=dev.get("driver_supply_v", motor.nominal_voltage_v),
                                    gravity_m_per_s2=g)
    except ScenarioError:
        raise
    except (ValueError, TypeError) as exc:
        raise ScenarioError(f"{src}: {exc}") from None


def parse_scenario(data: dict, source: str = "<scenario>", base_dir: str = ".") -> ScenarioSpec:
    """Validate a scenario given as a dict (the parsed TOML)."""
    top = _check_table(source, "", data)
    if "name" not in top:
        raise ScenarioError(f"{source}: missing required key 'name'")
    rd = top.get("reading", {})
    if sum(k in rd for k in ("passage", "text", "file")) > 1:
        raise ScenarioError(f"{source}: [reading] takes only one of passage, text, file")
    try:
        reading = ReadingSpec(**rd)
    except ScenarioError as exc:
        raise ScenarioError(f"{source}: {exc}") from None
    sp = SetpointSpec(**top.get("setpoint", {}))
    dev = _build_device(source, top.get("device", {}), top.get("rates", {}), top.get("estimator", {}), base_dir)
    ctl = top.get("controller", {})
    return ScenarioSpec(
        name=top["name"], description=top.get("description", ""), seed=top.get("seed", 0),
        duration_s=top.get("duration_s"), reading=reading, setpoint=sp, device=dev,
        finger=FingerSpec(**top.get("finger", {})),
        controller=ControllerSpec(name=ctl.get("name", "pid"), gains=ctl.get("gains", {})),
        criteria=top.get("criteria", {}), sections={k: top[k] for k in DELEGATES if k in top},
        source=source, base_dir=base_dir)


def load_scenario(path) -> ScenarioSpec:
    """Load and validate a scenario file.

    ``path`` may also be the bare name of a scenario shipped in ``scenarios/``.
    """
    p = resolve_scenario_path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"cannot read scenario file {str(p)!r}: {exc.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{p.name}: malformed TOML: {exc}") from None
    return parse_scenario(data, source=p.name, base_dir=str(p.parent))


def scenario_dirs() -> list[pathlib.Path]:
    """Folders searched for scenario names: ``./scenarios`` and the project's own."""
    here = pathlib.Path(__file__).resolve().parents[2] / "scenarios"
    cwd = pathlib.Path.cwd() / "scenarios"
    out = []
    for d in (cwd, here):
        if d.is_dir() and d not in out:
            out.append(d)
    return out


def resolve_scenario_path(path) -> pathlib.Path:
    p = pathlib.Path(path)
    if p.exists():
        return p
    if p.suffix == "" and len(p.parts) == 1:
        for d in scenario_dirs():
            cand = d / f"{p.name}.toml"
            if cand.exists():
                return cand
    names = ", ".join(list_scenarios()) or "none found"
    raise ScenarioError(f"scenario file {str(path)!r} not found (shipped scenarios: {names})")


def list_scenarios() -> list[str]:
    """Names of the scenario files found in :func:`scenario_dirs`."""
    names = []
    for d in scenario_dirs():
        for f in sorted(d.glob("*.toml")):
            if f.stem not in names:
                names.append(f.stem)
    return names
