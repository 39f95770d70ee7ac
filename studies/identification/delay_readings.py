"""The paper's two readings of its input delay on the virtual bench's records.

The paper prints no nk.  Two questions on the bench's six profiles (seed 0, as ``ebraille-sim
identify``): which reading of the paper's printed coefficients (fifth-order Wiener,
Hammerstein and linear models) reproduces the bench's force better, and how well a model
identified with the delay held at 0 or at 1 fits the same records
(:func:`ebraille_sim.identification.sysid.fit_readings`, estimation on the chirp, 4 starts).
Writes ``delay_readings.json`` next to this file and prints the fitness table (eq. 7, %).

    python studies/identification/delay_readings.py     # about 1 min on 2 shared cores
"""
from __future__ import annotations

import json
import pathlib
import sys

import numpy as np

from ebraille_sim.estimation.paper_models import NK_READINGS, paper_model
from ebraille_sim.identification import bench as B
from ebraille_sim.identification.sysid import fit_readings, fitness, simulate

HERE = pathlib.Path(__file__).resolve().parent


def main() -> int:
    ss_bench, _, _ = np.random.SeedSequence(0).spawn(3)
    recs = B.run_profiles(B.PAPER_PROFILES.values(), B.BenchParams(), ss_bench)
    out = {}
    for kind in ("wiener", "hammerstein", "linear"):
        for nk in NK_READINGS:
            m = paper_model(kind, 5, nk=nk)
            out[f"paper {kind} 5, nk {nk}"] = {n: fitness(r.force_n, simulate(m, r.voltage_v)) for n, r in recs.items()}
    chirp = recs["chirp"]
    for kind in ("wiener", "hammerstein"):
        for nk, r in fit_readings(kind, chirp.voltage_v, chirp.force_n, 5, dt_s=chirp.dt_s, seed=0,
                                  n_starts=4, max_nfev=200).items():
            out[f"identified {kind} 5, nk {nk}"] = {n: fitness(rr.force_n, simulate(r.model, rr.voltage_v))
                                                    for n, rr in recs.items()}
    (HERE / "delay_readings.json").write_text(json.dumps(out, indent=1) + "\n")
    names = list(recs)
    print("| model | " + " | ".join(names) + " | mean |")
    print("|---|" + "---:|" * (len(names) + 1))
    for key, row in out.items():
        print(f"| {key} | " + " | ".join(f"{row[n]:.2f}" for n in names) + f" | {np.mean(list(row.values())):.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
