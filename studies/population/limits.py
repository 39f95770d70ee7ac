"""What limits a drawn reader's time in band: the estimate's error or the loop's.

For each reader drawn around a scenario's device (``sample_devices``, calibrated as the
scenario's unit is): the in-band fraction of the true force, the in-band fraction of the
*estimate* around the setpoint (what the loop achieved on the signal it sees), the mean and
RMS of the estimate's error, and the unit's drawn FSR parameters.  A reader whose estimate
stays in band while the force does not is limited by the sensor chain; one whose estimate
leaves the band by the loop.

``--oracle`` removes the two per-unit errors no firmware can know: the film's press-to-press
repeatability (``FSRParams.press_repeatability``, a resistance factor drawn per press) and the
error of the calibration fixture's known loads (the divider at exactly 1 N, the table at its
exact loads).
What the loop still loses then is the rest of the sensor chain and the control.

    python studies/population/limits.py pressing_90wpm --readers 40 --seed 11 --controller dob_hold_1khz
    python studies/population/limits.py pressing_90wpm --readers 40 --seed 11 --controller dob_hold_1khz --oracle
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from ebraille_sim.base.validation import replace_fields
from ebraille_sim.estimation.calibration import TABLE_LOADS_N, calibrate_device, with_calibration_table
from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
from ebraille_sim.scenarios.runner import run_batch
from ebraille_sim.scenarios.spec import load_scenario

BATCH = 50
"""Readers per batch (traces are kept to compute the estimate's error)."""


def readers(scenario: str, n: int, seed: int, oracle: bool = False) -> list:
    """The drawn devices of one scenario; with ``oracle`` without press scatter and calibrated
    (divider and table, as the drawn units are) with exact loads."""
    spec = load_scenario(scenario)
    if not oracle:
        return sample_devices(seed, n, base=spec.device)
    raw = sample_devices(seed, n, PopulationSpec(calibrate=False), base=spec.device)
    exact = [calibrate_device(replace_fields(d, fsr=replace_fields(d.fsr, press_repeatability=0.0))) for d in raw]
    return [with_calibration_table(d, TABLE_LOADS_N) for d in exact]


def decompose(scenario: str, n: int, seed: int, duration_s: float, controller=None, firmware=None,
              oracle: bool = False) -> list[dict]:
    """One row per reader (see the module docstring)."""
    spec = load_scenario(scenario)
    devs = readers(scenario, n, seed, oracle)
    band = spec.setpoint.band_fraction
    start = spec.reading.start_s
    runs = [{"scenario": spec, "seed": spec.seed + 7 * i, "duration_s": duration_s, "device": d,
             **({} if controller is None else {"controller": controller}),
             **({} if firmware is None else {"firmware": firmware})} for i, d in enumerate(devs)]
    rows = []
    for j in range(0, len(runs), BATCH):
        for i, r in enumerate(run_batch(runs[j:j + BATCH], keep_traces=True), start=j):
            if isinstance(r, Exception):
                rows.append({"reader": i, "error": str(r)})
                continue
            tr = r.trace
            read = tr["t_s"] >= start
            f, fe, sp = tr["force_true_n"][read], tr["force_est_n"][read], tr["setpoint_n"][read]
            fsr = devs[i].fsr
            rows.append({"reader": i, "in_band": r.metrics["in_band_fraction"],
                         "estimate_in_band": float(np.mean(np.abs(fe - sp) <= band * sp)),
                         "estimate_error_mean_n": float(np.mean(fe - f)),
                         "estimate_error_rms_n": float(np.sqrt(np.mean((fe - f) ** 2))),
                         "fsr_hysteresis": fsr.hysteresis_fraction, "fsr_creep_per_decade": fsr.creep_per_decade,
                         "fsr_exponent": fsr.exponent, "fsr_k_ohm": fsr.resistance_at_1n_ohm,
                         "latched": (r.supervisor or {}).get("fault")})
    return rows


def summary(rows: list[dict]) -> dict:
    """Shares and quantiles of a decomposition."""
    ok = [r for r in rows if "in_band" in r]
    ib = np.array([r["in_band"] for r in ok])
    est = np.array([r["estimate_in_band"] for r in ok])
    err = np.array([r["estimate_error_mean_n"] for r in ok])
    return {"readers": len(ok), "share_in_band_0.9": float(np.mean(ib >= 0.9)),
            "share_estimate_in_band_0.9": float(np.mean(est >= 0.9)),
            "sensor_limited": int(np.sum((ib < 0.9) & (est >= 0.9))),
            "loop_limited": int(np.sum((ib < 0.9) & (est < 0.9))),
            "estimate_error_mean_n_p10_p50_p90": [float(x) for x in np.percentile(err, [10, 50, 90])]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--readers", type=int, default=40)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--controller", default=None)
    ap.add_argument("--firmware", default=None)
    ap.add_argument("--oracle", action="store_true")
    ap.add_argument("--out", default=None, help="write the rows and the summary as JSON here")
    a = ap.parse_args(argv)
    rows = decompose(a.scenario, a.readers, a.seed, a.duration, a.controller, a.firmware, a.oracle)
    s = summary(rows)
    print(json.dumps(s))
    if a.out:
        with open(a.out, "w", encoding="utf-8") as f:
            json.dump({"args": vars(a), "summary": s, "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
