"""Robust PID tuning over a population of readers and FSR units.

The gains minimise a tracking cost measured in closed-loop simulation (the nonlinear
plant, :func:`ebraille_sim.runner.run_scenario`) over a population, subject to a
robustness constraint checked on the sampled-data small-signal loop
(:mod:`controllers.tuning`): the sensitivity peak ``Ms <= ms_max`` (1.6 by default) at
every linearisation point, i.e. every device of the population at every setpoint of the
scenario.

Population (:func:`tuning_population`): the three reader presets (soft, nominal, stiff)
with the nominal FSR, the nominal reader with the low-k and high-k FSR presets, and
``n_random`` devices drawn by :func:`ebraille_sim.population.sample_devices` (reader, FSR
unit, motor and drive-train spread); every device's divider is calibrated for its FSR
unit (:func:`ebraille_sim.population.calibrate_device`).

Cost (:func:`tracking_cost`), over the population's runs, with ``e_rel`` the RMS force
error over the reading window divided by the mean setpoint::

    J = median(e_rel) + max(e_rel) + 2 (1 - min(in_band_fraction))

Families (:data:`FAMILIES`): a fixed PID (``"pid"``), or the PID of
:mod:`controllers.schedule` whose gains scale with the pulp stiffness
(``"pid_scheduled"``; the tuned values are its gains at 1 N, and 1 N is added to the
linearisation forces).

Search: Nelder-Mead on ``(ln kp, ln ki, ln kd)`` from the better of two starts (the
default gains and the SIMC rule, each scaled until it meets the Ms bound); a candidate
that violates the bound is charged ``10 + 10 (Ms_max - ms_max)`` without being simulated.
The hand-tuned default PID and the SIMC PID are evaluated on the same runs for the report.

Examples
--------
>>> from controllers.robust import tuning_population
>>> pop = tuning_population(n_random=2, seed=1)
>>> [label for label, _ in pop][:3]
['soft', 'nominal', 'stiff']
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ebraille_sim.params import FINGERS, FSRS, DeviceParams

from .pid import DEFAULT_PID, PID, PIDConfig

__all__ = ["FAMILIES", "tuning_population", "linearisation_points", "population_ms", "evaluate", "tracking_cost",
           "summarise", "robust_tune", "TuneResult", "scenario_setpoints"]


def tuning_population(n_random: int = 8, seed: int = 0, base: DeviceParams = DeviceParams()
                      ) -> list[tuple[str, DeviceParams]]:
    """Labelled devices: presets, FSR presets and ``n_random`` seeded draws (all calibrated)."""
    from ebraille_sim.population import calibrate_device, sample_devices
    if n_random < 0:
        raise ValueError(f"n_random must be >= 0, got {n_random}")
    out = []
    for name in ("soft", "nominal", "stiff"):
        out.append((name, calibrate_device(dataclasses.replace(base, finger=FINGERS[name]))))
    for name in ("low_k", "high_k"):
        out.append((f"fsr_{name}", calibrate_device(dataclasses.replace(base, finger=FINGERS["nominal"],
                                                                        fsr=FSRS[name]))))
    for k, dev in enumerate(sample_devices(seed, n_random, base=base)):
        out.append((f"draw_{k}", dev))
    return out


def scenario_setpoints(spec) -> list[float]:
    """The distinct setpoints of a scenario, sorted (its linearisation forces)."""
    vals = {round(spec.setpoint.force_n, 9)} | {round(f, 9) for _, f in spec.setpoint.steps}
    return sorted(vals)


@dataclass
class _Point:
    label: str
    force_n: float
    device: DeviceParams
    front: tuple


def linearisation_points(population, forces_n) -> list[_Point]:
    """Sampled plant fronts of every device at every force (cached for :func:`population_ms`)."""
    from .tuning import _sampled_front, operating_point
    pts = []
    for label, dev in population:
        for f in forces_n:
            op = operating_point(dev, f)
            pts.append(_Point(label, float(f), dev, _sampled_front(dev, op)))
    return pts


def population_ms(controller, points) -> np.ndarray:
    """Sensitivity peak at every linearisation point (``inf`` where the loop is unstable).

    ``controller`` is a :class:`PIDConfig` or a callable ``force_n -> PIDConfig | StateSpace``
    (a gain schedule).
    """
    import control

    from .tuning import loop_models, sensitivity_peak
    fixed = isinstance(controller, (PIDConfig, control.StateSpace))
    out = np.empty(len(points))
    for j, p in enumerate(points):
        c = controller if fixed else controller(p.force_n)
        loop, _ = loop_models(p.device, p.force_n, c, front=p.front)
        out[j] = sensitivity_peak(loop)
    return out


def evaluate(make_controller, population, spec, seed: int | None = None, duration_s: float | None = None,
             progress=None) -> list[dict]:
    """Run ``spec`` for every device; ``make_controller()`` builds a fresh controller per run.

    Returns one dict per device: ``label`` and the run's metrics.  Each run uses the
    scenario's seed (or ``seed``), so a population is evaluated on identical noise.
    """
    from ebraille_sim.runner import run_scenario
    rows = []
    for label, dev in population:
        d = dataclasses.replace(dev, rates=spec.device.rates, estimator=spec.device.estimator,
                                driver_supply_v=spec.device.driver_supply_v,
                                gravity_m_per_s2=spec.device.gravity_m_per_s2)
        s = dataclasses.replace(spec, device=d)
        res = run_scenario(s, controller=make_controller(), seed=seed, duration_s=duration_s)
        rows.append({"label": label, **res.metrics})
        if progress is not None:
            progress(1)
    return rows


def tracking_cost(rows, mean_setpoint_n: float) -> float:
    """``median(e_rel) + max(e_rel) + 2 (1 - min in_band)`` (module docstring)."""
    e = np.array([r["force_rmse_n"] for r in rows]) / mean_setpoint_n
    ib = np.array([r["in_band_fraction"] for r in rows])
    return float(np.median(e) + np.max(e) + 2.0 * (1.0 - np.min(ib)))


def summarise(rows, keys=("in_band_fraction", "force_rmse_n", "char_in_band_fraction", "peak_force_n",
                          "settling_time_s")) -> dict:
    """Median and worst case of each metric over the population (worst = min for fractions)."""
    out = {}
    for k in keys:
        vals = np.array([np.nan if r[k] is None else r[k] for r in rows], float)
        worst = np.nanmin(vals) if k.endswith("fraction") else np.nanmax(vals)
        out[k] = {"median": float(np.nanmedian(vals)), "worst": float(worst)}
    return out


@dataclass
class TuneResult:
    """Outcome of :func:`robust_tune`."""
    config: PIDConfig
    cost: float
    ms_max: float
    rows: list
    baseline_config: PIDConfig
    baseline_cost: float
    baseline_ms_max: float
    baseline_rows: list
    simc_config: PIDConfig
    simc_cost: float
    simc_ms_max: float
    simc_rows: list
    evaluations: int
    history: list = field(default_factory=list)
    family: str = "pid"

    def gains_file(self) -> dict:
        """The tuned controller as a gains document for ``controllers.make`` / ``run --controller``."""
        g = {k: float(getattr(self.config, k)) for k in ("kp_v_per_n", "ki_v_per_ns", "kd_vs_per_n",
                                                           "derivative_filter_s")}
        return {"controller": self.family, "gains": g}

    def report(self) -> dict:
        def block(cfg, cost, ms, rows):
            return {"gains": {k: float(getattr(cfg, k)) for k in ("kp_v_per_n", "ki_v_per_ns", "kd_vs_per_n",
                                                                  "derivative_filter_s")},
                    "cost": cost, "ms_max": ms, "metrics": summarise(rows),
                    "per_device": [{"label": r["label"], "in_band_fraction": r["in_band_fraction"],
                                    "force_rmse_n": r["force_rmse_n"], "peak_force_n": r["peak_force_n"]}
                                   for r in rows]}
        return {"tuned": block(self.config, self.cost, self.ms_max, self.rows),
                "default": block(self.baseline_config, self.baseline_cost, self.baseline_ms_max, self.baseline_rows),
                "simc": block(self.simc_config, self.simc_cost, self.simc_ms_max, self.simc_rows),
                "family": self.family, "evaluations": self.evaluations}


FAMILIES = ("pid", "pid_scheduled")
"""Controller families :func:`robust_tune` can tune: a fixed PID, or a PID whose gains are
scheduled on force by the pulp stiffness (:mod:`controllers.schedule`; the tuned values
are its gains at 1 N)."""


def _family_tools(family: str, base: PIDConfig):
    """``(config_of(kp, ki, kd), ms_controller(config), make(config))`` for a family."""
    if family == "pid":
        def config_of(kp, ki, kd):
            return dataclasses.replace(base, kp_v_per_n=kp, ki_v_per_ns=ki, kd_vs_per_n=kd)
        return config_of, (lambda cfg: cfg), (lambda cfg: PID(cfg))
    if family == "pid_scheduled":
        from .schedule import ScheduleConfig, ScheduledPID

        def config_of(kp, ki, kd):
            return ScheduleConfig(kp_v_per_n=kp, ki_v_per_ns=ki, kd_vs_per_n=kd,
                                  derivative_filter_s=base.derivative_filter_s, u_min_v=base.u_min_v,
                                  u_max_v=base.u_max_v)
        return config_of, (lambda cfg: ScheduledPID(cfg).pid_config_at), (lambda cfg: ScheduledPID(cfg))
    raise ValueError(f"family must be one of {', '.join(FAMILIES)}, got {family!r}")


def _gains(cfg) -> tuple[float, float, float]:
    return cfg.kp_v_per_n, cfg.ki_v_per_ns, cfg.kd_vs_per_n


def _scaled_to_bound(gains, config_of, ms_of, points, ms_max: float):
    """Scale kp, ki and kd together (bisection on the factor) until max Ms <= ms_max."""
    def scaled(a):
        return config_of(*(a * g for g in gains))
    if np.max(population_ms(ms_of(scaled(1.0)), points)) <= ms_max:
        return scaled(1.0)
    lo, hi = 0.0, 1.0
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        if np.max(population_ms(ms_of(scaled(mid)), points)) <= ms_max:
            lo = mid
        else:
            hi = mid
    return scaled(lo)


def robust_tune(spec, population, *, family: str = "pid", ms_max: float = 1.6, seed: int | None = None,
                duration_s: float | None = None, max_evaluations: int = 40, progress=None,
                base: PIDConfig = DEFAULT_PID) -> TuneResult:
    """Tune the gains of ``family`` for ``spec`` over ``population`` (see the module docstring).

    Parameters
    ----------
    spec : ScenarioSpec
    population : list of (label, DeviceParams)
    family : {"pid", "pid_scheduled"}
        Fixed gains, or gains scheduled on force (tuned at the 1 N reference).
    ms_max : float
        Bound on the sensitivity peak at every linearisation point.
    seed, duration_s : optional
        Passed to every run.
    max_evaluations : int
        Budget of Nelder-Mead cost evaluations (simulated or rejected).
    progress : callable, optional
        Called with the number of finished simulation runs.
    base : PIDConfig
        The hand-tuned baseline; also supplies the limits and the derivative filter.
    """
    import scipy.optimize

    from .tuning import simc_pid
    if not (math.isfinite(ms_max) and ms_max > 1.0):
        raise ValueError(f"ms_max must be > 1, got {ms_max}")
    config_of, ms_of, make = _family_tools(family, base)
    forces = scenario_setpoints(spec)
    points = linearisation_points(population, sorted(set(forces) | ({1.0} if family != "pid" else set())))
    sp_mean = float(np.mean(forces))
    history = []

    def run(mk):
        return evaluate(mk, population, spec, seed=seed, duration_s=duration_s, progress=progress)

    cache = {}

    def cost(x):
        key = tuple(np.round(x, 6))
        if key in cache:
            return cache[key][0]
        cfg = config_of(*np.exp(x))
        ms = float(np.max(population_ms(ms_of(cfg), points)))
        if ms > ms_max:
            c = 10.0 + 10.0 * min(ms - ms_max, 100.0)
            rows = None
        else:
            rows = run(lambda: make(cfg))
            c = tracking_cost(rows, sp_mean)
        history.append({"gains": dict(zip(("kp_v_per_n", "ki_v_per_ns", "kd_vs_per_n"), np.exp(x).tolist())),
                        "ms_max": ms, "cost": c})
        cache[key] = (c, cfg, ms, rows)
        return c

    baseline_rows = run(lambda: PID(base))
    baseline_ms = float(np.max(population_ms(base, points)))
    baseline_cost = tracking_cost(baseline_rows, sp_mean)
    nominal = dict(population).get("nominal", population[0][1])
    simc = simc_pid(nominal, float(np.median(forces)))
    simc = dataclasses.replace(base, kp_v_per_n=simc.kp_v_per_n, ki_v_per_ns=simc.ki_v_per_ns)
    simc_ms = float(np.max(population_ms(simc, points)))
    simc_rows = run(lambda: PID(simc))
    simc_cost = tracking_cost(simc_rows, sp_mean)

    starts = []
    for g in (_gains(base), _gains(simc)):
        c = _scaled_to_bound(g, config_of, ms_of, points, ms_max)
        kp, ki, kd = _gains(c)
        starts.append(np.log([kp, ki, kd if kd > 0 else 0.01 * kp]))
    start_costs = [cost(x) for x in starts]
    x0 = starts[int(np.argmin(start_costs))]
    simplex = np.array([x0, x0 + [0.0, 0.0, 1.5], x0 + [-0.3, 0.0, 0.0], x0 + [0.0, 0.5, 0.0]])
    scipy.optimize.minimize(cost, x0, method="Nelder-Mead",
                            options={"maxfev": max(4, max_evaluations - len(starts)), "initial_simplex": simplex,
                                     "xatol": 0.02, "fatol": 1e-3})
    c, cfg, ms, rows = min(cache.values(), key=lambda v: v[0])
    if rows is None:
        raise RuntimeError(f"no gains met Ms <= {ms_max:g} at every linearisation point")
    return TuneResult(config=cfg, cost=c, ms_max=ms, rows=rows, baseline_config=base, baseline_cost=baseline_cost,
                      baseline_ms_max=baseline_ms, baseline_rows=baseline_rows, simc_config=simc, simc_cost=simc_cost,
                      simc_ms_max=simc_ms, simc_rows=simc_rows, evaluations=len(history), history=history,
                      family=family)
