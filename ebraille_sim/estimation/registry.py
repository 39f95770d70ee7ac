"""Estimator models by name: the paper's block-oriented models or a saved model file,
optionally re-discretised at another rate (``"paper:wiener:5@1000"``).

The paper prints no input delay; a paper model's name chooses one of its two readings
(``":nk0"``, ``":nk1"``, MATLAB's ``nk = 1`` without a suffix), and :func:`delay_of`,
:func:`with_delay` and :func:`delay_readings` are the one place that reads and writes it."""
from __future__ import annotations

import functools
import pathlib

from ebraille_sim.estimation.blockmodels import BlockModel
from ebraille_sim.estimation.resample import resample, split_rate

__all__ = ["load_estimator", "cached_model", "plant_model", "delay_of", "with_delay", "delay_readings"]

_DELAY_SUFFIXES = ("nk0", "nk1")
"""Suffixes of a paper model name that choose the input delay (samples): the paper's two readings."""


def load_estimator(spec: str, base_dir=None):
    """The estimator model named by ``spec``.

    ``"paper:KIND:ORDER"`` is one of the paper's models (e.g. ``"paper:wiener:5"``), with the
    input delay of MATLAB's convention (1 sample); ``"paper:KIND:ORDER:nk0"`` reads the paper's
    notation literally (no delay; the paper prints none, docs/identification.md);
    anything else is the path of a model saved as JSON by
    :meth:`ebraille_sim.estimation.blockmodels.BlockModel.save`.  A suffix ``"@RATE"``
    (Hz) re-discretises the model's linear block at that rate
    (:func:`ebraille_sim.estimation.resample.resample`): ``"paper:wiener:5@1000"`` runs the
    paper's fifth-order Wiener model at 1 kHz.
    """
    base, rate_hz = split_rate(spec)
    model = _load_base(base, base_dir)
    return model if rate_hz is None else resample(model, rate_hz)


def _paper_parts(spec: str) -> tuple[str, int, int | None]:
    """``(kind, order, nk or None)`` of a ``"paper:KIND:ORDER[:nkK]"`` name (one-line ``ValueError``)."""
    parts = spec.split(":")
    if len(parts) not in (3, 4):
        raise ValueError(f"estimator model {spec!r} must look like 'paper:wiener:5' or 'paper:wiener:5:nk0'")
    try:
        order = int(parts[2])
    except ValueError:
        raise ValueError(f"estimator model {spec!r}: order {parts[2]!r} is not an integer") from None
    nk = None
    if len(parts) == 4:
        if parts[3] not in _DELAY_SUFFIXES:
            raise ValueError(f"[estimator] model {spec!r}: the input delay must be 'nk0' or 'nk1' (0 or 1 samples, "
                             f"the paper's two readings), got {parts[3]!r}")
        nk = int(parts[3][2:])
    return parts[1], order, nk


def delay_of(spec: str) -> int | None:
    """The input delay (samples) a paper model name chooses, or None where the name does not.

    ``"paper:KIND:ORDER"`` is MATLAB's convention (:data:`~ebraille_sim.estimation.paper_models.NK`,
    1), ``":nk0"``/``":nk1"`` name the reading; a name with a rate (``"...@1000"``) has no
    delay to choose (:func:`~ebraille_sim.estimation.resample.resample` drops it, so both
    readings give the same model) and a model file carries the delay it was identified with:
    both give None.

    >>> delay_of("paper:wiener:5"), delay_of("paper:wiener:5:nk0"), delay_of("paper:wiener:5@1000")
    (1, 0, None)
    """
    from ebraille_sim.estimation.paper_models import NK
    base, rate_hz = split_rate(spec)
    if rate_hz is not None or not base.startswith("paper:"):
        return None
    nk = _paper_parts(base)[2]
    return NK if nk is None else nk


def with_delay(spec: str, nk: int) -> str:
    """The paper model name ``spec`` with the input delay ``nk`` (0 or 1 samples).

    >>> with_delay("paper:wiener:5", 0), with_delay("paper:wiener:5:nk0", 1)
    ('paper:wiener:5:nk0', 'paper:wiener:5:nk1')

    Raises a one-line ``ValueError`` for another ``nk`` and for a name whose delay cannot be
    chosen (:func:`delay_of` is None).
    """
    from ebraille_sim.estimation.paper_models import NK_READINGS
    if isinstance(nk, bool) or nk not in NK_READINGS:
        raise ValueError(f"nk must be 0 or 1 (the paper's two readings of its input delay, samples), got {nk!r}")
    if delay_of(spec) is None:
        raise ValueError(f"estimator model {spec!r} has no input delay to choose: only a paper model at its own "
                         f"100 Hz ('paper:KIND:ORDER') carries the paper's two readings")
    kind, order, _ = _paper_parts(spec)
    return f"paper:{kind}:{order}:nk{int(nk)}"


def delay_readings(spec: str) -> dict[int, str]:
    """The estimator names of both readings of the paper's input delay, ``{nk: name}``.

    For a paper model at its own rate ``{0: "...:nk0", 1: "...:nk1"}``; for any other name
    (a rate suffix, a model file) ``{}``: there is no delay to choose.
    """
    from ebraille_sim.estimation.paper_models import NK_READINGS
    if delay_of(spec) is None:
        return {}
    return {k: with_delay(spec, k) for k in NK_READINGS}


def _load_base(spec: str, base_dir=None):
    if spec.startswith("paper:"):
        from ebraille_sim.estimation.paper_models import paper_model
        kind, order, nk = _paper_parts(spec)
        return paper_model(kind, order) if nk is None else paper_model(kind, order, nk=nk)
    path = pathlib.Path(spec)
    if base_dir is not None and not path.is_absolute():
        path = pathlib.Path(base_dir) / path
    return BlockModel.load(path)


@functools.lru_cache(maxsize=16)
def cached_model(spec: str):
    """The estimator model named ``spec``, loaded once per process (treat as read-only)."""
    return load_estimator(spec)


def plant_model(spec: str):
    """The model a plant packs for ``spec``: a paper model, a pure function of its name, from the
    process's cache (:func:`cached_model`; resampling the 1 kHz model costs about 3 ms), a model
    file loaded afresh (its path is read from the working folder now, and the file may have been
    refitted since)."""
    return cached_model(spec) if spec.startswith("paper:") else load_estimator(spec)
