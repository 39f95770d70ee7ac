"""Regression suite: tolerances, tampered baselines and degraded gains fail; the pytest helper."""
import json
import pathlib
import shutil

import pytest

from ebraille_sim.tools import regress as R
from ebraille_sim.cli import main as cli
from ebraille_sim.scenarios.spec import list_scenarios
from ebraille_sim.tools.testing import (assert_matches_baseline, assert_scenario, check_metrics,
                                        check_scenario_metrics)

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenarios"


@pytest.fixture
def suite(tmp_path):
    """A private scenario folder with two short scenarios and fresh baselines."""
    d = tmp_path / "scenarios"
    d.mkdir()
    shutil.copy(SCEN / "contact_onset.toml", d)
    text = (SCEN / "refresh_60wpm.toml").read_text().replace("duration_s = 20.0", "duration_s = 4.0")
    (d / "refresh_60wpm.toml").write_text(text)
    assert cli(["regress", "--scenarios", str(d), "--update"]) == 0
    return d


def test_tolerance_table_covers_every_metric_but_the_wall_clock():
    from ebraille_sim.scenarios.legibility import METRIC_NAMES as LEG
    from ebraille_sim.scenarios.metrics import METRIC_NAMES
    for m in list(METRIC_NAMES) + list(LEG):
        assert (m in R.TOLERANCES) != (m in R.EXCLUDED), m
    assert "real_time_factor" in R.EXCLUDED


def test_compare_metrics_statuses():
    base = {"force_rmse_n": 0.020, "contact_loss_count": 0, "settling_time_s": None, "old_metric": 1.0,
            "real_time_factor": 100.0}
    cur = {"force_rmse_n": 0.0225, "contact_loss_count": 1, "settling_time_s": None, "new_metric": 2.0,
           "real_time_factor": 300.0}
    rows = {r.metric: r for r in R.compare_metrics(cur, base)}
    assert rows["force_rmse_n"].status == "ok"                       # 2.5 mN < 2 mN + 5 % of 20 mN
    assert rows["contact_loss_count"].status == "moved" and rows["contact_loss_count"].note == "worse"
    assert rows["settling_time_s"].status == "ok"
    assert rows["old_metric"].status == "removed"
    assert rows["new_metric"].status == "new"
    assert "real_time_factor" not in rows
    worse = R.compare_metrics({"force_rmse_n": 0.03}, {"force_rmse_n": 0.02})[0]
    better = R.compare_metrics({"force_rmse_n": 0.01}, {"force_rmse_n": 0.02})[0]
    assert (worse.status, worse.note) == ("moved", "worse") and (better.status, better.note) == ("moved", "better")
    one_none = R.compare_metrics({"settling_time_s": None}, {"settling_time_s": 0.3})[0]
    assert one_none.status == "moved"


def test_unchanged_tree_matches_its_baselines(suite, capsys):
    assert cli(["regress", "--scenarios", str(suite)]) == 0
    assert "2 of 2 scenario(s) match their baselines" in capsys.readouterr().out
    doc = json.loads((suite / "baselines" / "contact_onset.json").read_text())
    assert doc["scenario"] == "contact_onset" and "real_time_factor" not in doc["metrics"]


def test_tampered_baseline_fails_with_a_table(suite, capsys):
    path = suite / "baselines" / "contact_onset.json"
    doc = json.loads(path.read_text())
    doc["metrics"]["peak_force_n"] += 0.1
    path.write_text(json.dumps(doc))
    assert cli(["regress", "--scenarios", str(suite)]) == 1
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("contact_onset") and "peak_force_n" in ln)
    assert "moved" in line and "-0.1" in line
    assert "1 of 2 scenario(s) match their baselines; 1 failed" in out
    assert cli(["regress", "--scenarios", str(suite), "--only", "refresh_60wpm"]) == 0


def test_degraded_gains_fail(suite, tmp_path, capsys):
    weak = tmp_path / "weak.toml"
    weak.write_text('controller = "pid"\n[gains]\nkp_v_per_n = 0.4\nki_v_per_ns = 1.0\n')
    assert cli(["regress", "--scenarios", str(suite), "--controller", str(weak)]) == 1
    out = capsys.readouterr().out
    assert "in_band_fraction" in out and "moved (worse)" in out


def test_criteria_fail_whatever_the_baseline(suite, capsys):
    p = suite / "contact_onset.toml"
    p.write_text(p.read_text().replace("onset_overshoot_max = 0.15", "peak_force_max_n = 1.55"))  # peaks 1.60 N
    assert cli(["regress", "--scenarios", str(suite), "--only", "contact_onset", "--update"]) == 1
    assert "criterion ([criteria] peak_force_max_n)" in capsys.readouterr().out


def test_missing_baseline_and_bad_names(suite, capsys):
    (suite / "baselines" / "refresh_60wpm.json").unlink()
    assert cli(["regress", "--scenarios", str(suite)]) == 1
    assert "no baseline refresh_60wpm.json; run with --update" in capsys.readouterr().out
    assert cli(["regress", "--scenarios", str(suite), "--only", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown scenario 'nope'") and err.count("\n") == 1
    (suite / "baselines" / "contact_onset.json").write_text("{not json")
    assert cli(["regress", "--scenarios", str(suite), "--only", "contact_onset"]) == 2      # bad input, not a check
    err = capsys.readouterr().err
    assert err.startswith("error: baseline") and "not valid JSON" in err and err.count("\n") == 1


def test_every_shipped_scenario_has_a_baseline():
    names = [p.stem for p in SCEN.glob("*.toml")]
    missing = [n for n in names if not (SCEN / "baselines" / f"{n}.json").exists()]
    assert not missing, f"run 'ebraille-sim regress --update --only {' '.join(missing)}'"


@pytest.mark.slow
def test_full_regression_suite_passes(capsys):
    assert cli(["regress", "--scenarios", str(SCEN), "-j", "2"]) == 0, capsys.readouterr().out


# ---------------------------------------------------------------- pytest helper

def test_assert_scenario_one_liner():
    m = assert_scenario("contact_onset", in_band_fraction__ge=0.5, peak_force_n__le=3.0,
                        settling_time_s__between=(0.0, 2.0))
    assert m["characters"] > 0
    with pytest.raises(AssertionError, match=r"scenario contact_onset: peak_force_n = 1\.\d+, expected <= 1"):
        assert_scenario("contact_onset", peak_force_n__le=1.0)
    fails = check_scenario_metrics("contact_onset", contact_loss_count__eq=0, settling_time_s__lt=1.0)
    assert len(fails) == 1 and fails[0].startswith("settling_time_s = 1.4")
    assert fails[0].endswith("expected < 1")


def test_helper_rejects_unknown_checks():
    with pytest.raises(ValueError, match="unknown metric 'in_band'"):
        check_metrics({"in_band_fraction": 1.0}, in_band__ge=0.9)
    with pytest.raises(ValueError, match="unknown operator 'atleast'"):
        check_metrics({"in_band_fraction": 1.0}, in_band_fraction__atleast=0.9)
    assert check_metrics({"settling_time_s": None}, settling_time_s__le=1.0) == \
        ["settling_time_s = None, expected <= 1"]


def test_shipped_names_are_listed():
    assert "refresh_120wpm" in list_scenarios() and "tremor_90wpm" in list_scenarios()


# ---------------------------------------------------------------- baselines from any working folder

OWN = """name = "own"
seed = 4
duration_s = 1.5
[reading]
wpm = 90
start_s = 0.5
[criteria]
peak_force_max_n = 3.0
"""


@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """A working folder with a scenarios/ folder of its own holding one unrelated file."""
    work = tmp_path / "work"
    (work / "scenarios").mkdir(parents=True)
    (work / "scenarios" / "unrelated.toml").write_text('name = "unrelated"\nduration_s = 1.0\n')
    monkeypatch.chdir(work)
    return work


def test_shipped_baselines_are_found_from_a_folder_with_its_own_scenarios(elsewhere, capsys):
    files = R.scenario_files(only=["tremor_90wpm", "unrelated"])
    assert files == [SCEN / "tremor_90wpm.toml", elsewhere / "scenarios" / "unrelated.toml"]
    assert R.baseline_path(files[0]) == SCEN / "baselines" / "tremor_90wpm.json"
    before = (SCEN / "baselines" / "tremor_90wpm.json").read_bytes()
    assert_matches_baseline("tremor_90wpm")
    assert cli(["regress", "--only", "tremor_90wpm"]) == 0
    assert "1 of 1 scenario(s) match their baselines" in capsys.readouterr().out
    assert (SCEN / "baselines" / "tremor_90wpm.json").read_bytes() == before
    assert not (elsewhere / "scenarios" / "baselines").exists()


def test_assert_matches_baseline_still_fails_on_a_moved_shipped_metric(elsewhere, tmp_path):
    """Checked against a copy of the shipped baseline with one number moved: the helper must fail."""
    moved = tmp_path / "moved"
    moved.mkdir()
    doc = json.loads((SCEN / "baselines" / "contact_onset.json").read_text())
    doc["metrics"]["onset_overshoot_fraction"] += 0.05
    (moved / "contact_onset.json").write_text(json.dumps(doc))
    with pytest.raises(AssertionError, match=r"contact_onset does not match its baseline .*moved/contact_onset\.json"
                       r"(?s:.*)onset_overshoot_fraction.*moved \(better\)"):
        assert_matches_baseline("contact_onset", baseline_dir=moved)


def test_own_scenario_gets_a_baseline_then_matches(elsewhere, tmp_path, capsys):
    own = tmp_path / "mine" / "own.toml"
    own.parent.mkdir()
    own.write_text(OWN)
    with pytest.raises(AssertionError, match=r"scenario own has no baseline .*own\.json; create it with "
                                             r"'ebraille-sim regress --update --only .*own\.toml'"):
        assert_matches_baseline(own)
    assert cli(["regress", "--only", str(own)]) == 1
    assert "no baseline own.json" in capsys.readouterr().out
    assert cli(["regress", "--update", "--only", str(own)]) == 0
    capsys.readouterr()
    base = own.parent / "baselines" / "own.json"
    doc = json.loads(base.read_text())
    assert doc["scenario"] == "own" and doc["seed"] == 4 and 0.5 < doc["metrics"]["peak_force_n"] < 1.5
    assert_matches_baseline(own)
    assert_matches_baseline(str(own))
    assert cli(["regress", "--only", str(own), "tremor_90wpm"]) == 0
    assert "2 of 2 scenario(s) match their baselines" in capsys.readouterr().out
    doc["metrics"]["force_rmse_n"] *= 2
    base.write_text(json.dumps(doc))
    with pytest.raises(AssertionError, match=r"own does not match its baseline(?s:.*)force_rmse_n"):
        assert_matches_baseline(own)


def test_a_missing_scenario_file_is_named_as_a_file(elsewhere, capsys):
    assert cli(["regress", "--only", "nope/missing.toml"]) == 2
    err = capsys.readouterr().err
    assert err == "error: scenario file 'nope/missing.toml' not found\n"
    assert cli(["regress", "--only", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: scenario 'nope' not found (looked in ") and "unrelated, battery_sag" in err
    with pytest.raises(ValueError, match="^scenario file 'nope/missing.toml' not found$"):
        assert_matches_baseline("nope/missing.toml")
