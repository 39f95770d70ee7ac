"""Supervisor events on strap_slip over drawn readers, for the scenario's whole duration.

    python studies/population/strap_slip_events.py --readers 300 --seed 8675309

Prints the readers with any supervisor event (a contact loss, a re-approach, a latch), the
events by kind, the readers with a counted contact loss and the share at >= 0.9 in band.
"""
from __future__ import annotations

import collections
import sys

import numpy as np

from ebraille_sim.scenarios.runner import run_batch
from ebraille_sim.scenarios.spec import load_scenario
from shares import drawn_runs, reader_args


def main(argv=None) -> int:
    a = reader_args(__doc__.splitlines()[0], 300, 8675309, argv)
    if a is None:
        return 2
    spec = load_scenario("strap_slip")
    _, runs = drawn_runs(spec, a.readers, a.seed)
    res = run_batch(runs, keep_traces=False)
    kinds: collections.Counter = collections.Counter()
    with_events = 0
    for r in res:
        events = (r.supervisor or {}).get("events", [])
        with_events += bool(events)
        kinds.update(str(e.get("event", e)) if isinstance(e, dict) else str(e) for e in events)
    losses = sum(1 for r in res if r.metrics["contact_loss_count"] > 0)
    latched = sum(1 for r in res if (r.supervisor or {}).get("fault"))
    ib = np.array([r.metrics["in_band_fraction"] for r in res])
    print(f"strap_slip, {spec.duration_s:g} s, {a.readers} readers of seed {a.seed}: readers with supervisor events "
          f"{with_events} {dict(kinds)}; with a contact loss {losses}; latched {latched}; "
          f"share >= 0.9 in band {np.mean(ib >= 0.9):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
