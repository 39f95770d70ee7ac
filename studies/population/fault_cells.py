"""The fault matrix of tests/test_fault_matrix.py with a given controller or design.

Every cell of the matrix (the single faults at 60 and 120 wpm and the pairs at 120 wpm on the
nominal reader, the single faults on the matrix's three drawn readers, the finger withdrawn at
the onset on its pinned reader), supervisor on, run with ``--controller`` instead of the
scenario's controller (a design brings its firmware).  Prints the number of cells whose true
force exceeds the supervisor's 3.5 N and the highest peaks.

    python studies/population/fault_cells.py --controller dob_hold_1khz --out cells.json
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

from test_fault_matrix import (PAIRS, PHASES, READERS, SAFE_N, SINGLE, WITHDRAWN_READER,  # noqa: E402
                               cell_spec)

from ebraille_sim.scenarios.population import device_from_variates  # noqa: E402
from ebraille_sim.scenarios.runner import run_scenario  # noqa: E402


def cells():
    """``(label, faults, phase, wpm, device)`` of every cell."""
    out = [("nominal", f, p, wpm, None) for wpm in (60, 120) for f in SINGLE for p in PHASES]
    out += [("nominal", f, p, 120, None) for f in PAIRS for p in PHASES]
    for k, variates in enumerate(READERS):
        dev = device_from_variates(*variates)
        out += [(f"reader {k}", f, p, (60, 120)[k % 2], dev) for f in SINGLE for p in PHASES]
    out.append(("withdrawn reader", ("finger_withdrawn",), "onset", 60, device_from_variates(*WITHDRAWN_READER)))
    return out


def matrix(controller: str) -> dict:
    rows = []
    for label, faults, phase, wpm, dev in cells():
        res = run_scenario(cell_spec(faults, phase, wpm, dev), controller=controller)
        rows.append({"reader": label, "faults": list(faults), "phase": phase, "wpm": wpm,
                     "peak_n": round(float(res.trace["force_true_n"].max()), 3)})
    above = [r for r in rows if r["peak_n"] > SAFE_N]
    return {"controller": controller, "cells": len(rows), "above_safe": len(above), "safe_n": SAFE_N,
            "worst": sorted(rows, key=lambda r: -r["peak_n"])[:10], "rows": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--controller", required=True, help="controller, design or gains file")
    ap.add_argument("--out", default=None, help="write the cells as JSON here")
    a = ap.parse_args(argv)
    try:
        r = matrix(a.controller)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if a.out:
        pathlib.Path(a.out).write_text(json.dumps(r, indent=1), encoding="utf-8")
    print(f"{a.controller}: {r['above_safe']} of {r['cells']} cells above {SAFE_N} N")
    for w in r["worst"][:5]:
        print(f"  {w['peak_n']:.2f} N  {w['reader']}, {' + '.join(w['faults'])}, {w['phase']}, {w['wpm']} wpm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
