"""The scenario file reference and its JSON Schema, generated from the declarations.

Every key a scenario file accepts is declared once: the tables of
:data:`ebraille_sim.scenarios.spec.SCHEMA` in the spec dataclasses' field metadata, the
delegate sections of :data:`~ebraille_sim.scenarios.spec.DELEGATES` in their own modules
(``[disturbances]``: the parameter dataclasses of
:data:`ebraille_sim.scenarios.disturbances.KINDS`; ``[[faults]]``: the kinds, keys and
ranges of :mod:`ebraille_sim.scenarios.faults`; ``[supervisor]``: the fields of
:class:`controllers.supervisor.SupervisorConfig`; ``[mechanism]``: the keys of
:mod:`ebraille_sim.scenarios.mechanism_section`).  :func:`reference` walks them into one
list of :class:`Section` records, from which

* :func:`markdown` writes ``docs/scenario-reference.md``: every section and key with its
  type, unit, admissible range, default and source, and the controller gains-file format
  with the keys of every registered controller's config dataclass;
* :func:`json_schema` writes ``scenarios/scenario.schema.json`` (JSON Schema draft
  2020-12, for editors): types, inclusive and exclusive bounds, enums, required keys and
  ``additionalProperties: false`` on every table.

The JSON Schema checks each key on its own.  Rules that tie keys together stay with the
loader (:func:`ebraille_sim.scenarios.spec.load_scenario`): one of ``passage``/``text``/
``file``, the refresh fractions summing below 1, increasing step times, the rates'
multiples, the supervisor's ordering of limits, a preset's own bounds beyond
``positive``/``non-negative``.

Run ``python -m ebraille_sim.tools.schema`` to rewrite both files (``--check`` only
compares them with what would be written).

Examples
--------
>>> secs = {s.path: s for s in reference()}
>>> k = {k.name: k for k in secs["reading"].keys}["wpm"]
>>> k.unit, k.range_text()
('1/min', '(0, 1000]')
>>> json_schema(configs={})["properties"]["reading"]["properties"]["wpm"]["exclusiveMinimum"]
0
"""
from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import math
import pathlib
import re
import sys
from dataclasses import dataclass
from typing import Any

from ebraille_sim.physics import params as _params
from ebraille_sim.scenarios import spec as _spec

__all__ = ["Key", "Section", "reference", "controller_configs", "markdown", "json_schema", "write", "main",
           "REFERENCE_PATH", "JSON_SCHEMA_PATH"]

REFERENCE_PATH = "docs/scenario-reference.md"
"""Where :func:`write` puts the Markdown reference, relative to the project root."""
JSON_SCHEMA_PATH = "scenarios/scenario.schema.json"
"""Where :func:`write` puts the JSON Schema, relative to the project root."""

_SETTING = "scenario setting"

def declared(where: str, name: str, metadata) -> tuple[str, str]:
    """The ``unit`` and ``doc`` (one-line description) a field carries at its declaration
    (:func:`ebraille_sim.base.fields.sourced`); a ``ValueError`` naming the field when either is
    missing: the reference guesses nothing from a name.

    >>> declared("[x]", "k_n", {"unit": "N", "doc": "A force."})
    ('N', 'A force.')
    >>> declared("[x]", "k_n", {"unit": "N"})
    Traceback (most recent call last):
    ...
    ValueError: [x] k_n has no description at its declaration (sourced(..., doc=...))
    """
    unit, doc = metadata.get("unit"), metadata.get("doc")
    missing = [w for w, v in (("unit", unit), ("description", doc)) if not (isinstance(v, str) and v.strip())]
    if missing:
        raise ValueError(f"{where} {name} has no {' and no '.join(missing)} at its declaration "
                         f"(sourced(..., doc=...))")
    return unit, doc


@dataclass(frozen=True)
class Key:
    """One key of a scenario table.

    ``kind`` is ``"number"``, ``"integer"``, ``"string"``, ``"boolean"``, ``"choice"``
    (``choices``), ``"band"`` (a ``[low, high]`` pair), ``"times"`` (a list of numbers),
    ``"rows"`` (a list of fixed-length rows, ``columns`` giving each column as a
    :class:`Key`), ``"table"`` (a sub-table, described by its own :class:`Section`) or
    ``"free"`` (any table).  ``doc`` is the one-line description of the key's declaration.
    ``lo``/``hi`` bound numbers (and every number of a band or
    of times), ``lo_open``/``hi_open`` exclude the bound itself.  ``default`` is
    :data:`None` when the key has no fixed default (``note`` says what applies).
    """
    name: str
    kind: str
    unit: str = "-"
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple = ()
    columns: tuple = ()
    source: str = _SETTING
    note: str = ""
    required: bool = False
    doc: str = ""

    def range_text(self) -> str:
        """The admissible values in words: ``(0, 1000]``, ``> 0``, ``one of: a, b``, ``-``."""
        if self.kind == "choice":
            return "one of: " + ", ".join(f"`{c}`" for c in self.choices)
        if self.kind == "boolean":
            return "true, false"
        if self.kind == "rows":
            return "rows [" + ", ".join(f"{c.name} {c.range_text()}" for c in self.columns) + "]"
        if self.lo is None and self.hi is None:
            return "-"
        if self.lo is not None and self.hi is not None:
            return (f"{'(' if self.lo_open else '['}{_num(self.lo)}, {_num(self.hi)}"
                    f"{')' if self.hi_open else ']'}")
        if self.lo is not None:
            return f"{'>' if self.lo_open else '>='} {_num(self.lo)}"
        return f"{'<' if self.hi_open else '<='} {_num(self.hi)}"


@dataclass(frozen=True)
class Section:
    """A table of a scenario file: its path (``"reading"``, ``"disturbances.tremor"``, ...), keys and words.

    ``array`` marks an array of tables (each kind of ``[[faults]]`` entry is one section);
    ``required`` lists the keys a table must have; ``experimental`` marks a table of study
    knobs (no stability promise); ``settable = False`` a table the reference shows but a
    scenario cannot set (the supervisor's drive envelope).
    """
    path: str
    title: str
    description: str
    keys: tuple[Key, ...]
    array: bool = False
    required: tuple[str, ...] = ()
    experimental: bool = False
    settable: bool = True


def _num(x) -> str:
    if isinstance(x, float) and math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if isinstance(x, int) and not isinstance(x, bool):
        return str(x)
    return f"{x:g}" if isinstance(x, float) else str(x)


def _md(text: str) -> str:
    """reStructuredText inline markup of a docstring as Markdown: ``x`` and :role:`~x` become `x`."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"`\1`", text)
    return text.replace("``", "`")


def _first_paragraph(doc: str | None) -> str:
    text = inspect.cleandoc(doc or "")
    return _md(" ".join(text.split("\n\n")[0].split()))


def _first_sentence(text: str) -> str:
    m = re.match(r"(.+?\.)(\s|$)", text)
    return m.group(1) if m else text


def _plain(value):
    """A default as JSON data: tuples become lists, infinities and None become None."""
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


# --------------------------------------------------------------------------------------
# the core tables (spec.SCHEMA)
# --------------------------------------------------------------------------------------

_STEPS_COLUMNS = (Key("time_s", "number", "s", lo=0.0, hi=3600.0),
                  Key("force_n", "number", "N", lo=0.0, hi=_params.TACTILE_FORCE_MAX_N, lo_open=True))
"""Columns of ``[setpoint] steps``, as :func:`ebraille_sim.scenarios.spec._check_value` checks them."""


def _spec_key(f: dataclasses.Field, where: str) -> Key:
    m = f.metadata
    kind = m["kind"]
    unit, doc = declared(where, f.name, m)
    default = f.default if f.default is not dataclasses.MISSING else None
    common = dict(unit=unit, default=_plain(default), source=m["source"], doc=doc)
    if kind in ("float", "int"):
        return Key(f.name, "number" if kind == "float" else "integer", lo=m.get("lo"), hi=m.get("hi"),
                   lo_open=m.get("lo_open", False), hi_open=m.get("hi_open", False), **common)
    if kind == "choice":
        return Key(f.name, "choice", choices=tuple(m["choices"]), **common)
    if kind == "str":
        return Key(f.name, "string", **common)
    if kind == "bool":
        return Key(f.name, "boolean", **common)
    if kind == "steps":
        return Key(f.name, "rows", columns=_STEPS_COLUMNS, **common)
    if kind in ("table", "overrides", "experimental"):
        return Key(f.name, "table", **common)
    if kind == "free":
        return Key(f.name, "free", **common)
    raise ValueError(f"field {f.name} has kind {kind!r}, which the reference does not know")


def _override_keys(cls) -> tuple[Key, ...]:
    """Keys of an override table: the numeric fields of a parameter dataclass."""
    defaults = cls()
    keys = []
    for f in dataclasses.fields(cls):
        if f.name in ("name", "sources"):
            continue
        m = f.metadata
        v = getattr(defaults, f.name)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        unit, doc = declared(cls.__name__, f.name, m)
        lo = 0.0 if (m.get("positive") or m.get("nonneg")) else m.get("lo")
        keys.append(Key(f.name, "number", unit, v, lo=lo, hi=m.get("hi"),
                        lo_open=bool(m.get("positive")), source=m.get("source", ""), doc=doc))
    return tuple(keys)


_EXPERIMENTAL_NOTE = ("**Experimental**: study knobs with no stability promise: a key may change its meaning, "
                      "range or name, or go, from one version to the next; the generated malformed-scenario "
                      "table does not cover it.")


def _gain_key(f: dataclasses.Field, where: str, default) -> Key:
    """A controller gain from its config field's declaration."""
    unit, doc = declared(where, f.name, f.metadata)
    t = str(f.type)
    kind = "boolean" if t == "bool" else "string" if t == "str" else "number"
    note = "Omitted: derived from the other gains." if default is None else ""
    return Key(f.name, kind, unit, _plain(default), source=f.metadata["source"], doc=doc, note=note)


def _core_sections() -> list[Section]:
    import importlib
    secs = []
    top = [dataclasses.replace(_spec_key(f, "the top level"), required=(f.name == "name"))
           for f in dataclasses.fields(_spec.ScenarioFile)]
    top += [Key(name, "table", note=f"validated by `{mod}`",
                doc=_first_sentence(_first_paragraph(importlib.import_module(mod).__doc__)))
            for name, mod in _spec.DELEGATES.items()]
    secs.append(Section("", "Top level", _first_paragraph(_spec.ScenarioFile.__doc__), tuple(top),
                        required=("name",)))
    for f in dataclasses.fields(_spec.ScenarioFile):
        if f.metadata["kind"] != "table":
            continue
        cls = f.metadata["table"]
        keys = tuple(_spec_key(g, f"[{f.name}]") for g in dataclasses.fields(cls))
        secs.append(Section(f.name, f"[{f.name}]", _first_paragraph(cls.__doc__), keys))
        for g in dataclasses.fields(cls):
            path = f"{f.name}.{g.name}"
            if g.metadata["kind"] == "overrides":
                target = g.metadata["target"]
                secs.append(Section(path, f"[{path}]",
                                    f"Field overrides of `{target.__name__}`: "
                                    f"{_first_paragraph(target.__doc__)}  Defaults shown are the "
                                    f"default preset's; a preset chosen in [{f.name}] brings its own.",
                                    _override_keys(target)))
            elif g.metadata["kind"] == "experimental" and "table" in g.metadata:
                sub = g.metadata["table"]
                secs.append(Section(path, f"[{path}]", _first_paragraph(sub.__doc__),
                                    tuple(_spec_key(h, f"[{path}]") for h in dataclasses.fields(sub)),
                                    experimental=True))
            elif g.metadata["kind"] == "experimental":
                gains = _spec.experimental_gains()
                secs.append(Section(path, f"[{path}]",
                                    "Experimental gains of the controller named in [controller] (each is a field "
                                    "of that controller's config, below); they join its gains.",
                                    tuple(_gain_key(h, f"[{path}]", h.default if h.default is not
                                                    dataclasses.MISSING else None) for h in gains.values()),
                                    experimental=True))
    return secs


# --------------------------------------------------------------------------------------
# delegate sections
# --------------------------------------------------------------------------------------

def _disturbance_sections() -> list[Section]:
    from ebraille_sim.scenarios import disturbances as dist
    secs = [Section("disturbances", "[disturbances]", _first_paragraph(dist.__doc__),
                    tuple(Key(name, "table", doc=_first_sentence(_first_paragraph(cls.__doc__)))
                          for name, cls in dist.KINDS.items()))]
    for name, cls in dist.KINDS.items():
        keys = []
        for f in dataclasses.fields(cls):
            m = f.metadata
            unit, doc = declared(f"[disturbances.{name}]", f.name, m)
            kind = {"float": "number", "int": "integer", "optional": "number", "band": "band",
                    "times": "times"}[m["kind"]]
            note = {"band": f"a [low, high] pair, low < high, at least {dist.MIN_BAND_WIDTH_HZ:g} Hz apart",
                    "times": "a list of times", "optional": "may be omitted"}.get(m["kind"], "")
            keys.append(Key(f.name, kind, unit, _plain(f.default), lo=m["lo"], hi=m["hi"],
                            source=m["source"], note=note, doc=doc))
        secs.append(Section(f"disturbances.{name}", f"[disturbances.{name}]", _first_paragraph(cls.__doc__),
                            tuple(keys)))
    return secs


_FAULT_DEFAULTS = {"duration_s": "until the end of the run", "distance_m": 3e-3, "move_s": 0.05}
"""Defaults :func:`ebraille_sim.scenarios.faults.validate_section` fills in."""


def _fault_sections() -> list[Section]:
    from ebraille_sim.scenarios import faults
    secs = []
    for kind in faults.KINDS:
        unit, doc = declared("[[faults]]", "kind", dict(zip(("unit", "doc"), faults.KEY_DOCS.get("kind", ("", "")))))
        keys = [Key("kind", "choice", unit, choices=(kind,), required=True, doc=doc)]
        extra = faults._EXTRA.get(kind, set())
        for name in sorted(faults._COMMON - {"kind"}) + sorted(extra):
            lo, hi, lo_open = faults._RANGES[name]
            unit, doc = declared("[[faults]]", name, dict(zip(("unit", "doc"), faults.KEY_DOCS.get(name, ("", "")))))
            default = _FAULT_DEFAULTS.get(name)
            note = default if isinstance(default, str) else ""
            keys.append(Key(name, "number", unit, None if note else default, lo=lo, hi=hi,
                            lo_open=lo_open, note=note, doc=doc,
                            required=name == "start_s" or (kind == "fsr_value" and name == "value_v")))
        target = faults.KINDS[kind][0]
        secs.append(Section(f"faults.{kind}", f"[[faults]] kind = \"{kind}\"",
                            f"Plant input driven: `{target}`." if target else
                            "Acts on the controller's command (see `ebraille_sim.scenarios.faults`).",
                            tuple(keys), array=True, required=tuple(k.name for k in keys if k.required)))
    return secs


def _supervisor_sections() -> list[Section]:
    from controllers.supervisor import DriveEnvelope, SupervisorConfig, SupervisorPolicy
    defaults = SupervisorConfig()
    keys = []
    for f in dataclasses.fields(SupervisorPolicy):
        unit, doc = declared("[supervisor]", f.name, f.metadata)
        v = getattr(defaults, f.name)
        if isinstance(v, bool):
            keys.append(Key(f.name, "boolean", unit, default=v, source=f.metadata["source"], doc=doc))
            continue
        keys.append(Key(f.name, "number", unit, v, lo=0.0, hi=f.metadata.get("hi"), lo_open=True,
                        source=f.metadata["source"], doc=doc))
    envelope = []
    for f in dataclasses.fields(DriveEnvelope):
        unit, doc = declared("the drive envelope", f.name, f.metadata)
        envelope.append(Key(f.name, "number", unit, getattr(defaults, f.name), source=f.metadata["source"], doc=doc))
    return [Section("supervisor", "[supervisor]",
                    _first_paragraph(SupervisorPolicy.__doc__) + "  The section wraps the run's controller in the "
                    "safety supervisor (`controllers.supervisor`); `enabled = false` switches it off.", tuple(keys)),
            Section("supervisor.envelope", "Drive envelope (derived from [device]; not settable)",
                    _first_paragraph(DriveEnvelope.__doc__) + "  Values shown: the nominal device's.",
                    tuple(envelope), settable=False)]


_MECHANISM_DEFAULT = 0.0
"""Value of an omitted numeric ``[mechanism]`` key (:func:`~ebraille_sim.scenarios.mechanism_section.build_inputs`)."""


def _mechanism_section() -> Section:
    from ebraille_sim.scenarios import mechanism_section as mech
    bounds = mech._SECTION_KEYS
    keys = []
    for name, b in bounds.items():
        unit, doc = declared("[mechanism]", name, dict(zip(("unit", "doc"), mech.KEY_DOCS.get(name, ("", "")))))
        if b is None:
            cols = (Key("time_s", "number", "s", lo=0.0, hi=3600.0),
                    Key("press_offset_m", "number", "m", lo=bounds["press_offset_m"][0],
                        hi=bounds["press_offset_m"][1]),
                    Key("finger_tilt_deg", "number", "deg", lo=bounds["finger_tilt_deg"][0],
                        hi=bounds["finger_tilt_deg"][1]))
            keys.append(Key(name, "rows", unit, [], columns=cols, note="times increase", doc=doc))
        else:
            keys.append(Key(name, "number", unit, _MECHANISM_DEFAULT, lo=b[0], hi=b[1], doc=doc))
    return Section("mechanism", "[mechanism]", _first_paragraph(mech.__doc__) +
                   "  Read by the pymunk backend only.", tuple(keys))


def reference() -> list[Section]:
    """Every table of a scenario file, in file order, with its keys (see :class:`Section`)."""
    secs = _core_sections()
    for name in _spec.DELEGATES:
        secs += {"disturbances": _disturbance_sections, "faults": _fault_sections,
                 "supervisor": _supervisor_sections, "mechanism": lambda: [_mechanism_section()]}[name]()
    return secs


# --------------------------------------------------------------------------------------
# controller gains
# --------------------------------------------------------------------------------------

def controller_configs() -> dict[str, tuple[str, tuple[Key, ...]]]:
    """``{registered name: (config class path, keys)}`` of every registered controller.

    Each controller is built with its defaults (:func:`controllers.make`) and its
    ``config`` dataclass is read: field names, types, the defaults that controller starts
    from and each field's declared unit and description (a ``ValueError`` naming a field
    without them).
    """
    import controllers
    out = {}
    for name in controllers.available():
        config = controllers.make(name).config
        cls = type(config)
        keys = []
        for f in dataclasses.fields(cls):
            k = _gain_key(f, f"{cls.__name__}", getattr(config, f.name))
            if f.metadata.get("experimental"):
                k = dataclasses.replace(k, note=(k.note + " Experimental: in a scenario, give it in "
                                                 "[controller.experimental].").strip())
            keys.append(k)
        out[name] = (f"{cls.__module__}.{cls.__name__}", tuple(keys))
    return out


# --------------------------------------------------------------------------------------
# JSON Schema
# --------------------------------------------------------------------------------------

def _bounds(k: Key) -> dict:
    out = {}
    if k.lo is not None:
        out["exclusiveMinimum" if k.lo_open else "minimum"] = k.lo
    if k.hi is not None:
        out["exclusiveMaximum" if k.hi_open else "maximum"] = k.hi
    return out


def _key_schema(k: Key) -> dict:
    desc = {"description": " ".join(x for x in (f"[{k.unit}]" if k.unit != "-" else "", k.doc, k.note) if x)}
    if not desc["description"]:
        desc = {}
    if k.default is not None and k.kind not in ("table", "free"):
        desc["default"] = k.default
    if k.kind in ("number", "integer"):
        return {"type": k.kind, **_bounds(k), **desc}
    if k.kind == "string":
        return {"type": "string", **desc}
    if k.kind == "boolean":
        return {"type": "boolean", **desc}
    if k.kind == "choice":
        return {"enum": list(k.choices), **desc}
    if k.kind == "band":
        return {"type": "array", "items": {"type": "number", **_bounds(k)}, "minItems": 2, "maxItems": 2, **desc}
    if k.kind == "times":
        return {"type": "array", "items": {"type": "number", **_bounds(k)}, **desc}
    if k.kind == "rows":
        n = len(k.columns)
        row = {"type": "array", "prefixItems": [_key_schema(c) for c in k.columns], "items": False,
               "minItems": n, "maxItems": n}
        return {"type": "array", "items": row, **desc}
    if k.kind == "free":
        return {"type": "object", **desc}
    raise ValueError(f"key {k.name} of kind {k.kind!r} has no plain schema")


def _object(keys, required=(), tables: dict | None = None, description: str = "") -> dict:
    props = {}
    for k in keys:
        props[k.name] = (tables or {}).get(k.name, {"type": "object"}) if k.kind == "table" else _key_schema(k)
    out = {"type": "object"}
    if description:
        out["description"] = description
    out["properties"] = props
    out["additionalProperties"] = False
    if required:
        out["required"] = list(required)
    return out


def _gains_rules(configs) -> list[dict]:
    """``if name is N (or omitted and N is the default, or the default design's family) then gains
    are N's config keys`` (its experimental gains excepted: a scenario gives them in
    ``[controller.experimental]``)."""
    from controllers.designs import designs
    default_name = _spec.ControllerSpec().name
    if default_name in designs():                   # the default design's gains are its family's keys
        default_name = designs()[default_name].controller
    experimental = set(_spec.experimental_gains())
    rules = []
    for name, (path, keys) in configs.items():
        cond = {"properties": {"name": {"const": name}}}
        if name != default_name:
            cond["required"] = ["name"]
        gains = _object([k for k in keys if k.name not in experimental],      # those go to [controller.experimental]
                        description=f"keyword gains of `{path}`")
        rules.append({"if": cond, "then": {"properties": {"gains": gains}}})
    return rules


def json_schema(sections: list[Section] | None = None, configs=None) -> dict:
    """The JSON Schema (draft 2020-12) of a scenario file, from :func:`reference`.

    ``[controller] gains`` is checked against the config of the controller named in
    ``[controller] name`` (the default controller when the name is omitted); a gains-file
    path or a ``policy:`` name leaves the gains free.
    """
    sections = reference() if sections is None else sections
    configs = controller_configs() if configs is None else configs
    by_path = {s.path: s for s in sections}

    def table(path: str) -> dict:
        s = by_path[path]
        subs = {k.name: table(f"{path}.{k.name}" if path else k.name)
                for k in s.keys if k.kind == "table" and (f"{path}.{k.name}" if path else k.name) in by_path}
        return _object(s.keys, s.required, subs,
                       ("Experimental (no stability promise). " if s.experimental else "") + s.description)

    top = table("")
    fault_kinds = [s for s in sections if s.array and s.path.startswith("faults.")]
    top["properties"]["faults"] = {
        "type": "array", "description": "injected faults, one table per fault",
        "items": {"type": "object", "required": ["kind", "start_s"],
                  "properties": {"kind": {"enum": [s.path.split(".", 1)[1] for s in fault_kinds]}},
                  "allOf": [{"if": {"properties": {"kind": {"const": s.path.split(".", 1)[1]}}, "required": ["kind"]},
                             "then": _object(s.keys, s.required, description=s.description)}
                            for s in fault_kinds]}}
    top["properties"]["controller"]["allOf"] = _gains_rules(configs)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "https://ebraille-sim/scenarios/scenario.schema.json",
            "title": "ebraille-sim scenario file",
            "description": f"Generated by `python -m ebraille_sim.tools.schema`; see {REFERENCE_PATH}.",
            **{k: v for k, v in top.items() if k != "description"}}


# --------------------------------------------------------------------------------------
# Markdown
# --------------------------------------------------------------------------------------

def _cell(x) -> str:
    return str(x).replace("|", "\\|").replace("\n", " ")


def _default_text(k: Key) -> str:
    if k.kind == "table":
        return ""
    if k.default is None:
        return "-"
    if isinstance(k.default, bool):
        return "true" if k.default else "false"
    if isinstance(k.default, str):
        return f'`"{k.default}"`' if k.default else '`""`'
    if isinstance(k.default, list):
        return "`[" + ", ".join(_num(v) for v in k.default) + "]`"
    if isinstance(k.default, dict):
        return "`{}`"
    return f"`{_num(k.default)}`"


def _type_text(k: Key) -> str:
    return {"number": "number", "integer": "integer", "string": "string", "boolean": "boolean",
            "choice": "string", "band": "[number, number]", "times": "[number, ...]",
            "rows": f"[[{', '.join(['number'] * len(k.columns))}], ...]", "table": "table",
            "free": "table"}[k.kind]


def _key_table(keys, with_range: bool = True) -> list[str]:
    cols = ["key", "type", "unit"] + (["range"] if with_range else []) + ["default", "description", "source / note"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for k in keys:
        name = f"`{k.name}`" + (" (required)" if k.required else "")
        src = "; ".join(x for x in ((k.source if k.source != _SETTING else ""), k.note) if x)
        if k.kind == "table":
            src = src or "sub-table, below"
        cells = ([name, _type_text(k), k.unit] + ([k.range_text()] if with_range else [])
                 + [_default_text(k), _md(k.doc), src])
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return lines


def markdown(sections: list[Section] | None = None, configs=None) -> str:
    """The scenario file reference as Markdown (``docs/scenario-reference.md``)."""
    sections = reference() if sections is None else sections
    configs = controller_configs() if configs is None else configs
    out = [
        "# Scenario file reference",
        "",
        "Generated by `python -m ebraille_sim.tools.schema` from the declarations of the keys",
        "(`ebraille_sim.scenarios.spec` and the delegate-section modules); do not edit by hand.",
        f"The same declarations give the JSON Schema `{JSON_SCHEMA_PATH}` for editors (draft",
        "2020-12; e.g. the Even Better TOML extension: `#:schema ./scenario.schema.json` as the",
        "first line of a file). [docs/scenarios.md](scenarios.md) explains what the sections do.",
        "",
        "Ranges: `[a, b]` includes both ends, `(a, b]` excludes `a`; `> 0` has no upper bound.",
        "A default `-` means the key has no fixed default (the note or the section says what",
        "applies). Source tags: `[R]` read, `[D]` derived, `[E]` estimate, `[M]` model (see",
        "[docs/model.md](model.md)); a key without a source is a scenario setting.",
        "",
        "Checked by the loader but not by the JSON Schema (they tie keys together): one of",
        "`passage`/`text`/`file` in [reading]; refresh fractions summing below 1; increasing",
        "`steps` and `pose_steps` times; the rates against the estimator (sensor a whole multiple",
        "of its rate, control at least its rate, anti-alias below Nyquist, physics step); the",
        "supervisor's ordering of limits; bounds of a preset's parameters beyond sign",
        "(e.g. `gear_efficiency <= 1`, whole `adc_bits` 1-24); the gains' own ranges.",
        "",
    ]
    last_disturbance = max(i for i, s in enumerate(sections) if s.path.split(".")[0] == "disturbances")
    for i, s in enumerate(sections):
        if s.path.startswith("faults."):
            continue
        out += [f"## {s.title}" if "." not in s.path else f"### {s.title}", ""]
        if s.experimental:
            out += [_EXPERIMENTAL_NOTE, ""]
        if not s.settable:
            out += ["**Not settable**: a scenario that gives one of these keys in [supervisor] is refused, "
                    "naming the key; change the device instead.", ""]
        out += [s.description, ""]
        out += _key_table(s.keys)
        out.append("")
        if i == last_disturbance:
            out += _fault_markdown(sections)
    out += _controller_markdown(configs)
    return "\n".join(out).rstrip() + "\n"


def _fault_markdown(sections) -> list[str]:
    """``[[faults]]`` is placed right after the disturbances, in :data:`spec.DELEGATES` order."""
    from ebraille_sim.scenarios import faults
    out = ["## [[faults]]", "", _first_paragraph(faults.__doc__) +
           "  Keys by kind (`kind` and `start_s` are always required):", ""]
    for s in sections:
        if s.path.startswith("faults."):
            out += [f"### {s.title}", "", s.description, ""] + _key_table(s.keys[1:]) + [""]
    return out


def _controller_markdown(configs) -> list[str]:
    import controllers
    out = ["## Controller gains files", "",
           "`[controller] name` is a registered controller name, the path of a gains file",
           "(`.toml` or `.json`, relative to the working folder), or `policy:PATH` for a trained",
           "policy; `[controller] gains` are keyword gains on top (the gains file's own gains",
           "first). The same files go to `--controller` on the command line. A gains file holds",
           "exactly two keys:", "",
           "```json", '{"controller": "pid", "gains": {"kp_v_per_n": 1.5, "ki_v_per_ns": 30.0}}', "```", "",
           "or in TOML:", "",
           "```toml", 'controller = "pid"', "", "[gains]", "kp_v_per_n = 1.5", "ki_v_per_ns = 30.0", "```", "",
           f"Registered controllers: {', '.join(f'`{n}`' for n in controllers.available())}. Omitted gains",
           "keep the defaults below; an unknown gain is an error naming it. Each config class",
           "checks its own ranges when the controller is made.", ""]
    for name, (path, keys) in configs.items():
        out += [f"### `{name}` (`{path}`)", ""] + _key_table(keys, with_range=False) + [""]
    return out


# --------------------------------------------------------------------------------------
# files
# --------------------------------------------------------------------------------------

def _root() -> pathlib.Path:
    return pathlib.Path(__file__).resolve().parents[2]


def rendered() -> dict[str, str]:
    """``{relative path: text}`` of the two generated files."""
    sections, configs = reference(), controller_configs()
    return {REFERENCE_PATH: markdown(sections, configs),
            JSON_SCHEMA_PATH: json.dumps(json_schema(sections, configs), indent=2, ensure_ascii=False) + "\n"}


def write(root: str | pathlib.Path | None = None, check: bool = False) -> list[str]:
    """Write (or with ``check`` only compare) the generated files under ``root``.

    Returns the relative paths that changed (or would change).
    """
    root = pathlib.Path(root) if root is not None else _root()
    changed = []
    for rel, text in rendered().items():
        p = root / rel
        old = p.read_text(encoding="utf-8") if p.is_file() else None
        if old != text:
            changed.append(rel)
            if not check:
                p.parent.mkdir(parents=True, exist_ok=True)
                p.write_text(text, encoding="utf-8")
    return changed


def main(argv: list[str] | None = None) -> int:
    """``python -m ebraille_sim.tools.schema [--root DIR] [--check]``."""
    ap = argparse.ArgumentParser(prog="python -m ebraille_sim.tools.schema",
                                 description=f"rewrite {REFERENCE_PATH} and {JSON_SCHEMA_PATH} from the "
                                             f"scenario declarations")
    ap.add_argument("--root", default=None, help="project root (default: this checkout)")
    ap.add_argument("--check", action="store_true", help="only report files that are out of date (exit 1)")
    args = ap.parse_args(argv)
    changed = write(args.root, check=args.check)
    for rel in changed:
        print(f"{'out of date' if args.check else 'wrote'}: {rel}")
    if not changed:
        print("up to date")
    return 1 if (args.check and changed) else 0


if __name__ == "__main__":
    sys.exit(main())
