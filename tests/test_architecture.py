"""The layer rule of docs/architecture.md, checked on every import statement of the package.

Layers, lowest first: base -> physics -> estimation -> plant -> scenarios -> {rl,
identification, analysis} -> tools -> cli.  ``controllers`` sits beside the plant and may
import base, physics and estimation only.  A module may import its own layer and the
layers below; the three peers rl, identification and analysis do not import one another.
Imports inside functions count as much as top-level ones.
"""
from __future__ import annotations

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
RANK = {"base": 0, "physics": 1, "estimation": 2, "controllers": 2.5, "plant": 3, "scenarios": 4,
        "rl": 5, "identification": 5, "analysis": 5, "tools": 6, "cli": 7}
PEERS = {"rl", "identification", "analysis"}


def layer_of(module: str) -> str | None:
    """Layer of a dotted module name of this project, None for third-party modules."""
    parts = module.split(".")
    if parts[0] == "controllers":
        return "controllers"
    if parts[0] != "ebraille_sim":
        return None
    if len(parts) == 1 or parts[1] in ("cli", "commands", "__main__", "__init__"):
        return "cli"
    return parts[1] if parts[1] in RANK else "cli"


def module_name(path: pathlib.Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def project_modules() -> list[pathlib.Path]:
    return sorted(list((ROOT / "ebraille_sim").rglob("*.py")) + list((ROOT / "controllers").rglob("*.py")))


def imports_of(path: pathlib.Path) -> set[str]:
    """Every project module ``path`` imports (absolute and relative, at any depth)."""
    name = module_name(path)
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[:len(pkg.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            for a in node.names:        # "from pkg import module"
                out.add(f"{mod}.{a.name}")
    known = {module_name(p) for p in project_modules()}
    return {m for m in out if m in known and m != name}


def graph() -> dict[str, set[str]]:
    return {module_name(p): imports_of(p) for p in project_modules()}


def test_every_module_has_a_layer():
    for p in project_modules():
        assert layer_of(module_name(p)) is not None, p


def violations(g: dict[str, set[str]]) -> list[str]:
    """Edges of the import graph ``g`` that break the layer rule."""
    bad = []
    for mod, deps in g.items():
        lm = layer_of(mod)
        for d in deps:
            ld = layer_of(d)
            if d == "ebraille_sim" and lm != "cli":
                bad.append(f"{mod} -> {d}")
            elif RANK[ld] > RANK[lm] or (lm in PEERS and ld in PEERS and ld != lm):
                bad.append(f"{mod} ({lm}) -> {d} ({ld})")
    return sorted(bad)


def test_no_module_imports_a_layer_above_its_own():
    bad = violations(graph())
    assert not bad, "layer rule broken:\n" + "\n".join(bad)


def test_controllers_see_only_physics_and_estimation():
    for mod, deps in graph().items():
        if layer_of(mod) == "controllers":
            assert {layer_of(d) for d in deps} <= {"base", "physics", "estimation", "controllers"}, (mod, deps)


def test_no_import_cycles():
    g = graph()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for d in sorted(g.get(m, ())):
            if d == "ebraille_sim" or d.startswith("ebraille_sim.") and d.count(".") == 1 and d not in g:
                continue
            if state.get(d) == 1:
                cycle = stack[stack.index(d):] + [d]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if state.get(d) is None:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(g):
        if state.get(m) is None:
            visit(m)


@pytest.mark.parametrize("importer, imported", [
    ("ebraille_sim.physics.motor", "ebraille_sim.plant.kernel"),          # upward
    ("controllers.pid", "ebraille_sim.scenarios.runner"),                 # controllers above estimation
    ("ebraille_sim.rl.env", "ebraille_sim.analysis.margins"),              # between peers
    ("ebraille_sim.plant.lumped", "ebraille_sim"),                          # the package front door
])
def test_the_checker_reports_a_forbidden_import(importer, imported):
    """The rule itself can fail: a real import graph with one forbidden edge added is reported."""
    g = {m: set(d) for m, d in graph().items()}
    g[importer].add(imported)
    assert violations(g) == [e for e in violations(g) if importer in e] and len(violations(g)) == 1


def test_shipped_scenarios_are_found_from_any_working_directory(tmp_path, monkeypatch):
    from ebraille_sim.scenarios.spec import list_scenarios, scenario_dirs
    monkeypatch.chdir(tmp_path)
    assert scenario_dirs() == [ROOT / "scenarios"]
    assert "steady_90wpm" in list_scenarios()


def test_architecture_doc_names_every_module():
    """docs/architecture.md covers every module of the package (commands as one folder)."""
    doc = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    missing = [module_name(p) for p in project_modules()
               if p.name not in ("__init__.py", "__main__.py") and p.parent.name != "commands"
               and f"`{p.name}`" not in doc]
    assert not missing, f"modules missing from docs/architecture.md: {missing}"


def _modules_after(statement: str) -> set[str]:
    import subprocess
    import sys
    code = f"{statement}\nimport sys\nprint(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    return set(out.split())


def test_importing_the_package_is_light():
    """``import ebraille_sim`` registers the env id but loads no heavy dependency (not even
    Gymnasium or NumPy); the id is there whichever of the two is imported first."""
    heavy = {"numba", "scipy", "matplotlib", "pymunk", "control", "ebraille_sim.rl.env", "ebraille_sim.plant.kernel"}
    assert not (heavy | {"gymnasium", "numpy"}) & _modules_after("import ebraille_sim")
    for first, second in (("ebraille_sim", "gymnasium as gym"), ("gymnasium as gym", "ebraille_sim")):
        mods = _modules_after(f"import {first}\nimport {second}\nassert 'EBraille/ContactForce-v0' in gym.registry")
        assert not heavy & mods, heavy & mods


def test_the_command_line_help_loads_no_simulator():
    """``ebraille-sim --help`` and every command's help parse without Numba, SciPy or plotting."""
    from ebraille_sim.commands.benchmark import SUITE_NAMES
    from ebraille_sim.tools.benchmark import SUITES
    assert SUITE_NAMES == tuple(sorted(SUITES))
    code = ("import contextlib, io\nfrom ebraille_sim.cli import main\n"
            "for argv in (['--help'], ['run', '--help'], ['benchmark', '--help'], ['sweep', '--help'],"
            " ['identify', '--help'], ['tune', '--help'], ['train', '--help'], ['regress', '--help'], ['list', '--help']):\n"
            "    with contextlib.redirect_stdout(io.StringIO()):\n"
            "        try:\n            main(argv)\n        except SystemExit:\n            pass")
    mods = _modules_after(code)
    assert not {"numba", "scipy", "matplotlib", "pymunk", "control", "gymnasium"} & mods, \
        {"numba", "scipy", "matplotlib", "pymunk", "control", "gymnasium"} & mods


def test_a_scenario_run_loads_no_plotting_or_analysis_library():
    """Importing the runner and running a scenario (plant packing, the anti-alias design, the
    estimator's initial state, the supervisor, metrics) loads no SciPy signal package."""
    mods = _modules_after("import ebraille_sim.scenarios.runner as r\nr.run_scenario('steady_90wpm', duration_s=0.1)")
    assert not {"scipy.signal", "matplotlib", "pymunk", "control"} & mods, \
        {"scipy.signal", "matplotlib", "pymunk", "control"} & mods


def test_the_resampled_estimator_without_scipy_signal_is_scipys_to_the_last_bit():
    """The 1 kHz path's zero-order-hold re-discretisation (``estimation.resample``) equals
    ``scipy.signal.cont2discrete`` exactly, on the paper's models and on random systems with a
    direct feedthrough and leading zeros."""
    import numpy as np
    import scipy.signal

    from ebraille_sim.estimation.registry import cached_model
    from ebraille_sim.estimation.resample import continuous_equivalent, zoh_discretised
    systems = []
    for spec in ("paper:wiener:5", "paper:wiener:3", "paper:hammerstein:5"):
        m = cached_model(spec)
        g, z, p = continuous_equivalent(m.linear, m.dt_s)
        systems.append((g * np.poly(-z) if z.size else np.array([g]), np.poly(-p)))
    rng = np.random.default_rng(1)
    for k in (2, 3, 5):
        den = np.poly(-rng.uniform(1.0, 100.0, k))
        systems += [(rng.normal(size=k + 1), den), (np.r_[0.0, rng.normal(size=k)], 2.0 * den)]
    for num, den in systems:
        for dt in (1e-3, 5e-4):
            want = scipy.signal.cont2discrete((num, den), dt, method="zoh")
            got = zoh_discretised(num, den, dt)
            assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1]), (num, den, dt)


def test_the_filter_designs_without_scipy_signal_are_scipys_to_the_last_bit():
    """The anti-alias Butterworth and the filters' steady-state initial states are computed
    without importing ``scipy.signal`` and equal its ``butter`` and ``lfilter_zi`` exactly."""
    import numpy as np
    import scipy.signal

    from ebraille_sim.estimation.registry import load_estimator
    from ebraille_sim.plant.lumped import _antialias_filter, _unit_step_state
    for fc, fs in ((20.0, 1000.0), (40.0, 1000.0), (5.0, 100.0), (200.0, 1000.0), (1.0, 10000.0), (33.3, 777.0)):
        b, a = scipy.signal.butter(2, fc, fs=fs)
        mb, ma = _antialias_filter(fc, fs)
        assert np.array_equal(b, mb) and np.array_equal(a, ma), (fc, fs)
    arr = load_estimator("paper:wiener:5").kernel_arrays()
    for num, den in ((arr["num"], arr["den"]), scipy.signal.butter(2, 20, fs=1000), ([1.0, 0.5], [2.0, -0.9, 0.2]),
                     ([0.3], [1.0, -0.5])):
        assert np.array_equal(scipy.signal.lfilter_zi(num, den), _unit_step_state(tuple(num), tuple(den)))
