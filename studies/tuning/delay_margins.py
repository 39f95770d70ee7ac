"""The paper's input delay as an uncertainty: margins and nominal closed loop under nk = 0 and 1.

The paper prints no input delay for its estimators: nk = 0 reads its notation literally,
nk = 1 is MATLAB's convention (the shipped default).  For each shipped controller the linear
model describes (the default PID, the scheduled PID, the scheduled PID with feedforward, the
LQG) this prints the phase margin, gain crossover, gain margin and Ms on the nominal reader at
0.6, 1 and 2 N under both readings (:func:`ebraille_sim.analysis.margins.delay_analyses`), the
largest Ms over the tuning population (5 presets and 8 draws, seed 0) per reading, and the
closed-loop metrics of the nominal reader on five scenarios with the scenarios' controller
(pid_dob) and the default PID.  Writes ``delay_margins.json`` next to this file.

    python studies/tuning/delay_margins.py            # about 1 min on 2 shared cores
"""
from __future__ import annotations

import dataclasses
import json
import math
import pathlib
import sys

import numpy as np

import controllers
from ebraille_sim.analysis.margins import delay_analyses
from ebraille_sim.analysis.robust import family_ms_controller, linearisation_points, population_ms, tuning_population
from ebraille_sim.estimation.registry import with_delay
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import load_scenario

CONTROLLERS = ("pid", "pid_scheduled", "pid_feedforward", "lqg")
FORCES_N = (0.6, 1.0, 2.0)
SCENARIOS = ("steady_90wpm", "contact_onset", "setpoint_steps", "refresh_60wpm", "strap_slip")
METRICS = ("in_band_fraction", "force_rmse_n", "onset_overshoot_fraction", "peak_force_n", "char_in_band_fraction")
HERE = pathlib.Path(__file__).resolve().parent


def _num(x):
    return None if x is None or not math.isfinite(x) else float(x)


def margins() -> list[dict]:
    rows = []
    for name in CONTROLLERS:
        c = controllers.make(name)
        for f in FORCES_N:
            for nk, a in delay_analyses(c, DeviceParams(), f).items():
                rows.append({"controller": name, "force_n": f, "nk": nk, "stable": a.stable,
                             "phase_margin_deg": _num(a.phase_margin_deg),
                             "gain_crossover_hz": _num(a.gain_crossover_hz),
                             "gain_margin": _num(a.gain_margin), "ms": _num(a.ms)})
    return rows


def population() -> list[dict]:
    pop = tuning_population(8, seed=0)
    pts = linearisation_points(pop, FORCES_N)
    rows = []
    for name in CONTROLLERS:
        c = controllers.make(name)
        ctrl = c.statespace() if name == "lqg" else family_ms_controller(c.config)
        ms = population_ms(ctrl, pts)
        for nk in (0, 1):
            sel = np.array([p.nk == nk for p in pts])
            rows.append({"controller": name, "nk": nk, "ms_max": _num(float(np.max(ms[sel]))),
                         "unstable_points": int(np.sum(~np.isfinite(ms[sel]))), "points": int(np.sum(sel))})
    return rows


def closed_loop() -> list[dict]:
    rows = []
    for sc in SCENARIOS:
        spec = load_scenario(sc)
        for ctrl in (None, "pid"):
            for nk in (1, 0):
                est = dataclasses.replace(spec.device.estimator, model=with_delay(spec.device.estimator.model, nk))
                s = dataclasses.replace(spec, device=dataclasses.replace(spec.device, estimator=est))
                r = run_scenario(s, controller=ctrl, duration_s=12.0)
                rows.append({"scenario": sc, "controller": ctrl or spec.controller.name, "nk": nk,
                             **{k: _num(r.metrics.get(k)) for k in METRICS}})
    return rows


def main() -> int:
    doc = {"margins": margins(), "population_ms": population(), "closed_loop": closed_loop()}
    (HERE / "delay_margins.json").write_text(json.dumps(doc, indent=1) + "\n")
    print("| controller | force | nk | PM (deg) | crossover (Hz) | GM | Ms |")
    print("|---|---|---|---|---|---|---|")
    for r in doc["margins"]:
        cells = [f"{r[k]:.1f}" if r[k] is not None else "-" for k in ("phase_margin_deg", "gain_crossover_hz")]
        cells[1] = f"{r['gain_crossover_hz']:.2f}" if r["gain_crossover_hz"] is not None else "-"
        gm = f"{r['gain_margin']:.2f}" if r["gain_margin"] is not None else "inf"
        ms = f"{r['ms']:.2f}" if r["ms"] is not None else "unstable"
        print(f"| {r['controller']} | {r['force_n']:g} N | {r['nk']} | {cells[0]} | {cells[1]} | {gm} | {ms} |")
    print()
    for r in doc["population_ms"]:
        ms = f"{r['ms_max']:.2f}" if r["ms_max"] is not None else "unstable"
        print(f"{r['controller']:16s} nk {r['nk']}: max Ms {ms} over {r['points']} points "
              f"({r['unstable_points']} unstable)")
    print()
    for r in doc["closed_loop"]:
        print(f"{r['scenario']:16s} {r['controller']:8s} nk {r['nk']}: " + "  ".join(
            f"{k} {r[k]:.3f}" for k in METRICS if r[k] is not None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
