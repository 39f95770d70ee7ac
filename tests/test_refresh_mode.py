"""Per-character refresh mode: schema, setpoint phases, the hold-only in-band window."""
import numpy as np
import pytest

from ebraille_sim.scenarios.metrics import CHAR_IN_BAND_REQUIRED, compute_metrics, in_band
from ebraille_sim.scenarios.inputs import build_schedule_for, refresh_phases, setpoint_profile
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import ScenarioError, parse_scenario


def spec(**reading):
    return parse_scenario({"name": "r", "duration_s": 5.0, "reading": {"wpm": 60, "start_s": 1.0, **reading},
                           "setpoint": {"force_n": 1.0}, "finger": {"gap_m": 1e-3}})


def test_mode_defaults_to_continuous_and_is_checked():
    assert spec().reading.mode == "continuous"
    with pytest.raises(ScenarioError, match=r"\[reading\] mode = 'flip' is not one of: continuous, refresh"):
        spec(mode="flip")
    with pytest.raises(ScenarioError, match="leaves no hold time"):
        spec(mode="refresh", refresh_lift_fraction=0.3, refresh_press_fraction=0.5, refresh_release_fraction=0.2)
    with pytest.raises(ScenarioError, match=r"refresh_lift_force_n = 4 is out of range"):
        spec(mode="refresh", refresh_lift_force_n=4.0)


def test_continuous_setpoint_ignores_the_schedule():
    s = spec()
    sched = build_schedule_for(s, np.random.default_rng(0))
    t = np.arange(5000) * 1e-3
    np.testing.assert_array_equal(setpoint_profile(s, t), setpoint_profile(s, t, sched))
    assert np.all(setpoint_profile(s, t) == 1.0)


def test_refresh_setpoint_follows_lift_press_hold_release():
    s = spec(mode="refresh", refresh_lift_fraction=0.1, refresh_press_fraction=0.3, refresh_release_fraction=0.2,
             refresh_lift_force_n=0.2)
    sched = build_schedule_for(s, np.random.default_rng(0))
    dwell = 0.2                                        # 60 wpm
    t0 = sched.start_s[3]
    probe = t0 + dwell * np.array([0.05, 0.15, 0.45, 0.75, 0.85])
    sp = setpoint_profile(s, probe, sched)
    np.testing.assert_allclose(sp, [0.2, 1.0, 1.0, 1.0, 0.2])
    pressed, hold = refresh_phases(s, sched, probe)
    assert pressed.tolist() == [False, True, True, True, False]
    assert hold.tolist() == [False, False, True, True, False]
    assert np.all(setpoint_profile(s, np.array([0.0, 0.5]), sched) == 1.0)      # onset before reading
    with pytest.raises(ValueError, match="needs the reading schedule"):
        setpoint_profile(s, probe)


def test_lift_force_never_exceeds_the_setpoint():
    s = spec(mode="refresh", refresh_lift_force_n=2.0)
    sched = build_schedule_for(s, np.random.default_rng(0))
    t = np.arange(5000) * 1e-3
    assert np.all(setpoint_profile(s, t, sched) == 1.0)


def test_in_band_window_of_a_character_is_its_hold_only():
    s = parse_scenario({"name": "r", "duration_s": 6.0, "seed": 4,
                        "reading": {"wpm": 60, "start_s": 1.5, "mode": "refresh", "refresh_lift_force_n": 0.4},
                        "setpoint": {"force_n": 1.0}, "finger": {"gap_m": 1e-3}})
    res = run_scenario(s)
    tr = res.trace
    _, hold = refresh_phases(s, res.schedule, tr["t_s"])
    ok = in_band(tr["force_true_n"], tr["setpoint_n"], 0.1)
    ci = tr["char_index"]
    chars = np.unique(ci[hold & (ci >= 0)])
    expected = np.mean([np.mean(ok[hold & (ci == c)]) >= CHAR_IN_BAND_REQUIRED for c in chars])
    assert res.metrics["char_in_band_fraction"] == pytest.approx(expected)
    whole_dwell = compute_metrics(tr, 1.5, 0.1, res.schedule)["char_in_band_fraction"]
    assert whole_dwell < res.metrics["char_in_band_fraction"]      # press and release are never in band
    assert res.metrics["characters"] == len(chars)


def test_continuous_metrics_use_the_whole_dwell():
    res = run_scenario("contact_onset")
    m = compute_metrics(res.trace, res.spec.reading.start_s, res.spec.setpoint.band_fraction, res.schedule)
    for k in ("char_in_band_fraction", "in_band_fraction", "force_rmse_n", "characters"):
        assert res.metrics[k] == m[k]


def test_refresh_meets_its_band_at_60_wpm_but_not_at_120_wpm():
    """8 s of refresh reading with seed 300: at 60 wpm every character in band (0.909-1.000 of
    them over seeds 300-311); at 120 wpm the
    band is not met (0.17-0.88 of the characters over seeds 300-315, 0.37 with seed 300: each
    character's press draws its own film scatter, and the shorter hold leaves less time to
    settle it)."""
    slow = run_scenario("refresh_60wpm", duration_s=8.0, seed=300).metrics["char_in_band_fraction"]
    fast = run_scenario("refresh_120wpm", duration_s=8.0, seed=300).metrics["char_in_band_fraction"]
    assert slow >= 0.9
    assert fast < 0.5


# ---------------------------------------------------------------- reading inputs

def test_user_text_file_with_natural_variability(tmp_path):
    from ebraille_sim.scenarios.braille import text_to_cells
    from ebraille_sim.scenarios.spec import load_scenario
    (tmp_path / "note.txt").write_text("Meet me at 5.\nBring the map, please!\n", encoding="utf-8")
    (tmp_path / "mine.toml").write_text(
        'name = "mine"\nseed = 3\n[reading]\nfile = "note.txt"\nwpm = 90\nstart_s = 1.0\n'
        'jitter_fraction = 0.2\nword_pause_s = 0.2\nline_pause_s = 0.8\n[finger]\ngap_m = 0.001\n')
    res = run_scenario(load_scenario(tmp_path / "mine.toml"))
    cells = text_to_cells((tmp_path / "note.txt").read_text(encoding="utf-8"))
    sched = res.schedule
    assert [c.unicode for c in sched.cells] == [c.unicode for c in cells]
    mean = 60.0 / (5 * 90)
    line_end = np.array([c.line_end for c in sched.cells])
    assert np.all(sched.dwell_s[line_end] >= 0.5 * mean + 0.8 - 1e-12)
    assert res.metrics["characters"] == len(cells)
    assert res.metrics["wpm"] < 70.0                                  # pauses slow the realised rate
    again = run_scenario(load_scenario(tmp_path / "mine.toml"))
    np.testing.assert_array_equal(sched.dwell_s, again.schedule.dwell_s)
    (tmp_path / "gone.toml").write_text('name = "gone"\n[reading]\nfile = "missing.txt"\n')
    with pytest.raises(ScenarioError, match="\\[reading\\] file '.*missing.txt' not found"):
        run_scenario(load_scenario(tmp_path / "gone.toml"))


def test_letter_passage_has_lines_for_line_pauses():
    from ebraille_sim.scenarios.braille import text_to_cells
    from ebraille_sim.scenarios.passages import load_passage
    cells = text_to_cells(load_passage("letter"))
    assert sum(c.line_end for c in cells) >= 10 and len(cells) > 500
