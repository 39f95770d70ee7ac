"""Which share of drawn readers any firmware could hold: the bounds beside the shipped designs.

For each scenario and each reader drawn around its device (``sample_devices``, each unit
calibrated on its bench as the scenario's is), with the supervisor on and the same episode
seed in every column, the in-band fraction of:

- ``dob_100hz``: the shipped default (``pid_dob`` on ``paper_100hz``);
- ``dob_hold_1khz``: the 1 kHz design with hysteresis compensation;
- ``actuator_bound``: a stiff PID fed the true force (what motor, gearhead and pulp allow);
- ``hysteresis_bound``: the same controller fed the true force through the unit's film
  hysteresis and its exact inverse (what the film's blind stretch after a reversal costs);
- ``sensor_bound_100hz`` / ``sensor_bound_1khz``: the actuator bound's force shifted by the
  estimator's error along it, ``F - (F_est - F)``, on either estimator path: what the finger
  would feel if a loop held the *estimate* as well as the actuator bound holds the force
  (first order, as in the benchmark); ``slow_`` the same with the error averaged over
  :data:`SLOW_S` (a loop passes on the error it can follow, not the estimator's lag of fast
  motion), ``offset_`` with the error's mean over the reading window alone (an estimator whose
  only error is the unit's constant offset);
- the sensor bounds and both designs on the *oracle* units: the same readers without the
  film's press-to-press repeatability and calibrated (divider and table) with exact loads, the
  two per-unit errors no firmware can know; ``dob_hold_1khz`` also without either alone
  (``press_oracle_``: no press scatter; ``load_oracle_``: exact loads).

Beside each column the share of readers at >= 0.9 in band; per reader the force error's mean
(bias) and standard deviation (what moves) over the reading window, the estimate's mean error,
and the drawn parameters (``ebraille_sim.tools.sweep.READER_COLUMNS``).

    python studies/population/reachable.py --readers 300 --seed 31337 --duration 12 \\
        --out studies/population/reachable_31337.json pressing_90wpm everyday_session
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from controllers.bounds import make_hysteresis_bound
from ebraille_sim.base.validation import replace_fields
from ebraille_sim.estimation.calibration import TABLE_LOADS_N, calibrate_device, with_calibration_table
from ebraille_sim.scenarios.metrics import in_band
from ebraille_sim.scenarios.population import PopulationSpec, sample_devices
from ebraille_sim.scenarios.runner import run_batch
from ebraille_sim.scenarios.spec import load_scenario
from ebraille_sim.tools.sweep import READER_COLUMNS

BATCH = 50
"""Readers per batch (traces are kept for the sensor bounds and the error split)."""

COLUMNS = ("dob_100hz", "dob_hold_1khz", "actuator_bound", "hysteresis_bound", "sensor_bound_100hz",
           "sensor_bound_1khz", "slow_sensor_bound_100hz", "slow_sensor_bound_1khz", "offset_sensor_bound_100hz",
           "offset_sensor_bound_1khz", "oracle_sensor_bound_100hz",
           "oracle_sensor_bound_1khz", "slow_oracle_sensor_bound_100hz", "slow_oracle_sensor_bound_1khz",
           "oracle_dob_100hz", "oracle_dob_hold_1khz", "press_oracle_dob_hold_1khz", "load_oracle_dob_hold_1khz")
"""The columns, in the order of the table."""

RUNS = {  # run -> (controller, firmware, oracle (ORACLES), derive the sensor bound)
    "dob_100hz": ("dob_100hz", None, "", False),
    "dob_hold_1khz": ("dob_hold_1khz", None, "", False),
    "actuator_bound": ("actuator_bound", "paper_100hz", "", True),
    "hysteresis_bound": ("hysteresis_bound", None, "", False),
    "actuator_bound_1khz": ("actuator_bound", "fast_1khz", "", True),
    "oracle_actuator_bound": ("actuator_bound", "paper_100hz", "all", True),
    "oracle_actuator_bound_1khz": ("actuator_bound", "fast_1khz", "all", True),
    "oracle_dob_100hz": ("dob_100hz", None, "all", False),
    "oracle_dob_hold_1khz": ("dob_hold_1khz", None, "all", False),
    "press_oracle_dob_hold_1khz": ("dob_hold_1khz", None, "press", False),
    "load_oracle_dob_hold_1khz": ("dob_hold_1khz", None, "load", False),
}
"""The runs behind the columns; an actuator-bound run also gives its path's sensor bound."""

SENSOR_COLUMN = {"actuator_bound": "sensor_bound_100hz", "actuator_bound_1khz": "sensor_bound_1khz",
                 "oracle_actuator_bound": "oracle_sensor_bound_100hz",
                 "oracle_actuator_bound_1khz": "oracle_sensor_bound_1khz"}
"""The sensor bound each actuator-bound run gives; ``slow_`` + it: the bound on the estimate's
error averaged over :data:`SLOW_S`; ``offset_`` + it: on the estimate's mean error over the
reading window alone (an estimator whose only error is the unit's constant offset)."""


ORACLES = ("", "all", "press", "load")
"""Units of a run: as drawn (""), or the same readers without the per-unit errors no firmware can
know: the film's press-to-press repeatability and the fixture's load errors (``"all"``), the
repeatability alone (``"press"``) or the load errors alone (``"load"``)."""


def devices(spec, n: int, seed: int, oracle: str = "") -> list:
    """The drawn readers of ``spec``, each calibrated on its bench as the scenario's unit is; with
    ``oracle`` (:data:`ORACLES`) the same readers without the press scatter (the film's
    ``press_repeatability`` 0, on the bench and in the session) and/or calibrated (divider and
    table) with exact loads."""
    if oracle not in ORACLES:
        raise ValueError(f"oracle must be one of {ORACLES}, got {oracle!r}")
    base = spec.device
    if oracle in ("all", "press"):
        base = replace_fields(base, fsr=replace_fields(base.fsr, press_repeatability=0.0))
    if oracle in ("", "press"):
        return sample_devices(seed, n, PopulationSpec(calibrate=spec.calibrated), base=base)
    raw = sample_devices(seed, n, PopulationSpec(calibrate=False), base=base)
    return [with_calibration_table(calibrate_device(d), TABLE_LOADS_N) for d in raw]


SLOW_S = 0.5
"""Window of the estimate's slow error, s: the part a loop holding its estimate passes on to the force."""

EARLY_S = 2.0
"""The first part of the reading window, s (after the onset), reported apart."""


def _split(t, f, fe, sp, band: float) -> dict:
    """In-band fraction of ``f`` (all, the first :data:`EARLY_S` and the rest), its error's mean
    and standard deviation, the estimate's mean error and in-band fraction."""
    e = f - sp
    ok = in_band(f, sp, band)
    early = t < t[0] + EARLY_S
    return {"in_band": float(np.mean(ok)), "in_band_early": float(np.mean(ok[early])),
            "in_band_late": float(np.mean(ok[~early])) if (~early).any() else None, "bias_n": float(np.mean(e)),
            "spread_n": float(np.std(e)), "estimate_error_n": float(np.mean(fe - f)),
            "estimate_in_band": float(np.mean(in_band(fe, sp, band)))}


def _moving_mean(x, n: int):
    """Centred moving mean of ``x`` over ``n`` samples (shorter at the ends)."""
    c = np.concatenate([[0.0], np.cumsum(x)])
    i = np.arange(len(x))
    lo, hi = np.maximum(i - n // 2, 0), np.minimum(i + n // 2 + 1, len(x))
    return (c[hi] - c[lo]) / (hi - lo)


def column_rows(scenario: str, run: str, n: int, seed: int, duration_s: float) -> dict:
    """``{column: [per-reader dict]}`` of one run kind (an actuator bound adds its three sensor bounds)."""
    spec = load_scenario(scenario)
    controller, firmware, oracle, derive = RUNS[run]
    devs = devices(spec, n, seed, oracle)
    band, start = spec.setpoint.band_fraction, spec.reading.start_s
    out: dict = {run: []}
    if derive:
        out[SENSOR_COLUMN[run]] = []
        out["slow_" + SENSOR_COLUMN[run]] = []
        out["offset_" + SENSOR_COLUMN[run]] = []
    for j in range(0, n, BATCH):
        batch = []
        for i in range(j, min(n, j + BATCH)):
            c = make_hysteresis_bound(devs[i].fsr) if controller == "hysteresis_bound" else controller
            batch.append({"scenario": spec, "seed": spec.seed + 7 * i, "duration_s": duration_s,
                          "device": devs[i], "controller": c,
                          **({} if firmware is None else {"firmware": firmware})})
        for i, r in enumerate(run_batch(batch, keep_traces=True), start=j):
            if isinstance(r, Exception):
                raise ValueError(f"{scenario} {run} reader {i}: {str(r).splitlines()[0]}")
            tr = r.trace
            read = tr["t_s"] >= start
            f, fe, sp = tr["force_true_n"][read], tr["force_est_n"][read], tr["setpoint_n"][read]
            t = tr["t_s"][read]
            row = {"reader": i, **_split(t, f, fe, sp, band), "latched": (r.supervisor or {}).get("fault")}
            out[run].append(row)
            if derive:
                shifted = np.maximum(2.0 * f - fe, 0.0)
                out[SENSOR_COLUMN[run]].append({"reader": i, **_split(t, shifted, f, sp, band), "latched": None})
                n_slow = max(1, int(round(SLOW_S / float(t[1] - t[0]))))
                slow = np.maximum(f - _moving_mean(fe - f, n_slow), 0.0)
                out["slow_" + SENSOR_COLUMN[run]].append({"reader": i, **_split(t, slow, f, sp, band),
                                                          "latched": None})
                offset = np.maximum(f - float(np.mean(fe - f)), 0.0)
                out["offset_" + SENSOR_COLUMN[run]].append({"reader": i, **_split(t, offset, f, sp, band),
                                                            "latched": None})
    return out


def share(rows: list) -> float:
    """Share of readers at >= 0.9 in band."""
    return float(np.mean([r["in_band"] >= 0.9 for r in rows]))


def study(scenario: str, n: int, seed: int, duration_s: float, runs=tuple(RUNS)) -> dict:
    """Every column of one scenario: per-reader rows, shares, the drawn parameters."""
    spec = load_scenario(scenario)
    cols: dict = {}
    for run in runs:
        cols.update(column_rows(scenario, run, n, seed, duration_s))
    cols.pop("actuator_bound_1khz", None)
    for k in [k for k in cols if k.startswith("oracle_actuator") or k.startswith("offset_oracle")]:
        cols.pop(k)
    params = [{col: float(get(d)) for col, get in READER_COLUMNS.items()}
              for d in devices(spec, n, seed)]
    near = {}
    if "actuator_bound" in cols:      # battery_sag's criterion: within 0.05 of the bound on the same reader
        ref = [r["in_band"] for r in cols["actuator_bound"]]
        near = {k: float(np.mean([r["in_band"] >= b - 0.05 for r, b in zip(v, ref)])) for k, v in cols.items()}
    return {"scenario": scenario, "readers": n, "seed": seed, "duration_s": duration_s,
            "shares": {k: share(v) for k, v in cols.items()}, "within_0.05_of_actuator_bound": near,
            "latched": {k: sum(r["latched"] is not None for r in v) for k, v in cols.items()},
            "columns": cols, "parameters": params}


DESIGNS = ("dob_100hz", "dob_hold_1khz", "oracle_dob_100hz", "oracle_dob_hold_1khz")
"""The columns whose failing readers are split by mechanism."""

PARAMETERS = ("finger_b_n_per_m", "relax_c0", "fsr_k_ohm", "fsr_exponent", "fsr_hysteresis", "fsr_creep_per_decade",
              "gear_efficiency", "guide_coulomb_n")
"""Drawn parameters compared between failing and held readers."""

OFFSET_BINS_N = (0.0, 0.02, 0.04, 0.06, np.inf)
"""Bins of the unit's offset (N) for the share held per bin."""


def _median_or_none(x):
    x = [v for v in x if v is not None]
    return round(float(np.median(x)), 4) if x else None


def _q(x, qs=(10, 50, 90)) -> list:
    return [round(float(v), 4) for v in np.percentile(x, qs)]


def summary(result: dict) -> dict:
    """Compact form of :func:`study`: per column its share, quantiles and latches; per design
    column the failing readers by mechanism (the estimate in band or not: sensor- or loop-limited;
    their bias, spread, in-band fraction early and late, parameters against the held readers);
    with both ``dob_hold_1khz`` and its oracle, the unit's offset (the estimate's mean error on
    the drawn unit minus on its oracle twin) and the share held per offset bin."""
    cols, params = result["columns"], result["parameters"]
    out = {k: result[k] for k in ("scenario", "readers", "seed", "duration_s")}
    per = {}
    for k, rows in cols.items():
        ib = np.array([r["in_band"] for r in rows])
        per[k] = {"share_in_band_0.9": round(float(np.mean(ib >= 0.9)), 4), "median": round(float(np.median(ib)), 4),
                  "p5": round(float(np.percentile(ib, 5)), 4), "latched": sum(r["latched"] is not None for r in rows),
                  "bias_n_p10_p50_p90": _q([r["bias_n"] for r in rows]),
                  "spread_n_p50_p90": _q([r["spread_n"] for r in rows], (50, 90)),
                  "estimate_error_n_p10_p50_p90": _q([r["estimate_error_n"] for r in rows])}
        if k in result.get("within_0.05_of_actuator_bound", {}):
            per[k]["within_0.05_of_actuator_bound"] = round(result["within_0.05_of_actuator_bound"][k], 4)
    out["columns"] = per
    mech = {}
    for k in DESIGNS:
        if k not in cols:
            continue
        rows = cols[k]
        fail = np.array([r["in_band"] < 0.9 for r in rows])
        est = np.array([r["estimate_in_band"] >= 0.9 for r in rows])
        m = {"failing": int(fail.sum()), "sensor_limited": int(np.sum(fail & est)),
             "loop_limited": int(np.sum(fail & ~est))}
        for lab, sel in (("failing", fail), ("held", ~fail)):
            if not sel.any():
                continue
            pick = [r for r, s_ in zip(rows, sel) if s_]
            m[lab + "_readers"] = {
                "abs_bias_n_p50": round(float(np.median([abs(r["bias_n"]) for r in pick])), 4),
                "spread_n_p50": round(float(np.median([r["spread_n"] for r in pick])), 4),
                "estimate_error_n_p10_p50_p90": _q([r["estimate_error_n"] for r in pick]),
                "in_band_early_p50": round(float(np.median([r["in_band_early"] for r in pick])), 4),
                "in_band_late_p50": _median_or_none([r["in_band_late"] for r in pick]),
                "parameters_p50": {n: round(float(np.median([params[r["reader"]][n] for r in pick])), 5)
                                   for n in PARAMETERS}}
        m["worst"] = [{"reader": r["reader"], "in_band": round(r["in_band"], 4), "bias_n": round(r["bias_n"], 4),
                       "spread_n": round(r["spread_n"], 4), "estimate_error_n": round(r["estimate_error_n"], 4),
                       **{n: round(params[r["reader"]][n], 5) for n in PARAMETERS}}
                      for r in sorted(rows, key=lambda r: r["in_band"])[:5]]
        mech[k] = m
    out["mechanism"] = mech
    if "dob_hold_1khz" in cols and "oracle_dob_hold_1khz" in cols:
        off = np.array([a["estimate_error_n"] - b["estimate_error_n"]
                        for a, b in zip(cols["dob_hold_1khz"], cols["oracle_dob_hold_1khz"])])
        held = np.array([r["in_band"] >= 0.9 for r in cols["dob_hold_1khz"]])
        bins = []
        for lo, hi in zip(OFFSET_BINS_N[:-1], OFFSET_BINS_N[1:]):
            sel = (np.abs(off) >= lo) & (np.abs(off) < hi)
            bins.append({"abs_offset_n": [lo, None if np.isinf(hi) else hi], "readers": int(sel.sum()),
                         "share_held": None if not sel.any() else round(float(np.mean(held[sel])), 4)})
        out["unit_offset"] = {"sd_n": round(float(np.std(off)), 4), "share_above_0.05_n": round(float(np.mean(
            np.abs(off) > 0.05)), 4), "dob_hold_1khz_by_offset": bins}
    return out


def table(summaries: list, key: str = "share_in_band_0.9") -> str:
    """Markdown: ``key`` of every column (default the share at >= 0.9 in band), one row per scenario."""
    cols = [c for c in COLUMNS if any(c in r["columns"] and key in r["columns"][c] for r in summaries)]
    lines = ["| scenario (readers, seed, s) | " + " | ".join(f"`{c}`" for c in cols) + " |",
             "|---|" + "---|" * len(cols)]
    for r in summaries:
        lines.append(f"| {r['scenario']} ({r['readers']}, {r['seed']}, {r['duration_s']:g}) | " + " | ".join(
            f"{r['columns'][c][key]:.3f}" if c in r["columns"] and key in r["columns"][c] else "" for c in cols)
            + " |")
    return "\n".join(lines)


def mechanism_table(summaries: list) -> str:
    """Markdown: the failing readers of each design column by mechanism."""
    lines = ["| scenario (seed) | design | failing | sensor-limited | loop-limited | failing: abs bias / spread (N) "
             "| held: abs bias / spread (N) | failing: in band early / late | failing: FSR hysteresis, exponent "
             "(held) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in summaries:
        for k, m in r["mechanism"].items():
            f, h = m.get("failing_readers"), m.get("held_readers")
            fp = "" if f is None else (f"{f['parameters_p50']['fsr_hysteresis']:.3f}, {f['parameters_p50']['fsr_exponent']:.3f}"
                                       + ("" if h is None else f" ({h['parameters_p50']['fsr_hysteresis']:.3f}, "
                                          f"{h['parameters_p50']['fsr_exponent']:.3f})"))
            lines.append(f"| {r['scenario']} ({r['seed']}) | `{k}` | {m['failing']} | {m['sensor_limited']} | "
                         f"{m['loop_limited']} | "
                         + ("" if f is None else f"{f['abs_bias_n_p50']:.3f} / {f['spread_n_p50']:.3f}") + " | "
                         + ("" if h is None else f"{h['abs_bias_n_p50']:.3f} / {h['spread_n_p50']:.3f}") + " | "
                         + ("" if f is None else f"{f['in_band_early_p50']:.2f} / {f['in_band_late_p50'] if f['in_band_late_p50'] is None else round(f['in_band_late_p50'], 2)}")
                         + f" | {fp} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*")
    ap.add_argument("--readers", type=int, default=100)
    ap.add_argument("--seed", type=int, default=31337)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--runs", default=",".join(RUNS), help="comma-separated runs (default: all): " + ", ".join(RUNS))
    ap.add_argument("--out", default=None, help="write the summaries (shares, quantiles, mechanisms) as JSON here")
    ap.add_argument("--rows", default=None, help="write every reader's row as JSON here")
    ap.add_argument("--tables", nargs="+", default=None, metavar="JSON",
                    help="print the tables of summaries written with --out (no runs)")
    a = ap.parse_args(argv)
    if a.tables:
        try:
            sums = [r for path in a.tables for r in json.load(open(path, encoding="utf-8"))["results"]]
        except (OSError, ValueError, KeyError) as exc:
            print(f"error: --tables: {str(exc).splitlines()[0]}", file=sys.stderr)
            return 2
        print("Share of readers at >= 0.9 in band", "", table(sums), "",
              "Share of readers within 0.05 of the actuator bound's in-band fraction on the same reader", "",
              table(sums, "within_0.05_of_actuator_bound"), "", "Failing readers by mechanism", "",
              mechanism_table(sums), sep="\n")
        return 0
    runs = [r.strip() for r in a.runs.split(",") if r.strip()]
    bad = [r for r in runs if r not in RUNS]
    if not a.scenarios or bad or not 1 <= a.readers <= 5000 or not a.duration > 0:
        print("error: " + ("give one or more scenarios (or --tables)" if not a.scenarios else
                           f"unknown run {bad[0]!r}" if bad else f"--readers must be 1-5000, got {a.readers}"
                           if not 1 <= a.readers <= 5000 else f"--duration must be > 0 s, got {a.duration:g}"),
              file=sys.stderr)
        return 2
    results = []
    for sc in a.scenarios:
        try:
            results.append(study(sc, a.readers, a.seed, a.duration, runs))
        except (ValueError, FileNotFoundError) as exc:
            print(f"error: {sc}: {str(exc).splitlines()[0]}", file=sys.stderr)
            return 2
        print(sc, json.dumps(results[-1]["shares"]), "latched", json.dumps(results[-1]["latched"]), flush=True)
    sums = [summary(r) for r in results]
    print(table(sums), "", mechanism_table(sums), sep="\n")
    if a.out:
        with open(a.out, "w", encoding="utf-8") as f:
            json.dump({"args": vars(a), "results": sums}, f, indent=1)
    if a.rows:
        with open(a.rows, "w", encoding="utf-8") as f:
            json.dump({"args": vars(a), "results": results}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
