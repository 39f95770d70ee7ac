"""Reading at 160 and 200 wpm: schedules, scenario files and range checks."""

import dataclasses

import numpy as np
import pytest

from ebraille_sim.scenarios.episodes import EpisodeDistribution
from ebraille_sim.scenarios.inputs import build_schedule_for
from ebraille_sim.scenarios.reading import CELLS_PER_WORD, build_schedule, mean_dwell_s, realised_wpm
from ebraille_sim.scenarios.spec import list_scenarios, load_scenario, parse_scenario


@pytest.mark.parametrize("wpm, dwell_s", [(124, 60 / 620), (160, 0.075), (200, 0.06)])
def test_fast_rates_give_the_standard_word_dwell(wpm, dwell_s):
    assert CELLS_PER_WORD == 5
    assert mean_dwell_s(wpm) == pytest.approx(dwell_s, rel=1e-12)
    sched = build_schedule("The bus - late again - came at 7:15.", wpm, start_s=2.0)
    np.testing.assert_allclose(sched.dwell_s, dwell_s, rtol=1e-12)
    assert sched.t_end_s == pytest.approx(2.0 + len(sched) * dwell_s, rel=1e-12)
    assert realised_wpm(sched) == pytest.approx(wpm, rel=1e-12)


def test_200_wpm_is_1000_cells_per_minute():
    sched = build_schedule("x" * 1000, 200)
    assert sched.duration_s == pytest.approx(60.0, rel=1e-12)


@pytest.mark.parametrize("wpm", [160, 200])
def test_scenario_files_accept_fast_rates(wpm):
    spec = parse_scenario({"name": "fast", "reading": {"text": "ab cd", "wpm": wpm, "start_s": 0.5}})
    assert spec.reading.wpm == wpm
    sched = build_schedule_for(spec, np.random.default_rng(0))
    assert sched.t_end_s == pytest.approx(0.5 + 5 * mean_dwell_s(wpm), rel=1e-12)


@pytest.mark.parametrize("kind", ["steady", "refresh"])
@pytest.mark.parametrize("wpm", [160, 200])
def test_fast_scenarios_copy_the_120_wpm_ones(kind, wpm):
    names = list_scenarios()
    assert f"{kind}_{wpm}wpm" in names
    fast = load_scenario(f"{kind}_{wpm}wpm")
    model = load_scenario(f"{kind}_120wpm")
    assert fast.name == f"{kind}_{wpm}wpm" and fast.reading.wpm == wpm
    same = dataclasses.replace(fast, name=model.name, description=model.description, seed=model.seed,
                               reading=dataclasses.replace(fast.reading, wpm=model.reading.wpm),
                               source=model.source)
    assert same == model
    if kind == "refresh":
        assert fast.seed not in (load_scenario("refresh_60wpm").seed, model.seed)


def test_steady_200_wpm_schedule_length():
    spec = load_scenario("steady_200wpm")
    sched = build_schedule_for(spec, np.random.default_rng(0))
    assert sched.dwell_s[0] == pytest.approx(0.06, rel=1e-12)
    assert sched.t_end_s == pytest.approx(spec.reading.start_s + len(sched) * 0.06, rel=1e-12)


def test_episode_distribution_accepts_fast_reading():
    dist = EpisodeDistribution(wpm_range=(120.0, 200.0))
    ss = np.random.SeedSequence(3)
    wpms = [dist.draw(s).reading.wpm for s in ss.spawn(8)]
    assert all(120.0 <= w <= 200.0 for w in wpms) and max(wpms) > 160.0
    assert EpisodeDistribution().wpm_range == (60.0, 120.0)    # the env's default draw is unchanged
