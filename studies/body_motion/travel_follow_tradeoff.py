"""The travel rule's follow time against false trips and fault peaks: a figure and its table.

The supervisor's travel rule (``fsr_implausible``: the board travelled further into the finger
than the soft reader's compression for the estimate allows) measures the travel from a reference
that follows where the pulp's surface must be with the time constant ``travel_follow_s``.  A
healthy soft reader whose pulp relaxes under a sustained load, and who presses and relaxes,
moves that place by more than a millimetre within seconds; a slow reference trips on it.  A fast
one lets a board that runs into the finger while the reading stays low go further before the rule
trips.  For each follow time this runs

- healthy readers: ``pressing_90wpm`` (12 s) on ``--readers`` readers drawn with ``--seed``
  around the scenario's device, the supervisor on, and the same with the pressing at
  ``--stress-rms`` (the schema allows 0.7 mm), counting latched faults (all false trips);
- the fault matrix of ``tests/test_fault_matrix.py``: every single fault in every phase (60 wpm)
  and every pair with a withdrawn finger (120 wpm), the worst true force;

and writes ``travel_follow_tradeoff.json`` (rows of earlier runs with the same readers and seed are
kept, those of this run replaced) and ``travel_follow_tradeoff.png`` beside this file.
Run from the repository root::

    python studies/body_motion/travel_follow_tradeoff.py --readers 200 --seed 8128
"""
from __future__ import annotations

import argparse
import collections
import concurrent.futures
import dataclasses
import json
import pathlib
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
FOLLOW_S = (5.0, 2.0, 1.4, 0.7, 0.35)


def _with_supervisor(spec, follow_s):
    return dataclasses.replace(spec, sections={**spec.sections, "supervisor": {"travel_follow_s": follow_s}})


def healthy(follow_s: float, readers: int, seed: int, rms_m: float | None) -> dict:
    """Latches over drawn readers on ``pressing_90wpm`` (pressing at ``rms_m`` when given)."""
    from ebraille_sim.scenarios.population import sample_devices
    from ebraille_sim.scenarios.runner import run_batch
    from ebraille_sim.scenarios.spec import load_scenario
    spec = load_scenario("pressing_90wpm")
    if rms_m is not None:
        dist = dict(spec.sections.get("disturbances", {}))
        dist["pressing"] = dataclasses.replace(dist["pressing"], rms_m=rms_m)
        spec = dataclasses.replace(spec, sections={**spec.sections, "disturbances": dist})
    spec = _with_supervisor(spec, follow_s)
    devs = sample_devices(seed, readers, base=spec.device)
    runs = [{"scenario": spec, "seed": spec.seed + 7 * i, "duration_s": 12.0, "device": d} for i, d in enumerate(devs)]
    causes = collections.Counter()
    latched = []
    for j in range(0, len(runs), 100):
        for k, r in enumerate(run_batch(runs[j:j + 100], keep_traces=False), start=j):
            f = None if isinstance(r, Exception) else (r.supervisor or {}).get("fault")
            if f:
                causes[f] += 1
                latched.append(k)
    return {"follow_s": follow_s, "rms_m": rms_m, "readers": readers, "latched": latched, "causes": dict(causes)}


def faults(follow_s: float) -> dict:
    """Worst true force over the fault matrix's single faults and the pairs with a withdrawn finger."""
    sys.path.insert(0, str(ROOT / "tests"))
    from test_fault_matrix import FAULTS, PHASES, cell_spec
    from ebraille_sim.scenarios.runner import run_scenario
    cells = [((f,), p, 60) for f in FAULTS for p in PHASES]
    cells += [(("finger_withdrawn", f), p, 120) for f in FAULTS if f != "finger_withdrawn" for p in PHASES]
    worst, where = 0.0, None
    for fs, phase, wpm in cells:
        spec = _with_supervisor(cell_spec(fs, phase, wpm), follow_s)
        peak = float(run_scenario(spec).trace["force_true_n"].max())
        if peak > worst:
            worst, where = peak, f"{'+'.join(fs)} ({phase}, {wpm} wpm)"
    return {"follow_s": follow_s, "cells": len(cells), "worst_peak_n": worst, "worst_cell": where}


def _key(row) -> tuple:
    return row["kind"], row["follow_s"], row.get("rms_m")


def _job(args):
    kind, rest = args[0], args[1:]
    t0 = time.time()
    out = healthy(*rest) if kind == "healthy" else faults(*rest)
    out["kind"], out["wall_s"] = kind, time.time() - t0
    return out


def figure(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    peaks = {r["follow_s"]: r["worst_peak_n"] for r in rows if r["kind"] == "faults"}
    for rms, marker in sorted({(r["rms_m"], None) for r in rows if r["kind"] == "healthy"},
                              key=lambda x: x[0] or 0.0):
        pts = sorted((r["follow_s"], 100.0 * len(r["latched"]) / r["readers"]) for r in rows
                     if r["kind"] == "healthy" and r["rms_m"] == rms)
        xs = [peaks[f] for f, _ in pts]
        ys = [y for _, y in pts]
        label = "pressing_90wpm" if rms is None else f"pressing at {rms * 1e3:g} mm RMS"
        ax.plot(xs, ys, "o-", label=label)
        for (f, y), x in zip(pts, xs):
            ax.annotate(f"{f:g} s", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.axvline(3.5, color="k", lw=0.8, ls="--")
    ax.set_xlabel("worst true force over the fault cells (N)")
    ax.set_ylabel("healthy readers latched (%)")
    ax.set_title("travel_follow_s: false trips against the worst fault peak")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readers", type=int, default=200)
    ap.add_argument("--seed", type=int, default=8128)
    ap.add_argument("--stress-rms", type=float, default=0.3e-3, help="pressing RMS of the stress population, m")
    ap.add_argument("--follow", type=float, action="append", help="follow times, s (default %s)" % (FOLLOW_S,))
    ap.add_argument("-j", "--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    if a.readers < 1 or a.jobs < 1:
        print("error: --readers and --jobs must be at least 1", file=sys.stderr)
        return 2
    follow = tuple(a.follow or FOLLOW_S)
    jobs = [("faults", f) for f in follow]
    jobs += [("healthy", f, a.readers, a.seed, rms) for f in follow for rms in (None, a.stress_rms)]
    out = HERE / "travel_follow_tradeoff.json"
    kept = {}
    if out.exists():                       # earlier runs of the same population: their other rows stay
        old = json.loads(out.read_text(encoding="utf-8"))
        if (old["readers"], old["seed"]) == (a.readers, a.seed):
            kept = {_key(r): r for r in old["rows"]}
    with concurrent.futures.ProcessPoolExecutor(a.jobs) as pool:
        for r in pool.map(_job, jobs):
            kept[_key(r)] = r
            print(json.dumps(r), flush=True)
            rows = sorted(kept.values(), key=lambda r: (r["kind"], -r["follow_s"], r.get("rms_m") or 0.0))
            out.write_text(json.dumps({"readers": a.readers, "seed": a.seed, "rows": rows}, indent=1),
                           encoding="utf-8")
    figure(rows, HERE / "travel_follow_tradeoff.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
