"""Population sweeps: planning, seeds, executors giving identical rows, outputs, risk measures."""
import csv
import math
import time

import numpy as np
import pytest

from ebraille_sim.tools import sweep as S
from ebraille_sim.cli import main as cli


DURATION_S = 2.1          # reading starts at 2.0 s (contact_onset) and 1.5 s (steady_90wpm)


def small_plan(**kw):
    args = dict(rates=[60, 120], readers=2, controllers=["pid"], seed=3, duration_s=DURATION_S)
    args.update(kw)
    return S.plan_sweep(["contact_onset", "steady_90wpm"], **args)


def test_plan_is_the_full_product_with_controller_independent_seeds(tmp_path):
    gains = tmp_path / "soft.toml"
    gains.write_text('controller = "pid"\n[gains]\nkp_v_per_n = 1.5\n')
    plan = small_plan(controllers=["pid", str(gains)], replicates=2)
    eps = plan.episodes
    assert len(eps) == 2 * 2 * 2 * 2 * 2
    assert [e.index for e in eps] == list(range(len(eps)))
    by_key = {}
    for e in eps:
        by_key.setdefault((e.scenario, e.wpm, e.reader, e.replicate), set()).add(e.seed)
    assert all(len(s) == 1 for s in by_key.values())                 # paired across controllers
    assert len({next(iter(s)) for s in by_key.values()}) == len(by_key)
    assert small_plan().episodes == small_plan().episodes
    assert small_plan(seed=4).episodes != small_plan().episodes
    a, b = plan.devices["contact_onset"]
    assert a.finger.stiffness_b_n_per_m != b.finger.stiffness_b_n_per_m
    # reader k is the same draw in every scenario (both scenarios use the nominal device)
    assert plan.devices["contact_onset"][0].fsr == plan.devices["steady_90wpm"][0].fsr


@pytest.mark.parametrize("kw, msg", [
    (dict(readers=-1), "readers must be a whole number >= 0"),
    (dict(replicates=0), "replicates must be >= 1"),
    (dict(rates=[0]), "reading rate 0"),
    (dict(controllers=["lqr"]), "unknown controller 'lqr'"),
    (dict(duration_s=-1.0), "duration_s must be a positive finite number"),
    (dict(duration_s=1.0), "episodes of 1 s end before scenario 'contact_onset' starts reading at 2 s"),
    (dict(duration_s=2.0), "use a duration above 2 s"),
])
def test_bad_plans_are_rejected(kw, msg):
    with pytest.raises(ValueError, match=msg):
        small_plan(**kw)


def test_serial_and_local_processes_give_identical_rows():
    plan = small_plan()
    a = S.run_sweep(plan, jobs=1, progress=False)
    b = S.run_sweep(plan, jobs=2, progress=False, batch_size=2)
    assert a.executor == "serial" and b.executor == "local x2"
    assert S.identical_results(a, b)
    assert [r["episode"] for r in b.rows] == list(range(len(plan.episodes)))
    assert {r["rate_wpm"] for r in a.rows} == {60.0, 120.0}
    assert all(r["error"] == "" for r in a.rows)
    # a rerun with another seed differs
    c = S.run_sweep(small_plan(seed=9), jobs=1, progress=False)
    assert not S.identical_results(a, c)


def test_episode_rows_match_a_direct_run():
    import dataclasses

    from ebraille_sim.scenarios.runner import run_scenario
    plan = small_plan()
    ep = plan.episodes[3]
    row = S.run_episode(plan, ep)
    spec = plan.specs[ep.scenario]
    spec = dataclasses.replace(spec, reading=dataclasses.replace(spec.reading, wpm=ep.wpm))
    res = run_scenario(spec, controller=ep.controller, seed=ep.seed, duration_s=DURATION_S,
                       device=plan.devices[ep.scenario][ep.reader])
    for k, v in res.metrics.items():
        if k != "real_time_factor":
            assert row[k] == v, k
    assert row["fsr_k_ohm"] == plan.devices[ep.scenario][ep.reader].fsr.resistance_at_1n_ohm


def test_batched_rows_equal_rows_of_single_episodes_and_every_force_metric_is_set():
    plan = small_plan(controllers=["pid", "lqg"])
    single = [S.run_episode(plan, ep) for ep in plan.episodes]
    for batch_size in (None, 5):
        res = S.run_sweep(plan, jobs=1, progress=False, batch_size=batch_size)
        assert S.identical_results(res, S.SweepResult(single, res.columns, 0.0))
    assert all(r["error"] == "" for r in single)
    for metric in ("force_rmse_n", "in_band_fraction", "estimate_rmse_n", "char_in_band_fraction"):
        assert all(r[metric] is not None and math.isfinite(r[metric]) for r in single), metric


def test_cvar_and_losses():
    assert S.cvar([1, 2, 3, 4, 5, 6, 7, 8, 9, 10], 0.1) == 10.0
    assert S.cvar([1, 2, 3, 4, 5, 6, 7, 8, 9, 10], 0.25) == 9.0            # worst ceil(2.5) = 3
    assert S.cvar([3.0, 1.0], 1.0) == 2.0
    with pytest.raises(ValueError):
        S.cvar([1.0], 0.0)
    rows = [{"in_band_fraction": 0.9, "force_rmse_n": 0.1, "error": ""},
            {"in_band_fraction": None, "force_rmse_n": None, "error": "diverged"}]
    np.testing.assert_allclose(S.loss_values(rows, "in_band_fraction"), [0.1, 1.0])
    assert S.loss_values(rows, "force_rmse_n")[1] == math.inf


def test_cli_writes_table_summary_and_figures(tmp_path, capsys):
    out = tmp_path / "sw"
    code = cli(["sweep", "contact_onset", "--rates", "90", "--readers", "3", "--duration", "2.1", "-j", "1",
                "--out", str(out), "--no-progress", "--loss", "char_in_band_fraction"])
    assert code == 0
    text = capsys.readouterr().out
    assert "3 episodes (0 failed) on serial" in text and "1 - char_in_band_fraction" in text
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and {"finger_b_n_per_m", "legible_char_fraction", "error"} <= set(rows[0])
    for f in ("distributions.png", "worst_cases.png", "cvar.png"):
        assert (out / "figures" / f).stat().st_size > 5000
    assert "cvar_0.1" in (out / "summary.txt").read_text()


def test_cli_rejects_bad_arguments(capsys):
    assert cli(["sweep", "contact_onset", "--loss", "speed"]) == 2
    assert "unknown --loss metric 'speed'" in capsys.readouterr().err
    assert cli(["sweep", "nope_scenario", "--no-progress"]) == 2
    assert cli(["sweep", "contact_onset", "--alpha", "0"]) == 2


@pytest.mark.slow
def test_thousand_episodes_on_dask_and_locally_are_identical(tmp_path):
    """>= 1,000 short episodes on a Dask LocalCluster and on local processes, same rows."""
    distributed = pytest.importorskip("dask.distributed")
    gains = tmp_path / "soft.toml"
    gains.write_text('controller = "pid"\n[gains]\nkp_v_per_n = 1.5\nki_v_per_ns = 6.0\n')
    plan = S.plan_sweep(["steady_90wpm", "tremor_90wpm"], rates=[60, 90, 120], readers=42,
                        controllers=["pid", str(gains)], seed=11, replicates=2, duration_s=1.7)
    assert len(plan.episodes) == 1008
    t0 = time.perf_counter()
    local = S.run_sweep(plan, jobs=2, progress=False)
    t_local = time.perf_counter() - t0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        t0 = time.perf_counter()
        remote = S.run_sweep(plan, scheduler=client, progress=False)
        t_dask = time.perf_counter() - t0
    assert remote.executor == "dask"
    assert S.identical_results(local, remote)
    assert sum(1 for r in local.rows if r["error"]) == 0
    print(f"\n1008 episodes: local x2 {t_local:.1f} s, dask LocalCluster(2) {t_dask:.1f} s")


def test_episode_scatter_has_one_marker_and_legend_entry_per_controller():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [{"controller": c, "finger_b_n_per_m": b, "fsr_k_ohm": k}
            for c, b, k in (("pid", 300.0, 4e3), ("lqg", 500.0, 6e3), ("pid", 800.0, 5e3),
                            ("scheduled", 400.0, 7e3), ("lqg", 900.0, 8e3), ("scheduled", 600.0, 5e3),
                            ("failed", 700.0, 6e3))]
    L = np.array([0.1, 0.2, 0.3, np.inf, 0.5, 0.6, np.inf])
    fig, ax = plt.subplots()
    try:
        S._episode_scatter(fig, ax, rows, L)
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        # an infinite loss is left out, and a controller with only infinite losses with it
        assert texts == ["pid (2)", "lqg (2)", "scheduled (1)"]
        cols = ax.collections
        assert [len(c.get_offsets()) for c in cols] == [2, 2, 1]
        assert len({tuple(map(tuple, c.get_paths()[0].vertices.round(6))) for c in cols}) == 3
        np.testing.assert_allclose(cols[1].get_offsets(), [[500.0, 0.2], [900.0, 0.5]])
        assert ax.get_xlabel() == "pulp stiffness b (N/m)" and len(fig.axes) == 2  # with the colour bar
    finally:
        plt.close(fig)


def test_episode_scatter_without_a_finite_loss_draws_an_empty_panel():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [{"controller": "pid", "finger_b_n_per_m": 300.0, "fsr_k_ohm": 4e3}]
    fig, ax = plt.subplots()
    try:
        S._episode_scatter(fig, ax, rows, np.array([np.inf]))
        fig.canvas.draw()
        assert len(ax.collections) == 0 and ax.get_legend() is None and len(fig.axes) == 1
    finally:
        plt.close(fig)
