"""Write the golden closed-loop trajectories of every plant backend (tests/data/golden/).

One file per backend of :data:`ebraille_sim.plant.loop.PLANT_BACKENDS`,
``tests/data/golden/<backend>.npz``: the first :data:`DURATION_S` seconds of the
:data:`SCENARIO` scenario with seed :data:`SEED` (approach from a 2 mm gap, contact and
the first reading at 1.5 N), one sample per control period, float64 columns
:data:`COLUMNS` plus the run's description (scenario, seed, duration, backend).

``tests/test_backends.py`` reruns the same scenario and compares every column within
:data:`RTOL` relative and :data:`ATOL` absolute.  After an intended change of the physics,
the estimator, the controller or the scenario, regenerate and commit the files with::

    python tests/make_golden.py              # every backend
    python tests/make_golden.py pymunk       # one backend

and state in the commit message why the trajectories moved.
"""
from __future__ import annotations

import pathlib
import sys

import numpy as np

GOLDEN_DIR = pathlib.Path(__file__).resolve().parent / "data" / "golden"
SCENARIO = "contact_onset"
SEED = 3
DURATION_S = 3.0
COLUMNS = ("force_true_n", "force_est_n", "fsr_voltage_v", "command_v", "motor_current_a", "board_pos_m")
RTOL = 1e-9
ATOL = 1e-9


def golden_path(backend: str) -> pathlib.Path:
    """File of the golden trajectory of ``backend``."""
    return GOLDEN_DIR / f"{backend}.npz"


def golden_run(backend: str) -> dict:
    """The golden scenario run on ``backend``: ``{column: ndarray}`` for :data:`COLUMNS`."""
    from ebraille_sim.scenarios.runner import run_scenario
    res = run_scenario(SCENARIO, seed=SEED, duration_s=DURATION_S, backend=backend)
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
    from ebraille_sim.plant.loop import PLANT_BACKENDS
    backends = argv or list(PLANT_BACKENDS)
    unknown = [b for b in backends if b not in PLANT_BACKENDS]
    if unknown:
        print(f"unknown backend {unknown[0]!r}; available: {', '.join(PLANT_BACKENDS)}", file=sys.stderr)
        return 2
    for b in backends:
        path = write_golden(b)
        print(f"{path}: {path.stat().st_size / 1024:.1f} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
