"""The compiled-code cache is keyed on every compiled source, and importing deletes nothing."""
from __future__ import annotations

import pathlib
import shutil
import subprocess
import sys

from ebraille_sim.base import compiled

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_the_key_covers_the_laws_the_kernel_inlines():
    names = {p.relative_to(ROOT).as_posix() for p in compiled.compiled_sources()}
    for must in ("ebraille_sim/plant/kernel.py", "ebraille_sim/plant/layout.py",
                 "ebraille_sim/physics/fingertip.py", "ebraille_sim/physics/fsr.py",
                 "ebraille_sim/physics/motor.py", "ebraille_sim/physics/drivetrain.py",
                 "controllers/features.py"):
        assert must in names, must


def test_a_changed_law_changes_the_key(tmp_path):
    src = tmp_path / "pkg"
    shutil.copytree(ROOT / "ebraille_sim" / "physics", src / "physics")
    shutil.copy(ROOT / "ebraille_sim" / "plant" / "layout.py", src / "layout.py")
    before = compiled.source_key((src,))
    law = src / "physics" / "fingertip.py"
    law.write_text(law.read_text().replace("exp_minus_one(m_per_m * d_m)", "1.05 * exp_minus_one(m_per_m * d_m)"))
    compiled.source_key.cache_clear()
    assert compiled.source_key((src,)) != before


def test_package_functions_use_the_keyed_locator():
    from ebraille_sim.plant import kernel
    locator = kernel.advance._cache._impl.locator
    assert type(locator).__name__ == "_PackageCacheLocator"
    assert locator.get_source_stamp() == compiled.source_key()


def test_importing_the_package_deletes_no_cache_file(tmp_path):
    cache = ROOT / "ebraille_sim" / "plant" / "__pycache__"
    cache.mkdir(exist_ok=True)
    marker = cache / "kernel.unrelated_probe-1.py311.nbi"
    marker.write_bytes(b"probe")
    try:
        subprocess.run([sys.executable, "-c", "import ebraille_sim; import ebraille_sim.plant.kernel"],
                       check=True, cwd=tmp_path)
        assert marker.exists()
    finally:
        marker.unlink(missing_ok=True)


def _load(path: pathlib.Path, name: str):
    import importlib.util
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_code_outside_the_package_that_uses_its_njit_is_keyed_on_the_package_too(tmp_path):
    """A test, benchmark or user module compiled with the package's njit inlines package
    functions (the supervisor, the laws): its cache must go stale when they change, not only
    when its own file does (a stale test loop once disagreed with the supervisor it called)."""
    ours = tmp_path / "user_loop.py"
    ours.write_text("from ebraille_sim.base.compiled import njit\n\n\n@njit\ndef f(x):\n    return x + 1.0\n")
    other = tmp_path / "plain_loop.py"
    other.write_text("import numba\n\n\n@numba.njit(cache=True)\ndef g(x):\n    return x + 2.0\n")
    mod, plain = _load(ours, "user_loop"), _load(other, "plain_loop")
    assert mod.f(1.0) == 2.0 and plain.g(1.0) == 3.0
    locator = mod.f._cache._impl.locator
    assert type(locator).__name__ == "_PackageCacheLocator"
    stamp = locator.get_source_stamp()
    assert stamp[0] == compiled.source_key() and stamp[2] == ours.stat().st_size
    assert type(plain.g._cache._impl.locator).__name__ != "_PackageCacheLocator"


def test_a_function_loaded_from_the_cache_runs_without_the_compiler_registries(tmp_path):
    """Loading from the cache skips Numba's registry refresh (no ``numba.np.arraymath``, no
    ``scipy.linalg`` at load): a loaded function that allocates arrays and calls BLAS
    (``np.dot``) still gives the compiled result, in a fresh process."""
    mod = tmp_path / "blas_loop.py"
    mod.write_text("import numpy as np\n\nfrom ebraille_sim.base.compiled import njit\n\n\n@njit\n"
                   "def f(a, m):\n    out = np.empty(a.shape[0] + 1)\n    out[:-1] = np.dot(m, a)\n"
                   "    out[-1] = np.dot(a, a)\n    return out\n")
    code = ("import sys\nimport numpy as np\nsys.path.insert(0, sys.argv[1])\nimport blas_loop\n"
            "a = np.arange(3.0) + 0.5\nm = np.arange(9.0).reshape(3, 3) / 7.0\n"
            "blas_loop.f.compile('(float64[::1], float64[:, ::1])')\n"
            "before = ['numba.np.arraymath' in sys.modules, 'scipy.linalg' in sys.modules]\n"
            "print(sorted(blas_loop.f.stats.cache_hits.values()) or [0], *before,\n"
            "      blas_loop.f(a, m).tolist(), (m @ a).tolist() + [float(a @ a)])\n")
    env = {**__import__("os").environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    runs = [subprocess.run([sys.executable, "-c", code, str(tmp_path)], check=True, capture_output=True, text=True,
                           env=env, cwd=tmp_path).stdout.split(" ", 3) for _ in range(2)]
    (hits0, *_), (hits1, arraymath, linalg, values) = runs
    assert hits0 == "[0]" and hits1 == "[1]"                  # compiled, then loaded from the cache
    assert arraymath == "False" and linalg == "False"         # loaded, not yet called
    got, want = values.strip().split("] [")
    assert got + "]" == "[" + want


def test_the_threaded_vector_step_runs_in_a_fresh_process_as_the_serial_one():
    """The ``parallel=True`` row step (threads started by its reload hook when it comes from
    the cache) gives the serial step's observations and rewards in a fresh process."""
    code = ("import sys\nimport numpy as np\nfrom ebraille_sim.rl.vector_env import ContactForceVectorEnv, step_rows\n"
            "out = []\nfor par in (True, False):\n"
            "    env = ContactForceVectorEnv(num_envs=4, parallel=par)\n"
            "    obs, _ = env.reset(seed=3)\n    acc = [obs.copy()]\n"
            "    for k in range(30):\n"
            "        obs, r, term, trunc, _ = env.step(np.full((4, 1), 0.3, np.float32))\n"
            "        acc += [obs.copy(), r.copy()]\n"
            "    out.append(np.concatenate([a.ravel() for a in acc]))\n"
            "loaded = sum(step_rows.stats.cache_hits.values()) > 0\n"
            "print(np.array_equal(out[0], out[1]), not loaded or 'numba.np.arraymath' not in sys.modules)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["True", "True"]


def test_entry_point_runs_the_compiled_code_and_falls_back_to_the_function():
    import numpy as np
    from ebraille_sim.plant import kernel
    from ebraille_sim.plant.layout import N_INPUT, N_PARAM, N_STATE
    s, p, u = np.zeros(N_STATE), np.zeros(N_PARAM), np.zeros(N_INPUT)
    fn = compiled.entry_point(kernel.advance, s, p, u, 0)
    assert fn is not kernel.advance and callable(fn)
    assert fn(s, p, u, 0) is None and not s.any()        # zero substeps change nothing
    assert compiled.entry_point(kernel.advance, s.copy(), p, u, 3) is fn     # kept per argument types
    ro = s.copy()
    ro.flags.writeable = False
    keys = {compiled._type_key(a) for a in (s, ro, s[::2], s.astype(np.float32), s[None, :], 0, 0.0, (s, 0))}
    assert len(keys) == 8                                # what changes Numba's type changes the key

    def plain(x):
        return x + 1
    assert compiled.entry_point(plain, 1) is plain
