"""Estimator models by name: the paper's block-oriented models or a saved model file,
optionally re-discretised at another rate (``"paper:wiener:5@1000"``)."""
from __future__ import annotations

import functools
import pathlib

from ebraille_sim.estimation.blockmodels import BlockModel
from ebraille_sim.estimation.resample import resample, split_rate

__all__ = ["load_estimator", "cached_model"]


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


def _load_base(spec: str, base_dir=None):
    if spec.startswith("paper:"):
        from ebraille_sim.estimation.paper_models import paper_model
        parts = spec.split(":")
        if len(parts) not in (3, 4):
            raise ValueError(f"estimator model {spec!r} must look like 'paper:wiener:5' or 'paper:wiener:5:nk0'")
        try:
            order = int(parts[2])
        except ValueError:
            raise ValueError(f"estimator model {spec!r}: order {parts[2]!r} is not an integer") from None
        nk = None
        if len(parts) == 4:
            if parts[3] not in ("nk0", "nk1"):
                raise ValueError(f"estimator model {spec!r}: the delay must be 'nk0' or 'nk1', got {parts[3]!r}")
            nk = int(parts[3][2:])
        return paper_model(parts[1], order) if nk is None else paper_model(parts[1], order, nk=nk)
    path = pathlib.Path(spec)
    if base_dir is not None and not path.is_absolute():
        path = pathlib.Path(base_dir) / path
    return BlockModel.load(path)


@functools.lru_cache(maxsize=16)
def cached_model(spec: str):
    """The estimator model named ``spec``, loaded once per process (treat as read-only)."""
    return load_estimator(spec)
