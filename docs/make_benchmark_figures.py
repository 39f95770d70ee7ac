"""Leaderboard, results file and figure of docs/benchmark.md.

Run from the repository root (about 8 minutes of wall time with ``-j 2`` on the shared
2-core development machine)::

    python docs/make_benchmark_figures.py            # run the standard suite, then the figure
    python docs/make_benchmark_figures.py --reuse    # redraw the figure from benchmark.json

The run is the command ``ebraille-sim benchmark pid pid_scheduled pid_feedforward
pid_friction lqg -j 2 --out docs/figures/benchmark``; it writes ``benchmark.json`` (the
results file ``--compare`` reads) and ``leaderboard.md`` there.  Every number quoted in
docs/benchmark.md comes from those two files.
"""
from __future__ import annotations

import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from ebraille_sim.cli import main as cli  # noqa: E402

OUT = ROOT / "docs" / "figures" / "benchmark"
CONTROLLERS = ["pid", "pid_scheduled", "pid_feedforward", "pid_friction", "lqg"]


def figure(doc: dict, path: pathlib.Path) -> None:
    """Worst-case (CVaR10) in_band and char_in_band per scenario, controllers between the bounds."""
    order = doc["ranking"]
    keys = [s["key"] for s in doc["scenarios"] if not s["fault"]]
    fig, axes = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    width = 0.8 / len(order)
    x = np.arange(len(keys))
    for ax, stat, title in ((axes[0], "in_band_fraction_cvar10", "CVaR10 in_band_fraction"),
                            (axes[1], "char_in_band_fraction_cvar10", "CVaR10 char_in_band_fraction")):
        for j, c in enumerate(order):
            vals = [doc["summary"][c]["scenarios"][k][stat] for k in keys]
            vals = [np.nan if v is None else v for v in vals]
            style = dict(hatch="//", edgecolor="k", linewidth=0.5) if doc["summary"][c]["bound"] else {}
            ax.bar(x + (j - (len(order) - 1) / 2) * width, vals, width, label=c, **style)
        ax.axhline(0.9, color="k", lw=0.6, ls="--")
        ax.set_ylabel(title)
        ax.set_ylim(0, 1.05)
    axes[1].set_xticks(x, keys, rotation=35, ha="right")
    axes[0].legend(ncol=4, fontsize=8, loc="lower left")
    axes[0].set_title(f"suite {doc['suite']} v{doc['suite_version']}, {doc['readers']} readers: worst 10 % "
                      "(hatched: bounds)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    OUT.mkdir(parents=True, exist_ok=True)
    if "--reuse" not in argv:
        code = cli(["benchmark", *CONTROLLERS, "-j", "2", "--out", str(OUT)])
        if code:
            return code
    doc = json.loads((OUT / "benchmark.json").read_text())
    figure(doc, OUT / "cvar_by_scenario.png")
    print(f"wrote {OUT / 'cvar_by_scenario.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
