"""Wheels and sdists ship the scenario library and its baselines; an installed wheel finds them.

The slow tests build a wheel from a copy of the source tree (no build files land in the
tree), install it with ``--no-deps`` into a fresh virtual environment that borrows this
environment's dependencies through a ``.pth`` file (the editable install of the tree is not
seen there), and run the console script from a working folder with no ``scenarios/``.
"""
import importlib.metadata
import importlib.util
import json
import os
import pathlib
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile

import pytest

from ebraille_sim.scenarios.spec import tomllib

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenarios"


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def _library_files() -> set[str]:
    """The library's files, relative to scenarios/ (what must ship as ebraille_sim/library)."""
    files = {p.name for p in SCEN.glob("*.toml")} | {f"baselines/{p.name}" for p in (SCEN / "baselines").glob("*.json")}
    assert "steady_90wpm.toml" in files and "baselines/steady_90wpm.json" in files
    return files


def test_every_package_of_the_tree_is_listed_and_the_library_is_mapped():
    """A new sub-package must be added to [tool.setuptools] packages or it would not ship."""
    st = _pyproject()["tool"]["setuptools"]
    found = {".".join(p.parent.relative_to(ROOT).parts)
             for top in ("ebraille_sim", "controllers") for p in (ROOT / top).rglob("__init__.py")}
    assert set(st["packages"]) == found | {"ebraille_sim.library"}, "update [tool.setuptools] packages"
    assert st["package-dir"]["ebraille_sim.library"] == "scenarios"
    assert set(st["package-data"]["ebraille_sim.library"]) == {"*.toml", "baselines/*.json"}
    assert not (ROOT / "ebraille_sim" / "library").exists()      # scenarios/ stays the only source


def _source_copy(dest: pathlib.Path) -> pathlib.Path:
    """What a build needs, copied without caches (an in-tree build would write build/ and *.egg-info)."""
    dest.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc", "*.egg-info")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, dest / name)
    for name in ("ebraille_sim", "controllers", "scenarios"):
        shutil.copytree(ROOT / name, dest / name, ignore=ignore)
    return dest


def _clean_env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    env["PYTHONNOUSERSITE"] = "1"
    env.update(extra)
    return env


def _can_build_without_isolation() -> bool:
    """This environment has the build backend the project asks for (setuptools>=68 and wheel)."""
    try:
        major = int(importlib.metadata.version("setuptools").split(".")[0])
    except importlib.metadata.PackageNotFoundError:
        return False
    return major >= 68 and (major >= 71 or importlib.util.find_spec("wheel") is not None)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> pathlib.Path:
    base = tmp_path_factory.mktemp("wheel")
    src = _source_copy(base / "src")
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(base / "dist"), str(src)]
    if _can_build_without_isolation():
        cmd.insert(4, "--no-build-isolation")
    r = subprocess.run(cmd, capture_output=True, text=True, env=_clean_env(), timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    [whl] = (base / "dist").glob("ebraille_sim-*.whl")
    return whl


@pytest.mark.slow
def test_wheel_ships_the_library_and_its_baselines(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {n[len("ebraille_sim/library/"):] for n in names if n.startswith("ebraille_sim/library/")}
    assert shipped == _library_files()
    assert "ebraille_sim/data/passages/default.txt" in names and "controllers/pid.py" in names
    root = pathlib.Path(__file__).resolve().parents[1] / "ebraille_sim" / "data"
    for kind in ("firmware", "designs"):                  # the named firmware presets and designs
        files = {p.name for p in (root / kind).glob("*.toml")}
        assert files and {f"ebraille_sim/data/{kind}/{f}" for f in files} <= names
    policies = {p.relative_to(root).as_posix() for p in (root / "policies").rglob("policy.*")}
    assert {"policies/ppo/policy.npz", "policies/sac/policy.json"} <= policies      # the shipped learned policies
    assert {f"ebraille_sim/data/{f}" for f in policies} <= names
    assert not any(n.endswith(".zip") for n in names)                             # their NumPy actors only
    assert not any(n.startswith("scenarios/") for n in names)                     # no top-level package
    with zipfile.ZipFile(wheel) as z:
        assert z.read("ebraille_sim/library/baselines/steady_90wpm.json") == \
            (SCEN / "baselines" / "steady_90wpm.json").read_bytes()


@pytest.mark.slow
def test_sdist_ships_the_library(tmp_path):
    if importlib.util.find_spec("setuptools") is None:
        pytest.skip("setuptools is not installed in this environment")
    src = _source_copy(tmp_path / "src")
    r = subprocess.run([sys.executable, "-c", "from setuptools import build_meta as b; print(b.build_sdist('dist'))"],
                       cwd=src, capture_output=True, text=True, env=_clean_env(), timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    sdist = src / "dist" / r.stdout.strip().splitlines()[-1]
    with tarfile.open(sdist) as tf:
        members = {m.split("/", 1)[1] for m in tf.getnames() if "/" in m}
    assert {f"scenarios/{f}" for f in _library_files()} <= members


def _venv_with_wheel(tmp: pathlib.Path, wheel: pathlib.Path) -> pathlib.Path:
    """A fresh venv holding only the wheel; this environment's site-packages lent by a .pth."""
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    py = venv / "bin" / "python"
    site = pathlib.Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                       capture_output=True, text=True, check=True).stdout.strip())
    lent = dict.fromkeys(sysconfig.get_paths()[k] for k in ("purelib", "platlib"))
    (site / "lent_dependencies.pth").write_text("".join(f"{p}\n" for p in lent))
    r = subprocess.run([str(py), "-m", "pip", "install", "--no-deps", "--no-index", "--ignore-installed", "-q",
                        str(wheel)], capture_output=True, text=True, env=_clean_env(), timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    return venv


@pytest.mark.slow
def test_installed_wheel_runs_the_shipped_library_from_any_folder(wheel, tmp_path):
    venv = _venv_with_wheel(tmp_path, wheel)
    exe = venv / "bin" / "ebraille-sim"
    work = tmp_path / "work"
    work.mkdir()
    env = _clean_env(NUMBA_CACHE_DIR=str(tmp_path / "numba"))

    def cli(*args, cwd=work):
        return subprocess.run([str(exe), *args], cwd=cwd, capture_output=True, text=True, env=env, timeout=600)

    where = subprocess.run([str(venv / "bin" / "python"), "-c", "import ebraille_sim; print(ebraille_sim.__file__)"],
                           cwd=work, capture_output=True, text=True, env=env)
    assert pathlib.Path(where.stdout.strip()).is_relative_to(venv), where.stdout + where.stderr

    r = cli("list")
    assert r.returncode == 0 and "steady_90wpm" in r.stdout, r.stderr
    doc = json.loads(cli("list", "--json").stdout)
    lib = {s["name"]: s for s in doc["scenarios"]}
    assert pathlib.Path(lib["steady_90wpm"]["file"]).is_relative_to(venv) and lib["steady_90wpm"]["from"] == "library"
    assert len(lib) == len(list(SCEN.glob("*.toml")))
    from controllers.designs import designs
    from ebraille_sim.estimation.presets import firmware_presets
    assert {d["name"] for d in doc["designs"]} == set(designs())
    assert {f["name"] for f in doc["firmware"]} == set(firmware_presets())
    assert all(isinstance(e["score"], float) for e in doc["designs"] + doc["firmware"])

    r = cli("run", "steady_90wpm", "--duration", "3", "--no-plot", "--out", str(tmp_path / "run"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["scenario"] == "steady_90wpm"
    probe = ("import controllers; from controllers.policy import shipped_policies; "
             "c = controllers.make('policy:ppo'); print(type(c.model).__name__, *sorted(shipped_policies()))")
    r = subprocess.run([str(venv / "bin" / "python"), "-c", probe], cwd=work, capture_output=True, text=True, env=env)
    assert r.stdout.split() == ["MlpActor", "ppo", "ppo_hc", "sac"], r.stdout + r.stderr   # shipped policies, by name

    # a working folder with scenarios of its own does not hide the library or its baselines
    mine = tmp_path / "mine"
    (mine / "scenarios").mkdir(parents=True)
    (mine / "scenarios" / "unrelated.toml").write_text('name = "unrelated"\nduration_s = 1.0\n')
    r = cli("regress", "--only", "steady_90wpm", cwd=mine)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "1 of 1 scenario(s) match their baselines" in r.stdout
    assert not (mine / "scenarios" / "baselines").exists()
