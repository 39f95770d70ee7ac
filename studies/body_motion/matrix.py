"""The body-motion axis of the fault matrix: the wearer's own motion relative to the board.

Each cell is a scenario built here from the public API: a firmware (``default``: the 100 Hz
estimator and the default PID; ``1khz``: the firmware of the shipped scenario
``refresh_120wpm_1khz``), an FSR preset on a device calibrated for the nominal unit (as the
fault matrix's ``high_k_unit``), a reader (the nominal and stiff presets and drawn readers), a
setpoint (1, 2 or 3 N; the supervisor clips 3 N to 2.7 N) and one body motion from
:data:`MOTIONS`.  The contract inside the relative-motion budget of docs/safety.md (section
6): the true force stays at or below 3.5 N.

Run ``python studies/body_motion/matrix.py`` (the full matrix; ``--quick`` for the sample the
tests run) from the repository root; it prints one row per cell and a summary.
"""
from __future__ import annotations

import argparse
import sys
import time

from ebraille_sim.tools.body_motion import DURATION_S, MOTION_AT_S, SAFE_N, cells, motions, readers, run_cell


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the CI-sized sample only")
    ap.add_argument("--motion", action="append", help="only these motions (repeatable)")
    ap.add_argument("--unsupervised", action="store_true", help="switch the supervisor off")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a [supervisor] field for every cell (repeatable)")
    ap.add_argument("--fsr", action="append", help="only these FSR presets (repeatable)")
    ap.add_argument("--reader", action="append", help="only these readers (repeatable)")
    ap.add_argument("--setpoint", action="append", type=float, help="only these setpoints (repeatable)")
    ap.add_argument("--firmware", action="append", help="only these firmwares (repeatable)")
    ap.add_argument("--duration", type=float, default=DURATION_S,
                    help=f"seconds per cell (default {DURATION_S}; a re-approach after a loss of contact ends "
                    f"about 1.5 s after the motion at {MOTION_AT_S} s)")
    a = ap.parse_args(argv)
    ms = motions()
    devs = readers()
    sup = {}
    for kv in a.set:
        key, _, value = kv.partition("=")
        sup[key] = float(value)
    rows = []
    t0 = time.time()
    for motion, fw, sp, fsr, reader in cells(a.quick):
        if ((a.motion and motion not in a.motion) or (a.fsr and fsr not in a.fsr) or (a.reader and reader not in a.reader)
                or (a.setpoint and sp not in a.setpoint) or (a.firmware and fw not in a.firmware)):
            continue
        r = run_cell(motion, fw, sp, fsr, devs[reader], supervised=not a.unsupervised, supervisor=sup,
                     duration_s=a.duration)
        inside = ms[motion][2]
        rows.append((motion, fw, sp, fsr, reader, inside, r["peak_n"], r["above_s"], r["fault"]))
        print(f"{motion:22s} {fw:7s} {sp:3.1f} {fsr:7s} {reader:7s} {'in ' if inside else 'out'} "
              f"{r['peak_n']:6.2f} N {r['above_s'] * 1e3:6.1f} ms {r['fault'] or '-'}", flush=True)
    inside = [r for r in rows if r[5]]
    bad = [r for r in inside if r[6] > SAFE_N]
    print(f"{len(rows)} cells ({len(inside)} inside the budget) in {time.time() - t0:.0f} s; inside the budget "
          f"{len(bad)} above {SAFE_N} N, worst {max((r[6] for r in inside), default=0):.2f} N; outside: "
          f"{sum(r[6] > SAFE_N for r in rows if not r[5])} of {len(rows) - len(inside)} above, worst "
          f"{max((r[6] for r in rows if not r[5]), default=0):.2f} N")
    return 0


if __name__ == "__main__":
    sys.exit(main())
