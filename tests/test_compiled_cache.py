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
    law.write_text(law.read_text().replace("math.expm1(m_per_m * d_m)", "1.05 * math.expm1(m_per_m * d_m)"))
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
