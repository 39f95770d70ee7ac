"""Bode and Nyquist plots of analysed loops (:class:`ebraille_sim.analysis.margins.LoopAnalysis`)."""
from __future__ import annotations

import math

import numpy as np

from ebraille_sim.analysis.margins import freq_grid, freq_response

__all__ = ["plot_bode", "plot_nyquist"]


def plot_bode(analyses, path, title: str = "") -> None:
    """Bode plot of the loop transfer of several :class:`LoopAnalysis` (one line each).

    The legend gives the margins of :func:`~ebraille_sim.analysis.margins.loop_margins` (or says
    that the closed loop is unstable); a circle marks the gain crossover of the phase margin, a
    square the phase crossover of the gain margin.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for an in analyses:
        w = freq_grid(an.loop.dt, 600)
        l = freq_response(an.loop, w)
        f = w / (2 * math.pi)
        ms = f"Ms {an.ms:.2f}" if math.isfinite(an.ms) else "Ms inf"
        lab = f"{an.force_n:g} N ({an.margin_label()}, {ms})"
        phase = np.degrees(np.unwrap(np.angle(l)))
        phase -= 360.0 * math.floor((phase[0] + 180.0) / 360.0)   # start within [-180, 180)
        line, = a1.semilogx(f, 20 * np.log10(np.abs(l)), label=lab)
        a2.semilogx(f, phase, color=line.get_color())
        if an.stable and math.isfinite(an.gain_crossover_hz):
            a1.plot(an.gain_crossover_hz, 0.0, "o", color=line.get_color(), ms=4)
        if an.stable and math.isfinite(an.phase_crossover_hz):
            p_gm = np.interp(an.phase_crossover_hz, f, phase)
            a2.plot(an.phase_crossover_hz, -180.0 + 360.0 * round((p_gm + 180.0) / 360.0), "s",
                    color=line.get_color(), ms=4)
    a1.axhline(0, color="0.5", lw=0.8)
    a2.axhline(-180, color="0.5", lw=0.8)
    a1.set_ylabel("|L| (dB)")
    a2.set_ylabel("phase L (deg)")
    a2.set_xlabel("frequency (Hz)")
    a1.legend(fontsize=8)
    a1.set_title(title or "loop transfer L = C P (sampled at the estimator rate)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_nyquist(analyses, path, title: str = "", ms_limit: float = 1.6) -> None:
    """Nyquist plot of the loop transfers with the ``1/ms_limit`` circle around -1."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 6))
    for an in analyses:
        w = freq_grid(an.loop.dt, 800)
        l = freq_response(an.loop, w)
        ax.plot(l.real, l.imag, label=f"{an.force_n:g} N (Ms {an.ms:.2f})")
        ax.plot(l.real, -l.imag, color=ax.lines[-1].get_color(), ls=":", lw=0.8)
    th = np.linspace(0, 2 * np.pi, 200)
    ax.plot(-1 + np.cos(th) / ms_limit, np.sin(th) / ms_limit, "k--", lw=0.8, label=f"|1+L| = 1/{ms_limit:g}")
    ax.plot([-1], [0], "r+", ms=12)
    ax.set_xlim(-3, 1.5)
    ax.set_ylim(-2.5, 2.5)
    ax.set_aspect("equal")
    ax.set_xlabel("Re L")
    ax.set_ylabel("Im L")
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(title or "Nyquist plot of L")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
