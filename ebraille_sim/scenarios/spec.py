"""Scenario files: TOML, loaded with ``tomllib`` and validated strictly.

A scenario names a reading passage and rate, a force setpoint profile, the device
(presets plus field overrides), the rates, the estimator, the reader's finger and the
controller.  Every table accepts only the keys in :data:`SCHEMA`, which is derived from
the field declarations of the table dataclasses (:class:`ScenarioFile`, :class:`ReadingSpec`,
:class:`SetpointSpec`, :class:`DeviceSpec`, :class:`RatesSpec`, :class:`EstimatorSpec`,
:class:`FingerSpec`, :class:`ControllerSpec`, :class:`CriteriaSpec`): each key is declared
once, with its default, unit, kind and range.  An unknown key is an error that names it and
lists the allowed ones, a value out of range names the value and the range.  The full
reference, generated from the schema, is ``docs/scenario-reference.md``.

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
import functools
import math
import os
import pathlib
import re
import warnings
from dataclasses import dataclass, field
from typing import Any

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

from ebraille_sim.base.fields import sourced
from ebraille_sim.base.validation import check_bool, check_choice, check_keys, check_number
from ebraille_sim.physics import params as _params
from ebraille_sim.estimation.presets import firmware_presets as _firmware_presets


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message is one line naming the problem.

    A ``ValueError`` subclass, so the checks of :mod:`ebraille_sim.base.validation` are
    re-raised as a ``ScenarioError`` with the file name in front.
    """


class ScenarioWarning(UserWarning):
    """A scenario that runs but is physically doubtful (e.g. a setpoint the finger cannot feel).

    Issued with :func:`warnings.warn`; the command line prints it as one ``warning: ...`` line.
    """


def check_section_table(source: str, section: str, value, allowed) -> None:
    """A delegate section must be a table whose keys are all in ``allowed``.

    Raises :class:`ScenarioError` ``"SOURCE: [section] must be a table"`` or
    ``"SOURCE: unknown key 'k' in [section]; allowed: ..."``.
    """
    if not isinstance(value, dict):
        raise ScenarioError(f"{source}: [{section}] must be a table")
    try:
        check_keys(f"[{section}]", value, allowed)
    except ValueError as exc:
        raise ScenarioError(f"{source}: {exc}") from None


_SETTING = "scenario setting"

DEFAULT_DESIGN = "dob_wide_1khz"
"""The controller a scenario without ``[controller]`` runs: the shipped design that serves the
drawn population best (docs/choosing.md), on the scenario's estimator."""

DEFAULT_FIRMWARE = "fast_1khz_centred"
"""The firmware preset a scenario's estimator starts from unless ``[estimator] firmware`` names
another: the default design's."""


def _key(default: Any, unit: str, kind: str, source: str = _SETTING, *, doc: str, **rule) -> Any:
    """A scenario key: a :func:`~ebraille_sim.base.fields.sourced` field whose metadata is its rule.

    ``kind`` is ``"float"``, ``"int"``, ``"str"``, ``"bool"``, ``"choice"`` (``choices=``),
    ``"steps"``, ``"table"`` (``table=`` the dataclass of the sub-table), ``"overrides"``
    (``target=`` the parameter dataclass), ``"free"`` (any table) or ``"experimental"``
    (the section's study knobs: ``table=`` their dataclass, or ``gains=True`` for the
    controllers' experimental gains).  Numbers take ``lo``, ``hi``, ``lo_open``, ``hi_open``;
    ``doc`` is the key's one-line description.
    """
    return sourced(default, unit, source, kind=kind, doc=doc, **rule)


def _table(cls) -> Any:
    """A sub-table key: its description is the first line of its dataclass's docstring after the
    ``[name]:`` title."""
    doc = cls.__doc__.split(":", 1)[1].strip().split("\n")[0]
    return field(default=None, metadata={"unit": "-", "source": _SETTING, "kind": "table", "table": cls,
                                         "doc": doc[:1].upper() + doc[1:]})


_TACTILE = "[R] seed paper: tactile forces 0.2-3 N (physics.params.TACTILE_FORCE_MAX_N)"
_EXPERIMENTAL = ("Study knobs: no stability promise (a knob may change meaning, range or name, or go, "
                 "between versions); not part of the generated malformed-scenario table.")

DELEGATES: dict[str, str] = {
    "disturbances": "ebraille_sim.scenarios.disturbances",
    "faults": "ebraille_sim.scenarios.faults",
    "supervisor": "ebraille_sim.scenarios.supervision",
    "mechanism": "ebraille_sim.scenarios.mechanism_section",
}
"""Top-level scenario sections validated and applied by their own module.

Each module provides ``validate_section(source, value) -> object`` (raising
:class:`ScenarioError` with a one-line message) and is used by the runner through
``driven_inputs(section) -> tuple`` (the plant inputs it drives) with
``build_inputs(section, t_s, rng, device, out=None) -> dict`` (per-period plant inputs;
``out`` maps those inputs to the rows of the run's profile table, which a module may write
its "set" profiles into) and/or
``wrap_controller(section, controller, dt_s, device=None) -> Controller``.  Wrappers are
applied in the order of this dict, so an injected controller fault (``faults``) always sits
inside the safety supervisor (``supervisor``)."""


@dataclass(frozen=True)
class ReadingSpec:
    """``[reading]``: the passage and the reading schedule."""
    passage: str = _key("default", "-", "str", doc="A shipped passage by name (`ebraille-sim list`).")
    text: str | None = _key(None, "-", "str", doc="The text to read, given inline (instead of passage).")
    file: str | None = _key(None, "-", "str", doc="A UTF-8 text file to read, relative to the scenario file "
                                                  "(instead of passage).")
    wpm: float = _key(90.0, "1/min", "float", lo=0, hi=1000, lo_open=True, doc="Reading rate in words per minute.")
    start_s: float = _key(1.5, "s", "float", lo=0, hi=600, doc="Time of the first character.")
    jitter_fraction: float = _key(0.0, "-", "float", lo=0, hi=0.5,
                                  doc="Random spread of each character's dwell, a fraction of the dwell.")
    word_pause_s: float = _key(0.0, "s", "float", lo=0, hi=5, doc="Extra pause after each word.")
    line_pause_s: float = _key(0.0, "s", "float", lo=0, hi=10, doc="Extra pause after each line.")
    max_characters: int | None = _key(None, "-", "int", lo=1, hi=10**6,
                                      doc="Read at most this many cells (None: the whole text).")
    # per-character refresh: each dwell is lift | press | hold | release, as fractions of
    # the dwell; the setpoint is refresh_lift_force_n while lifted or released and the
    # force setpoint from the press on; only the hold part counts as the character's window
    # (see ebraille_sim.scenarios.inputs.refresh_phases)
    mode: str = _key("continuous", "-", "choice", choices=("continuous", "refresh"),
                     doc="continuous: the finger slides over a held force; refresh: the board lifts, presses, "
                         "holds and releases for every character.")
    refresh_lift_fraction: float = _key(0.10, "-", "float", lo=0, hi=1,
                                        doc="Refresh mode: part of each dwell with the board lifted.")
    refresh_press_fraction: float = _key(0.30, "-", "float", lo=0, hi=1,
                                         doc="Refresh mode: part of each dwell for the press (not counted).")
    refresh_release_fraction: float = _key(0.15, "-", "float", lo=0, hi=1,
                                           doc="Refresh mode: part of each dwell for the release.")
    refresh_lift_force_n: float = _key(0.1, "N", "float", _TACTILE, lo=0, hi=_params.TACTILE_FORCE_MAX_N,
                                       doc="Refresh mode: setpoint while lifted or released.")

    def __post_init__(self):
        if self.mode == "refresh":
            used = self.refresh_lift_fraction + self.refresh_press_fraction + self.refresh_release_fraction
            if not used < 1.0:
                raise ScenarioError(f"[reading] refresh_lift_fraction + refresh_press_fraction + "
                                    f"refresh_release_fraction = {used:g} leaves no hold time; it must be < 1")


@dataclass(frozen=True)
class SetpointSpec:
    """``[setpoint]``: the force setpoint profile."""
    force_n: float = _key(1.0, "N", "float", _TACTILE, lo=0, hi=_params.TACTILE_FORCE_MAX_N, lo_open=True,
                          doc="Force setpoint (the first one when steps are given).")
    band_fraction: float = _key(0.10, "-", "float", lo=0, hi=1, lo_open=True,
                                doc="Half-width of the in-band window around the setpoint, a fraction of it.")
    steps: tuple[tuple[float, float], ...] = _key((), "s, N", "steps",
                                                  doc="Setpoint changes as [time_s, force_n] pairs.")
    ramp_s: float = _key(0.0, "s", "float", lo=0, hi=10, doc="Ramp time of each setpoint change (0: a step).")


@dataclass(frozen=True)
class ControllerSpec:
    """``[controller]``: a registered name (or design, or gains file) and its keyword gains."""
    name: str = _key(DEFAULT_DESIGN, "-", "str", doc="A registered controller, a shipped design, a design or gains "
                                                     "file, or policy:PATH.")
    gains: dict = field(default_factory=dict, metadata={"unit": "-", "source": _SETTING, "kind": "free",
                                                        "doc": "Keyword gains of the controller (see the gains "
                                                               "tables below)."})
    experimental: dict = field(default_factory=dict, metadata={
        "unit": "-", "source": _SETTING, "kind": "experimental", "gains": True,
        "doc": "Experimental gains of the controller (study knobs, no stability promise)."})


@dataclass(frozen=True)
class FingerSpec:
    """``[finger]``: where the reader's pulp rests."""
    gap_m: float = _key(1.0e-3, "m", "float", lo=-0.01, hi=0.01,
                        doc="Gap between the board and the resting pulp at the start (< 0: pressed in).")


@dataclass(frozen=True)
class DeviceSpec:
    """``[device]``: presets and field overrides (None: the preset's or the motor's value)."""
    motor: str = _key("faulhaber_0816_006sr", "-", "choice", choices=tuple(sorted(_params.MOTORS)),
                      doc="Motor preset.")
    drivetrain: str = _key("planetary_64", "-", "choice", choices=tuple(sorted(_params.DRIVETRAINS)),
                           doc="Drive train preset (gearhead, pinion, rack, board).")
    finger: str = _key("nominal", "-", "choice", choices=tuple(sorted(_params.FINGERS)),
                       doc="Reader (fingertip pulp) preset.")
    fsr: str = _key("nominal", "-", "choice", choices=tuple(sorted(_params.FSRS)), doc="Force sensor preset.")
    driver_supply_v: float | None = _key(None, "V", "float", lo=0, hi=48, lo_open=True,
                                         doc="H-bridge supply (None: the motor's nominal voltage).")
    hand_orientation_deg: float = _key(0.0, "deg", "float", lo=-180, hi=180,
                                       doc="Hand orientation: the board's weight acts with g cos(angle).")
    motor_overrides: dict | None = _key(None, "-", "overrides", target=_params.MotorParams,
                                        doc="Field overrides of the motor preset.")
    drivetrain_overrides: dict | None = _key(None, "-", "overrides", target=_params.DriveTrainParams,
                                             doc="Field overrides of the drive train preset.")
    finger_overrides: dict | None = _key(None, "-", "overrides", target=_params.FingerParams,
                                         doc="Field overrides of the reader preset.")
    fsr_overrides: dict | None = _key(None, "-", "overrides", target=_params.FSRParams,
                                      doc="Field overrides of the force sensor preset.")
    circuit_overrides: dict | None = _key(None, "-", "overrides", target=_params.CircuitParams,
                                          doc="Field overrides of the FSR's divider and ADC.")
    current_sense_overrides: dict | None = _key(None, "-", "overrides", target=_params.CurrentSenseParams,
                                                doc="Field overrides of the motor current chain.")
    calibrate: bool = _key(True, "-", "bool", "true: R2 trimmed for this FSR unit and estimator until a press to "
                           "1 N held 20 s reads 1 N (estimation.calibration.calibrate_device, as drawn units are), "
                           "then the bench stores the unit's calibration table at 0.5-2 N, its creep and its "
                           "loop (estimation.calibration.with_calibration_table); "
                           "false: a miscalibrated unit on purpose, with the circuit's R2",
                           doc="Calibrate the divider's R2 for this FSR unit and estimator.")


@dataclass(frozen=True)
class RatesSpec:
    """``[rates]``: control, sensor and physics rates."""
    control_hz: float = _key(1000.0, "Hz", "float", lo=0, hi=1e6, lo_open=True, doc="Controller rate.")
    sensor_hz: float = _key(1000.0, "Hz", "float", lo=0, hi=1e6, lo_open=True, doc="FSR sampling rate.")
    physics_hz: float = _key(10000.0, "Hz", "float", lo=0, hi=1e7, lo_open=True,
                             doc="Plant integration rate (a whole multiple of the control rate).")


_PARAM = "see EstimatorParams"


@dataclass(frozen=True)
class EstimatorExperimentalSpec:
    """``[estimator.experimental]``: the hysteresis compensation's turn test and centring (study knobs, no
    stability promise)."""
    hysteresis_turn_lsb: float | None = _key(None, "LSB", "float", _PARAM, lo=0, hi=1e3, experimental=True,
                                             doc="Turn test of the hysteresis compensation: reversal threshold "
                                                 "in ADC codes (0: off).")
    hysteresis_follow_lsb: float | None = _key(None, "LSB", "float", _PARAM, lo=0, hi=1e3, experimental=True,
                                               doc="With the turn test: the deadband a move on in the followed "
                                                   "direction passes.")
    hysteresis_turn_time_s: float | None = _key(None, "s", "float", _PARAM, lo=0, hi=10, lo_open=True,
                                                experimental=True,
                                                doc="Time constant of the turn test's exponential average.")
    hysteresis_centre_time_s: float | None = _key(None, "s", "float", _PARAM, lo=0, hi=10, experimental=True,
                                                  doc="Time constant over which the compensation's input, while the "
                                                      "film shows no move, relaxes to the middle of its blind "
                                                      "stretch (0: off).")


@dataclass(frozen=True)
class EstimatorSpec:
    """``[estimator]``: overrides of :class:`ebraille_sim.physics.params.EstimatorParams` (None keeps its value).

    ``firmware`` names a firmware preset (:mod:`ebraille_sim.estimation.presets`): its settings
    come first, and the section's other keys replace them."""
    firmware: str = _key(DEFAULT_FIRMWARE, "-", "choice", choices=tuple(sorted(_firmware_presets())),
                         doc="A firmware preset (`ebraille-sim list`): its settings come first.")
    model: str | None = _key(None, "-", "str", _PARAM,
                             doc="Estimator model: paper:NAME[@RATE] or a model file relative to the scenario.")
    antialias_cutoff_hz: float | None = _key(None, "Hz", "float", _PARAM, lo=0, hi=1e5, lo_open=True,
                                             doc="Cutoff of the anti-alias filter before the estimator.")
    tare_at_start: bool | None = _key(None, "-", "bool", _PARAM, doc="Zero the estimate at the start of the run.")
    clamp_nonnegative: bool | None = _key(None, "-", "bool", _PARAM, doc="Clamp the estimate at 0 N.")
    nyquist_average: bool | None = _key(None, "-", "bool", _PARAM,
                                        doc="Average the samples of each estimator period.")
    creep_compensation: bool | None = _key(None, "-", "bool", _PARAM,
                                           doc="Divide the nominal FSR's predicted creep out of the estimate.")
    creep_reference_hold_s: float | None = _key(None, "s", "float", _PARAM, lo=0, hi=1e5, lo_open=True,
                                                doc="Hold of the calibration the creep compensation refers to.")
    hysteresis_compensation: bool | None = _key(None, "-", "bool", _PARAM,
                                                doc="Invert the nominal FSR's hysteresis.")
    hysteresis_fraction: float | None = _key(None, "-", "float", _PARAM, lo=0, hi=1, hi_open=True,
                                             doc="Loop width the hysteresis compensation inverts.")
    hysteresis_deadband_lsb: float | None = _key(None, "LSB", "float", _PARAM, lo=0, hi=1e3,
                                                 doc="Deadband of the hysteresis compensation, in ADC codes.")
    experimental: dict | None = _key(None, "-", "experimental", table=EstimatorExperimentalSpec,
                                     doc="Experimental estimator settings (study knobs, no stability promise).")


@dataclass(frozen=True)
class CriteriaSpec:
    """``[criteria]``: pass/fail limits checked by the regression suite (None: not checked)."""
    onset_overshoot_max: float | None = _key(None, "-", "float", lo=0, hi=10,
                                             doc="Largest onset overshoot, a fraction of the setpoint.")
    in_band_min: float | None = _key(None, "-", "float", lo=0, hi=1, doc="Smallest share of time in band.")
    peak_force_max_n: float | None = _key(None, "N", "float", lo=0, hi=100, doc="Largest true peak force.")


@dataclass(frozen=True)
class ScenarioFile:
    """The top level of a scenario file (the sections of :data:`DELEGATES` come on top)."""
    name: str | None = _key(None, "-", "str", doc="The scenario's name (letters, digits, '_', '-').")
    description: str = _key("", "-", "str", doc="One line on what the scenario tests.")
    seed: int = _key(0, "-", "int", lo=0, hi=2**52, doc="Seed of every random draw of the run.")
    duration_s: float | None = _key(None, "s", "float", lo=0, hi=3600, lo_open=True,
                                    doc="Length of the run (None: until the passage is read).")
    reading: ReadingSpec | None = _table(ReadingSpec)
    setpoint: SetpointSpec | None = _table(SetpointSpec)
    device: DeviceSpec | None = _table(DeviceSpec)
    rates: RatesSpec | None = _table(RatesSpec)
    estimator: EstimatorSpec | None = _table(EstimatorSpec)
    finger: FingerSpec | None = _table(FingerSpec)
    controller: ControllerSpec | None = _table(ControllerSpec)
    criteria: CriteriaSpec | None = _table(CriteriaSpec)


def _rule(f: dataclasses.Field) -> Any:
    """The validation rule of one key, from its field metadata."""
    m = f.metadata
    kind = m["kind"]
    if kind in ("float", "int"):
        return {"type": kind, "lo": m.get("lo"), "hi": m.get("hi"), "lo_open": m.get("lo_open", False),
                "hi_open": m.get("hi_open", False)}
    if kind == "choice":
        return {"type": "choice", "choices": list(m["choices"])}
    if kind in ("str", "bool", "steps"):
        return {"type": kind}
    if kind == "experimental":
        return "gains" if m.get("gains") else "table"
    return kind                                            # table, overrides, free


def _derive_schema() -> dict[str, dict[str, Any]]:
    top = {f.name: _rule(f) for f in dataclasses.fields(ScenarioFile)}
    top.update({k: "delegate" for k in DELEGATES})
    schema = {"": top}
    for f in dataclasses.fields(ScenarioFile):
        if f.metadata["kind"] == "table":
            schema[f.name] = {g.name: _rule(g) for g in dataclasses.fields(f.metadata["table"])}
            for g in dataclasses.fields(f.metadata["table"]):
                if g.metadata["kind"] == "experimental" and "table" in g.metadata:
                    schema[f"{f.name}.{g.name}"] = {h.name: _rule(h) for h in dataclasses.fields(g.metadata["table"])}
    return schema


SCHEMA: dict[str, dict[str, Any]] = _derive_schema()
"""Every table's keys and their rules, derived from the field metadata of :class:`ScenarioFile`
and its table dataclasses (:class:`ReadingSpec`, :class:`SetpointSpec`, :class:`DeviceSpec`, ...)."""

_OVERRIDE_TARGET = {f.name: f.metadata["target"] for f in dataclasses.fields(DeviceSpec)
                    if f.metadata["kind"] == "overrides"}


@dataclass(frozen=True)
class ScenarioSpec:
    """A validated scenario.  ``device`` is the fully resolved :class:`DeviceParams`;
    ``calibrated`` is the file's ``[device] calibrate`` (units drawn around ``device`` are
    calibrated, or not, as it is)."""
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
    calibrated: bool = True


def _check_value(src, table, key, value, rule):
    where = f"[{table}] {key}" if table else key
    t = rule["type"]
    try:
        if t == "str":
            if not isinstance(value, str):
                raise ValueError(f"{where} must be a string, got {value!r}")
            return value
        if t == "bool":
            return check_bool(where, value)
        if t == "choice":
            return check_choice(where, value, rule["choices"])
        if t == "steps":
            if not isinstance(value, list) or not all(isinstance(r, list) and len(r) == 2 for r in value):
                raise ValueError(f"{where} must be a list of [time_s, force_n] pairs")
            out = tuple((check_number(where + " time", t_s, 0, 3600),
                         check_number(where + " force", f_n, 0, _params.TACTILE_FORCE_MAX_N, lo_open=True))
                        for t_s, f_n in value)
            if any(b[0] <= a[0] for a, b in zip(out, out[1:])):
                raise ValueError(f"{where} times must increase")
            return out
        return check_number(where, value, rule["lo"], rule["hi"], rule["lo_open"], rule["hi_open"],
                            integer=(t == "int"))
    except ValueError as exc:
        raise ScenarioError(f"{src}: {exc}") from None


def _check_table(src, name, data):
    allowed = SCHEMA[name]
    if not isinstance(data, dict):
        raise ScenarioError(f"{src}: [{name}] must be a table")
    try:
        check_keys(f"[{name}]" if name else "the top level", data, sorted(allowed))
    except ValueError as exc:
        raise ScenarioError(f"{src}: {exc}") from None
    out = {}
    for key, value in data.items():
        rule = allowed[key]
        if rule == "table":
            out[key] = _check_table(src, f"{name}.{key}" if name else key, value)
        elif rule == "gains":
            out[key] = _check_experimental_gains(src, f"{name}.{key}", value)
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


@functools.lru_cache(maxsize=1)
def experimental_gains() -> dict[str, dataclasses.Field]:
    """The controllers' experimental gains by name: the fields of every registered controller's
    config declared with ``experimental=True`` (:func:`~ebraille_sim.base.fields.sourced`).

    A scenario gives them in ``[controller.experimental]``, not in ``[controller] gains``.
    """
    import controllers
    out: dict[str, dataclasses.Field] = {}
    for name in controllers.available():
        for f in dataclasses.fields(type(controllers.make(name).config)):
            if f.metadata.get("experimental"):
                out.setdefault(f.name, f)
    return out


def _check_experimental_gains(src, where, data):
    if not isinstance(data, dict):
        raise ScenarioError(f"{src}: [{where}] must be a table")
    try:
        check_keys(f"[{where}]", data, sorted(experimental_gains()))
        for key, value in data.items():
            if value is not None:
                check_number(f"[{where}] {key}", value)
    except ValueError as exc:
        raise ScenarioError(f"{src}: {exc}") from None
    return dict(data)


def _check_overrides(src, where, data, cls):
    if not isinstance(data, dict):
        raise ScenarioError(f"{src}: [{where}] must be a table")
    names = sorted(f.name for f in dataclasses.fields(cls) if f.name not in ("name", "sources"))
    try:
        check_keys(f"[{where}]", data, names)
        for key, value in data.items():
            check_number(f"[{where}] {key}", value)
    except ValueError as exc:
        raise ScenarioError(f"{src}: {exc}") from None
    return dict(data)


def _build_device(src, dev: dict, rates: dict, est: dict, base_dir: str = ".") -> _params.DeviceParams:
    try:
        d0, r0 = DeviceSpec(), RatesSpec()
        motor = _params.MOTORS[dev.get("motor", d0.motor)]
        drivetrain = _params.DRIVETRAINS[dev.get("drivetrain", d0.drivetrain)]
        finger = _params.FINGERS[dev.get("finger", d0.finger)]
        fsr = _params.FSRS[dev.get("fsr", d0.fsr)]
        circuit = _params.CircuitParams()
        motor = _params.replace_checked(motor, **dev.get("motor_overrides", {}))
        drivetrain = _params.replace_checked(drivetrain, **dev.get("drivetrain_overrides", {}))
        finger = _params.replace_checked(finger, **dev.get("finger_overrides", {}))
        fsr = _params.replace_checked(fsr, **dev.get("fsr_overrides", {}))
        circuit = _params.replace_checked(circuit, **dev.get("circuit_overrides", {}))
        current_sense = _params.replace_checked(_params.CurrentSenseParams(), **dev.get("current_sense_overrides", {}))
        r = _params.RateParams(
            control_rate_hz=rates.get("control_hz", r0.control_hz),
            sensor_rate_hz=rates.get("sensor_hz", r0.sensor_hz),
            physics_rate_hz=rates.get("physics_hz", r0.physics_hz))
        if "experimental" in est:               # the study knobs are EstimatorParams fields like the rest
            est = {**{k: v for k, v in est.items() if k != "experimental"}, **est["experimental"]}
        est = {**_firmware_presets()[est.get("firmware", EstimatorSpec().firmware)].estimator,
               **{k: v for k, v in est.items() if k != "firmware"}}
        e = _params.replace_checked(_params.EstimatorParams(), **est)    # the section's keys are its fields
        if "model" in est and not est["model"].startswith("paper:"):
            mp = pathlib.Path(est["model"])
            if not mp.is_absolute():
                mp = pathlib.Path(base_dir) / mp
            if not mp.exists():
                raise ScenarioError(f"{src}: [estimator] model file {str(mp)!r} not found")
            e = _params.replace_checked(e, model=str(mp))
        angle = math.radians(dev.get("hand_orientation_deg", d0.hand_orientation_deg))
        g = _params.STANDARD_GRAVITY_M_PER_S2 * math.cos(angle)
        device = _params.DeviceParams(motor=motor, drivetrain=drivetrain, finger=finger, fsr=fsr,
                                      circuit=circuit, current_sense=current_sense, estimator=e, rates=r,
                                      driver_supply_v=dev.get("driver_supply_v", motor.nominal_voltage_v),
                                      gravity_m_per_s2=g)
        _check_rates(device)
        return _calibrated(src, device, dev, {k: est[k] for k in _params.UNIT_ESTIMATOR_FIELDS if k in est})
    except ScenarioError:
        raise
    except (ValueError, TypeError, KeyError, OSError) as exc:
        msg = str(exc).strip("'\"") if isinstance(exc, KeyError) else str(exc)
        raise ScenarioError(f"{src}: {msg}") from None


def _calibrated(src, device: _params.DeviceParams, dev: dict, given: dict) -> _params.DeviceParams:
    """``device`` with the divider calibrated for its FSR unit and estimator as every drawn unit's
    is (:func:`ebraille_sim.estimation.calibration.calibrate_device`: one press to the 1 N load held
    20 s, R2 turned until the estimate reads 1 N) and the unit's calibration table, creep and loop
    stored as the bench measures them (:func:`ebraille_sim.estimation.calibration.with_calibration_table`,
    the fixture's loads exact; the table keeps the divider's level at 1 N), unless ``[device]
    calibrate = false``.  A given ``[device.circuit_overrides] r2_ohm`` needs ``calibrate =
    false`` (the calibration would replace it).  A unit that no R2 in 500-50 000 ohm makes read
    1 N gets the bench's best fit over its loads and holds
    (:func:`ebraille_sim.estimation.calibration.bench_calibrate_device`) with a
    :class:`ScenarioWarning`.  A bench field the scenario's ``[estimator]`` gives (``given``, e.g.
    ``hysteresis_fraction``) stays as given."""
    if not dev.get("calibrate", DeviceSpec().calibrate):
        return device
    if "r2_ohm" in dev.get("circuit_overrides", {}):
        raise ScenarioError(f"{src}: [device.circuit_overrides] r2_ohm is set by the bench calibration; "
                            f"set [device] calibrate = false to run a unit with a given R2")
    from ebraille_sim.estimation.calibration import BENCH_R2_RANGE_OHM, bench_calibrate_device, calibrate_device
    out = calibrate_device(device)
    if out is device:                                 # no R2 of the range reads 1 N on this unit
        out, inside = bench_calibrate_device(device)
        lo, hi = BENCH_R2_RANGE_OHM
        where = "the end of the range" if not inside else "the bench's best fit"
        warnings.warn(f"{src}: no R2 in {lo:g}-{hi:g} ohm makes this FSR unit read 1 N on its estimator; the divider "
                      f"gets R2 = {out.circuit.r2_ohm:.4g} ohm, {where}, and the unit reads off",
                      ScenarioWarning, stacklevel=4)
    out = _bench_tabled(out)
    return dataclasses.replace(out, estimator=_params.replace_checked(out.estimator, **given)) if given else out


@functools.lru_cache(maxsize=64)
def _bench_tabled(device: _params.DeviceParams) -> _params.DeviceParams:
    """:func:`ebraille_sim.estimation.calibration.with_calibration_table` of a scenario unit, once
    per unit and process: the bench is a pure function of the unit (0.9 ms a scenario load)."""
    from ebraille_sim.estimation.calibration import with_calibration_table
    return with_calibration_table(device)


def _check_rates(device: _params.DeviceParams) -> None:
    """The rates of a scenario device against its estimator and its mechanics (``ValueError``).

    * the sensor rate is a whole multiple of the estimator model's rate and the anti-alias
      cutoff lies below the sensor's Nyquist frequency
      (:func:`ebraille_sim.plant.lumped.check_sensor_rates`);
    * the control rate is at least the estimator's rate: the controller acts on force
      estimates, and a loop slower than them discards estimates while the drive moves
      within a few mechanical time constants of the motor (6.5 ms for the Faulhaber 0816);
    * the physics rate resolves the stiff mesh/pulp contact
      (:func:`ebraille_sim.plant.lumped.check_step`).

    The plant repeats the first and last check when it is built; here they reject a file
    before anything runs.
    """
    from ebraille_sim.estimation.registry import cached_model
    from ebraille_sim.plant.lumped import check_sensor_rates, check_step
    model = cached_model(device.estimator.model)   # read only: its rate
    check_sensor_rates(device, model)
    est_hz = 1.0 / model.dt_s
    r = device.rates
    if r.control_rate_hz < est_hz * (1 - 1e-9):
        tau_ms = 1e3 * device.motor.mechanical_time_constant_s
        raise ValueError(f"[rates] control_hz = {r.control_rate_hz:g} is below the {est_hz:g} Hz rate of the "
                         f"force estimate it acts on: a force loop must update at least once per estimate "
                         f"(one period of {1e3 / r.control_rate_hz:g} ms is "
                         f"{1.0 / r.control_rate_hz / device.motor.mechanical_time_constant_s:.3g} mechanical "
                         f"time constants of the motor, {tau_ms:.3g} ms, during which the drive runs unchecked)")
    check_step(device)


def with_firmware(spec: "ScenarioSpec", firmware) -> "ScenarioSpec":
    """``spec`` running on a firmware preset (a name or a preset file): the preset's estimator
    settings replace the scenario's (the rest at :class:`~ebraille_sim.physics.params.EstimatorParams`'
    defaults), and the unit keeps what its bench measured
    (:data:`~ebraille_sim.physics.params.UNIT_ESTIMATOR_FIELDS`); a preset whose rates do not
    suit the scenario's device is a one-line :class:`ScenarioError`."""
    from ebraille_sim.estimation.presets import get_firmware
    fw = get_firmware(firmware)
    return with_estimator(spec, fw.estimator, f"firmware {fw.name!r}")


def with_estimator(spec: "ScenarioSpec", settings: dict, label: str) -> "ScenarioSpec":
    """``spec`` with the estimator ``settings`` (:class:`~ebraille_sim.physics.params.EstimatorParams`
    fields; the others at their defaults) and the unit's bench fields
    (:data:`~ebraille_sim.physics.params.UNIT_ESTIMATOR_FIELDS`); settings that do not suit the
    scenario's device are a one-line :class:`ScenarioError` that starts with ``label``."""
    unit = {k: getattr(spec.device.estimator, k) for k in _params.UNIT_ESTIMATOR_FIELDS}
    try:
        device = dataclasses.replace(spec.device, estimator=_params.replace_checked(_params.EstimatorParams(),
                                                                                   **{**settings, **unit}))
        _check_rates(device)
    except (ValueError, TypeError) as exc:
        raise ScenarioError(f"{spec.source}: {label}: {exc}") from None
    return dataclasses.replace(spec, device=device)


def _check_gap(source: str, finger: FingerSpec, device: _params.DeviceParams) -> None:
    """A negative ``[finger] gap_m`` (the board starts pressed into the pulp) may overlap the
    pulp at most by the compression at which the device's finger pushes back with the top of
    the tactile range (:data:`~ebraille_sim.physics.params.TACTILE_FORCE_MAX_N`): a start
    beyond it is a press no reading begins with (at -10 mm the pulp would push tens of kN)."""
    if finger.gap_m >= 0:
        return
    limit = device.finger.compression_at_m(_params.TACTILE_FORCE_MAX_N)
    if -finger.gap_m > limit * (1 + 1e-12):
        raise ScenarioError(f"{source}: [finger] gap_m = {finger.gap_m:g} starts the board {-1e3 * finger.gap_m:g} mm "
                            f"into the pulp; the {device.finger.name} finger pushes "
                            f"{_params.TACTILE_FORCE_MAX_N:g} N (the top of the tactile range) at "
                            f"{1e3 * limit:.3g} mm, so gap_m must be >= {-limit:.4g} m")


def _warn_setpoints(source: str, sp: SetpointSpec) -> None:
    """Warn (:class:`ScenarioWarning`) about force setpoints below the tactile range."""
    lo = _params.TACTILE_FORCE_MIN_N
    low = [("force_n", sp.force_n)] if sp.force_n < lo else []
    low += [(f"steps at {t_s:g} s", f_n) for t_s, f_n in sp.steps if f_n < lo]
    if low:
        what = ", ".join(f"{k} = {v:g} N" for k, v in low)
        warnings.warn(f"{source}: [setpoint] {what} {'is' if len(low) == 1 else 'are'} below the {lo:g} N "
                      f"lower end of the tactile range "
                      f"([R] seed paper: tactile forces 0.2-3 N): the reader may not feel the display",
                      ScenarioWarning, stacklevel=3)


_NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")


def check_scenario_name(source: str, name) -> str:
    """A scenario name is also the default output folder (``runs/NAME``): letters, digits,
    ``_``, ``-`` and ``.``, starting with a letter or digit, at most 100 characters, and no
    ``..``; so a name can never point outside the run folder."""
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name) or ".." in name:
        from ebraille_sim.base.files import short
        shown = short(name) if isinstance(name, str) else short(repr(name))
        raise ScenarioError(f"{source}: name {shown} must be 1-100 letters, digits, '_', '-' or '.', start with "
                            f"a letter or digit and contain no '..' (it names the output folder runs/NAME)")
    return name


def parse_scenario(data: dict, source: str = "<scenario>", base_dir: str = ".") -> ScenarioSpec:
    """Validate a scenario given as a dict (the parsed TOML)."""
    top = _check_table(source, "", data)
    if "name" not in top:
        raise ScenarioError(f"{source}: missing required key 'name'")
    check_scenario_name(source, top["name"])
    rd = top.get("reading", {})
    if sum(k in rd for k in ("passage", "text", "file")) > 1:
        raise ScenarioError(f"{source}: [reading] takes only one of passage, text, file")
    try:
        reading = ReadingSpec(**rd)
    except ScenarioError as exc:
        raise ScenarioError(f"{source}: {exc}") from None
    if reading.file is not None:                 # refused now, not when the run reads it
        from ebraille_sim.base.files import check_regular
        rp = pathlib.Path(reading.file)
        try:
            check_regular(rp if rp.is_absolute() else pathlib.Path(base_dir) / rp, "[reading] file",
                          MAX_READING_BYTES)
        except (ValueError, FileNotFoundError) as exc:
            raise ScenarioError(f"{source}: {exc}") from None
    sp = SetpointSpec(**top.get("setpoint", {}))
    dev = _build_device(source, top.get("device", {}), top.get("rates", {}), top.get("estimator", {}), base_dir)
    _warn_setpoints(source, sp)
    finger = FingerSpec(**top.get("finger", {}))
    _check_gap(source, finger, dev)
    ctl = top.get("controller", {})
    gains, trial = ctl.get("gains", {}), ctl.get("experimental", {})
    if gains:
        late = sorted(set(gains) & set(experimental_gains()))
        if late:
            raise ScenarioError(f"{source}: [controller] gains {late[0]} is experimental: give it in "
                                f"[controller.experimental]")
    return ScenarioSpec(
        name=top["name"], description=top.get("description", ""), seed=top.get("seed", 0),
        duration_s=top.get("duration_s"), reading=reading, setpoint=sp, device=dev,
        finger=finger,
        controller=ControllerSpec(name=ctl.get("name", ControllerSpec().name), gains={**gains, **trial},
                                  experimental=dict(trial)),
        criteria=top.get("criteria", {}), sections={k: top[k] for k in DELEGATES if k in top},
        source=source, base_dir=base_dir, calibrated=top.get("device", {}).get("calibrate", DeviceSpec().calibrate))


def load_scenario(path) -> ScenarioSpec:
    """Load and validate a scenario file.

    ``path`` may also be the bare name of a scenario shipped in ``scenarios/``.
    """
    p = resolve_scenario_path(path)
    return parse_scenario(parse_toml(read_scenario_bytes(p), p.name), source=p.name, base_dir=str(p.parent))


MAX_READING_BYTES = 16 * 2 ** 20
"""Largest ``[reading] file`` read (16 MiB of text, days of reading at 200 wpm)."""

MAX_SCENARIO_BYTES = 4 * 2 ** 20
"""Largest scenario file read (4 MiB; the shipped ones hold a few KiB)."""


def read_scenario_bytes(p) -> bytes:
    """The bytes of scenario file ``p`` (a regular file of at most :data:`MAX_SCENARIO_BYTES`),
    or one :class:`ScenarioError` line."""
    from ebraille_sim.base.files import read_bytes
    try:
        return read_bytes(p, "scenario file", MAX_SCENARIO_BYTES)
    except (ValueError, FileNotFoundError) as exc:
        raise ScenarioError(str(exc)) from None


def parse_toml(raw: bytes, name: str) -> dict:
    """Decode and parse the bytes of a scenario file; raise :class:`ScenarioError` (one line).

    The file must be UTF-8.  Line ends may be LF, CRLF or a lone CR: TOML itself allows only
    LF and CRLF, but a lone CR (old Mac line ends) cannot be part of any valid TOML value, so
    it is read as a line break (as Python's text mode does) instead of failing with a
    misleading position.  Tables or arrays nested beyond the parser's recursion limit (about
    a thousand levels; the schema nests three) are rejected with one line.
    """
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{name}: not valid UTF-8 (byte 0x{raw[exc.start]:02x} at offset {exc.start}); "
                            f"TOML files must be UTF-8 encoded") from None
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{name}: malformed TOML: {exc}") from None
    except RecursionError:
        raise ScenarioError(f"{name}: tables or arrays nested too deeply to parse (a scenario nests "
                            f"at most 3 levels)") from None


@functools.lru_cache(maxsize=1)
def library_dir() -> pathlib.Path | None:
    """The folder of the shipped scenario library, or None when it cannot be found.

    In an installed wheel it is the package data ``ebraille_sim/library`` (built from the
    project's ``scenarios/`` folder), found with :mod:`importlib.resources`; in a source
    checkout (also an editable install) it is that top-level ``scenarios/`` folder itself.
    Where the package is installed does not change while it runs: the folder is looked for
    once per process.
    """
    import importlib.resources
    shipped = importlib.resources.files("ebraille_sim") / "library"
    if isinstance(shipped, pathlib.Path) and shipped.is_dir():
        return shipped
    root = pathlib.Path(__file__).resolve().parents[2]
    try:
        is_checkout = 'name = "ebraille-sim"' in (root / "pyproject.toml").read_text(encoding="utf-8")
    except OSError:
        is_checkout = False
    if is_checkout and (root / "scenarios").is_dir():
        return root / "scenarios"
    return None


def scenario_dirs() -> list[pathlib.Path]:
    """Folders searched for scenario names, first match wins.

    ``./scenarios`` in the working folder (your own scenarios) comes first, then the
    shipped library (:func:`library_dir`).  A name not found in ``./scenarios`` still
    resolves to the shipped scenario of that name.
    """
    out = []
    for d in (pathlib.Path.cwd() / "scenarios", library_dir()):
        if d is not None and d.is_dir() and not (out and d.resolve() in [o.resolve() for o in out]):
            out.append(d)
    return out


def resolve_scenario_path(path) -> pathlib.Path:
    """The file of a scenario given as a path or as a bare name.

    The path of an existing file is returned as it is.  A bare name (no folder, no suffix) is looked
    up as ``NAME.toml`` in :func:`scenario_dirs`, first match wins.

    Raises
    ------
    ScenarioError
        ``"scenario file 'PATH' not found"`` for a path, or ``"scenario 'NAME' not found
        (looked in DIRS); available: ..."`` for a name.
    """
    p = pathlib.Path(path)
    try:
        if p.is_file():
            return p
    except OSError:                       # a name too long for the file system: not found
        pass
    if not (p.suffix == "" and len(p.parts) == 1):
        if os.path.lexists(p) and not p.is_dir():      # a FIFO, a device: the reader says what it is
            return p
        raise ScenarioError(f"scenario file {_short(path)} " + ("is not a file" if p.exists() else "not found"))
    dirs = scenario_dirs()
    for d in dirs:
        cand = d / f"{p.name}.toml"
        if os.path.lexists(cand):         # not a regular file: the reader says what it is
            return cand
    names = ", ".join(list_scenarios()) or "none"
    lib = library_dir()
    where = ", ".join("./scenarios" if d == pathlib.Path.cwd() / "scenarios" else
                      "the shipped library" if lib is not None and d.resolve() == lib.resolve() else
                      _short(d) for d in dirs) or "no scenario folder found"
    if len(names) > 160:
        names = names[:names.rfind(", ", 0, 150)] + ", ... ('ebraille-sim list' shows them all)"
    raise ScenarioError(f"scenario {_short(path)} not found (looked in {where}); available: {names}")


def _short(text) -> str:
    from ebraille_sim.base.files import short
    return short(text, 80)


def list_scenarios() -> list[str]:
    """Names of the scenario files found in :func:`scenario_dirs` (yours first, then the library's)."""
    names = []
    for d in scenario_dirs():
        for f in sorted(d.glob("*.toml")):
            if f.stem not in names:
                names.append(f.stem)
    return names
