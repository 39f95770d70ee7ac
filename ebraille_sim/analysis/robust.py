"""Robust PID tuning over a population of readers and FSR units, on several scenarios.

The gains minimise a tracking cost measured in closed-loop simulation (the nonlinear
plant, :func:`ebraille_sim.scenarios.runner.run_scenario`) over a population and a set of scenarios,
subject to a robustness constraint checked on the sampled-data small-signal loop
(:mod:`ebraille_sim.analysis.margins`): the sensitivity peak ``Ms <= ms_max`` (1.6 by default) at
every linearisation point, i.e. every device of the population at every setpoint of every
scenario under both readings of the paper's input delay.

The input delay is an uncertainty (:func:`linearisation_points`).  The paper prints no ``nk``
for its estimators; read literally its notation gives ``nk = 0``, MATLAB's convention
``nk = 1`` (:mod:`ebraille_sim.estimation.paper_models`), 10 ms apart at 100 Hz.  Every device
whose estimator is a paper model at its own rate is linearised with both
(:func:`ebraille_sim.analysis.margins.delay_devices`), so the gains meet the bound whichever
reading the board's estimator runs; an estimator re-discretised at another rate or read from a
file has no delay to choose and is linearised once.

Population (:func:`tuning_population`): the three reader presets (soft, nominal, stiff)
with the nominal FSR, the nominal reader with the low-k and high-k FSR presets, and
``n_random`` devices drawn by :func:`ebraille_sim.scenarios.population.sample_devices` (reader, FSR
unit, motor and drive-train spread); every device's divider is calibrated for its FSR
unit (:func:`ebraille_sim.estimation.calibration.calibrate_device`).

Scenarios (:func:`standard_scenarios`): steady reading at 90 wpm shortened to 12 s, the
contact onset, the setpoint steps, the same steps without their 0.3 s ramp
(:func:`unramped`), and a strap slip (the pulp moves 0.2 mm away at 8 s) shortened to 14 s.
One fixed PID or one schedule has to serve all of them, which is what keeps a design tuned
on the setpoint steps from hunting in steady reading or recovering slowly from a slip.

Cost (:func:`scenario_cost`, :func:`multi_cost`), per scenario over the population's runs,
``ib`` the in-band fractions, ``e_rel`` the RMS force errors over the mean setpoint, ``pk``
the peak true forces (N), ``sp`` the largest setpoint of the scenario::

    c = 2 (1 - min ib) + (1 - CVaR25 ib) + (median e_rel + max e_rel) / 2
        + 2 max(0, max pk / sp - 1.15) + 2 max(0, max pk - 3)

(``CVaR25`` the mean of the worst quarter of the devices, at least one; the overshoot term
is the contact-onset bound of 15 %, the last the tactile cap); the tuning cost is the mean
of ``c`` over the scenarios.

The robustness model (``ms_gain``).  The linearised loop describes the **sliding** drive:
Coulomb friction has no small-signal term.  Around a held force the drive sticks inside
its friction band, which behaves like a play operator of about 0.7 V (nominal device at
1 N, :func:`friction_band_v`) at the command; its describing function has a gain
``|N(A)| < 1`` that falls to zero as the oscillation amplitude ``A`` approaches the play's
half-width (and a phase lag of up to 90 deg).  ``ms_gain`` multiplies the loop by a real
factor ``kappa``: 1 (default) is the sliding model (the loop linearised with the friction sliding); ``kappa < 1`` is the
describing-function relaxation (``kappa = 0.5``: oscillations of about twice the band;
see docs/tuning.md for the measured describing function and for why the phase lag the
argument leaves out makes this relaxation optimistic).

Families (:data:`FAMILIES`): a fixed PID (``"pid"``); the PID of
:mod:`controllers.schedule` whose gains scale with the pulp stiffness, with the static
reference map (``"pid_scheduled"``; the tuned values are its gains at 1 N, and 1 N is
added to the linearisation forces); the same with the friction-band feedforward
(``"pid_feedforward"``).

Search: Nelder-Mead on ``(ln kp, ln ki, ln(kd + 1e-3))``.  Starts: the hand-tuned default
gains (kp 2, ki 8, kd 0) as they are when they meet the bound, otherwise scaled down
together until they do; the SIMC rule, scaled the same way; the default kp with ki/kp = 1,
2 and 16 1/s (other integral times), scaled the same way; the best start is refined.  A
candidate that violates the bound is charged ``10 + 10 (Ms_max - ms_max)`` without being
simulated.  The hand-tuned default PID, the SIMC PID, the family at the default gains
(``"hand"``) and the shipped controller of the family (``"shipped"``,
:func:`shipped_config`; for ``"pid"`` it is the default PID) are evaluated on the same
runs for the report.

Selection: the result is the search optimum unless the shipped controller of the family
has a lower cost on the named (first) scenario; then the shipped controller is kept
(:attr:`TuneResult.selected`, with the reason in :attr:`TuneResult.selection_reason`),
even where it exceeds the Ms bound, which the reason states.

Examples
--------
>>> from ebraille_sim.analysis.robust import tuning_population
>>> pop = tuning_population(n_random=2, seed=1)
>>> [label for label, _ in pop][:3]
['soft', 'nominal', 'stiff']
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ebraille_sim.physics.params import FINGERS, FSRS, TACTILE_FORCE_MAX_N, DeviceParams, unit_estimator

from controllers.pid import DEFAULT_PID, PID, PIDConfig

__all__ = ["FAMILIES", "TuneScenario", "tuning_population", "standard_scenarios", "unramped",
           "linearisation_points", "population_ms", "evaluate", "evaluate_scenarios", "tracking_cost",
           "scenario_cost", "multi_cost", "summarise", "cvar", "robust_tune", "TuneResult", "scenario_setpoints",
           "family_config", "family_controller", "family_ms_controller", "gains_document", "gains_toml", "toml_value",
           "friction_band_v", "shipped_config", "KD_OFFSET", "point_labels"]

KD_OFFSET = 1e-3
"""kd enters the search as ``ln(kd + KD_OFFSET)``, so that kd = 0 is a finite point."""

START_KI_OVER_KP = (1.0, 2.0, 16.0)
"""Integral-to-proportional ratios (1/s) of the extra starts (the default PID has 4)."""


def tuning_population(n_random: int = 8, seed: int = 0, base: DeviceParams = DeviceParams()
                      ) -> list[tuple[str, DeviceParams]]:
    """Labelled devices: presets, FSR presets and ``n_random`` seeded draws (all calibrated)."""
    from ebraille_sim.estimation.calibration import calibrate_device
    from ebraille_sim.scenarios.population import sample_devices
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


@dataclass(frozen=True)
class TuneScenario:
    """One scenario of the tuning cost: a label, the parsed spec, an optional duration (s)."""
    name: str
    spec: object
    duration_s: float | None = None


def unramped(spec):
    """``spec`` with its setpoint steps taken at once (``ramp_s = 0``), renamed ``NAME_unramped``."""
    return dataclasses.replace(spec, name=f"{spec.name}_unramped",
                               setpoint=dataclasses.replace(spec.setpoint, ramp_s=0.0))


def with_estimator(spec, estimator):
    """``spec`` with its device's ``[estimator]`` settings replaced by ``estimator``."""
    if spec.device.estimator == estimator:
        return spec
    return dataclasses.replace(spec, device=dataclasses.replace(spec.device, estimator=estimator))


def standard_scenarios(primary=None, steady_s: float = 12.0, slip_s: float = 14.0) -> list[TuneScenario]:
    """The tuning set: ``steady_90wpm`` (shortened to ``steady_s``), ``contact_onset``,
    ``setpoint_steps``, ``setpoint_steps`` without its ramp, and ``strap_slip`` shortened to
    ``slip_s`` (one 0.2 mm slip of the pulp away from the board at 8 s, at 1 N).

    ``primary`` (a parsed spec) comes first; it replaces the shipped scenario of the same
    name, and a ramped primary also brings its unramped twin.  Every scenario of the set
    runs with the primary's ``[estimator]`` settings (:func:`with_estimator`), so that a
    primary with another estimator (e.g. ``paper:wiener:5@1000``) tunes for that estimator
    in every run, as the Ms check does on a population built on the primary's device.
    """
    from ebraille_sim.scenarios.spec import load_scenario
    out = []
    if primary is not None:
        dur = steady_s if (primary.name.startswith("steady_") and primary.duration_s is None) else None
        out.append(TuneScenario(primary.name, primary, dur))
        if primary.setpoint.steps and primary.setpoint.ramp_s > 0:
            u = unramped(primary)
            out.append(TuneScenario(u.name, u, None))
    steps = load_scenario("setpoint_steps")
    for sc in (TuneScenario("steady_90wpm", load_scenario("steady_90wpm"), steady_s),
               TuneScenario("contact_onset", load_scenario("contact_onset"), None),
               TuneScenario("setpoint_steps", steps, None),
               TuneScenario("setpoint_steps_unramped", unramped(steps), None),
               TuneScenario("strap_slip", load_scenario("strap_slip"), slip_s)):
        if sc.name not in {s.name for s in out}:
            if primary is not None:
                sc = TuneScenario(sc.name, with_estimator(sc.spec, primary.device.estimator), sc.duration_s)
            out.append(sc)
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
    nk: int | None = None
    """Input delay of the estimator at this point (samples; None: no delay to choose)."""


def linearisation_points(population, forces_n, delays: bool = True) -> list[_Point]:
    """Sampled plant fronts of every device at every force, under both readings of the
    paper's input delay (cached for :func:`population_ms`).

    Order: device, then delay reading (:func:`ebraille_sim.analysis.margins.delay_devices`),
    then force.  ``delays=False`` linearises each device with its estimator as given (one
    reading).
    """
    from ebraille_sim.analysis.margins import delay_devices
    from ebraille_sim.analysis.plant_model import operating_point
    from ebraille_sim.analysis.sampled import sampled_front
    pts = []
    for label, dev in population:
        for nk, d in delay_devices(dev, delays):
            for f in forces_n:
                op = operating_point(d, f)
                pts.append(_Point(label, float(f), d, sampled_front(d, op), nk))
    return pts


def point_labels(points, n_forces: int) -> list[str]:
    """One label per row of a points-by-force table: the device, with its delay reading
    (``"nominal, nk 0"``) where the device was linearised under both."""
    rows = points[::n_forces]
    return [p.label if p.nk is None else f"{p.label}, nk {p.nk}" for p in rows]


def population_ms(controller, points, gain: float = 1.0) -> np.ndarray:
    """Sensitivity peak at every linearisation point (``inf`` where the loop is unstable).

    ``controller`` is a :class:`PIDConfig`, a ``StateSpace`` or a callable
    ``force_n -> PIDConfig | StateSpace`` (a gain schedule).  ``gain`` multiplies the loop
    transfer (the describing-function factor ``kappa`` of the module docstring; 1 is the
    sliding model).
    """
    import control

    from ebraille_sim.analysis.margins import sensitivity_peak
    from ebraille_sim.analysis.sampled import loop_models
    if not (math.isfinite(gain) and gain > 0):
        raise ValueError(f"gain must be finite and > 0, got {gain}")
    fixed = isinstance(controller, (PIDConfig, control.StateSpace))
    out = np.empty(len(points))
    for j, p in enumerate(points):
        c = controller if fixed else controller(p.force_n)
        loop, _ = loop_models(p.device, p.force_n, c, front=p.front)
        if gain != 1.0:
            loop = control.ss(loop.A, gain * loop.B, loop.C, loop.D, dt=loop.dt)
        out[j] = sensitivity_peak(loop)
    return out


def evaluate(make_controller, population, spec, seed: int | None = None, duration_s: float | None = None,
             progress=None) -> list[dict]:
    """Run ``spec`` for every device; ``make_controller()`` builds a fresh controller per run.

    Returns one dict per device: ``label`` and the run's metrics.  Each run uses the
    scenario's seed (or ``seed``), so a population is evaluated on identical noise.
    """
    from ebraille_sim.scenarios.runner import run_scenario
    rows = []
    for label, dev in population:
        d = dataclasses.replace(dev, rates=spec.device.rates, estimator=unit_estimator(spec.device.estimator,
                                                                                      dev.estimator),
                                driver_supply_v=spec.device.driver_supply_v,
                                gravity_m_per_s2=spec.device.gravity_m_per_s2)
        s = dataclasses.replace(spec, device=d)
        res = run_scenario(s, controller=make_controller(), seed=seed, duration_s=duration_s)
        rows.append({"label": label, **res.metrics})
        if progress is not None:
            progress(1)
    return rows


def evaluate_scenarios(make_controller, population, scenarios, seed: int | None = None,
                       progress=None) -> dict:
    """:func:`evaluate` on every :class:`TuneScenario`; ``{name: rows}``."""
    return {sc.name: evaluate(make_controller, population, sc.spec, seed=seed, duration_s=sc.duration_s,
                              progress=progress) for sc in scenarios}


def cvar(values, fraction: float = 0.25, worst: str = "low") -> float:
    """Mean of the worst ``fraction`` of ``values`` (at least one); ``worst`` "low" or "high"."""
    v = np.sort(np.asarray(values, float))
    if worst == "high":
        v = v[::-1]
    k = max(1, int(math.ceil(fraction * len(v))))
    return float(np.mean(v[:k]))


def tracking_cost(rows, mean_setpoint_n: float) -> float:
    """The single-scenario cost of earlier versions:
    ``median(e_rel) + max(e_rel) + 2 (1 - min in_band)``."""
    e = np.array([r["force_rmse_n"] for r in rows]) / mean_setpoint_n
    ib = np.array([r["in_band_fraction"] for r in rows])
    return float(np.median(e) + np.max(e) + 2.0 * (1.0 - np.min(ib)))


def scenario_cost(rows, mean_setpoint_n: float, max_setpoint_n: float | None = None,
                  peak_limit_n: float = TACTILE_FORCE_MAX_N) -> float:
    """``2 (1 - min ib) + (1 - CVaR25 ib) + (median e_rel + max e_rel)/2
    + 2 max(0, max pk / max sp - 1.15) + 2 max(0, max pk - 3 N)`` (module docstring)."""
    e = np.array([r["force_rmse_n"] for r in rows]) / mean_setpoint_n
    ib = np.array([r["in_band_fraction"] for r in rows])
    pk = float(np.max([r["peak_force_n"] for r in rows]))
    sp = mean_setpoint_n if max_setpoint_n is None else max_setpoint_n
    return float(2.0 * (1.0 - np.min(ib)) + (1.0 - cvar(ib)) + 0.5 * (np.median(e) + np.max(e))
                 + 2.0 * max(0.0, pk / sp - 1.15) + 2.0 * max(0.0, pk - peak_limit_n))


def multi_cost(rows_by_scenario: dict, scenarios) -> float:
    """Mean of :func:`scenario_cost` over the scenarios."""
    vals = []
    for sc in scenarios:
        sps = scenario_setpoints(sc.spec)
        vals.append(scenario_cost(rows_by_scenario[sc.name], float(np.mean(sps)), float(np.max(sps))))
    return float(np.mean(vals))


def summarise(rows, keys=("in_band_fraction", "force_rmse_n", "char_in_band_fraction", "peak_force_n",
                          "settling_time_s")) -> dict:
    """Median, worst case and CVaR25 (mean of the worst quarter) of each metric over the
    population (worst = min for fractions, max otherwise)."""
    out = {}
    for k in keys:
        vals = np.array([np.nan if r.get(k) is None else r[k] for r in rows], float)
        frac = k.endswith("fraction")
        fin = vals[~np.isnan(vals)]
        if not fin.size:
            out[k] = {"median": math.nan, "worst": math.nan, "cvar25": math.nan}
            continue
        worst = np.min(fin) if frac else np.max(fin)
        out[k] = {"median": float(np.median(fin)), "worst": float(worst),
                  "cvar25": cvar(fin, 0.25, "low" if frac else "high")}
    return out


FAMILIES = ("pid", "pid_scheduled", "pid_feedforward")
"""Controller families :func:`robust_tune` can tune: a fixed PID; a PID whose gains are
scheduled on force by the pulp stiffness, with the static reference map
(:mod:`controllers.schedule`; the tuned values are its gains at 1 N); the same with the
friction-band feedforward."""

_SCHEDULE_SWITCHES = {"pid_scheduled": {"schedule": True, "reference_map": True, "feedforward": False},
                      "pid_feedforward": {"schedule": True, "reference_map": True, "feedforward": True}}


def family_config(family: str, kp: float, ki: float, kd: float, base: PIDConfig = DEFAULT_PID):
    """The configuration of ``family`` with gains ``(kp, ki, kd)`` (at 1 N for a schedule)."""
    if family == "pid":
        return dataclasses.replace(base, kp_v_per_n=float(kp), ki_v_per_ns=float(ki), kd_vs_per_n=float(kd))
    if family in _SCHEDULE_SWITCHES:
        from controllers.schedule import ScheduleConfig
        return ScheduleConfig(kp_v_per_n=float(kp), ki_v_per_ns=float(ki), kd_vs_per_n=float(kd),
                              derivative_filter_s=base.derivative_filter_s, u_min_v=base.u_min_v,
                              u_max_v=base.u_max_v, **_SCHEDULE_SWITCHES[family])
    raise ValueError(f"family must be one of {', '.join(FAMILIES)}, got {family!r}")


def family_controller(cfg, family: str | None = None):
    """A fresh controller for a configuration of :func:`family_config`."""
    if isinstance(cfg, PIDConfig):
        return PID(cfg)
    from controllers.schedule import ScheduledPID
    return ScheduledPID(cfg, name=family or ("pid_feedforward" if cfg.feedforward else "pid_scheduled"))


def shipped_config(family: str):
    """The configuration ``controllers.make(family)`` builds: the shipped controller of ``family``."""
    import controllers
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {', '.join(FAMILIES)}, got {family!r}")
    return controllers.make(family).config


def family_ms_controller(cfg):
    """What :func:`population_ms` needs: the fixed config, or the schedule ``force -> PIDConfig``."""
    if isinstance(cfg, PIDConfig):
        return cfg
    from controllers.schedule import ScheduledPID
    return ScheduledPID(cfg).pid_config_at


def gains_document(cfg, family: str) -> dict:
    """``{"controller": name, "gains": {...}}`` for ``controllers.make`` / ``run --controller``.

    For a schedule every :class:`~controllers.schedule.ScheduleConfig` field is written, so
    the file does not depend on the factory's defaults.
    """
    if isinstance(cfg, PIDConfig):
        g = {k: float(getattr(cfg, k)) for k in ("kp_v_per_n", "ki_v_per_ns", "kd_vs_per_n", "derivative_filter_s")}
        return {"controller": "pid", "gains": g}
    g = {}
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if v is not None:                  # None = derived (e.g. tracking_time_s); TOML has no null
            g[f.name] = v if isinstance(v, (bool, str)) else float(v)
    return {"controller": family, "gains": g}


def toml_value(v) -> str:
    """A TOML literal of a bool, string, whole number or float (infinities as ``inf``).

    >>> toml_value(True), toml_value("pid"), toml_value(3), toml_value(float("inf")), toml_value(0.5)
    ('true', '"pid"', '3', 'inf', '0.5')
    """
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, int):
        return str(v)
    v = float(v)
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return repr(v)


def gains_toml(doc: dict, comment: str = "") -> str:
    """A gains document (:func:`gains_document`, ``{"controller": name, "gains": {...}}``) as the
    text of a TOML gains file for ``controllers.make`` / ``run --controller``; each line of
    ``comment`` becomes a ``#`` line at the top.

    >>> doc = {"controller": "pid_scheduled", "gains": {"kp_v_per_n": 1.5, "reference_map": True}}
    >>> print(gains_toml(doc, "tuned"), end="")
    # tuned
    controller = "pid_scheduled"
    <BLANKLINE>
    [gains]
    kp_v_per_n = 1.5
    reference_map = true
    """
    lines = [f"# {line}" for line in comment.splitlines()]
    lines += [f'controller = "{doc["controller"]}"', "", "[gains]"]
    lines += [f"{k} = {toml_value(v)}" for k, v in doc["gains"].items()]
    return "\n".join(lines) + "\n"


def _gains(cfg) -> tuple[float, float, float]:
    return cfg.kp_v_per_n, cfg.ki_v_per_ns, cfg.kd_vs_per_n


def _scaled_to_bound(gains, config_of, points, ms_max: float, ms_gain: float):
    """Scale kp, ki and kd together (bisection on the factor) until max Ms <= ms_max."""
    def scaled(a):
        return config_of(*(a * g for g in gains))

    def ms(a):
        return float(np.max(population_ms(family_ms_controller(scaled(a)), points, ms_gain)))
    if ms(1.0) <= ms_max:
        return scaled(1.0), 1.0
    lo, hi = 0.0, 1.0
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        if ms(mid) <= ms_max:
            lo = mid
        else:
            hi = mid
    return scaled(lo), lo


def friction_band_v(device: DeviceParams = DeviceParams(), force_n: float = 1.0) -> float:
    """Width of the drive's kinetic friction band at ``force_n``, in command volts.

    The difference between the commands that hold ``force_n`` at the pressing and at the
    releasing edge (:func:`ebraille_sim.analysis.plant_model.operating_point`); inside it the drive
    sticks, so for small signals the drive acts as a play operator of this width.
    """
    from ebraille_sim.analysis.plant_model import operating_point
    return float(operating_point(device, force_n, friction="press").command_v
                 - operating_point(device, force_n, friction="release").command_v)


@dataclass
class Candidate:
    """One evaluated controller: configuration, cost, Ms at every linearisation point, runs."""
    config: object
    family: str
    cost: float
    ms: np.ndarray
    """Ms per linearisation point (population x forces, row-major), ``inf`` if unstable."""
    rows: dict
    """``{scenario name: per-device metric rows}``."""

    @property
    def ms_max(self) -> float:
        return float(np.max(self.ms))

    def block(self, scenarios, labels, forces) -> dict:
        """The report entry of this controller (``ms_table``: one row per device and delay reading)."""
        doc = gains_document(self.config, self.family)
        ms = np.asarray(self.ms, float).reshape(-1, len(forces))
        return {"controller": doc["controller"], "gains": doc["gains"], "cost": self.cost, "ms_max": self.ms_max,
                "ms_table": np.where(np.isfinite(ms), ms, -1.0).tolist(),
                "scenarios": {sc.name: {"metrics": summarise(self.rows[sc.name]),
                                        "per_device": [{"label": r["label"], "in_band_fraction": r["in_band_fraction"],
                                                        "force_rmse_n": r["force_rmse_n"],
                                                        "peak_force_n": r["peak_force_n"]}
                                                       for r in self.rows[sc.name]]}
                              for sc in scenarios},
                # the first scenario's summary, as in the single-scenario report
                "metrics": summarise(self.rows[scenarios[0].name]),
                "per_device": [{"label": r["label"], "in_band_fraction": r["in_band_fraction"],
                                "force_rmse_n": r["force_rmse_n"], "peak_force_n": r["peak_force_n"]}
                               for r in self.rows[scenarios[0].name]]}


@dataclass
class TuneResult:
    """Outcome of :func:`robust_tune`."""
    tuned: Candidate
    references: dict
    """``{"default": ..., "simc": ..., "hand": ...}``: :class:`Candidate` of the hand-tuned
    default PID, the SIMC PID and the family at the default gains."""
    scenarios: list
    labels: list
    forces_n: list
    ms_bound: float
    ms_gain: float
    evaluations: int
    history: list = field(default_factory=list)
    family: str = "pid"
    start_scale: float = 1.0
    """Factor the default gains were scaled by to meet the bound (1: they meet it)."""
    selected: str = "tuned"
    """The controller returned: ``"tuned"`` (the search optimum) or the key in
    :attr:`references` of the shipped controller that beat it on the named scenario."""
    selection_reason: str = ""
    """Why the shipped controller was kept instead of the optimum (empty when it was not)."""
    ms_labels: list = field(default_factory=list)
    """Rows of the Ms tables: each device, with its delay reading where it has two
    (:func:`point_labels`)."""
    delays: list = field(default_factory=list)
    """Readings of the paper's input delay in the Ms check (samples; empty: none to choose)."""

    @property
    def chosen(self) -> Candidate:
        """The candidate returned (:attr:`selected`)."""
        return self.tuned if self.selected == "tuned" else self.references[self.selected]

    # single-scenario era attribute names, of the controller returned
    @property
    def config(self):
        return self.chosen.config

    @property
    def cost(self) -> float:
        return self.chosen.cost

    @property
    def ms_max(self) -> float:
        return self.chosen.ms_max

    @property
    def rows(self) -> list:
        return self.chosen.rows[self.scenarios[0].name]

    @property
    def baseline_config(self):
        return self.references["default"].config

    @property
    def baseline_rows(self) -> list:
        return self.references["default"].rows[self.scenarios[0].name]

    def named_cost(self, key: str = "tuned") -> float:
        """:func:`scenario_cost` of a controller (``"tuned"`` or a reference key) on the named scenario."""
        sc = self.scenarios[0]
        c = self.tuned if key == "tuned" else self.references[key]
        sps = scenario_setpoints(sc.spec)
        return scenario_cost(c.rows[sc.name], float(np.mean(sps)), float(np.max(sps)))

    def gains_file(self) -> dict:
        """The controller returned as a gains document for ``controllers.make`` / ``run --controller``."""
        return gains_document(self.chosen.config, self.chosen.family)

    def report(self) -> dict:
        args = (self.scenarios, self.labels, self.forces_n)
        rep = {"tuned": self.tuned.block(*args)}
        for k, c in self.references.items():
            rep[k] = c.block(*args)
        rep.update(family=self.family, evaluations=self.evaluations, ms_bound=self.ms_bound, ms_gain=self.ms_gain,
                   start_scale=self.start_scale, scenarios=[sc.name for sc in self.scenarios],
                   scenario_durations_s=[sc.duration_s for sc in self.scenarios], labels=self.labels,
                   forces_n=self.forces_n, history=self.history, selected=self.selected,
                   selection_reason=self.selection_reason, ms_labels=self.ms_labels, delays=self.delays,
                   named_costs={k: self.named_cost(k) for k in ["tuned", *self.references]})
        return rep


def robust_tune(spec, population, *, family: str = "pid", ms_max: float = 1.6, seed: int | None = None,
                duration_s: float | None = None, max_evaluations: int = 40, progress=None,
                base: PIDConfig = DEFAULT_PID, scenarios=None, ms_gain: float = 1.0, delays: bool = True) -> TuneResult:
    """Tune the gains of ``family`` over ``population`` (see the module docstring).

    Parameters
    ----------
    spec : ScenarioSpec
        The primary scenario.  Used alone (with ``duration_s``) when ``scenarios`` is None.
    population : list of (label, DeviceParams)
    family : {"pid", "pid_scheduled", "pid_feedforward"}
    ms_max : float
        Bound on the sensitivity peak at every linearisation point; ``math.inf`` for none
        (the loop is then not required to be stable in the linear model).
    seed, duration_s : optional
        Passed to every run (``duration_s`` only in the single-scenario form).
    max_evaluations : int
        Budget of Nelder-Mead cost evaluations (simulated or rejected).
    progress : callable, optional
        Called as ``progress(done, total)`` after every simulation run: ``done`` runs so far
        of at most ``total``.  ``total`` shrinks as candidates are rejected by the Ms bound
        or found in the cache; the last call has ``done == total``.
    base : PIDConfig
        The hand-tuned baseline; also supplies the limits and the derivative filter.
    scenarios : list of TuneScenario, optional
        The scenarios of the cost (e.g. :func:`standard_scenarios`); ``[spec]`` if None.
    ms_gain : float
        The describing-function factor ``kappa`` applied to the loop in the Ms check (1:
        the sliding model).
    delays : bool
        Check the bound under both readings of the paper's input delay (default;
        :func:`linearisation_points`); False checks the population's estimator as given.
    """
    import scipy.optimize

    from ebraille_sim.analysis.design import simc_pid
    if not (ms_max > 1.0):
        raise ValueError(f"ms_max must be > 1, got {ms_max}")
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {', '.join(FAMILIES)}, got {family!r}")
    if scenarios is None:
        scenarios = [TuneScenario(spec.name, spec, duration_s)]
    scenarios = list(scenarios)
    if not scenarios:
        raise ValueError("scenarios must not be empty")
    forces = sorted({f for sc in scenarios for f in scenario_setpoints(sc.spec)}
                    | ({1.0} if family != "pid" else set()))
    points = linearisation_points(population, forces, delays)
    labels = [lab for lab, _ in population]
    history = []
    per_candidate = len(population) * len(scenarios)
    shipped = shipped_config(family)
    shipped_is_default = family == "pid" and shipped == base
    n_refs = 3 + (family != "pid") - shipped_is_default
    n_seeds = 2 + len(START_KI_OVER_KP)
    maxfev = max(4, max_evaluations - n_seeds)
    # candidates that may be simulated: references, starts, and Nelder-Mead, which may
    # overrun maxfev by one iteration (at most 2 + n evaluations past the check, n = 3)
    runs = {"done": 0, "total": per_candidate * (n_refs + n_seeds + maxfev + 4)}

    def tick(k):
        runs["done"] += k
        if progress is not None:
            progress(runs["done"], max(runs["total"], runs["done"]))

    def skipped():
        runs["total"] -= per_candidate

    def config_of(kp, ki, kd):
        return family_config(family, kp, ki, kd, base)

    def ms_of(cfg):
        return population_ms(family_ms_controller(cfg), points, ms_gain)

    def run(cfg, fam):
        return evaluate_scenarios(lambda: family_controller(cfg, fam), population, scenarios, seed=seed,
                                  progress=tick)

    def candidate(cfg, fam):
        rows = run(cfg, fam)
        return Candidate(cfg, fam, multi_cost(rows, scenarios), ms_of(cfg), rows)

    cache = {}

    def cost(x):
        key = tuple(np.round(x, 6))
        if key in cache:
            skipped()
            return cache[key].cost if cache[key] is not None else cache[key + ("c",)]
        kp, ki = np.exp(x[:2])
        kd = float(np.exp(x[2])) - KD_OFFSET
        kd = kd if kd > 1e-7 else 0.0
        cfg = config_of(kp, ki, kd)
        ms = ms_of(cfg)
        m = float(np.max(ms))
        if m > ms_max:
            c = 10.0 + 10.0 * min(m - ms_max, 100.0)
            cache[key], cache[key + ("c",)] = None, c
            skipped()
        else:
            rows = run(cfg, family)
            cand = Candidate(cfg, family, multi_cost(rows, scenarios), ms, rows)
            cache[key] = cand
            c = cand.cost
        history.append({"gains": {"kp_v_per_n": float(kp), "ki_v_per_ns": float(ki), "kd_vs_per_n": kd},
                        "ms_max": m, "cost": c})
        return c

    refs = {"default": candidate(base, "pid")}
    nominal = dict(population).get("nominal", population[0][1])
    simc = simc_pid(nominal, float(np.median(forces)))
    simc = dataclasses.replace(base, kp_v_per_n=simc.kp_v_per_n, ki_v_per_ns=simc.ki_v_per_ns)
    refs["simc"] = candidate(simc, "pid")
    hand = config_of(*_gains(base))
    if family != "pid":
        refs["hand"] = candidate(hand, family)
    shipped_key = "default" if shipped_is_default else "shipped"
    if not shipped_is_default:
        refs["shipped"] = candidate(shipped, family)

    # starts: the default gains and SIMC, and the default kp with other integral times
    # (ki/kp = 1, 2 and 16 1/s against the default's 4), each scaled down to the bound
    seeds = [_gains(base), _gains(simc)] + [(base.kp_v_per_n, r * base.kp_v_per_n, base.kd_vs_per_n)
                                            for r in START_KI_OVER_KP]
    starts = []
    start_scale = 1.0
    for j, g in enumerate(seeds):
        c, a = _scaled_to_bound(g, config_of, points, ms_max, ms_gain) if math.isfinite(ms_max) else \
            (config_of(*g), 1.0)
        if j == 0:
            start_scale = a
        kp, ki, kd = _gains(c)
        if kp <= 0 or ki <= 0:             # its slot goes to Nelder-Mead (maxfev counts the starts)
            continue
        starts.append(np.log([kp, ki, kd + KD_OFFSET]))
    start_costs = [cost(x) for x in starts]
    x0 = starts[int(np.argmin(start_costs))]
    simplex = np.array([x0, x0 + [0.0, 0.0, 1.5], x0 + [-0.3, 0.0, 0.0], x0 + [0.0, 0.5, 0.0]])
    scipy.optimize.minimize(cost, x0, method="Nelder-Mead",
                            options={"maxfev": max(4, max_evaluations - len(starts)), "initial_simplex": simplex,
                                     "xatol": 0.02, "fatol": 1e-3})
    runs["total"] = runs["done"]
    tick(0)
    found = [c for k, c in cache.items() if len(k) == 3 and c is not None]
    if not found:
        raise RuntimeError(f"no gains met Ms <= {ms_max:g} at every linearisation point")
    best = min(found, key=lambda c: c.cost)
    res = TuneResult(tuned=best, references=refs, scenarios=scenarios, labels=labels, forces_n=forces,
                     ms_bound=float(ms_max), ms_gain=float(ms_gain), evaluations=len(history), history=history,
                     family=family, start_scale=start_scale, ms_labels=point_labels(points, len(forces)),
                     delays=sorted({p.nk for p in points if p.nk is not None}))
    c_opt, c_ship = res.named_cost("tuned"), res.named_cost(shipped_key)
    if c_ship < c_opt:
        ship = refs[shipped_key]
        bound = f"Ms <= {ms_max:g}" if math.isfinite(ms_max) else "no Ms bound"
        ms_note = (f"its max Ms {ship.ms_max:.2f} exceeds the bound {ms_max:g}" if ship.ms_max > ms_max
                   else f"its max Ms {ship.ms_max:.2f} meets the bound")
        res.selected = shipped_key
        res.selection_reason = (f"on {scenarios[0].name} its cost is {c_ship:.3f} against {c_opt:.3f} for the "
                                f"{bound} optimum; {ms_note}")
    return res
