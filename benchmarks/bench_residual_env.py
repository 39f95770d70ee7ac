"""Speed of the residual env with the design compiled in the loop engine against the design
stepped from Python through the runner's per-period shim, measured in the same run.

Both envs are :class:`ebraille_sim.rl.residual.ResidualEnv` on the same design (``--design``,
default ``dob_100hz``), history 4, episodes of the default length, random corrections from a
seeded generator, resets included.  The compiled env steps the design's compiled controller
plus the correction inside the safety supervisor in one call of
:func:`ebraille_sim.rl.residual.residual_step`; the reference is the same env with the runner's
compiled loop switched off (``runner._USE_COMPILED_LOOP = False`` while it resets), which
calls the design and the supervisor from Python each period, as every residual env did
before.  The two are stepped in turn, ``--chunk`` steps at a time
(:func:`bench_env.interleaved_steps_per_s`), so that on a shared machine both see the same
load; the figure is their ratio, the median of ``--repeat`` rounds.

Run:  python benchmarks/bench_residual_env.py [--design dob_100hz] [--seconds 3] [--repeat 3] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_env import interleaved_steps_per_s  # noqa: E402

import ebraille_sim.scenarios.runner as runner  # noqa: E402
from ebraille_sim.rl.residual import ResidualEnv  # noqa: E402


class _Shimmed(ResidualEnv):
    """The residual env whose design runs from Python through the per-period shim."""

    def reset(self, **kwargs):
        runner._USE_COMPILED_LOOP = False
        try:
            return super().reset(**kwargs)
        finally:
            runner._USE_COMPILED_LOOP = True


def measure(design: str, seconds: float, repeat: int, chunk: int = 500) -> dict:
    fast = ResidualEnv(residual=design, history=4)
    shim = _Shimmed(residual=design, history=4)
    rounds = []
    for i in range(repeat):
        f, s = interleaved_steps_per_s([fast, shim], seconds, seed=i, chunk=chunk)
        rounds.append({"compiled_steps_per_s": round(f), "shim_steps_per_s": round(s), "ratio": round(f / s, 2)})
    assert fast._fast is not None and shim._fast is None
    return {"design": design, "rounds": rounds,
            "median_ratio": statistics.median(r["ratio"] for r in rounds),
            "machine": {"cpus": os.cpu_count(), "processor": platform.machine(),
                        "load_average": [round(x, 2) for x in os.getloadavg()]}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--design", default="dob_100hz", help="the design the correction is added to")
    ap.add_argument("--seconds", type=float, default=3.0, help="measuring time per env and round, s")
    ap.add_argument("--repeat", type=int, default=3, help="rounds")
    ap.add_argument("--json", default=None, help="also write the results to this file")
    a = ap.parse_args(argv)
    out = measure(a.design, a.seconds, a.repeat)
    for r in out["rounds"]:
        print(f"{out['design']}: compiled {r['compiled_steps_per_s']:,} steps/s, shim {r['shim_steps_per_s']:,} "
              f"steps/s, ratio {r['ratio']:.2f}")
    print(f"median ratio {out['median_ratio']:.2f} (load average {out['machine']['load_average']})")
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump(out, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
