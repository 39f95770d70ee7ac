"""Every entry point that takes keyword configuration rejects an unknown key.

The entry points are discovered where the code lists them (the controller registry, the
parameter dataclasses of ``physics.params``, the config dataclasses of the controller
modules, the scenario schema and its delegate sections, the disturbance kinds), so a new
controller, parameter set, table or disturbance is covered without editing this file.
Each must raise ``ValueError`` (or ``KeyError``) with a one-line message that names the key.
"""
import dataclasses
import importlib
import inspect
import pkgutil

import pytest

import controllers
from ebraille_sim.physics import params
from ebraille_sim.scenarios import disturbances, spec
from ebraille_sim.scenarios.runner import make_controller, run_scenario

KEY = "bogus_key"


def _rejects(call, key=KEY):
    with pytest.raises((ValueError, KeyError)) as info:
        call()
    msg = str(info.value.args[0]) if isinstance(info.value, KeyError) else str(info.value)
    assert "\n" not in msg, msg
    assert repr(key) in msg, msg
    return msg


# --- controllers -----------------------------------------------------------------------

@pytest.mark.parametrize("name", controllers.available())
def test_make_rejects_an_unknown_gain(name):
    _rejects(lambda: controllers.make(name, **{KEY: 1.0}))


@pytest.mark.parametrize("name", controllers.available())
def test_a_gains_file_rejects_an_unknown_gain_and_an_unknown_key(tmp_path, name):
    p = tmp_path / "gains.toml"
    p.write_text(f'controller = "{name}"\n[gains]\n{KEY} = 1.0\n')
    _rejects(lambda: controllers.make(p))
    p.write_text(f'controller = "{name}"\n{KEY} = 1\n')
    _rejects(lambda: controllers.make(p))


def _controller_config_classes():
    """Dataclasses with a ``from_dict`` in every module of the ``controllers`` package (and its
    sub-packages)."""
    found = {}
    for info in pkgutil.walk_packages(controllers.__path__, "controllers."):
        try:
            mod = importlib.import_module(info.name)
        except ImportError:                       # optional extras (e.g. the policy's)
            continue
        for obj in vars(mod).values():
            if (inspect.isclass(obj) and dataclasses.is_dataclass(obj) and hasattr(obj, "from_dict")
                    and obj.__module__ == mod.__name__):
                found[obj.__name__] = obj
    return [found[k] for k in sorted(found)]


CONFIG_CLASSES = _controller_config_classes()


def test_the_controller_configs_are_found():
    names = {c.__name__ for c in CONFIG_CLASSES}
    assert {"PIDConfig", "ScheduleConfig", "LQGConfig", "SupervisorConfig"} <= names


@pytest.mark.parametrize("cls", CONFIG_CLASSES, ids=lambda c: c.__name__)
def test_controller_config_from_dict_rejects_an_unknown_key(cls):
    msg = _rejects(lambda: cls.from_dict({KEY: 1.0}))
    first = dataclasses.fields(cls)[0].name
    assert first in msg                                    # the allowed keys are listed


def test_supervisor_for_device_and_pid_state_reject_an_unknown_key():
    from controllers.pid import PID, DEFAULT_PID
    from controllers.supervisor import SupervisorConfig
    _rejects(lambda: SupervisorConfig.for_device(params.DeviceParams(), **{KEY: 1.0}))
    pid = PID(DEFAULT_PID)
    _rejects(lambda: pid.set_state({**pid.state(), KEY: 0.0}))


# --- physical parameters and populations -----------------------------------------------

PARAM_CLASSES = [obj for _, obj in sorted(vars(params).items())
                 if inspect.isclass(obj) and dataclasses.is_dataclass(obj) and obj.__module__ == params.__name__]


def test_the_parameter_classes_are_found():
    assert {"MotorParams", "FingerParams", "FSRParams", "DeviceParams"} <= {c.__name__ for c in PARAM_CLASSES}


@pytest.mark.parametrize("cls", PARAM_CLASSES, ids=lambda c: c.__name__)
def test_replace_checked_rejects_an_unknown_key(cls):
    msg = _rejects(lambda: params.replace_checked(cls(), **{KEY: 1.0}))
    assert cls.__name__ in msg


def test_population_spec_rejects_an_unknown_key():
    from ebraille_sim.scenarios.population import PopulationSpec
    _rejects(lambda: PopulationSpec.from_dict({KEY: (0.0, 1.0)}))


# --- scenarios ---------------------------------------------------------------------------

@pytest.mark.parametrize("kind", sorted(disturbances.KINDS))
def test_every_disturbance_kind_rejects_an_unknown_key(kind):
    msg = _rejects(lambda: disturbances.validate_section("x.toml", {kind: {KEY: 1.0}}))
    assert f"[disturbances.{kind}]" in msg


def _scenario_with_unknown_key():
    """One scenario dict per table of the schema, per parameter override table and per
    delegate section, each with ``KEY`` in that place."""
    cases = {"top level": {"name": "x", KEY: 1}}
    for table in spec.SCHEMA:
        if table:
            doc = {KEY: 1}
            for part in reversed(table.split(".")):         # [estimator.experimental] nests in [estimator]
                doc = {part: doc}
            cases[f"[{table}]"] = {"name": "x", **doc}
    cases["[controller.experimental]"] = {"name": "x", "controller": {"experimental": {KEY: 1.0}}}
    for key, rule in spec.SCHEMA["device"].items():
        if rule == "overrides":
            cases[f"[device.{key}]"] = {"name": "x", "device": {key: {KEY: 1.0}}}
    delegate = {"disturbances": {KEY: {}}, "faults": [{"kind": "fsr_open", "start_s": 1.0, KEY: 1.0}],
                "supervisor": {KEY: 1.0}, "mechanism": {KEY: 1.0}}
    for section in spec.DELEGATES:
        cases[f"[{section}]"] = {"name": "x", section: delegate[section]}
    return cases


SCENARIO_CASES = _scenario_with_unknown_key()


def test_every_delegate_section_has_a_case():
    assert all(f"[{d}]" in SCENARIO_CASES for d in spec.DELEGATES)


@pytest.mark.parametrize("where", sorted(SCENARIO_CASES))
def test_scenario_parse_rejects_an_unknown_key(where):
    msg = _rejects(lambda: spec.parse_scenario(SCENARIO_CASES[where], source="x.toml"))
    assert msg.startswith("x.toml: ")


@pytest.mark.parametrize("name", controllers.available())
def test_run_scenario_rejects_an_unknown_controller_gain(name):
    sc = spec.parse_scenario({"name": "x", "controller": {"name": name, "gains": {KEY: 1.0}}}, source="x.toml")
    msg = _rejects(lambda: make_controller(sc))
    assert msg.startswith("x.toml: [controller]")
    _rejects(lambda: run_scenario(sc, duration_s=0.1))


def test_run_scenario_rejects_an_unknown_key_in_a_controller_file(tmp_path):
    p = tmp_path / "gains.json"
    p.write_text(f'{{"controller": "pid", "gains": {{"{KEY}": 1.0}}}}')
    sc = spec.parse_scenario({"name": "x"}, source="x.toml")
    _rejects(lambda: run_scenario(sc, controller=str(p), duration_s=0.1))


# --- reinforcement-learning environment --------------------------------------------------

def test_env_reset_options_reject_an_unknown_key():
    env = pytest.importorskip("ebraille_sim.rl.env")
    _rejects(lambda: env.validate_options({KEY: 1.0}, 3.0))


# --- physical bounds of the parameter dataclasses ----------------------------------------

@pytest.mark.parametrize("cls, changes, fragment", [
    (params.DriveTrainParams, {"gear_efficiency": 60}, "gear_efficiency = 60 must be in (0, 1]: it is a fraction"),
    (params.DriveTrainParams, {"gear_efficiency": 1.0001}, "gear_efficiency = 1.0001 must be in (0, 1]"),
    (params.DriveTrainParams, {"travel_min_m": 6e-3, "travel_max_m": 0.0}, "travel_max_m (0 m) must be above"),
    (params.DriveTrainParams, {"travel_min_m": 3e-3, "travel_max_m": 3e-3}, "needs a travel range"),
    (params.CircuitParams, {"adc_bits": 2000}, "adc_bits must be an int in [1, 24], got 2000"),
    (params.CircuitParams, {"adc_bits": 10.5}, "adc_bits must be a whole number, got 10.5"),
    (params.CircuitParams, {"adc_bits": 0.5}, "adc_bits must be a whole number, got 0.5"),
    (params.CircuitParams, {"adc_bits": 0}, "adc_bits must be > 0, got 0"),
    (params.FSRParams, {"hysteresis_fraction": 1.0}, "hysteresis_fraction = 1 must be below 1"),
])
def test_parameter_dataclasses_reject_unphysical_values(cls, changes, fragment):
    with pytest.raises(ValueError) as info:
        cls(**changes)
    msg = str(info.value)
    assert fragment in msg and "\n" not in msg, msg


def test_adc_bits_given_as_a_whole_float_is_stored_as_an_int():
    c = params.CircuitParams(adc_bits=12.0)
    assert c.adc_bits == 12 and isinstance(c.adc_bits, int) and c.adc_max_code == 4095.0
    assert params.DriveTrainParams(gear_efficiency=1.0).gear_loss_coefficient == 0.0
