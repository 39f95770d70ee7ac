"""Consequences of the FSR model over drawn readers, and a long session on the nominal reader.

Population: ``--readers`` devices drawn with :func:`ebraille_sim.scenarios.population.sample_devices`
(seed ``--seed``) around each scenario's own device, each scenario run for ``--duration`` s with its
default controller and supervisor, one episode seed per reader.  Per scenario: the share of readers
whose in-band fraction reaches 0.9, the in-band fraction's 10th percentile and minimum, the readers
whose supervisor latched a fault (and which faults), and the estimate's bias, the mean of
``force_est - force_true`` over the reading window (median, 5th and 95th percentile of the readers).

Session: ``everyday_session`` on its own (nominal) reader for ``--session`` s (0 skips it), with
the same bias and in-band fraction per 10-minute window (``--session-unit``: see
:data:`SESSION_UNITS`).

Run:  python studies/fsr/population.py [--readers 200] [--seed 4242] [--duration 12] [--session 7200]
      [--session-unit nominal|uncompensated|creep_5pct] [--scenarios ...]
"""
from __future__ import annotations

import argparse
import collections
import pathlib
import sys
import time

import numpy as np

from ebraille_sim.scenarios.population import sample_devices
from ebraille_sim.scenarios.runner import run_batch, run_scenario
from ebraille_sim.scenarios.spec import load_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCENARIOS = ("steady_90wpm", "contact_onset", "pressing_90wpm")
WINDOW_S = 600.0


def _bias(res) -> float:
    tr = res.trace
    read = tr["t_s"] >= res.spec.reading.start_s
    return float(np.mean(tr["force_est_n"][read] - tr["force_true_n"][read]))


def population(name: str, readers: int, seed: int, duration_s: float) -> dict:
    spec = load_scenario(ROOT / "scenarios" / f"{name}.toml")
    devices = sample_devices(seed, readers, base=spec.device)
    runs = [{"scenario": spec, "seed": seed * 1000 + k, "duration_s": duration_s, "device": d}
            for k, d in enumerate(devices)]
    results = run_batch(runs)
    band, bias, faults, errors = [], [], collections.Counter(), 0
    for res in results:
        if isinstance(res, Exception):
            errors += 1
            continue
        band.append(res.metrics["in_band_fraction"])
        bias.append(_bias(res))
        fault = (res.supervisor or {}).get("fault")
        if fault:
            faults[str(fault).split(":")[0]] += 1
    band, bias = np.array(band), np.array(bias)
    return {"scenario": name, "n": len(band), "errors": errors, "share_ge_0.9": float(np.mean(band >= 0.9)),
            "band_p10": float(np.percentile(band, 10)), "band_min": float(band.min()),
            "latched": sum(faults.values()), "faults": dict(faults),
            "bias_median_n": float(np.median(bias)), "bias_p5_n": float(np.percentile(bias, 5)),
            "bias_p95_n": float(np.percentile(bias, 95))}


SESSION_UNITS = {
    "nominal": {},
    "uncompensated": {"estimator": {"creep_compensation": False}},
    "creep_5pct": {"fsr": {"creep_per_decade": 0.05}},
}
"""The session's reader: the scenario's nominal one; the same without the firmware's creep
compensation (the creep as the estimate sees it); a unit at the population's top creep rate
(5 %/decade of the crept force) under the nominal firmware law."""


def session(duration_s: float, unit: str = "nominal") -> list[dict]:
    import dataclasses
    from ebraille_sim.physics.params import replace_checked
    spec = load_scenario(ROOT / "scenarios" / "everyday_session.toml")
    change = SESSION_UNITS[unit]
    dev = spec.device
    if "fsr" in change:
        dev = dataclasses.replace(dev, fsr=replace_checked(dev.fsr, **change["fsr"]))
    if "estimator" in change:
        dev = dataclasses.replace(dev, estimator=replace_checked(dev.estimator, **change["estimator"]))
    res = run_scenario(spec, duration_s=duration_s, device=dev)
    tr = res.trace
    t, f, fe, sp = tr["t_s"], tr["force_true_n"], tr["force_est_n"], tr["setpoint_n"]
    ok = np.abs(f - sp) <= spec.setpoint.band_fraction * sp
    rows = []
    for a in np.arange(0.0, duration_s, WINDOW_S):
        w = (t >= max(a, spec.reading.start_s)) & (t < a + WINDOW_S)
        rows.append({"window_min": f"{a / 60:.0f}-{(a + WINDOW_S) / 60:.0f}", "in_band": float(np.mean(ok[w])),
                     "bias_n": float(np.mean(fe[w] - f[w])), "force_mean_n": float(np.mean(f[w]))})
    rows.append({"window_min": "all", "in_band": res.metrics["in_band_fraction"],
                 "bias_n": _bias(res), "force_mean_n": float(np.mean(f[t >= spec.reading.start_s])),
                 "fault": (res.supervisor or {}).get("fault")})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readers", type=int, default=200)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--session", type=float, default=7200.0)
    ap.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--session-unit", choices=sorted(SESSION_UNITS), default="nominal")
    a = ap.parse_args(argv)
    print(f"| scenario | readers | share in band >= 0.9 | in-band p10 | min | latched faults | "
          f"estimate bias median [p5, p95] (N) |")
    print("|---|---|---|---|---|---|---|")
    for name in a.scenarios:
        t0 = time.time()
        r = population(name, a.readers, a.seed, a.duration)
        faults = ", ".join(f"{k} {v}" for k, v in sorted(r["faults"].items())) or "-"
        print(f"| {name} | {r['n']} | {r['share_ge_0.9']:.3f} | {r['band_p10']:.3f} | {r['band_min']:.3f} | "
              f"{r['latched']} ({faults}) | {r['bias_median_n']:+.4f} [{r['bias_p5_n']:+.4f}, "
              f"{r['bias_p95_n']:+.4f}] |", flush=True)
        print(f"  ({time.time() - t0:.0f} s wall, errors {r['errors']})", file=sys.stderr, flush=True)
    if a.session > 0:
        print(f"\neveryday_session, {a.session_unit} reader, {a.session:.0f} s\n")
        print("| window (min) | in band | estimate bias (N) | mean force (N) |")
        print("|---|---|---|---|")
        for row in session(a.session, a.session_unit):
            print(f"| {row['window_min']} | {row['in_band']:.3f} | {row['bias_n']:+.4f} | {row['force_mean_n']:.3f} |"
                  + (f" fault: {row['fault']}" if row.get("fault") else ""), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
