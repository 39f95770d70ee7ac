"""Why the 1 kHz design loses steady readers: each failing reader's estimate and force.

For the readers of a scenario that a design holds below 0.9 in band (readers drawn around the
scenario's device, each calibrated as the scenario's unit is; supervisor on), the same reader
and episode seed again with traces, on the design's own firmware and on that firmware with the
hysteresis compensation off.  Per reader, over the reading after ``--after`` seconds: the
in-band fraction, the mean error of the estimate (estimate minus true force), the standard
deviation of the true force and of the estimate, and the unit's drawn hysteresis.  A failing
reader whose estimate swings (its standard deviation far above the force's noise) while the
force is flat on average is one the compensation puts into a loop with the controller; one whose
estimate is flat and off by ~0.1 N reads a unit offset the loop cannot see.

    python studies/population/steady_mechanism.py --readers 1000 --seed 31337 steady_90wpm
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import tempfile

import numpy as np

from ebraille_sim.estimation.presets import get_firmware
from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
from ebraille_sim.scenarios.runner import design_firmware, run_batch
from ebraille_sim.scenarios.spec import load_scenario

HELD = 0.9
"""In-band fraction at which a reader is held."""


def _compensation_off(firmware: str, folder: str) -> str:
    """A preset file: ``firmware`` with the hysteresis compensation off."""
    est = dict(get_firmware(firmware).estimator, hysteresis_compensation=False)
    lines = [f'name = "{pathlib.Path(firmware).stem}_no_hysteresis_compensation"', "[estimator]"]
    lines += [f"{k} = {json.dumps(v)}" for k, v in est.items()]
    path = pathlib.Path(folder) / "off.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return str(path)


def _row(res, after_s: float) -> dict:
    t = res.trace["t_s"]
    m = t > after_s
    f, fe = res.trace["force_true_n"][m], res.trace["force_est_n"][m]
    return {"in_band": round(float(res.metrics["in_band_fraction"]), 3),
            "estimate_error_n": round(float(np.mean(fe - f)), 3),
            "force_sd_n": round(float(np.std(f)), 3), "estimate_sd_n": round(float(np.std(fe)), 3)}


def mechanism(scenario: str, readers: int, seed: int, duration_s: float, design: str, after_s: float) -> dict:
    spec = load_scenario(scenario)
    firmware = design_firmware(design)
    if firmware is None:
        raise ValueError(f"{design!r} is not a design with a firmware preset")
    devs = sample_devices(seed, readers, PopulationSpec(), base=spec.device)
    runs = [{"scenario": spec, "seed": spec.seed + 7 * i, "duration_s": duration_s, "device": d,
             "controller": design} for i, d in enumerate(devs)]
    ib = np.array([r.metrics["in_band_fraction"] for r in run_batch(runs, keep_traces=False)])
    failing = [int(i) for i in np.nonzero(ib < HELD)[0]]
    with tempfile.TemporaryDirectory() as folder:
        off = _compensation_off(firmware, folder)
        on_res = run_batch([runs[i] for i in failing], keep_traces=True)
        off_res = run_batch([{**runs[i], "firmware": off} for i in failing], keep_traces=True)
    rows = [{"reader": i, "hysteresis": round(devs[i].fsr.hysteresis_fraction, 3),
             "exponent": round(devs[i].fsr.exponent, 3), "on": _row(a, after_s), "off": _row(b, after_s)}
            for i, a, b in zip(failing, on_res, off_res)]
    return {"scenario": scenario, "design": design, "firmware": firmware, "readers": readers, "seed": seed,
            "duration_s": duration_s, "share_held": float(np.mean(ib >= HELD)),
            "median_hysteresis_held": float(np.median([d.fsr.hysteresis_fraction for k, d in enumerate(devs)
                                                       if ib[k] >= HELD])),
            "failing": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--readers", type=int, default=300)
    ap.add_argument("--seed", type=int, default=31337)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--design", default="dob_hold_1khz")
    ap.add_argument("--after", type=float, default=3.0, help="the reading window starts here, s")
    ap.add_argument("--out", default=None, help="write the result as JSON here")
    a = ap.parse_args(argv)
    if a.readers < 1:
        print(f"error: --readers must be at least 1, got {a.readers}", file=sys.stderr)
        return 2
    try:
        r = mechanism(a.scenario, a.readers, a.seed, a.duration, a.design, a.after)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{a.scenario} {a.design}: {r['share_held']:.3f} of {a.readers} held; median hysteresis of the held "
          f"{r['median_hysteresis_held']:.3f}")
    print("reader  hyst   | compensation on: in band, estimate error, force sd, estimate sd | off: the same")
    for x in r["failing"]:
        on, off = x["on"], x["off"]
        print(f"{x['reader']:6d}  {x['hysteresis']:.3f}  | {on['in_band']:.3f} {on['estimate_error_n']:+.3f} "
              f"{on['force_sd_n']:.3f} {on['estimate_sd_n']:.3f} | {off['in_band']:.3f} {off['estimate_error_n']:+.3f} "
              f"{off['force_sd_n']:.3f} {off['estimate_sd_n']:.3f}")
    if a.out:
        with open(a.out, "w", encoding="utf-8") as f:
            json.dump(r, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
