"""Hostile scenario files: every malformed mutation of a shipped scenario is rejected with one line.

The cases are generated from ``scenarios/*.toml`` by a seeded generator: unknown keys at
every table level, wrong types (string, array, table, bool for numbers and the reverse),
NaN and infinities, negative, zero, fractional and huge values, empty travel ranges and
bands, broken encodings (invalid UTF-8, UTF-16, NUL bytes), deep nesting and runs too large
to hold in memory.  A numeric mutation is generated only where it breaks a declared bound of
its key (the scenario schema, the disturbance and fault tables, the parameter dataclasses),
so a mutation that happens to be legal is never produced (and never counted as a pass).

The default test command checks a seeded sample of :data:`N_SAMPLE` (every category and
every shipped scenario at least once); the whole table runs with ``-m fuzz_table``.
Cases are checked in-process (parse, validate, build the run's inputs and controller);
a seeded sample of :data:`N_CLI` goes through ``python -m ebraille_sim run FILE --out DIR``,
which must exit 2 with exactly one ``error:`` line on stderr and write nothing.
"""
from __future__ import annotations

import concurrent.futures
import copy
import dataclasses
import json
import math
import pathlib
import random
import subprocess
import sys
import warnings

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

import controllers.supervisor as supervisor
from ebraille_sim.physics import params
from ebraille_sim.scenarios import disturbances, faults, mechanism_section, spec
from ebraille_sim.scenarios.inputs import build_run_inputs
from ebraille_sim.scenarios.runner import make_controller

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"
SHIPPED = sorted(SCENARIOS.glob("*.toml"))
SEED = 20261123
N_CLI = 20
UNKNOWN = "zz_not_a_key"
INJECT_INTO = ("steady_90wpm", "soft_reader_120wpm", "fault_fsr_open")
"""Files that also get every override field and supervisor policy key they do not set (the injected
keys do not interact with the rest of a file, so three files cover them)."""

# --------------------------------------------------------------------------------------
# TOML writer (inline tables; enough for scenario documents)
# --------------------------------------------------------------------------------------


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dumps(doc: dict) -> bytes:
    """A scenario document as TOML: one ``key = value`` line per top-level key."""
    return "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in doc.items()).encode()


# --------------------------------------------------------------------------------------
# declared bounds of every numeric key: (lo, hi, lo_open, hi_open, integer)
# --------------------------------------------------------------------------------------

_OVERRIDE_EXTRA = {
    "gear_efficiency": (0.0, 1.0, True, False, False),
    "adc_bits": (1, params.ADC_BITS_MAX, False, False, True),
    "hysteresis_fraction": (0.0, 1.0, False, True, False),
}


def _override_bounds(cls, key):
    if key in _OVERRIDE_EXTRA:
        return _OVERRIDE_EXTRA[key]
    m = {f.name: f for f in dataclasses.fields(cls)}[key].metadata
    if m.get("positive"):
        return (0.0, None, True, False, False)
    if m.get("nonneg"):
        return (0.0, None, False, False, False)
    if "lo" in m or "hi" in m:
        return (m.get("lo"), m.get("hi"), False, False, False)
    return (None, None, False, False, False)


def bounds(path: tuple):
    """Declared bounds of the number at ``path`` in a scenario document, or None if unknown."""
    head = path[0]
    if head == "disturbances" and len(path) == 3:
        m = {f.name: f for f in dataclasses.fields(disturbances.KINDS[path[1]])}[path[2]].metadata
        if m["kind"] not in ("float", "int", "optional"):
            return None
        return (m["lo"], m["hi"], False, False, m["kind"] == "int")
    if head == "faults" and len(path) == 3:
        lo, hi, lo_open = faults._RANGES[path[2]]
        return (lo, hi, lo_open, False, False)
    if head == "mechanism" and len(path) == 2 and path[1] != "pose_steps":
        lo, hi = mechanism_section._SECTION_KEYS[path[1]]
        return (lo, hi, False, False, False)
    if head == "supervisor" and len(path) == 2:
        hi = supervisor.FORCE_CAP_LIMIT_N if path[1] == "force_cap_n" else None
        return (0.0, hi, path[1] not in supervisor.config._MAY_BE_ZERO, False, False)
    if head == "device" and len(path) == 3 and path[1].endswith("_overrides"):
        return _override_bounds(spec._OVERRIDE_TARGET[path[1]], path[2])
    table, key = ("", head) if len(path) == 1 else (head, path[1])
    rule = spec.SCHEMA.get(table, {}).get(key) if len(path) <= 2 else None
    if not isinstance(rule, dict) or rule["type"] not in ("float", "int"):
        return None
    return (rule["lo"], rule["hi"], rule["lo_open"], rule["hi_open"], rule["type"] == "int")


def violates(b, v) -> bool:
    """True if ``v`` breaks the bounds ``b`` (so the mutation is certainly invalid)."""
    lo, hi, lo_open, hi_open, integer = b
    if isinstance(v, int) and abs(v) > 1e308:
        return True                                   # beyond the float range
    if isinstance(v, float) and not math.isfinite(v):
        return True
    if integer and v != int(v):
        return True
    if lo is not None and (v < lo or (lo_open and v == lo)):
        return True
    return hi is not None and (v > hi or (hi_open and v == hi))


# --------------------------------------------------------------------------------------
# the generator
# --------------------------------------------------------------------------------------

NUMBER_VALUES = {"negative": -1.0, "zero": 0, "fraction": 0.5, "huge": 1e300, "huge_int": 10 ** 400,
                 "nan": math.nan, "inf": math.inf, "-inf": -math.inf}
WRONG_FOR_NUMBER = {"string": "1.0", "array": [1.0], "table": {"v": 1.0}, "bool": True}
WRONG_FOR_STRING = {"number": 1, "array": ["x"], "table": {"v": "x"}, "bool": True}
WRONG_FOR_BOOL = {"number": 1, "string": "true", "array": [True]}
WRONG_FOR_LIST = {"string": "1.0", "number": 1.0, "table": {"v": 1.0}}
WRONG_FOR_TABLE = {"number": 1.0, "string": "x", "array": [1.0]}
FREE_TABLES = {("controller", "gains")}
EXPERIMENTAL = "experimental"
"""Name of the sections' tables of study knobs (``[estimator.experimental]``, ...): the table
makes no stability promise, so no case is generated inside it."""


@dataclasses.dataclass
class Case:
    name: str
    raw: bytes
    match: str | None = None          # a fragment the message must contain (the physical reason)


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _set(doc, path, value):
    d = copy.deepcopy(doc)
    _get(d, path[:-1])[path[-1]] = value
    return d


def _walk(node, path=()):
    """(path, value) of every table, array and leaf below ``node``."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k == EXPERIMENTAL and path:
                continue
            yield path + (k,), v
            if path + (k,) not in FREE_TABLES:
                yield from _walk(v, path + (k,))
    elif isinstance(node, list):
        for j, v in enumerate(node):
            if isinstance(v, (dict, list)):
                yield path + (j,), v
                yield from _walk(v, path + (j,))


def _label(path):
    return ".".join(str(p) for p in path)


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _injected(doc):
    """Extra tables and keys to mutate: every override table and every supervisor key."""
    out = []
    dev = doc.get("device", {})
    for table, cls in spec._OVERRIDE_TARGET.items():
        if table in dev:
            continue
        for f in dataclasses.fields(cls):
            if f.name in ("name", "sources"):
                continue
            out.append((("device", table, f.name), getattr(cls(), f.name)))
    if "supervisor" in doc and not doc["supervisor"]:
        for name in supervisor.POLICY_KEYS:         # the drive envelope is no scenario key
            out.append((("supervisor", name), getattr(supervisor.SupervisorConfig(), name)))
    return out


def _with_path(doc, path, value):
    """``doc`` with ``value`` at ``path``, creating missing tables on the way."""
    d = copy.deepcopy(doc)
    node = d
    for k in path[:-1]:
        node = node.setdefault(k, {})
    node[path[-1]] = value
    return d


def structural_cases(stem: str, doc: dict):
    """Mutations of the document's own tables, arrays and leaves."""
    for path, value in _walk(doc):
        lab = f"{stem}:{_label(path)}"
        if isinstance(value, dict):
            if path not in FREE_TABLES:
                yield Case(f"{lab}:unknown_key", dumps(_set(doc, path, {**value, UNKNOWN: 1})), "unknown key")
            for kind, bad in WRONG_FOR_TABLE.items():
                yield Case(f"{lab}:table_as_{kind}", dumps(_set(doc, path, bad)))
        elif isinstance(value, list):
            for kind, bad in WRONG_FOR_LIST.items():
                yield Case(f"{lab}:list_as_{kind}", dumps(_set(doc, path, bad)))
            if value and all(isinstance(x, dict) for x in value):
                continue
            for j, x in enumerate(value):
                if _is_number(x):
                    for kind, bad in (("nan", math.nan), ("string", "1.0"), ("bool", True), ("array", [1.0])):
                        yield Case(f"{lab}[{j}]:{kind}", dumps(_set(doc, path + (j,), bad)))
                elif isinstance(x, list):
                    yield Case(f"{lab}[{j}]:long_row", dumps(_set(doc, path + (j,), x + [1.0])))
            if path[-1] == "band_hz" and len(value) == 2:
                lo, hi = value
                yield Case(f"{lab}:empty", dumps(_set(doc, path, [lo, lo])), "low < high")
                yield Case(f"{lab}:reversed", dumps(_set(doc, path, [hi, lo])), "low < high")
                yield Case(f"{lab}:micro_hz", dumps(_set(doc, path, [lo, lo + 2e-6])), "Hz wide")
        elif path[-1] == "kind" and path[0] == "faults":
            for kind, bad in WRONG_FOR_STRING.items():
                yield Case(f"{lab}:{kind}", dumps(_set(doc, path, bad)), "kind")
            yield Case(f"{lab}:unknown", dumps(_set(doc, path, "fsr_melted")), "is not one of")
        elif isinstance(value, str):
            for kind, bad in WRONG_FOR_STRING.items():
                yield Case(f"{lab}:{kind}", dumps(_set(doc, path, bad)))
        elif isinstance(value, bool):
            for kind, bad in WRONG_FOR_BOOL.items():
                yield Case(f"{lab}:{kind}", dumps(_set(doc, path, bad)))
        elif _is_number(value):
            yield from _number_cases(lab, doc, path, _set)


def _number_cases(lab, doc, path, put):
    b = bounds(path)
    for kind, bad in WRONG_FOR_NUMBER.items():
        yield Case(f"{lab}:{kind}", dumps(put(doc, path, bad)))
    if b is None:
        return
    for kind, bad in NUMBER_VALUES.items():
        if violates(b, bad):
            yield Case(f"{lab}:{kind}", dumps(put(doc, path, bad)))


def injected_cases(stem: str, doc: dict):
    """Mutations of keys the file does not set: every override field, every supervisor field."""
    for path, default in _injected(doc):
        lab = f"{stem}:{_label(path)}"
        yield Case(f"{lab}:unknown_key", dumps(_with_path(doc, path[:-1] + (UNKNOWN,), 1)), "unknown key")
        if isinstance(default, bool):
            for kind, bad in WRONG_FOR_BOOL.items():
                yield Case(f"{lab}:{kind}", dumps(_with_path(doc, path, bad)))
        elif _is_number(default):
            yield from _number_cases(lab, doc, path, _with_path)


def special_cases(stem: str, doc: dict, raw: bytes, rng: random.Random):
    """Encodings, nesting, travel ranges, sizes and the required key."""
    lab = f"{stem}:"
    for j in range(3):
        at = rng.randrange(len(raw) + 1)
        yield Case(f"{lab}invalid_utf8_{j}", raw[:at] + b"\xff" + raw[at:], "not valid UTF-8")
    at = rng.randrange(len(raw) + 1)
    yield Case(f"{lab}truncated_utf8", raw[:at] + "\u00e9".encode()[:1] + raw[at:], "not valid UTF-8")
    yield Case(f"{lab}utf16", raw.decode().encode("utf-16"), "not valid UTF-8")
    at = rng.randrange(len(raw) + 1)
    yield Case(f"{lab}nul_byte", raw[:at] + b"\x00" + raw[at:], "malformed TOML")
    yield Case(f"{lab}missing_name", dumps({k: v for k, v in doc.items() if k != "name"}), "missing required key")
    for depth in (40, 1000, 100_000):
        why = "unknown key 'zz'" if depth < 100 else "nested too deeply"
        yield Case(f"{lab}deep_array_{depth}", dumps(doc) + b"zz = " + b"[" * depth + b"]" * depth + b"\n", why)
        yield Case(f"{lab}deep_table_{depth}", dumps(doc) + b"zz = " + b"{a = " * depth + b"1" + b"}" * depth + b"\n",
                   why)
    yield Case(f"{lab}deep_seed", dumps(_set(doc, ("seed",), [[[[[[1]]]]]])) if "seed" in doc else dumps(doc) + b"seed = [[[1]]]\n")
    over = lambda d: _with_path(doc, ("device", "drivetrain_overrides"), d)  # noqa: E731
    yield Case(f"{lab}travel_empty", dumps(over({"travel_min_m": 3e-3, "travel_max_m": 3e-3})), "travel range")
    yield Case(f"{lab}travel_inverted", dumps(over({"travel_min_m": 6e-3, "travel_max_m": 0.0})), "travel range")
    yield Case(f"{lab}travel_below_min", dumps(over({"travel_max_m": -1e-3})), "travel range")
    yield Case(f"{lab}gear_efficiency_percent", dumps(over({"gear_efficiency": 60})), "fraction")
    fast = {"control_hz": 1e6, "sensor_hz": 1e6, "physics_hz": 1e6}
    yield Case(f"{lab}hour_at_1MHz", dumps({**_with_path(doc, ("rates",), fast), "duration_s": 3600}), "GB")
    slow = {k: v for k, v in _with_path(doc, ("reading", "wpm"), 0.001).items() if k != "duration_s"}
    yield Case(f"{lab}wpm_0.001_no_duration", dumps(slow), "GB")
    yield Case(f"{lab}control_1hz", dumps(_with_path(doc, ("rates", "control_hz"), 1.0)), "force estimate")
    yield Case(f"{lab}sensor_150hz", dumps(_with_path(doc, ("rates",), {"sensor_hz": 1050.0, "physics_hz": 10500.0,
                                                                         "control_hz": 1050.0})), "whole multiple")
    yield Case(f"{lab}adc_2000_bits", dumps(_with_path(doc, ("device", "circuit_overrides", "adc_bits"), 2000)), "bits")
    yield Case(f"{lab}adc_10.5_bits", dumps(_with_path(doc, ("device", "circuit_overrides", "adc_bits"), 10.5)), "bits")
    yield Case(f"{lab}force_cap_100", dumps(_with_path(doc, ("supervisor",), {"force_cap_n": 100.0,
                                                                             "out_of_range_n": 200.0})), "safe limit")
    yield Case(f"{lab}faults_kind_array", dumps({**doc, "faults": [{"kind": ["fsr_open"], "start_s": 1.0}]}), "kind")
    yield Case(f"{lab}faults_kind_table", dumps({**doc, "faults": [{"kind": {"a": 1}, "start_s": 1.0}]}), "kind")
    yield Case(f"{lab}empty_file", b"", "missing required key")


def generate() -> list[Case]:
    rng = random.Random(SEED)
    cases = []
    for path in SHIPPED:
        raw = path.read_bytes()
        doc = tomllib.loads(raw.decode())
        cases += structural_cases(path.stem, doc)
        if path.stem in INJECT_INTO:
            cases += injected_cases(path.stem, doc)
        cases += special_cases(path.stem, doc, raw, rng)
    names = [c.name for c in cases]
    assert len(names) == len(set(names)), "case names must be unique"
    return cases


CASES = generate()

N_SAMPLE = 300
"""Cases the default test command checks: every category and every shipped scenario at least
once, the rest a seeded draw.  The whole table runs under the ``fuzz_table`` marker
(``pytest -m fuzz_table tests/test_fuzz.py``; CI runs it)."""


def _sample() -> list:
    rng = random.Random(SEED + 2)
    groups: dict = {}
    for c in CASES:
        groups.setdefault(c.name.split(":")[-1], []).append(c)
    chosen = {rng.choice(v).name for _, v in sorted(groups.items())}
    for path in SHIPPED:
        if not any(n.startswith(f"{path.stem}:") for n in chosen):
            chosen.add(rng.choice([c.name for c in CASES if c.name.startswith(f"{path.stem}:")]))
    rest = [c.name for c in CASES if c.name not in chosen]
    chosen |= set(rng.sample(rest, N_SAMPLE - len(chosen)))
    return [c for c in CASES if c.name in chosen]


SAMPLE = _sample()
_IN_SAMPLE = {c.name for c in SAMPLE}
TABLE = [pytest.param(c, id=c.name, marks=() if c.name in _IN_SAMPLE else pytest.mark.fuzz_table) for c in CASES]


def validate(raw: bytes) -> None:
    """Everything a run checks before its first period, in-process."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", spec.ScenarioWarning)
        s = spec.parse_scenario(spec.parse_toml(raw, "fuzz.toml"), source="fuzz.toml", base_dir=str(SCENARIOS))
        build_run_inputs(s)
        make_controller(s)


# --------------------------------------------------------------------------------------
# the tests
# --------------------------------------------------------------------------------------

def test_the_generator_covers_every_shipped_scenario_and_every_category():
    assert len(SHIPPED) >= 20 and len(CASES) > 3000
    for path in SHIPPED:
        assert any(c.name.startswith(f"{path.stem}:") for c in CASES)
    for fragment in (":unknown_key", ":string", ":array", ":table", ":bool", ":nan", ":inf", ":negative", ":zero",
                     ":huge", "travel_empty", "invalid_utf8", "deep_array_1000", "hour_at_1MHz", "micro_hz"):
        assert any(fragment in c.name for c in CASES), fragment


def test_the_generator_never_produces_a_legal_numeric_mutation():
    # a value inside a key's declared bounds is not generated: e.g. no "zero" for [finger] gap_m
    # (range [-0.01, 0.01]) and no "huge" for a key without an upper bound
    names = {c.name for c in CASES}
    assert "steady_90wpm:finger.gap_m:zero" not in names
    assert "steady_90wpm:finger.gap_m:huge" in names
    assert "steady_90wpm:device.motor_overrides.resistance_ohm:huge" not in names
    assert "steady_90wpm:device.motor_overrides.resistance_ohm:zero" in names
    assert "steady_90wpm:reading.wpm:fraction" not in names and "steady_90wpm:seed:fraction" in names


def test_the_sample_covers_every_category_and_scenario_and_is_a_few_hundred():
    assert len(SAMPLE) == N_SAMPLE
    assert {c.name.split(":")[-1] for c in SAMPLE} == {c.name.split(":")[-1] for c in CASES}
    assert {c.name.split(":")[0] for c in SAMPLE} == {p.stem for p in SHIPPED}


@pytest.mark.parametrize("case", TABLE)
def test_malformed_scenario_is_rejected_in_one_line(case):
    with pytest.raises(ValueError) as info:
        validate(case.raw)
    msg = str(info.value)
    assert msg and "\n" not in msg, msg
    if case.match is not None:
        assert case.match in msg, msg


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_scenario_round_trips_through_the_writer_and_cr_line_ends(path):
    # the writer is faithful (so every mutation differs from a valid file only by itself), and
    # CR-only and CRLF line ends read exactly as LF
    raw = path.read_bytes()
    doc = tomllib.loads(raw.decode())
    assert tomllib.loads(dumps(doc).decode()) == doc
    assert spec.parse_toml(raw.replace(b"\n", b"\r"), path.name) == doc
    assert spec.parse_toml(raw.replace(b"\n", b"\r\n"), path.name) == doc
    validate(dumps(doc))


def _cli_sample() -> list[Case]:
    rng = random.Random(SEED + 1)
    by_name = {c.name: c for c in CASES}
    holes = [by_name[n] for n in (
        "steady_90wpm:hour_at_1MHz", "jittered_reading:wpm_0.001_no_duration", "steady_90wpm:deep_array_1000",
        "steady_90wpm:adc_2000_bits", "steady_90wpm:travel_inverted", "steady_90wpm:force_cap_100",
        "steady_90wpm:control_1hz", "tremor_90wpm:disturbances.tremor.band_hz:micro_hz",
        "steady_90wpm:invalid_utf8_0", "steady_90wpm:faults_kind_table")]
    rest = [c for c in CASES if c not in holes]
    return holes + rng.sample(rest, N_CLI - len(holes))


CLI_CASES = _cli_sample()


def _run_cli(case: Case, tmp: pathlib.Path):
    src = tmp / "case.toml"
    src.write_bytes(case.raw)
    out = tmp / "out"
    out.mkdir()
    proc = subprocess.run([sys.executable, "-m", "ebraille_sim", "run", str(src), "--out", str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)
    return proc, sorted(out.iterdir())


def test_cli_rejects_a_sample_with_exit_2_one_error_line_and_nothing_written(tmp_path):
    assert len(CLI_CASES) == N_CLI
    dirs = []
    for j in range(N_CLI):
        d = tmp_path / f"c{j}"
        d.mkdir()
        dirs.append(d)
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(_run_cli, CLI_CASES, dirs))
    for case, (proc, written) in zip(CLI_CASES, results):
        lines = proc.stderr.splitlines()
        assert proc.returncode == 2, (case.name, proc.stderr[-2000:])
        assert len(lines) == 1 and lines[0].startswith("error: "), (case.name, proc.stderr[-2000:])
        assert written == [], (case.name, written)
        if case.match is not None:
            assert case.match in lines[0], (case.name, lines[0])


def test_the_table_promises_neither_the_drive_envelope_nor_the_experimental_knobs():
    names = [c.name for c in CASES]
    assert any(":supervisor.stall_time_s:" in n for n in names)
    assert not [n for n in names for k in supervisor.ENVELOPE_KEYS if f":supervisor.{k}:" in n]
    doc = {"name": "x", "estimator": {"model": "paper:wiener:5", "experimental": {"hysteresis_turn_lsb": 1.0}},
           "controller": {"name": "pid_dob", "experimental": {"refresh_learning_gain": 0.25}}}
    made = [c.name for c in structural_cases("x", doc)]
    assert any("estimator.model" in n for n in made) and not any("experimental" in n for n in made)
