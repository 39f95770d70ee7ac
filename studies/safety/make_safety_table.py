"""Run the fault matrix of tests/test_fault_matrix.py and write its tables into docs/safety.md.

The tables go between the ``<!-- matrix:begin -->`` and ``<!-- matrix:end -->`` markers.
Run from the repository root:  python studies/safety/make_safety_table.py
"""
from __future__ import annotations

import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

from test_fault_matrix import PAIRS, PHASES, SAFE_N, SINGLE, detection, run_cell  # noqa: E402

from controllers.supervisor import SupervisorConfig  # noqa: E402
from ebraille_sim.scenarios.population import sample_devices  # noqa: E402

BEGIN, END = "<!-- matrix:begin -->", "<!-- matrix:end -->"


def _fmt(r) -> str:
    d = detection(r["trace"], r["t0_s"])
    return f"{r['peak_n']:.2f} N / " + ("—" if d is None else f"{d:.2f} s")


def main() -> None:
    cells = []
    lines = ["Single faults, nominal reader, 60 wpm with tremor: peak true force / time from the fault "
             "to the first retract command (— : no retract needed).", "",
             "| fault | " + " | ".join(PHASES) + " |", "|---|" + "---|" * len(PHASES)]
    for f in SINGLE:
        row = []
        for p in PHASES:
            r = run_cell(f, p)
            cells.append((f, p, "nominal 60 wpm", r["peak_n"]))
            row.append(_fmt(r))
        lines.append(f"| {f[0]} | " + " | ".join(row) + " |")
    pair_rows = []
    for f in PAIRS:
        for p in PHASES:
            r = run_cell(f, p, wpm=120)
            cells.append((f, p, "nominal 120 wpm", r["peak_n"]))
            pair_rows.append((r["peak_n"], f, p, _fmt(r)))
    pair_rows.sort(key=lambda x: -x[0])
    lines += ["", f"Pairs of faults, nominal reader, 120 wpm with tremor ({len(pair_rows)} cells), the ten "
              "highest peaks:", "", "| faults | phase | peak / retract |", "|---|---|---|"]
    lines += [f"| {' + '.join(f)} | {p} | {s} |" for _, f, p, s in pair_rows[:10]]
    devices = sample_devices(13, 3)
    pop_rows = []
    for k, dev in enumerate(devices):
        worst = (0.0, None, None)
        for f in SINGLE:
            for p in PHASES:
                r = run_cell(f, p, wpm=(60, 120)[k % 2], device=dev)
                cells.append((f, p, f"device {k}", r["peak_n"]))
                if r["peak_n"] > worst[0]:
                    worst = (r["peak_n"], f, p)
        c = SupervisorConfig.for_device(dev)
        pop_rows.append(f"| {k} | {dev.drivetrain.gear_efficiency:.2f} | {dev.finger.stiffness_b_n_per_m:.0f} | "
                        f"{c.current_limit_a * 1e3:.1f} mA | {worst[0]:.2f} N | {worst[1][0]} ({worst[2]}) |")
    lines += ["", "Single faults over three devices of the population (seed 13; 60, 120, 60 wpm):", "",
              "| device | gear efficiency | pulp b (N/m) | current limit | worst peak | worst cell |",
              "|---|---|---|---|---|---|"] + pop_rows
    worst = max(cells, key=lambda c: c[3])
    above = sum(1 for c in cells if c[3] > SAFE_N)
    lines += ["", f"**{len(cells)} cells, {above} above {SAFE_N} N; worst peak {worst[3]:.2f} N** "
              f"({' + '.join(worst[0])}, {worst[1]}, {worst[2]})."]
    doc = ROOT / "docs" / "safety.md"
    text = doc.read_text(encoding="utf-8")
    a, b = text.index(BEGIN) + len(BEGIN), text.index(END)
    doc.write_text(text[:a] + "\n" + "\n".join(lines) + "\n" + text[b:], encoding="utf-8")
    print(f"{len(cells)} cells, {above} above {SAFE_N} N, worst {worst[3]:.2f} N")


if __name__ == "__main__":
    main()
