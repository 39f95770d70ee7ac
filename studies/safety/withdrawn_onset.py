"""The finger withdrawn at the contact onset over drawn readers: the fault matrix's
``finger_withdrawn`` cell (tests/test_fault_matrix.py) in every phase, at 60 and 120 wpm, over
``--readers`` readers of ``sample_devices(--seed, n)``; lists the cells whose peak true force
exceeds 3.5 N with the reader's drawn values, and with ``--trace K`` prints the run of reader K
around the finger's return (board position, estimate and true force, command, current, the
supervisor's events).

    python studies/safety/withdrawn_onset.py --readers 40 --seed 2024
    python studies/safety/withdrawn_onset.py --readers 40 --seed 2024 --trace 7 --wpm 120

With ``--durations`` it runs the onset cell only, for each time the finger stays away (the
matrix's 3 mm lift, back within 50 ms), and prints per duration the readers above 3.5 N, the worst
peak and the latched faults; ``--controller`` runs a design or controller instead of the
scenario's default:

    python studies/safety/withdrawn_onset.py --readers 40 --seed 9090 --durations 0.4 0.6 0.8 1.0 1.5 2.5
"""
from __future__ import annotations

import argparse
import contextlib
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

from test_fault_matrix import FAULTS, PHASE_START_S, PHASES, SAFE_N, cell_spec  # noqa: E402

from ebraille_sim.scenarios.population import sample_devices  # noqa: E402
from ebraille_sim.scenarios.runner import run_scenario  # noqa: E402

CELL = ("finger_withdrawn",)
RATES = (60, 120)


def _describe(dev) -> str:
    f, s, m, d = dev.finger, dev.fsr, dev.motor, dev.drivetrain
    return (f"b={f.stiffness_b_n_per_m:.0f} N/m m={f.exponent_m_per_m:.0f} /m c0={f.relax_weight_inf:.2f} "
            f"fsr R1={s.resistance_at_1n_ohm:.0f} ohm n={s.exponent:.2f} hyst={s.hysteresis_fraction:.3f} "
            f"R={m.resistance_ohm:.2f} ohm kt={m.torque_constant_nm_per_a:.2e} eff={d.gear_efficiency:.2f} "
            f"guide={d.guide_coulomb_n:.3f} N backlash={d.backlash_m * 1e6:.0f} um")


def sweep(seed: int, n: int, phases=PHASES, controller=None) -> list[tuple]:
    """``(k, wpm, phase, peak_n)`` of every cell of readers ``sample_devices(seed, n)``."""
    out = []
    for k, dev in enumerate(sample_devices(seed, n)):
        for wpm in RATES:
            for p in phases:
                res = run_scenario(cell_spec(CELL, p, wpm, dev), controller=controller, trace_every=None)
                out.append((k, wpm, p, float(res.metrics["peak_force_n"])))
    return out


@contextlib.contextmanager
def _away_for(duration_s: float):
    """The matrix's withdrawn finger staying away ``duration_s`` instead of its own time."""
    saved = FAULTS["finger_withdrawn"]
    FAULTS["finger_withdrawn"] = {**saved, "duration_s": float(duration_s)}
    try:
        yield
    finally:
        FAULTS["finger_withdrawn"] = saved


def durations(seed: int, n: int, times_s, controller=None) -> list[dict]:
    """The onset cell of readers ``sample_devices(seed, n)`` (reader k at ``RATES[k % 2]`` wpm) for
    each time away in ``times_s``: readers above 3.5 N, the worst peak and the latched faults."""
    devs = sample_devices(seed, n)
    rows = []
    for away in times_s:
        peaks, faults = [], {}
        with _away_for(away):
            for k, dev in enumerate(devs):
                res = run_scenario(cell_spec(CELL, "onset", RATES[k % 2], dev), controller=controller,
                                   trace_every=None)
                peaks.append(float(res.metrics["peak_force_n"]))
                fault = res.supervisor.get("fault")
                if fault:
                    faults[fault] = faults.get(fault, 0) + 1
        rows.append({"away_s": away, "readers": n, "above": sum(p > SAFE_N for p in peaks),
                     "worst_n": max(peaks), "median_n": sorted(peaks)[n // 2], "faults": faults})
    return rows


def trace(dev, wpm: int, phase: str, every_s: float = 0.005) -> None:
    """Print the run around the finger's return and the supervisor's events."""
    res = run_scenario(cell_spec(CELL, phase, wpm, dev))
    tr = res.trace
    t0 = PHASE_START_S[phase]
    t_back = t0 + FAULTS["finger_withdrawn"]["duration_s"]
    print("events:", res.supervisor.get("events"), "fault:", res.supervisor.get("fault"))
    dt = tr["t_s"][1] - tr["t_s"][0]
    step = max(1, int(round(every_s / dt)))
    print(f"{'t s':>7} {'board mm':>9} {'est N':>6} {'true N':>6} {'cmd V':>6} {'I A':>6}")
    for i in range(0, len(tr["t_s"]), step):
        t = tr["t_s"][i]
        if t < t0 or (t0 + 0.1 < t < t_back - 0.15) or t > t_back + 0.3:
            continue
        print(f"{t:7.3f} {tr['board_pos_m'][i] * 1e3:9.3f} {tr['force_est_n'][i]:6.2f} "
              f"{tr['force_true_n'][i]:6.2f} {tr['command_v'][i]:6.2f} {tr['motor_current_a'][i]:6.3f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readers", type=int, default=40)
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--trace", type=int, default=None, help="reader index to trace (onset phase)")
    ap.add_argument("--wpm", type=int, default=60, choices=RATES)
    ap.add_argument("--phase", default="onset", choices=PHASES)
    ap.add_argument("--controller", default=None, help="a design or controller (default: the scenario's)")
    ap.add_argument("--durations", type=float, nargs="+", default=None,
                    help="times the finger stays away, s: the onset cell for each")
    a = ap.parse_args(argv)
    if a.readers < 1:
        print("error: --readers must be at least 1", file=sys.stderr)
        return 2
    if a.durations is not None:
        if not all(0.0 < d <= 3.0 for d in a.durations):
            print("error: --durations must lie in (0, 3] s (the cell runs 4 s)", file=sys.stderr)
            return 2
        print(f"finger lifted 3 mm at the onset, {a.readers} readers of seed {a.seed}, "
              f"controller {a.controller or 'the scenario default'}")
        for r in durations(a.seed, a.readers, a.durations, a.controller):
            print(f"  away {r['away_s']:.2f} s: {r['above']} of {r['readers']} above {SAFE_N} N, "
                  f"worst {r['worst_n']:.2f} N, median {r['median_n']:.2f} N, latched {r['faults'] or 'none'}")
        return 0
    devs = sample_devices(a.seed, a.readers)
    if a.trace is not None:
        if not 0 <= a.trace < a.readers:
            print(f"error: --trace must be in [0, {a.readers})", file=sys.stderr)
            return 2
        print(_describe(devs[a.trace]))
        trace(devs[a.trace], a.wpm, a.phase)
        return 0
    cells = sweep(a.seed, a.readers, controller=a.controller)
    above = [c for c in cells if c[3] > SAFE_N]
    for p in PHASES:
        pk = [c for c in cells if c[2] == p]
        w = max(pk, key=lambda c: c[3])
        print(f"{p:7s}: {len(pk)} cells, {sum(c[3] > SAFE_N for c in pk)} above {SAFE_N} N, "
              f"worst {w[3]:.2f} N (reader {w[0]}, {w[1]} wpm)")
    print(f"all: {len(cells)} cells, {len(above)} above {SAFE_N} N, worst {max(c[3] for c in cells):.2f} N")
    for k, wpm, p, pk in sorted(above, key=lambda c: -c[3]):
        print(f"  reader {k:3d} {wpm:3d} wpm {p:6s} {pk:.2f} N  {_describe(devs[k])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
