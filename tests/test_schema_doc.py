"""The generated scenario reference and JSON Schema: current, complete and in agreement with the loader.

``docs/scenario-reference.md`` and ``scenarios/scenario.schema.json`` are written by
``python -m ebraille_sim.tools.schema``; these tests fail when either is stale, when a
shipped scenario does not validate against the schema, and when the schema accepts a key
or value the loader rejects at a range boundary.  The JSON Schema is checked with the
small validator below, which implements exactly the keywords the generator emits (a test
makes sure no other keyword appears).
"""
from __future__ import annotations

import copy
import json
import math
import pathlib
import warnings

import pytest

from ebraille_sim.scenarios.spec import ScenarioError, parse_scenario, parse_toml
from ebraille_sim.tools import schema as gen

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENARIOS = sorted((ROOT / "scenarios").glob("*.toml"))

# --------------------------------------------------------------------------------------
# a validator for the subset of draft 2020-12 the generator emits
# --------------------------------------------------------------------------------------

ANNOTATIONS = {"$schema", "$id", "title", "description", "default"}
ASSERTIONS = {"type", "properties", "additionalProperties", "required", "enum", "const", "minimum", "maximum",
              "exclusiveMinimum", "exclusiveMaximum", "items", "prefixItems", "minItems", "maxItems", "allOf",
              "if", "then"}


def _is_type(value, t: str) -> bool:
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    return {"object": isinstance(value, dict), "array": isinstance(value, list), "string": isinstance(value, str),
            "boolean": isinstance(value, bool), "number": number,
            "integer": number and (isinstance(value, int) or (math.isfinite(value) and value == int(value)))}[t]


def errors(value, s, path: str = "$") -> list[str]:
    """Every violation of schema ``s`` by ``value`` (empty: valid)."""
    if s is True:
        return []
    if s is False:
        return [f"{path}: not allowed"]
    out: list[str] = []
    if "type" in s and not _is_type(value, s["type"]):
        return [f"{path}: {value!r} is not of type {s['type']}"]
    if "enum" in s and value not in s["enum"]:
        out.append(f"{path}: {value!r} not in {s['enum']}")
    if "const" in s and value != s["const"]:
        out.append(f"{path}: {value!r} != {s['const']!r}")
    if _is_type(value, "number"):
        for key, bad in (("minimum", lambda v, b: v < b), ("maximum", lambda v, b: v > b),
                         ("exclusiveMinimum", lambda v, b: v <= b), ("exclusiveMaximum", lambda v, b: v >= b)):
            if key in s and bad(value, s[key]):
                out.append(f"{path}: {value!r} violates {key} {s[key]}")
    if isinstance(value, dict):
        props = s.get("properties", {})
        for k in s.get("required", ()):
            if k not in value:
                out.append(f"{path}: missing required {k!r}")
        for k, v in value.items():
            if k in props:
                out += errors(v, props[k], f"{path}.{k}")
            elif s.get("additionalProperties", True) is False:
                out.append(f"{path}: unknown key {k!r}")
    if isinstance(value, list):
        if "minItems" in s and len(value) < s["minItems"]:
            out.append(f"{path}: fewer than {s['minItems']} items")
        if "maxItems" in s and len(value) > s["maxItems"]:
            out.append(f"{path}: more than {s['maxItems']} items")
        prefix = s.get("prefixItems", [])
        for i, v in enumerate(value):
            sub = prefix[i] if i < len(prefix) else s.get("items", True)
            out += errors(v, sub, f"{path}[{i}]")
    for sub in s.get("allOf", ()):
        out += errors(value, sub, path)
    if "if" in s and not errors(value, s["if"], path):
        out += errors(value, s.get("then", True), path)
    return out


@pytest.fixture(scope="module")
def rendered() -> dict[str, str]:
    return gen.rendered()


@pytest.fixture(scope="module")
def js(rendered) -> dict:
    return json.loads(rendered[gen.JSON_SCHEMA_PATH])


def loader_rejects(data: dict) -> bool:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            parse_scenario(data, source="probe")
        except ScenarioError:
            return True
    return False


# --------------------------------------------------------------------------------------
# the files are what the generator writes now
# --------------------------------------------------------------------------------------

def test_committed_files_equal_the_generator_output(rendered):
    for rel, text in rendered.items():
        p = ROOT / rel
        assert p.is_file(), f"{rel} missing: run python -m ebraille_sim.tools.schema"
        assert p.read_text(encoding="utf-8") == text, f"{rel} is stale: run python -m ebraille_sim.tools.schema"


def test_check_mode_reports_a_stale_file(tmp_path, rendered):
    assert gen.write(tmp_path) == [gen.REFERENCE_PATH, gen.JSON_SCHEMA_PATH]       # written from nothing
    assert gen.write(tmp_path, check=True) == []
    (tmp_path / gen.JSON_SCHEMA_PATH).write_text("{}\n", encoding="utf-8")
    assert gen.main(["--root", str(tmp_path), "--check"]) == 1
    assert (tmp_path / gen.JSON_SCHEMA_PATH).read_text(encoding="utf-8") == "{}\n"    # --check writes nothing


def test_schema_uses_only_the_keywords_the_validator_implements(js):
    seen = set()

    def walk(s):
        if isinstance(s, bool):
            return
        seen.update(s)
        for k in ("properties",):
            for sub in s.get(k, {}).values():
                walk(sub)
        for k in ("items", "additionalProperties", "if", "then"):
            if k in s:
                walk(s[k])
        for k in ("prefixItems", "allOf"):
            for sub in s.get(k, ()):
                walk(sub)
    walk(js)
    assert seen <= ASSERTIONS | ANNOTATIONS, seen - ASSERTIONS - ANNOTATIONS
    assert js["$schema"] == "https://json-schema.org/draft/2020-12/schema"


# --------------------------------------------------------------------------------------
# completeness
# --------------------------------------------------------------------------------------

def test_every_table_and_key_of_the_loader_is_documented(rendered, js):
    from ebraille_sim.scenarios import disturbances, faults, mechanism_section
    from ebraille_sim.scenarios.spec import DELEGATES, SCHEMA
    from controllers.supervisor import ENVELOPE_KEYS, POLICY_KEYS, SupervisorConfig
    import dataclasses
    md = rendered[gen.REFERENCE_PATH]
    props = js["properties"]
    assert set(props) == set(SCHEMA[""]) and set(DELEGATES) <= set(props)
    for table, rules in SCHEMA.items():
        where = props
        for part in table.split(".") if table else ():
            where = where[part]["properties"]
        assert set(where) == set(rules), table
        if table:
            assert f"# [{table}]" in md
        for key in rules:
            assert f"| `{key}`" in md
    for kind, cls in disturbances.KINDS.items():
        assert f"### [disturbances.{kind}]" in md
        assert set(props["disturbances"]["properties"][kind]["properties"]) == {f.name for f in dataclasses.fields(cls)}
    for kind in faults.KINDS:
        assert f'### [[faults]] kind = "{kind}"' in md
    assert props["faults"]["items"]["properties"]["kind"]["enum"] == list(faults.KINDS)
    assert set(props["supervisor"]["properties"]) == set(POLICY_KEYS)
    assert set(POLICY_KEYS) | set(ENVELOPE_KEYS) == {f.name for f in dataclasses.fields(SupervisorConfig)}
    assert set(props["mechanism"]["properties"]) == set(mechanism_section._SECTION_KEYS)


def test_gains_file_format_and_every_registered_controller_is_documented(rendered, js):
    import dataclasses

    import controllers
    md = rendered[gen.REFERENCE_PATH]
    assert '{"controller": "pid", "gains": {' in md and "[gains]" in md
    rules = {r["if"]["properties"]["name"]["const"]: r["then"]["properties"]["gains"]
             for r in js["properties"]["controller"]["allOf"]}
    assert set(rules) == set(controllers.available())
    for name in controllers.available():
        config = controllers.make(name).config
        assert f"### `{name}` (`{type(config).__module__}.{type(config).__name__}`)" in md
        gains = rules[name]
        settable = [f for f in dataclasses.fields(config) if not f.metadata.get("experimental")]
        assert set(gains["properties"]) == {f.name for f in settable}
        assert gains["additionalProperties"] is False
        for f in settable:                                  # the defaults each controller starts from
            v = getattr(config, f.name)
            assert gains["properties"][f.name].get("default") == v, (name, f.name)
    assert rules["pid"]["properties"]["kp_v_per_n"]["default"] == 2.0     # DEFAULT_PID, not the class default
    assert rules["pid_feedforward"]["properties"]["feedforward"]["default"] is True
    assert rules["pid_scheduled"]["properties"]["feedforward"]["default"] is False


def test_reference_states_units_ranges_defaults_and_sources(rendered):
    md = rendered[gen.REFERENCE_PATH]
    assert "| `wpm` | number | 1/min | (0, 1000] | `90` |" in md
    assert ("| `force_n` | number | N | (0, 3] | `1` | Force setpoint (the first one when steps are given). "
            "| [R] seed paper: tactile forces") in md
    assert "| `seed` | integer | - | [0, 4503599627370496] | `0` |" in md
    assert "| `rms_m` | number | m | [0, 0.0002] | `1.5e-05` | RMS of the pulp's tremor motion. | [R]/[E] Growdon 2000" in md
    assert "| `resistance_ohm` | number | ohm | > 0 | `21.2` | Armature resistance R. | [R] Faulhaber 0816" in md
    assert "| `force_cap_n` | number | N | (0, 4] | `3` |" in md
    assert "| `value_v` (required) | number | V | [-1, 10] | - |" in md
    assert "| `finger_tilt_deg` | number | deg | [-30, 30] | `0` |" in md


def test_the_generator_refuses_a_field_without_unit_or_description():
    # a synthetic parameter dataclass: the generator reads the declaration, guesses nothing
    # from the name (a "_n" suffix is no unit) and names the field that lacks either
    import dataclasses

    from ebraille_sim.base.fields import sourced

    @dataclasses.dataclass(frozen=True)
    class Declared:
        force_n: float = sourced(1.0, "N", "[E] test", positive=True, doc="A force.")

    @dataclasses.dataclass(frozen=True)
    class NoDoc:
        force_n: float = sourced(1.0, "N", "[E] test", positive=True)

    @dataclasses.dataclass(frozen=True)
    class NoUnit:
        ok_s: float = sourced(1.0, "s", "[E] test", doc="A time.")
        force_n: float = dataclasses.field(default=1.0, metadata={"source": "[E] test", "doc": "A force."})

    (k,) = gen._override_keys(Declared)
    assert (k.unit, k.doc) == ("N", "A force.")
    with pytest.raises(ValueError, match=r"^NoDoc force_n has no description at its declaration"):
        gen._override_keys(NoDoc)
    with pytest.raises(ValueError, match=r"^NoUnit force_n has no unit at its declaration"):
        gen._override_keys(NoUnit)
    assert not hasattr(gen, "unit_from_name") and not hasattr(gen, "_field_docs")


def test_every_generated_key_has_a_unit_and_a_description():
    sections, configs = gen.reference(), gen.controller_configs()
    keys = [(s.path, k) for s in sections for k in s.keys]
    keys += [(name, k) for name, (_, ks) in configs.items() for k in ks]
    assert len(keys) > 300
    undeclared = [(where, k.name) for where, k in keys if not k.unit.strip() or not k.doc.strip()]
    assert undeclared == []


def test_units_are_the_declared_ones_not_guessed_from_names(rendered):
    secs = {s.path: s for s in gen.reference()}
    envelope = {k.name: k for k in secs["supervisor.envelope"].keys}
    assert not secs["supervisor.envelope"].settable
    assert envelope["reader_b_n_per_m"].unit == "N/m" and envelope["reader_m_per_m"].unit == "1/m"
    assert envelope["push_force_per_a_n"].unit == "N/A" and envelope["board_mass_kg"].unit == "kg"
    sup = {k.name: k for k in secs["supervisor"].keys}
    assert sup["stuck_response_s"].doc == "Time the estimate needs to show a command's effect."
    assert sup["slew_v_per_s"].unit == "V/s" and sup["moving_speed_m_per_s"].unit == "m/s"
    assert not set(sup) & set(envelope)
    gains = {k.name: k for k in gen.controller_configs()["lqg"][1]}
    assert gains["q_force"].unit == "1/N^2" and gains["r_command"].unit == "1/V^2"
    md = rendered[gen.REFERENCE_PATH]
    assert "### Drive envelope (derived from [device]; not settable)" in md


def test_experimental_tables_are_marked_and_hold_the_study_knobs(rendered, js):
    secs = {s.path: s for s in gen.reference()}
    experimental = {s.path for s in secs.values() if s.experimental}
    assert experimental == {"estimator.experimental", "controller.experimental"}
    assert {k.name for k in secs["estimator.experimental"].keys} == {
        "hysteresis_turn_lsb", "hysteresis_follow_lsb", "hysteresis_turn_time_s", "hysteresis_centre_time_s"}
    assert {k.name for k in secs["controller.experimental"].keys} == {
        "refresh_learning_gain", "refresh_learning_lead_s", "refresh_learning_smoothing_s",
        "refresh_learning_after_s", "refresh_learning_limit_fraction", "refresh_hold_damping_v_per_v",
        "wide_error_fraction", "wide_kp_v_per_n", "wide_ki_v_per_ns", "wide_filter_s",
        "approach_fraction", "approach_ki_v_per_ns"}
    assert "hysteresis_turn_lsb" not in {k.name for k in secs["estimator"].keys}
    md = rendered[gen.REFERENCE_PATH]
    for path in experimental:
        block = md.split(f"### [{path}]", 1)[1]
        assert block.lstrip().startswith("**Experimental**: study knobs with no stability promise")
    est = js["properties"]["estimator"]["properties"]["experimental"]
    assert est["description"].startswith("Experimental (no stability promise).")


# --------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_every_shipped_scenario_validates(path, js):
    data = parse_toml(path.read_bytes(), path.name)
    assert errors(data, js) == []


BAD = {
    "unknown top-level key": ({"name": "x", "sed": 1}, "unknown key 'sed'"),
    "unknown [reading] key": ({"name": "x", "reading": {"wmp": 90}}, "unknown key 'wmp'"),
    "wpm at its open bound": ({"name": "x", "reading": {"wpm": 0}}, "exclusiveMinimum"),
    "wpm too high": ({"name": "x", "reading": {"wpm": 1001}}, "maximum"),
    "seed not whole": ({"name": "x", "seed": 1.5}, "type integer"),
    "setpoint above the tactile range": ({"name": "x", "setpoint": {"force_n": 3.5}}, "maximum"),
    "step force zero": ({"name": "x", "setpoint": {"steps": [[1.0, 0.0]]}}, "exclusiveMinimum"),
    "step with three columns": ({"name": "x", "setpoint": {"steps": [[1.0, 1.0, 1.0]]}}, "more than 2"),
    "unknown motor": ({"name": "x", "device": {"motor": "maxon"}}, "not in"),
    "unknown override": ({"name": "x", "device": {"motor_overrides": {"r_ohm": 1.0}}}, "unknown key 'r_ohm'"),
    "negative resistance": ({"name": "x", "device": {"motor_overrides": {"resistance_ohm": -1.0}}},
                            "exclusiveMinimum"),
    "boolean as number": ({"name": "x", "estimator": {"tare_at_start": 1}}, "type boolean"),
    "missing name": ({"seed": 1}, "missing required 'name'"),
    "unknown disturbance": ({"name": "x", "disturbances": {"tremors": {}}}, "unknown key 'tremors'"),
    "unknown tremor key": ({"name": "x", "disturbances": {"tremor": {"rms": 1e-5}}}, "unknown key 'rms'"),
    "tremor band above range": ({"name": "x", "disturbances": {"tremor": {"band_hz": [8.0, 200.0]}}}, "maximum"),
    "tremor band of three": ({"name": "x", "disturbances": {"tremor": {"band_hz": [8.0, 9.0, 10.0]}}}, "more than 2"),
    "battery cells not whole": ({"name": "x", "disturbances": {"battery": {"cells_series": 1.5}}}, "type integer"),
    "unknown fault kind": ({"name": "x", "faults": [{"kind": "fsr_melted", "start_s": 1.0}]}, "not in"),
    "fault key of another kind": ({"name": "x", "faults": [{"kind": "fsr_open", "start_s": 1.0, "value_v": 1.0}]},
                                  "unknown key 'value_v'"),
    "fsr_value without value_v": ({"name": "x", "faults": [{"kind": "fsr_value", "start_s": 1.0}]},
                                  "missing required 'value_v'"),
    "fault without start": ({"name": "x", "faults": [{"kind": "motor_stall"}]}, "missing required 'start_s'"),
    "fault value out of range": ({"name": "x", "faults": [{"kind": "fsr_value", "start_s": 1.0, "value_v": 11.0}]},
                                 "maximum"),
    "supervisor cap above the limit": ({"name": "x", "supervisor": {"force_cap_n": 4.5}}, "maximum"),
    "supervisor unknown key": ({"name": "x", "supervisor": {"cap_n": 2.0}}, "unknown key 'cap_n'"),
    "supervisor envelope key": ({"name": "x", "supervisor": {"board_mass_kg": 0.01}}, "unknown key 'board_mass_kg'"),
    "study knob outside its table": ({"name": "x", "estimator": {"hysteresis_turn_lsb": 1.75}},
                                     "unknown key 'hysteresis_turn_lsb'"),
    "experimental gain among the gains": ({"name": "x", "controller": {"name": "pid_dob",
                                                                       "gains": {"refresh_learning_gain": 0.25}}},
                                          "unknown key 'refresh_learning_gain'"),
    "mechanism tilt too far": ({"name": "x", "mechanism": {"finger_tilt_deg": 31.0}}, "maximum"),
    "mechanism pose row too short": ({"name": "x", "mechanism": {"pose_steps": [[1.0, 0.0]]}}, "fewer than 3"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_schema_and_loader_reject_a_bad_scenario(case, js):
    data, why = BAD[case]
    errs = errors(data, js)
    assert errs and any(why in e for e in errs), errs
    assert loader_rejects(data), f"the loader accepts {data}"


def test_the_loader_names_an_envelope_key_and_routes_the_experimental_tables():
    from ebraille_sim.scenarios import spec

    def parse(data):
        return spec.parse_scenario(data, source="x.toml")

    with pytest.raises(spec.ScenarioError, match=r"^x.toml: \[supervisor\] board_mass_kg is not a setting: the "
                                                 r"supervisor derives it from \[device\]"):
        parse({"name": "x", "supervisor": {"board_mass_kg": 0.01}})
    with pytest.raises(spec.ScenarioError, match=r"^x.toml: \[controller\] gains refresh_learning_gain is "
                                                 r"experimental: give it in \[controller.experimental\]$"):
        parse({"name": "x", "controller": {"name": "pid_dob", "gains": {"refresh_learning_gain": 0.25}}})
    with pytest.raises(spec.ScenarioError, match=r"unknown key 'kp_v_per_n' in \[controller.experimental\]"):
        parse({"name": "x", "controller": {"experimental": {"kp_v_per_n": 1.0}}})
    with pytest.raises(spec.ScenarioError, match=r"\[estimator.experimental\] hysteresis_turn_lsb = -1 is out of range"):
        parse({"name": "x", "estimator": {"experimental": {"hysteresis_turn_lsb": -1.0}}})
    s = parse({"name": "x", "estimator": {"firmware": "paper_100hz", "experimental": {"hysteresis_turn_lsb": 1.5}},
               "controller": {"name": "pid_dob", "gains": {"kp_v_per_n": 2.0},
                              "experimental": {"refresh_learning_gain": 0.25}}})
    assert s.device.estimator.hysteresis_turn_lsb == 1.5
    assert s.controller.gains == {"kp_v_per_n": 2.0, "refresh_learning_gain": 0.25}
    fw = parse({"name": "x", "estimator": {"firmware": "fast_1khz"}})
    assert fw.device.estimator.hysteresis_turn_lsb == 1.75            # a preset still carries its knob


def test_gains_are_checked_against_the_named_controller(js):
    import controllers
    ok = {"name": "x", "controller": {"gains": {"kp_v_per_n": 1.5}}}                  # default controller: pid
    assert errors(ok, js) == []
    bad = {"name": "x", "controller": {"gains": {"kp": 1.5}}}
    assert any("unknown key 'kp'" in e for e in errors(bad, js))
    with pytest.raises(ValueError, match="unknown key 'kp'"):
        controllers.make("pid", kp=1.5)
    sched = {"name": "x", "controller": {"name": "pid_scheduled", "gains": {"reference_map": False}}}
    assert errors(sched, js) == []
    assert errors({"name": "x", "controller": {"name": "pid", "gains": {"reference_map": False}}}, js)
    assert errors({"name": "x", "controller": {"name": "lqg", "gains": {"q_force": "high"}}}, js)
    free = {"name": "x", "controller": {"name": "my_gains.toml", "gains": {"anything": 1.0}}}
    assert errors(free, js) == []                 # a gains file names its own controller


def _probe(section: gen.Section, key: gen.Key, value) -> dict:
    """A minimal scenario that sets ``key`` of ``section`` to ``value``."""
    data: dict = {"name": "probe"}
    path = section.path
    if path.startswith("faults."):
        kind = path.split(".", 1)[1]
        entry = {"kind": kind, "start_s": 1.0, **({"value_v": 1.0} if kind == "fsr_value" else {})}
        entry[key.name] = value
        data["faults"] = [entry]
        return data
    table = data
    for part in path.split(".") if path else ():
        table = table.setdefault(part, {})
    table[key.name] = value
    return data


def _outside(key: gen.Key):
    """Values just outside ``key``'s range (and at an excluded bound), each with what it violates."""
    step = (lambda b: 1) if key.kind == "integer" else (lambda b: max(abs(b), 1.0) * 1e-3)
    out = []
    if key.lo is not None:
        out.append(key.lo - step(key.lo))
        if key.lo_open:
            out.append(key.lo)
    if key.hi is not None:
        out.append(key.hi + step(key.hi))
        if key.hi_open:
            out.append(key.hi)
    return out


def _inside(key: gen.Key):
    out = []
    if key.lo is not None and not key.lo_open:
        out.append(key.lo)
    if key.hi is not None and not key.hi_open:
        out.append(key.hi)
    return out


def _wrap(key: gen.Key, v):
    """The value ``v`` of one number placed in a key's shape (band, times, rows)."""
    if key.kind == "band":
        return [v, v + 1.0] if v == key.lo or v < key.lo else [v - 1.0, v]
    if key.kind == "times":
        return [v]
    return v


def _bounded_keys():
    for s in gen.reference():
        for k in s.keys:
            if k.kind in ("number", "integer", "band", "times") and (k.lo is not None or k.hi is not None):
                yield s, k
            if k.kind == "rows":
                for j, col in enumerate(k.columns):
                    yield s, dataclasses_replace(col, name=f"{k.name}[{j}]")


def dataclasses_replace(obj, **kw):
    import dataclasses
    return dataclasses.replace(obj, **kw)


def test_every_bound_agrees_with_the_loader(js):
    """Just outside every range both reject; at a closed bound the schema accepts."""
    checked = 0
    for s, k in _bounded_keys():
        if "[" in k.name:                                  # a column of a rows key
            name, j = k.name[:-1].split("[")
            parent = next(x for x in s.keys if x.name == name)
            ok_row = [c.lo if c.lo is not None and not c.lo_open else (c.lo + c.hi) / 2 for c in parent.columns]

            def place(v, parent=parent, ok_row=ok_row, j=int(j)):
                row = list(ok_row)
                row[j] = v
                return _probe(s, parent, [row])
        else:
            def place(v, k=k):
                return _probe(s, k, _wrap(k, v))
        for v in _outside(k):
            data = place(v)
            assert errors(data, js), f"schema accepts {s.path} {k.name} = {v}"
            assert loader_rejects(data), f"loader accepts {s.path} {k.name} = {v}"
            checked += 1
        for v in _inside(k):
            assert errors(place(v), js) == [], f"schema rejects {s.path} {k.name} = {v}"
    assert checked > 150


def test_overrides_sign_bounds_agree_with_the_loader(js):
    """``positive`` parameters reject 0 in both; ``nonneg`` ones accept it in the schema."""
    sec = next(s for s in gen.reference() if s.path == "device.motor_overrides")
    keys = {k.name: k for k in sec.keys}
    zero = _probe(sec, keys["resistance_ohm"], 0.0)
    assert errors(zero, js) and loader_rejects(zero)
    ok = _probe(sec, keys["viscous_friction_nm_s_per_rad"], 0.0)
    assert errors(ok, js) == [] and not loader_rejects(copy.deepcopy(ok))
