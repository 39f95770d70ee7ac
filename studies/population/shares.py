"""Shares of a drawn population that a firmware and controller serve.

For each scenario: readers drawn around the scenario's device (``sample_devices``, each unit
calibrated as the scenario's device is), the given controller or design, supervisor on; the
share of readers at >= 0.9 in band, the median and the CVaR10 of the in-band fraction, the
largest peak force and the supervisor's latched faults (a latch in a non-fault scenario is a
false trip).  Writes one JSON document and prints a table.

    python studies/population/shares.py --readers 200 --seed 20261128 --duration 12 \
        --controller dob_learn_1khz steady_90wpm contact_onset pressing_90wpm

``--nk 0`` or ``--nk 1`` runs the scenario's estimator with that reading of the paper's input
delay (the paper prints none; docs/identification.md); it needs a paper model at its own rate.
"""
from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import sys

import numpy as np

from ebraille_sim.estimation.registry import with_delay
from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
from ebraille_sim.scenarios.runner import design_firmware, run_batch
from ebraille_sim.scenarios.spec import load_scenario
from ebraille_sim.tools.benchmark import sensor_bound_metrics


def reader_args(description: str, readers: int, seed: int, argv=None, most: int = 10000):
    """``--readers`` and ``--seed`` of a population study (defaults given); None after a one-line
    error when the readers are not 1 to ``most``."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--readers", type=int, default=readers)
    ap.add_argument("--seed", type=int, default=seed)
    a = ap.parse_args(argv)
    if not 1 <= a.readers <= most:
        print(f"error: --readers must be 1-{most}, got {a.readers}", file=sys.stderr)
        return None
    return a


def drawn_runs(spec, readers: int, seed: int, duration_s: float | None = None) -> tuple[list, list]:
    """``(devices, runs)``: readers drawn around ``spec``'s device, each unit calibrated as drawn
    units are, and their :func:`run_batch` runs (episode seeds ``spec.seed + 7 i``)."""
    devs = sample_devices(seed, readers, PopulationSpec(), base=spec.device)
    runs = [{"scenario": spec, "seed": spec.seed + 7 * i, "device": d,
             **({} if duration_s is None else {"duration_s": duration_s})} for i, d in enumerate(devs)]
    return devs, runs


def cvar_low(x, alpha=0.1):
    x = np.sort(np.asarray(x, float))
    k = max(1, int(np.ceil(alpha * len(x))))
    return float(np.mean(x[:k]))


def shares(scenario: str, readers: int, seed: int, duration_s: float, controller=None, base=None,
           nk: int | None = None, table: bool = True, bound: bool = False, press_repeatability=None) -> dict:
    """One row: readers drawn around ``base`` (default the scenario's device); with ``nk`` the
    estimator runs with that reading of the paper's input delay (samples, 0 or 1)."""
    spec = load_scenario(scenario)
    if nk is not None:
        if design_firmware(spec.controller.name if controller is None else controller) is not None:
            raise ValueError("a design runs on its own firmware preset's estimator; --nk sets the scenario's "
                             "(give a controller or a gains file, not a design)")
        est = spec.device.estimator
        est = dataclasses.replace(est, model=with_delay(est.model, nk))
        spec = dataclasses.replace(spec, device=dataclasses.replace(spec.device, estimator=est))
        if base is not None:
            base = dataclasses.replace(base, estimator=est)
    devs = sample_devices(seed, readers, PopulationSpec(calibration_table=table),
                          base=spec.device if base is None else base)
    if press_repeatability is not None:
        devs = [dataclasses.replace(d, fsr=dataclasses.replace(d.fsr, press_repeatability=press_repeatability))
                for d in devs]
    runs = [{"scenario": spec, "seed": spec.seed + 7 * i, "duration_s": duration_s, "device": d,
             **({} if controller is None else {"controller": controller})} for i, d in enumerate(devs)]
    res = run_batch(runs, keep_traces=False)
    ok = [r for r in res if not isinstance(r, Exception)]
    ib = np.array([r.metrics["in_band_fraction"] for r in ok])
    gap = {}
    if bound:
        # the actuator bound (the true force at the control rate) on the same readers and seeds, and the
        # sensor bound from its traces (its force shifted by the estimator's error along it), in chunks
        ref, sensor = [], []
        for k in range(0, len(runs), 25):
            chunk = run_batch([{**r, "controller": "actuator_bound"} for r in runs[k:k + 25]], keep_traces=True)
            ref += [b if isinstance(b, Exception) else b.metrics["in_band_fraction"] for b in chunk]
            sensor += [b if isinstance(b, Exception) else sensor_bound_metrics(b)["in_band_fraction"] for b in chunk]
        trip = [(a.metrics["in_band_fraction"], b, s) for a, b, s in zip(res, ref, sensor)
                if not isinstance(a, Exception) and not isinstance(b, Exception)]
        d = np.array([b - a for a, b, _ in trip])
        ds = np.array([b - s for _, b, s in trip])
        gap = {"bound_median_in_band": float(np.median([b for _, b, _ in trip])),
               "share_within_0.05_of_bound": float(np.mean(d <= 0.05)), "bound_gap_p90": float(np.percentile(d, 90)),
               "sensor_bound_share_within_0.05_of_bound": float(np.mean(ds <= 0.05)),
               "bound_in_band": [round(float(b), 4) for _, b, _ in trip],
               "sensor_bound_in_band": [round(float(s), 4) for _, _, s in trip]}
    faults = collections.Counter((r.supervisor or {}).get("fault") for r in ok if (r.supervisor or {}).get("fault"))
    worst = sorted(range(len(ok)), key=lambda i: ib[i])[:3]
    return {"scenario": scenario, "controller": controller or spec.controller.name, "readers": readers,
            "estimator": spec.device.estimator.model,
            "runs": len(ok), "errors": [str(r) for r in res if isinstance(r, Exception)][:3],
            "share_in_band_0.9": float(np.mean(ib >= 0.9)), "median_in_band": float(np.median(ib)),
            "cvar10_in_band": cvar_low(ib), "peak_max_n": float(max(r.metrics["peak_force_n"] for r in ok)),
            "latched": dict(faults), "worst_readers": [int(i) for i in worst], **gap,
            "in_band": [round(float(x), 4) for x in ib]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--readers", type=int, default=200)
    ap.add_argument("--seed", type=int, default=20261128)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--controller", default=None, help="controller, design or gains file (default: the scenario's)")
    ap.add_argument("--nk", default=None,
                    help="the estimator's input delay, samples: 0 (the paper's notation read literally) or 1 "
                         "(MATLAB's convention); default: the scenario's estimator as it is")
    ap.add_argument("--no-table", action="store_true",
                    help="drawn units with the divider's one-point calibration only (no calibration table)")
    ap.add_argument("--bound", action="store_true",
                    help="also run the actuator bound on the same readers: the share within 0.05 of it, and "
                         "the sensor bound's share (the bound's force shifted by the estimator's error)")
    ap.add_argument("--press-repeatability", type=float, default=None,
                    help="replace every drawn film's press-to-press repeatability in the session (after its "
                         "bench): what a film without the datasheet's press scatter would allow")
    ap.add_argument("--out", default=None, help="write the rows as JSON here")
    a = ap.parse_args(argv)
    nk = None
    if a.nk is not None:
        if a.nk not in ("0", "1"):
            print(f"error: --nk must be 0 or 1 (the paper's two readings of its input delay), got {a.nk!r}",
                  file=sys.stderr)
            return 2
        nk = int(a.nk)
    rows = []
    for sc in a.scenarios:
        try:
            r = shares(sc, a.readers, a.seed, a.duration, a.controller, nk=nk, table=not a.no_table, bound=a.bound,
                       press_repeatability=a.press_repeatability)
        except ValueError as exc:
            print(f"error: {sc}: {exc}", file=sys.stderr)
            return 2
        rows.append(r)
        print(f"{sc:24s} {r['controller']:16s} share>=0.9 {r['share_in_band_0.9']:.3f}  median {r['median_in_band']:.3f}"
              f"  CVaR10 {r['cvar10_in_band']:.3f}  peak max {r['peak_max_n']:.2f} N  latched {r['latched']}"
              + (f"  within 0.05 of the bound {r['share_within_0.05_of_bound']:.3f} (bound median "
                 f"{r['bound_median_in_band']:.3f}; the sensor bound within 0.05 of it "
                 f"{r['sensor_bound_share_within_0.05_of_bound']:.3f})" if a.bound else ""), flush=True)
    if a.out:
        with open(a.out, "w", encoding="utf-8") as f:
            json.dump({"seed": a.seed, "readers": a.readers, "duration_s": a.duration, "nk": nk,
                       "press_repeatability": a.press_repeatability,
                       "calibration_table": not a.no_table, "rows": rows}, f,
                      indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
