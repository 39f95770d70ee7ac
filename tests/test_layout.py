"""Product, studies and documentation apart.

* ``docs/`` holds reference pages and the PNG figures they show: no Python file, no data.
* The package (``ebraille_sim/``, ``controllers/``), the tests and the benchmarks read no
  path under ``docs/`` and name none but a reference page: a ``docs/NAME.md`` that exists
  (a docstring or a help text may send the reader there; ``tests/test_architecture.py``
  checks the architecture page against the code, and ``ebraille_sim.tools.schema`` writes
  the generated scenario reference).  Nothing names ``docs/figures``, a study script or a
  results file.
* The package and the tests read nothing under ``studies/`` (no string of their code but a
  docstring names it; a docstring may say which study chose a number): tests read package
  data and ``tests/data/`` only.
* The study scripts (``studies/*/*.py``) use the package's public API: no name with a
  leading underscore imported from, or taken as an attribute of, ``ebraille_sim`` or
  ``controllers``.
"""
from __future__ import annotations

import ast
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
CODE = ("ebraille_sim", "controllers", "tests", "benchmarks")
PACKAGES = ("ebraille_sim", "controllers")
DOCS_PATH = re.compile(r"""docs/[^\s'"`),;:\[\]]*""")
DOCS_PART = re.compile(r"""["']docs["']\s*(?:/\s*["']([^"']*)["'])?""")


def _code_files() -> list[pathlib.Path]:
    this = pathlib.Path(__file__).resolve()
    return sorted(p for top in CODE for p in (ROOT / top).rglob("*.py") if p.resolve() != this)


def _pages() -> set[str]:
    return {f"docs/{p.name}" for p in DOCS.glob("*.md")}


def docs_violations(path: pathlib.Path, text: str, pages: set[str]) -> list[str]:
    """Every mention of a path under docs/ in ``text`` that is not an existing reference page."""
    rel = path.relative_to(ROOT) if path.is_absolute() else path
    out = []
    for m in DOCS_PATH.finditer(text):
        name = m.group(0).rstrip(".")
        if name not in pages:
            out.append(f"{rel}: {name}")
    for m in DOCS_PART.finditer(text):               # ROOT / "docs" / "NAME"
        name = f"docs/{m.group(1)}" if m.group(1) is not None else "docs"
        if name not in pages:
            out.append(f"{rel}: {m.group(0)}")
    return out


def studies_paths(path: pathlib.Path, text: str) -> list[str]:
    """String constants of ``text`` other than docstrings that name ``studies`` or a path in it."""
    tree = ast.parse(text)
    docs = {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body
            and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    rel = path.relative_to(ROOT) if path.is_absolute() else path
    found = [node for node in ast.walk(tree)
             if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
             and (node.value == "studies" or "studies/" in node.value)]
    return [f"{rel}:{node.lineno} {node.value!r}" for node in sorted(found, key=lambda n: (n.lineno, n.col_offset))]


def private_uses(path: pathlib.Path) -> list[str]:
    """Private names of the package a script imports or takes as an attribute of its modules."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    modules, out = set(), []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in PACKAGES:
            if any(part.startswith("_") for part in node.module.split(".")):
                out.append(f"{path.name}:{node.lineno} from {node.module}")
            for a in node.names:
                if a.name.startswith("_"):
                    out.append(f"{path.name}:{node.lineno} {node.module}.{a.name}")
                else:
                    modules.add(a.asname or a.name)
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PACKAGES:
                    modules.add(a.asname or a.name.split(".")[0])
                    if any(part.startswith("_") for part in a.name.split(".")):
                        out.append(f"{path.name}:{node.lineno} import {a.name}")
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                and isinstance(node.value, (ast.Name, ast.Attribute)) and ast.unparse(node.value).split(".")[0]
                in modules):
            out.append(f"{path.name}:{node.lineno} {ast.unparse(node)}")
    return out


def test_docs_holds_pages_and_figures_only():
    assert DOCS.is_dir() and _pages() >= {"docs/benchmark.md", "docs/performance.md", "docs/choosing.md"}
    stray = sorted(str(p.relative_to(ROOT)) for p in DOCS.rglob("*")
                   if p.is_file() and p.suffix not in (".md", ".png"))
    assert not stray, f"docs/ holds only reference pages (.md) and their figures (.png); move these to studies/: {stray}"
    assert all(p.parent == DOCS for p in DOCS.rglob("*.md")), \
        "the reference pages sit in docs/ itself; results tables belong to studies/"


def test_the_rule_catches_a_read_of_docs_data_and_lets_reference_pages_pass():
    pages = {"docs/model.md"}
    here = pathlib.Path("tests/x.py")
    assert docs_violations(here, 'open("docs/figures/rl/ppo/policy.json")', pages) == \
        ["tests/x.py: docs/figures/rl/ppo/policy.json"]
    assert docs_violations(here, 'ROOT / "docs" / "figures" / "rl"', pages) == ['tests/x.py: "docs" / "figures"']
    assert docs_violations(here, '"""see docs/make_dob_tuning.py"""', pages) == ["tests/x.py: docs/make_dob_tuning.py"]
    assert docs_violations(here, '"""Source tags follow docs/model.md."""  (ROOT / "docs" / "model.md")', pages) == []
    assert docs_violations(here, "[docs/model.md](model.md)", pages) == []
    code = '"""Chosen by studies/benchmark/make_dob_tuning.py."""\nP = ROOT / "studies" / "rl"\nQ = "studies/x.json"\n'
    assert studies_paths(here, code) == ["tests/x.py:2 'studies'", "tests/x.py:3 'studies/x.json'"]


def test_package_tests_and_benchmarks_name_no_docs_data_and_no_studies():
    pages = _pages()
    bad, studies = [], []
    for path in _code_files():
        text = path.read_text(encoding="utf-8")
        bad += docs_violations(path, text, pages)
        studies += studies_paths(path, text)
    assert not bad, "code may name only reference pages under docs/: " + "; ".join(bad)
    assert not studies, "tests and the package read package data and tests/data only: " + "; ".join(studies)


def test_the_private_check_finds_private_names():
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        p = pathlib.Path(tmp) / "s.py"
        p.write_text("from ebraille_sim.tools import benchmark as bm\nfrom ebraille_sim.commands.tune import _toml\n"
                     "import numpy as np\nbm._spec(1)\nbm.scenario_spec(1)\nnp._x\n")
        assert private_uses(p) == ["s.py:2 ebraille_sim.commands.tune._toml", "s.py:4 bm._spec"]


def test_study_scripts_use_public_api_only():
    scripts = sorted((ROOT / "studies").glob("*/*.py"))
    assert len(scripts) >= 11, "the study scripts live in studies/<topic>/"
    bad = [u for p in scripts for u in private_uses(p)]
    assert not bad, f"studies use public API only; promote what they need: {bad}"
    for p in scripts:
        assert (p.parent / "README.md").is_file(), f"{p.parent.relative_to(ROOT)} has no README.md"


def test_the_choosing_guide_and_the_benchmark_page_quote_the_shipped_library():
    """Every shipped design and firmware preset is on docs/choosing.md with its library score,
    and every design on docs/benchmark.md: a re-measured score shows up as a stale page."""
    from controllers.designs import designs
    from ebraille_sim.estimation.presets import firmware_presets
    choosing = (DOCS / "choosing.md").read_text(encoding="utf-8").splitlines()
    bench = (DOCS / "benchmark.md").read_text(encoding="utf-8").splitlines()

    def row(lines, name, score):
        return [ln for ln in lines if ln.startswith("|") and f"`{name}`" in ln and f"| {score:.2f} |" in ln]

    stale = []
    for d in designs().values():
        stale += [f"choosing.md: {d.name} {d.score}"] * (not row(choosing, d.name, d.score))
        stale += [f"benchmark.md: {d.name} {d.score}"] * (not row(bench, d.name, d.score))
    for f in firmware_presets().values():
        design = f.benchmark.get("design")
        stale += [f"choosing.md: {f.name} with {design} {f.score}"] * \
            (not [ln for ln in row(choosing, design, f.score) if f"`{f.name}`" in ln])
    assert not stale, f"update the pages to the library's scores: {stale}"
