"""The firmware reads the motor current only through the board's sensing chain.

Controllers, the safety supervisor, the loop engine's firmware side, the runner's per-period
shim, the Gymnasium envs and learned policies must read ``S.current_meas_a`` (the firmware's
reading, :mod:`ebraille_sim.physics.current_sense`), never the plant's armature current
``S.current_a``.  Like the layer test, this reads every source line of those paths; a line
that records the plant's truth on purpose (a trace column) says so with ``# plant truth``.
"""
from __future__ import annotations

import pathlib
import re

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
FIRMWARE_PATHS = [ROOT / "controllers", ROOT / "ebraille_sim" / "rl", ROOT / "ebraille_sim" / "plant" / "engine.py",
                  ROOT / "ebraille_sim" / "scenarios" / "runner.py", ROOT / "ebraille_sim" / "scenarios" / "supervision.py"]
PLANT_CURRENT = re.compile(r"""S\.current_a\b|S\[\s*["']current_a["']\s*\]|\.motor_current_a\b|_col\(\s*["']current_a""")


def _sources():
    for path in FIRMWARE_PATHS:
        yield from ([path] if path.is_file() else sorted(path.rglob("*.py")))


def test_no_firmware_path_reads_the_plant_current():
    offending = []
    for path in _sources():
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            code = line.split("#", 1)[0]
            if PLANT_CURRENT.search(code) and "# plant truth" not in line:
                offending.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not offending, "firmware paths read the plant's current:\n" + "\n".join(offending)


def test_the_scan_finds_a_plant_current_read():
    """The pattern catches the ways a module could read the armature current."""
    for line in ("cur = state[S.current_a]", 'x = st[S["current_a"]]', "i = plant.motor_current_a[0]"):
        assert PLANT_CURRENT.search(line), line
    assert not PLANT_CURRENT.search("cur = state[S.current_meas_a]")


def test_the_engine_hands_the_controller_the_sensed_current():
    """A controller that records the current it is handed sees the firmware's reading (quantised
    to the chain's ADC step around the zero it measured), not the plant's current."""
    import controllers
    import ebraille_sim
    from ebraille_sim.physics.params import CurrentSenseParams

    class Recorder:
        name = "recorder"

        def __init__(self):
            self.inner = controllers.make("pid")
            self.seen = []

        def reset(self, **kw):
            self.inner.reset(**kw)

        def update(self, f, sp, dt, cur=None):
            self.seen.append(cur)
            return self.inner.update(f, sp, dt, cur)

    rec = Recorder()
    res = ebraille_sim.run_scenario("contact_onset", controller=rec, duration_s=2.0, supervised=False)
    seen = np.array(rec.seen[1:], dtype=float)
    true = res.trace["motor_current_a"][:-1]
    lsb = CurrentSenseParams().lsb_a
    assert np.abs(seen).max() > 20 * lsb                   # the motor drew current
    assert not np.array_equal(seen, true)
    steps = (seen - seen[0]) / lsb
    assert np.allclose(steps, np.round(steps), atol=1e-9)  # whole ADC steps from one another
