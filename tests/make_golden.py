"""Write the stored references of the tests: the golden trajectories and the scenario baselines.

The one update command after an intended change of the physics, the sensor chain, the
estimator, a controller or a scenario::

    python tests/make_golden.py              # every golden trajectory and every baseline
    python tests/make_golden.py pymunk       # the golden trajectory of one backend only

Commit the rewritten files with the change and say in the commit message why they moved.

Golden trajectories: one file per backend of :data:`ebraille_sim.plant.backends.PLANT_BACKENDS`,
``tests/data/golden/<backend>.npz``: the first :data:`DURATION_S` seconds of the
:data:`SCENARIO` scenario with seed :data:`SEED` (approach from a 2 mm gap, contact and the
first reading at 1.5 N), one sample per control period, float64 columns :data:`COLUMNS` plus
the run's description (scenario, seed, duration, backend).  ``tests/test_backends.py``
reruns the same scenario and compares every column within its absolute tolerance in
:data:`TOLERANCES`, which names the physics it guards.

Design checks: the ``[check]`` metrics of the shipped designs (``ebraille_sim/data/designs``),
a nominal run of the named scenario with the design on its firmware.

Scenario baselines: ``scenarios/baselines/<name>.json``, the metrics of every shipped
scenario, rewritten as ``ebraille-sim regress --update`` does (checked by ``ebraille-sim
regress`` within the tolerances of :data:`ebraille_sim.tools.regress.TOLERANCES`).
"""
from __future__ import annotations

import pathlib
import sys

import numpy as np

GOLDEN_DIR = pathlib.Path(__file__).resolve().parent / "data" / "golden"
SCENARIO = "contact_onset"
SEED = 3
DURATION_S = 3.0
FIRMWARE = "paper_100hz"
"""The golden runs' firmware: the paper's 100 Hz path, without the hysteresis compensation.  On
the scenarios' default firmware the compensation's reversal decisions on single ADC codes let a
1e-12 relative change of the pulp's stiffness move the PID's force by 7 mN, so no tolerance that
guards the physics would hold across machines there."""
CONTROLLER = "pid"
"""The golden runs' controller: the PID, whose trajectory on the pymunk plant is not sensitive to
round-off (with ``pid_dob``, a 1e-12 relative change of the pulp's
stiffness moves the force by up to 27 mN after the stick-slip break-away, so no tolerance that
guards the physics would hold across machines)."""
COLUMNS = ("force_true_n", "force_est_n", "fsr_voltage_v", "command_v", "motor_current_a", "board_pos_m")
TOLERANCES = {
    "force_true_n": (1e-3, "1 mN, a quarter of the ADC's 4 mN step at 1 N: the force on the finger"),
    "force_est_n": (1e-3, "1 mN: the estimate the controller regulates, from the same ADC codes"),
    "fsr_voltage_v": (2.4e-3, "half of the 10-bit ADC's 4.9 mV code: the same code in every sample"),
    "command_v": (3.4e-4, "0.34 mV drives 16 uA through the 21.2 ohm winding, 1 mN of push"),
    "motor_current_a": (1.6e-5, "16 uA is 1 mN of push through the gearhead's 63.3 N/A"),
    "board_pos_m": (1e-7, "0.1 um: 1 mN over the pulp's tangent stiffness at 1.5 N (12.7 kN/m) is 0.08 um"),
}
"""Absolute tolerance of each column of :data:`COLUMNS` and the physics it guards.

Round-off that differs between machines (another CPU, libm, NumPy, Numba or pymunk) stays far
inside them: a change of the pulp stiffness by 1e-15 relative moves the lumped trajectory by
at most 1.5e-8 N and the pymunk one by 1.8e-5 N, 1.6e-7 A and 1.7 nm, with the same ADC codes
in every sample.  A physics change shows: 0.01 % stiffer pulp moves the true force by 22 mN.
One ADC code that flips (the analogue voltage on the other side of a code edge) moves the true
force by up to 7 mN and fails the comparison: check the physics tests
(``test_plant_physics.py``, ``test_pymunk_model.py``) on that platform and regenerate.
"""


def golden_path(backend: str) -> pathlib.Path:
    """File of the golden trajectory of ``backend``."""
    return GOLDEN_DIR / f"{backend}.npz"


def golden_run(backend: str) -> dict:
    """The golden scenario run on ``backend``: ``{column: ndarray}`` for :data:`COLUMNS`."""
    from ebraille_sim.scenarios.runner import run_scenario
    res = run_scenario(SCENARIO, controller=CONTROLLER, seed=SEED, duration_s=DURATION_S, backend=backend,
                       firmware=FIRMWARE)
    return {c: np.asarray(res.trace[c], dtype=np.float64) for c in COLUMNS}


def write_golden(backend: str) -> pathlib.Path:
    """Run the golden scenario on ``backend`` and write its file; returns the path."""
    cols = golden_run(backend)
    GOLDEN_DIR.mkdir(parents=True, exist_ok=True)
    path = golden_path(backend)
    np.savez_compressed(path, scenario=np.str_(SCENARIO), seed=np.int64(SEED), duration_s=np.float64(DURATION_S),
                        backend=np.str_(backend), **cols)
    return path


def read_golden(backend: str) -> dict:
    """The stored golden trajectory of ``backend`` (columns and description)."""
    with np.load(golden_path(backend), allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


def main(argv: list[str]) -> int:
    from ebraille_sim.plant.backends import PLANT_BACKENDS
    backends = argv or list(PLANT_BACKENDS)
    unknown = [b for b in backends if b not in PLANT_BACKENDS]
    if unknown:
        print(f"error: unknown backend {unknown[0]!r}; available: {', '.join(PLANT_BACKENDS)}", file=sys.stderr)
        return 2
    for b in backends:
        path = write_golden(b)
        print(f"{path}: {path.stat().st_size / 1024:.1f} kB")
    if not argv:
        from ebraille_sim.tools.regress import regress_scenarios
        failed = 0
        for check in regress_scenarios(update=True):
            errors = [r.note for r in check.rows if r.status == "error"]
            print(f"{check.baseline}: " + ("written" if check.updated else f"not written: {errors[0]}"))
            failed += not check.updated
        for path in write_design_checks():
            print(f"{path}: [check] written")
        if failed:
            return 1
    return 0


def design_check_run(design) -> dict:
    """The ``[check]`` metrics of a shipped design: its scenario on the nominal reader, the
    design on its own firmware (``run SCENARIO --controller NAME``)."""
    from ebraille_sim.scenarios.runner import run_scenario
    res = run_scenario(design.check["scenario"], controller=design.name, trace_every=None)
    return {k: float(res.metrics[k]) for k in design.check if k != "scenario"}


def write_design_checks() -> list:
    """Rewrite the ``[check]`` values of every shipped design that has one (3 decimals)."""
    import re

    from controllers.designs import designs
    out = []
    for d in designs().values():
        if not d.check:
            continue
        path = pathlib.Path(d.source)
        text = path.read_text(encoding="utf-8")
        for k, v in design_check_run(d).items():
            text = re.sub(rf"(?m)^{re.escape(k)} = .*$", f"{k} = {v:.3f}", text)
        path.write_text(text, encoding="utf-8")
        out.append(path)
    return out


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
