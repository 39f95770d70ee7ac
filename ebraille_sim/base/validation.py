"""One vocabulary for validating configuration values and keyword overrides.

Every check raises ``ValueError`` with a one-line message that names the parameter, the
offending value and what is admissible; a valid value is returned normalised (a float, an
int, a bool, a tuple).  Callers that add context (a file name, a table) catch the
``ValueError`` and re-raise with a prefix; :class:`ebraille_sim.scenarios.spec.ScenarioError`
is a ``ValueError`` subclass for that purpose.

Message forms (``R`` is the admissible interval, e.g. ``(0, 1000]``):

==================================  =======================================================
failure                             message
==================================  =======================================================
not a real number (or a bool)       ``NAME must be a number >= 0, got '2'``
not finite                          ``NAME must be finite, got nan; admissible: a finite
                                    number in R``
not whole (``integer=True``)        ``NAME must be a whole number, got 1.5; admissible:
                                    an int >= 1``
an int out of range                 ``NAME must be an int >= 1, got 0``
outside a one-sided bound           ``NAME must be > 0, got -1.0``
outside a two-sided range           ``NAME = -3 is out of range (0, 1000]``
not a bool                          ``NAME must be true or false, got 1``
not a choice                        ``NAME = 'x' is not one of: a, b``
unknown key                         ``unknown key 'k' in WHERE; allowed: a, b``
==================================  =======================================================

Examples
--------
>>> check_number("wpm", 90, lo=0, hi=1000, lo_open=True)
90.0
>>> check_number("wpm", -3, lo=0, hi=1000, lo_open=True)
Traceback (most recent call last):
...
ValueError: wpm = -3 is out of range (0, 1000]
>>> check_number("kp_v_per_n", -1.0, lo=0)
Traceback (most recent call last):
...
ValueError: kp_v_per_n must be >= 0, got -1.0
>>> check_keys("[reading]", {"wmp": 90}, ("passage", "wpm"))
Traceback (most recent call last):
...
ValueError: unknown key 'wmp' in [reading]; allowed: passage, wpm
"""
from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["admissible", "check_number", "check_finite", "check_positive", "check_bool", "check_choice",
           "check_pair", "check_keys", "check_range", "check_count", "check_seeds", "read_table",
           "replace_checked"]


def _g(x: float) -> str:
    return "inf" if x == math.inf else ("-inf" if x == -math.inf else f"{x:g}")


def _interval(lo, hi, lo_open, hi_open) -> str:
    a = "-inf" if lo is None else _g(lo)
    b = "inf" if hi is None else _g(hi)
    return f"{'(' if lo_open or lo is None else '['}{a}, {b}{')' if hi_open or hi is None else ']'}"


def admissible(lo: float | None = None, hi: float | None = None, lo_open: bool = False,
               hi_open: bool = False) -> str:
    """Words for the admissible set of :func:`check_number`: ``'>= 0'``, ``'in (0, 3]'`` or ``''``.

    Examples
    --------
    >>> admissible(0, None, lo_open=True), admissible(0, 3), admissible()
    ('> 0', 'in [0, 3]', '')
    """
    if lo is not None and hi is not None:
        return f"in {_interval(lo, hi, lo_open, hi_open)}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {_g(lo)}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {_g(hi)}"
    return ""


def check_number(name: str, value: Any, lo: float | None = None, hi: float | None = None,
                 lo_open: bool = False, hi_open: bool = False, integer: bool = False,
                 finite: bool = True) -> float | int:
    """Return ``value`` as a float (an int with ``integer=True``) if it is admissible.

    Parameters
    ----------
    name : str
        Parameter name used in the message (may carry context, e.g. ``"[reading] wpm"``).
    value : object
        A real number; bools are rejected.  numpy scalars are accepted.
    lo, hi : float or None, optional
        Bounds; None leaves that side open-ended.
    lo_open, hi_open : bool, optional
        Exclude the bound itself.  Default False (closed).
    integer : bool, optional
        Require a whole number; the value is returned as an int.  Default False.
    finite : bool, optional
        Reject NaN and infinities (default True).  With False, infinities within the
        bounds pass; NaN is always rejected.

    Returns
    -------
    float or int

    Raises
    ------
    ValueError
        One line naming ``name``, the value and the admissible set.
    """
    if type(value) is float and not integer and -math.inf < value < math.inf and \
            (lo is None or (value > lo if lo_open else value >= lo)) and \
            (hi is None or (value < hi if hi_open else value <= hi)):
        return value                   # the common case, without composing the message
    adm = admissible(lo, hi, lo_open, hi_open)
    noun = "an int" if integer else "a number"
    want = f"{noun} {adm}".rstrip()
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {want}, got {value!r}")
    if isinstance(value, numbers.Integral):
        v = int(value)
        if not integer:
            try:
                v = float(v)
            except OverflowError:                          # an int beyond the float range
                v = math.inf if v > 0 else -math.inf
    else:
        v = float(value)
    if isinstance(v, float) and (math.isnan(v) or (finite or integer) and not math.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {value!r}; admissible: "
                         f"{'an int' if integer else 'a finite number'} {adm}".rstrip())
    if integer and isinstance(v, float) and v != int(v):
        raise ValueError(f"{name} must be a whole number, got {value!r}; admissible: {want}")
    bad = (lo is not None and (v < lo or (lo_open and v == lo))) or \
          (hi is not None and (v > hi or (hi_open and v == hi)))
    if bad:
        if lo is not None and hi is not None and not integer:
            raise ValueError(f"{name} = {_g(v)} is out of range {_interval(lo, hi, lo_open, hi_open)}")
        raise ValueError(f"{name} must be {want if integer else adm}, got {value!r}")
    return int(v) if integer else float(v)


def check_range(name: str, value: Any, lo: float, hi: float, lo_open: bool = False,
                hi_open: bool = False) -> float:
    """A finite number in the two-sided range ``[lo, hi]`` (ends excluded by ``lo_open`` / ``hi_open``).

    Same as :func:`check_number` with both bounds; the signature of the reset-option
    checks of :mod:`ebraille_sim.rl.env`.
    """
    return check_number(name, value, lo, hi, lo_open, hi_open)


def check_finite(name: str, value: Any) -> float:
    """A finite real number, as a float.

    Examples
    --------
    >>> check_finite("force_est_n", float("nan"))
    Traceback (most recent call last):
    ...
    ValueError: force_est_n must be finite, got nan; admissible: a finite number
    """
    return check_number(name, value)


def check_positive(name: str, value: Any) -> float:
    """A finite number > 0, as a float (e.g. a time step or a rate)."""
    return check_number(name, value, lo=0.0, lo_open=True)


def check_bool(name: str, value: Any) -> bool:
    """``value`` itself if it is a bool (``True``/``False``; 0 and 1 are rejected)."""
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def check_choice(name: str, value: Any, choices: Iterable[Any]) -> Any:
    """``value`` if it is one of ``choices``.

    Examples
    --------
    >>> check_choice("[reading] mode", "flip", ("continuous", "refresh"))
    Traceback (most recent call last):
    ...
    ValueError: [reading] mode = 'flip' is not one of: continuous, refresh
    """
    choices = list(choices)
    try:
        ok = value in choices
    except TypeError:
        ok = False
    if not ok:
        raise ValueError(f"{name} = {value!r} is not one of: {', '.join(str(c) for c in choices)}")
    return value


def check_pair(name: str, value: Any, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False, hi_open: bool = False, strict: bool = False) -> tuple[float, float]:
    """A ``(low, high)`` pair of numbers in the range, with ``low <= high`` (``low < high`` if ``strict``).

    Each element is checked by :func:`check_number` as ``NAME[0]`` / ``NAME[1]``.

    Examples
    --------
    >>> check_pair("band_hz", [8, 12], 0, 100)
    (8.0, 12.0)
    >>> check_pair("band_hz", [12, 8], 0, 100)
    Traceback (most recent call last):
    ...
    ValueError: band_hz must have low <= high, got [12, 8]
    """
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list)) or len(value) != 2:
        raise ValueError(f"{name} must be a pair (low, high), got {value!r}")
    a = check_number(f"{name}[0]", value[0], lo, hi, lo_open, hi_open)
    b = check_number(f"{name}[1]", value[1], lo, hi, lo_open, hi_open)
    if a > b or (strict and a == b):
        raise ValueError(f"{name} must have low {'<' if strict else '<='} high, got {value!r}")
    return (a, b)


def check_count(name: str, value: Any, hi: int, lo: int = 1) -> int:
    """A count (a Python or NumPy int, not a bool) in ``[lo, hi]``, as an int.

    Examples
    --------
    >>> check_count("num_envs", 2 ** 40, 65536)
    Traceback (most recent call last):
    ...
    ValueError: num_envs must be an int in [1, 65536], got 1099511627776
    """
    import numbers
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not lo <= int(value) <= hi:
        shown = repr(value) if isinstance(value, numbers.Number) else type(value).__name__
        raise ValueError(f"{name} must be an int in [{lo}, {hi}], got {shown}")
    return int(value)


def check_seeds(name: str, value: Any, n: int, limit: int = 2 ** 63) -> list:
    """``n`` seeds from ``value``: None (all None), an int ``s`` (``s, s + 1, ...``) or a
    sequence of ``n`` entries, each None or an int in ``[0, limit)``.

    Examples
    --------
    >>> check_seeds("seed", 5, 3)
    [5, 6, 7]
    >>> check_seeds("seed", True, 2)
    Traceback (most recent call last):
    ...
    ValueError: seed must be None, an int or a sequence of 2 ints, got bool
    """
    import numbers
    if value is None:
        return [None] * n
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        if not 0 <= int(value) <= limit - n:
            raise ValueError(f"{name} must lie in [0, {limit} - {n}] for {n} envs, got {int(value)}")
        return [int(value) + i for i in range(n)]
    if isinstance(value, (bool, str, bytes, Mapping)) or not isinstance(value, Iterable):
        raise ValueError(f"{name} must be None, an int or a sequence of {n} ints, got {type(value).__name__}")
    seeds = list(value)
    if len(seeds) != n:
        raise ValueError(f"{name} must be an int or a sequence of {n} seeds, got {len(seeds)}")
    for i, s in enumerate(seeds):
        if s is not None and (isinstance(s, bool) or not isinstance(s, numbers.Integral) or not 0 <= int(s) < limit):
            shown = repr(s) if isinstance(s, numbers.Number) else type(s).__name__
            raise ValueError(f"{name}[{i}] must be None or an int in [0, 2**63), got {shown}")
    return [None if s is None else int(s) for s in seeds]


def check_keys(where: str, given: Iterable[str] | Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Reject the first key of ``given`` that is not in ``allowed``.

    Parameters
    ----------
    where : str
        What the keys belong to, e.g. ``"[reading]"`` or ``"PIDConfig"``.
    given : iterable of str or mapping
        The keys supplied (a mapping's keys are used).
    allowed : iterable of str
        The admissible keys, listed in this order in the message.

    Raises
    ------
    ValueError
        ``unknown key 'k' in WHERE; allowed: a, b``.
    """
    if not given:
        return
    allowed = list(allowed)
    names = set(allowed)
    for key in given:
        if key not in names:
            raise ValueError(f"unknown key {key!r} in {where}; allowed: {', '.join(map(str, allowed))}")


def read_table(path: str, what: str) -> dict:
    """Read a ``.toml`` or ``.json`` file holding one table/object (by the file's suffix).

    Parameters
    ----------
    path : str
        The file.
    what : str
        What the file is, for the messages (e.g. ``"controller config"``).

    Raises
    ------
    FileNotFoundError
        ``"WHAT not found: PATH"``.
    ValueError
        One line for malformed TOML/JSON, a file that does not hold a table/object, or one
        :func:`ebraille_sim.base.files.read_bytes` refuses (not a regular file, too large,
        nested too deeply).
    """
    import os

    from ebraille_sim.base.files import read_json, read_toml, short
    if not os.path.lexists(path):
        raise FileNotFoundError(f"{what} not found: {short(path)}")
    read = read_toml if str(path).lower().endswith(".toml") else read_json
    data = read(path, what)
    if not isinstance(data, dict):
        raise ValueError(f"{what} {short(path)} must hold a table/object, got {type(data).__name__}")
    return data


def replace_checked(obj, **changes):
    """``dataclasses.replace`` that rejects unknown field names with a one-line error.

    Raises
    ------
    ValueError
        ``unknown key 'k' in TYPE; allowed: ...`` (fields sorted by name).
    """
    names = _replace_plan(type(obj))[0]
    if not names.issuperset(changes):
        check_keys(type(obj).__name__, changes, sorted(names))
    return _replaced(obj, changes)


def replace_fields(obj, **changes):
    """``dataclasses.replace(obj, **changes)`` of a dataclass instance, without its generic
    machinery where the class allows: for a class whose fields are all set by ``__init__``,
    without ``InitVar``, ``ClassVar`` or ``__slots__``, the new instance gets the fields (changed or
    copied) and then runs ``__post_init__``, as the generated ``__init__`` does; other
    classes and unknown names go through ``dataclasses.replace``."""
    return _replaced(obj, changes)


def _replaced(obj, changes: dict):
    """:func:`replace_fields` with the changes as a dict.  The instance's attributes are copied
    with dict updates; what is cached on it besides its fields (attributes that are not fields)
    is left out."""
    names, post_init = _replace_plan(type(obj))
    if post_init is None or not names.issuperset(changes):
        import dataclasses
        return dataclasses.replace(obj, **changes)
    new = object.__new__(type(obj))
    d, old = new.__dict__, obj.__dict__
    d.update(old)
    if len(old) != len(names):                  # every field is in old: more means cached attributes
        for name in old.keys() - names:
            del d[name]
    d.update(changes)
    if post_init:
        new.__post_init__()
    return new


_REPLACE_PLANS: dict = {}


def _replace_plan(cls) -> tuple:
    """``(field names, has __post_init__)`` of a dataclass (read once per class); the second is
    None where :func:`replace_fields` must use ``dataclasses.replace``."""
    plan = _REPLACE_PLANS.get(cls)
    if plan is None:
        import dataclasses
        import inspect
        fields = dataclasses.fields(cls)
        names = frozenset(f.name for f in fields)
        post = getattr(cls, "__post_init__", None)
        params = getattr(cls, "__dataclass_params__", None)
        simple = (params is not None and params.init and all(f.init for f in fields)
                  and not any("__slots__" in k.__dict__ for k in cls.__mro__[:-1])
                  and len(cls.__dataclass_fields__) == len(fields)
                  and (post is None or len(inspect.signature(post).parameters) == 1))
        plan = (names, (post is not None) if simple else None)
        _REPLACE_PLANS[cls] = plan
    return plan
