"""One-line assertions on a scenario's metrics, for your own test suite.

Checks are keyword arguments ``METRIC__OP=value`` with ``OP`` one of ``ge``, ``gt``,
``le``, ``lt``, ``eq`` or ``between`` (value ``(low, high)``, inclusive)::

    from ebraille_sim.tools.testing import assert_scenario

    def test_reading_at_120_wpm():
        assert_scenario("steady_120wpm", in_band_fraction__ge=0.95, peak_force_n__le=1.5)

    def test_my_gains_on_a_slip():
        assert_scenario("strap_slip", controller="my_gains.toml", contact_loss_count__eq=0)

``assert_scenario`` runs the scenario once per ``(name, seed, controller, duration_s)``
in a test session (results are cached; controllers given as objects are never cached)
and raises ``AssertionError`` listing every failed check with the measured value.
``assert_matches_baseline`` checks a scenario (a shipped name, or your own file with its
baseline in ``baselines/`` beside it) against its regression baseline with the tolerances of
:mod:`ebraille_sim.tools.regress`.

Examples
--------
>>> check_metrics({"in_band_fraction": 0.97, "peak_force_n": 1.2},
...               in_band_fraction__ge=0.9, peak_force_n__le=1.0)
['peak_force_n = 1.2, expected <= 1']
>>> check_metrics({"in_band_fraction": 0.97}, in_band__ge=0.9)
Traceback (most recent call last):
...
ValueError: unknown metric 'in_band' in check 'in_band__ge'; metrics: in_band_fraction
"""
from __future__ import annotations

import functools
import operator

__all__ = ["OPERATORS", "check_metrics", "scenario_metrics", "check_scenario_metrics", "assert_scenario",
           "assert_matches_baseline"]

OPERATORS = {
    "ge": (operator.ge, ">="), "gt": (operator.gt, ">"), "le": (operator.le, "<="), "lt": (operator.lt, "<"),
    "eq": (operator.eq, "=="),
}
"""Comparison suffixes of a check (plus ``between``)."""


def _parse(check: str, names) -> tuple[str, str]:
    metric, sep, op = check.rpartition("__")
    if not sep:
        raise ValueError(f"check {check!r} must look like METRIC__OP (OP: {', '.join([*OPERATORS, 'between'])})")
    if op not in OPERATORS and op != "between":
        raise ValueError(f"unknown operator {op!r} in check {check!r}; allowed: {', '.join([*OPERATORS, 'between'])}")
    if metric not in names:
        raise ValueError(f"unknown metric {metric!r} in check {check!r}; metrics: {', '.join(names)}")
    return metric, op


def check_metrics(metrics: dict, **checks) -> list[str]:
    """Failed checks of ``metrics`` as readable lines (empty when all pass).

    Raises ``ValueError`` for an unknown metric or operator.  A metric that is None
    (e.g. ``settling_time_s`` of a run that never settles) fails every check.
    """
    failures = []
    for check, want in checks.items():
        metric, op = _parse(check, list(metrics))
        got = metrics[metric]
        if op == "between":
            lo, hi = want
            ok = got is not None and lo <= got <= hi
            expect = f"in [{lo:g}, {hi:g}]"
        else:
            fn, sym = OPERATORS[op]
            ok = got is not None and fn(got, want)
            expect = f"{sym} {want:g}" if isinstance(want, (int, float)) else f"{sym} {want!r}"
        if not ok:
            shown = "None" if got is None else (f"{got:.6g}" if isinstance(got, float) else str(got))
            failures.append(f"{metric} = {shown}, expected {expect}")
    return failures


@functools.lru_cache(maxsize=64)
def _cached_metrics(name, seed, controller, duration_s):
    from ebraille_sim.scenarios.runner import run_scenario
    return dict(run_scenario(name, controller=controller, seed=seed, duration_s=duration_s).metrics)


def scenario_metrics(name, *, seed=None, controller=None, duration_s=None) -> dict:
    """Metrics of a scenario run (a name, a path or a ScenarioSpec); cached when hashable."""
    from ebraille_sim.scenarios.runner import run_scenario
    cacheable = isinstance(name, str) and (controller is None or isinstance(controller, str))
    if cacheable:
        return dict(_cached_metrics(name, seed, controller, duration_s))
    return dict(run_scenario(name, controller=controller, seed=seed, duration_s=duration_s).metrics)


def check_scenario_metrics(name, *, seed=None, controller=None, duration_s=None, **checks) -> list[str]:
    """Run a scenario and return its failed checks (see :func:`check_metrics`)."""
    return check_metrics(scenario_metrics(name, seed=seed, controller=controller, duration_s=duration_s), **checks)


def assert_scenario(name, *, seed=None, controller=None, duration_s=None, **checks) -> dict:
    """Run a scenario and assert every check; returns its metrics.

    Raises
    ------
    AssertionError
        Listing each failed check with the measured value.
    ValueError
        For an unknown metric or operator (before any assertion).
    """
    metrics = scenario_metrics(name, seed=seed, controller=controller, duration_s=duration_s)
    failures = check_metrics(metrics, **checks)
    if failures:
        label = name if isinstance(name, str) else getattr(name, "name", str(name))
        raise AssertionError(f"scenario {label}: " + "; ".join(failures))
    return metrics


def assert_matches_baseline(name, *, controller=None, scenario_dir=None, baseline_dir=None) -> None:
    """Assert that a scenario still matches its regression baseline.

    Parameters
    ----------
    name : str or path
        A scenario name or a scenario file path.  A name is looked up in ``scenario_dir``
        when given, else in ``./scenarios`` and then in the shipped library, whatever the
        working folder; a shipped scenario is checked against its shipped baseline.  A
        path's baseline is ``baselines/NAME.json`` beside the file (create it with
        ``ebraille-sim regress --update --only PATH``).
    controller : str, path or Controller, optional
        Replaces the scenario's controller.
    scenario_dir, baseline_dir : path, optional
        As in :func:`ebraille_sim.tools.regress.regress_scenarios`.

    Raises
    ------
    AssertionError
        When a metric moved (with the report table), a ``[criteria]`` limit fails, the
        baseline is missing (with the command that creates it) or the scenario did not run.
    ValueError, FileNotFoundError
        For an unknown scenario name or a missing scenario file.
    """
    from ebraille_sim.tools.regress import format_report, regress_scenarios
    [check] = regress_scenarios(scenario_dir, only=[str(name)], controller=controller, baseline_dir=baseline_dir)
    if not check.failed:
        return
    statuses = {r.status for r in check.rows}
    if "missing" in statuses:
        raise AssertionError(f"scenario {check.name} has no baseline {check.baseline}; create it with "
                             f"'ebraille-sim regress --update --only {check.source}'")
    if "error" in statuses:
        raise AssertionError(f"scenario {check.name} could not be checked:\n{format_report([check])}")
    what = (f"does not match its baseline {check.baseline}" if statuses & {"moved", "removed"}
            else "fails its [criteria]")
    raise AssertionError(f"scenario {check.name} {what}:\n{format_report([check])}")
