"""Contact-force controllers for the E-Braille reader simulator.

Every controller implements :class:`Controller` (see
:mod:`controllers.base`). Controllers are built by name or from a config
file with :func:`make`; new families are added with :func:`register`.

Config files (``.toml`` or ``.json``) hold the registered controller name
and its keyword arguments::

    {"controller": "pid", "gains": {"kp_v_per_n": 1.5, "ki_v_per_ns": 30.0}}

or in TOML::

    controller = "pid"
    [gains]
    kp_v_per_n = 1.5
    ki_v_per_ns = 30.0

For ``"pid"`` the gains are :class:`PIDConfig` fields; omitted fields keep
their :data:`controllers.pid.DEFAULT_PID` values.

Examples
--------
>>> import controllers
>>> controllers.available()
['actuator_bound', 'lqg', 'pid', 'pid_dob', 'pid_feedforward', 'pid_friction', 'pid_scheduled']
>>> ctrl = controllers.make("pid", kp_v_per_n=1.0)
>>> ctrl.config.kp_v_per_n
1.0
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from ebraille_sim.base.validation import check_keys, read_table

from controllers.base import Controller
from controllers.pid import DEFAULT_PID, PID, PIDConfig, pid_from_dict

__all__ = ["Controller", "PID", "PIDConfig", "available", "make", "register"]

_CONFIG_SUFFIXES = (".toml", ".json")
_POLICY_PREFIX = "policy:"
_FILE_KEYS = ("name", "description", "controller", "firmware", "gains", "benchmark", "check")

_REGISTRY: dict[str, Callable[..., Controller]] = {}


def register(name: str, factory: Callable[..., Controller], *, replace: bool = False) -> None:
    """Register a controller factory under ``name``.

    Parameters
    ----------
    name : str
        Registry name. Non-empty, without ``/``, ``\\`` or a ``.toml`` /
        ``.json`` suffix (those denote config files in :func:`make`).
    factory : callable
        Called as ``factory(**kwargs)`` with the file's ``gains`` and the
        keyword overrides of :func:`make`; returns a :class:`Controller`.
    replace : bool, optional
        Allow replacing an existing registration. Default False.

    Raises
    ------
    ValueError
        If the name is invalid or already registered and ``replace`` is
        False.
    TypeError
        If ``factory`` is not callable.

    Examples
    --------
    >>> def slow_pid(**gains):
    ...     return make("pid", **{"kp_v_per_n": 0.5, **gains})
    >>> register("pid_slow", slow_pid)  # doctest: +SKIP
    >>> make("pid_slow").config.kp_v_per_n  # doctest: +SKIP
    0.5
    """
    if not isinstance(name, str) or not name or "/" in name or "\\" in name:
        raise ValueError(f"controller name must be a non-empty string without path separators, got {name!r}")
    if name.lower().endswith(_CONFIG_SUFFIXES):
        raise ValueError(f"controller name must not end in .toml or .json, got {name!r}")
    if not callable(factory):
        raise TypeError(f"factory for {name!r} must be callable, got {type(factory).__name__}")
    if name in _REGISTRY and not replace:
        raise ValueError(f"controller {name!r} is already registered; pass replace=True to override")
    _REGISTRY[name] = factory


def available() -> list[str]:
    """Return the registered controller names, sorted.

    Returns
    -------
    list of str
    """
    return sorted(_REGISTRY)


def _load_config_file(path: str) -> dict[str, Any]:
    """Read a ``.toml`` or ``.json`` controller config file."""
    data = read_table(path, "controller config file")
    check_keys(path, data, _FILE_KEYS)
    if "controller" not in data:
        raise ValueError(f"controller config {path} has no 'controller' key")
    gains = data.get("gains", {})
    if not isinstance(gains, dict):
        raise ValueError(f"'gains' in {path} must be a table/object, got {type(gains).__name__}")
    return data


def make(name_or_path: str | os.PathLike[str], **overrides: Any) -> Controller:
    """Build a controller from a registered name or a config file.

    Parameters
    ----------
    name_or_path : str or path-like
        A name from :func:`available`, a shipped design's name
        (:mod:`controllers.designs`), a path to a ``.toml`` / ``.json``
        file holding ``{"controller": name, "gains": {...}}`` (a design file:
        its ``firmware`` is applied by the scenario runner, not here), or
        ``"policy:PATH"`` for a policy saved by ``ebraille-sim train`` or by
        Stable-Baselines3's ``model.save`` with its metadata beside it, or
        ``"policy:NAME"`` for a shipped policy (:func:`controllers.policy.shipped_policies`:
        ``ppo``, ``sac``, ``ppo_hc``; a path that exists wins over a name)
        (:mod:`controllers.policy`; a ``.zip`` without its ``.npz`` needs the ``rl`` extra).
    **overrides
        Keyword arguments passed to the factory; they take precedence over
        the file's ``gains``. For ``"pid"`` these are :class:`PIDConfig`
        fields.

    Returns
    -------
    Controller

    Raises
    ------
    FileNotFoundError
        If a config path does not exist.
    ValueError
        If the name is not registered (the message lists the available
        names), the file is malformed, or a gain is unknown or invalid.

    Examples
    --------
    >>> make("pid").config == DEFAULT_PID
    True
    >>> make("lqr")
    Traceback (most recent call last):
    ...
    ValueError: unknown controller 'lqr'; available: actuator_bound, lqg, pid, pid_dob, pid_feedforward, pid_friction, pid_scheduled; designs: dob_100hz, dob_hold_1khz, dob_learn_1khz, dob_wide_1khz (or give a path to a .toml/.json config file)
    """
    spec = os.fspath(name_or_path)
    if spec.startswith(_POLICY_PREFIX):
        from controllers.policy import load_policy  # imports stable-baselines3 only when a policy is loaded
        return load_policy(spec[len(_POLICY_PREFIX):], make_base=make, **overrides)
    if spec in _REGISTRY:
        return _REGISTRY[spec](**overrides)
    from controllers.designs import designs
    if spec in designs():
        d = designs()[spec]
        return make(d.controller, **{**d.gains, **overrides})
    if spec.lower().endswith(_CONFIG_SUFFIXES):
        data = _load_config_file(spec)
        name = data["controller"]
        if name not in _REGISTRY:
            raise ValueError(
                f"unknown controller {name!r} in {spec}; available: {', '.join(available())}"
            )
        kwargs = {**data.get("gains", {}), **overrides}
        return _REGISTRY[name](**kwargs)
    raise ValueError(
        f"unknown controller {spec!r}; available: {', '.join(available())}; designs: {', '.join(designs())}"
        " (or give a path to a .toml/.json config file)"
    )


def _make_pid(**gains: Any) -> PID:
    """Factory for ``"pid"``: :data:`DEFAULT_PID` with ``gains`` applied."""
    return pid_from_dict(gains, base=DEFAULT_PID)


register("pid", _make_pid)


def _make_scheduled(**gains: Any) -> Controller:
    """Factory for ``"pid_scheduled"`` (imported lazily from :mod:`controllers.schedule`)."""
    from controllers.schedule import make_scheduled
    return make_scheduled(**gains)


def _make_feedforward(**gains: Any) -> Controller:
    """Factory for ``"pid_feedforward"`` (imported lazily from :mod:`controllers.schedule`)."""
    from controllers.schedule import make_feedforward
    return make_feedforward(**gains)


def _make_lqg(**gains: Any) -> Controller:
    """Factory for ``"lqg"``: the LQG designed on the simulator's linearised plant.

    The design model comes from the analysis layer
    (:func:`ebraille_sim.analysis.design.make_lqg`), resolved when the controller is
    made, like a plugin entry point; ``controllers`` itself imports only the physics and
    estimation layers.
    """
    import importlib
    return importlib.import_module("ebraille_sim.analysis.design").make_lqg(**gains)


register("pid_scheduled", _make_scheduled)
register("pid_feedforward", _make_feedforward)
register("lqg", _make_lqg)


def _make_actuator_bound(**gains: Any) -> Controller:
    """Factory for ``"actuator_bound"``: the true-force reference of :mod:`controllers.bounds`."""
    from controllers.bounds import make_actuator_bound
    return make_actuator_bound(**gains)


register("actuator_bound", _make_actuator_bound)


def _make_friction(**gains: Any) -> Controller:
    """Factory for ``"pid_friction"``: friction compensation keyed on the error (:mod:`controllers.friction`)."""
    from controllers.friction import make_friction
    return make_friction(**gains)


register("pid_friction", _make_friction)


def _make_dob(**gains: Any) -> Controller:
    """Factory for ``"pid_dob"``: the default PID with a disturbance observer (:mod:`controllers.dob`)."""
    from controllers.dob import make_dob
    return make_dob(**gains)


register("pid_dob", _make_dob)
