"""The fit's candidate pulp under the shipped firmware: population shares against the shipped pulp.

For each scenario, readers are drawn (``sample_devices``) around the scenario's device twice:
once as shipped and once with the candidate of ``fit.json`` in place of its reader's pulp (the
fitted weights and, for the scenario's preset, the fitted b and m; the draw then spreads b, m
and c0 as it does for every pulp).  Controllers, supervisor and firmware are the shipped
ones (or ``--controller``).  The rows are those of ``studies/population/shares.py`` (share at >= 0.9 in band,
median, CVaR10, the largest peak, the latched faults), printed and written to ``--out``.

    python studies/pulp_fit/population.py --readers 200 --seed 777001 --duration 12 --controller pid \\
        --out studies/pulp_fit/population.json
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import pathlib
import sys

from ebraille_sim.base.validation import replace_checked, replace_fields
from ebraille_sim.scenarios.spec import load_scenario

HERE = pathlib.Path(__file__).resolve().parent
SCENARIOS = ("steady_90wpm", "contact_onset", "soft_reader_120wpm", "pressing_90wpm")


def _shares_module():
    spec = importlib.util.spec_from_file_location("population_shares", HERE.parent / "population" / "shares.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def candidate_device(device, fit: dict):
    """``device`` with the candidate pulp of ``fit`` (fit.json) for its reader's preset."""
    f = device.finger
    row = fit[f.name] if f.name in ("soft", "nominal", "stiff") else fit["nominal"]
    c0, c1, c2, c3 = row["weights"]
    finger = replace_checked(f, name=f"candidate_{f.name}", stiffness_b_n_per_m=row["b_n_per_m"],
                             exponent_m_per_m=row["m_per_m"], relax_weight_inf=c0, relax_weight_1=c1,
                             relax_weight_2=c2, relax_weight_3=1.0 - c0 - c1 - c2,
                             sources=tuple((k, "[D] candidate of studies/pulp_fit/fit.py") for k in (
                                 "stiffness_b_n_per_m", "exponent_m_per_m", "relax_weight_inf", "relax_weight_1",
                                 "relax_weight_2", "relax_weight_3")))
    return replace_fields(device, finger=finger)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readers", type=int, default=200)
    ap.add_argument("--seed", type=int, default=777001)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--controller", default=None, help="controller or design (default: the scenario's)")
    ap.add_argument("--out", default=None, help="write both sets of rows as JSON here")
    a = ap.parse_args(argv)
    shares = _shares_module().shares
    fit = json.loads((HERE / "fit.json").read_text(encoding="utf-8"))
    out = {"seed": a.seed, "readers": a.readers, "duration_s": a.duration, "shipped": [], "candidate": []}
    for sc in SCENARIOS:
        dev = load_scenario(sc).device
        for pulp, base in (("shipped", dev), ("candidate", candidate_device(dev, fit))):
            r = shares(sc, a.readers, a.seed, a.duration, a.controller, base=base)
            out[pulp].append(r)
            print(f"{sc:20s} {pulp:9s} share>=0.9 {r['share_in_band_0.9']:.3f}  median {r['median_in_band']:.3f}"
                  f"  CVaR10 {r['cvar10_in_band']:.3f}  peak max {r['peak_max_n']:.2f} N  latched {r['latched']}",
                  flush=True)
    if a.out:
        pathlib.Path(a.out).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
