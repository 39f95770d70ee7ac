"""Exit codes and machine-readable outputs for CI: run's criteria, regress --junit/--json, list --json."""
import json
import pathlib
import xml.etree.ElementTree as ET

import pytest

from ebraille_sim.cli import main as cli

ROOT = pathlib.Path(__file__).resolve().parent.parent

SHORT = """name = "{name}"
seed = 2
duration_s = 1.5
[reading]
wpm = 90
start_s = 0.5
[criteria]
{criteria}
"""


def _scenario(folder: pathlib.Path, name: str, criteria: str = "") -> pathlib.Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / f"{name}.toml"
    p.write_text(SHORT.format(name=name, criteria=criteria))
    return p


# ---------------------------------------------------------------- run: exit 1 on a failed criterion

def test_run_exits_1_naming_each_failed_criterion(tmp_path, capsys):
    # a 1.5 s run reaches about 1 N and stays in band about 95 % of the reading time:
    # a zero force limit and a perfect band cannot both be met, an overshoot of 10 (1000 %) can
    path = _scenario(tmp_path, "impossible",
                     "peak_force_max_n = 0.0\nin_band_min = 1.0\nonset_overshoot_max = 10.0")
    out = tmp_path / "out"
    assert cli(["run", str(path), "--no-plot", "--out", str(out)]) == 1
    cap = capsys.readouterr()
    lines = cap.err.splitlines()
    assert len(lines) == 2, cap.err
    assert lines[0].startswith("criterion failed: peak_force_n = 1.0") and lines[0].endswith(
        "expected <= 0 ([criteria] peak_force_max_n)")
    assert lines[1].startswith("criterion failed: in_band_fraction = 0.9") and lines[1].endswith(
        "expected >= 1 ([criteria] in_band_min)")
    assert "criterion onset_overshoot_fraction <= 10: pass" in cap.out       # the table still prints
    doc = json.loads((out / "metrics.json").read_text())                    # and the outputs are written
    assert [k for k, c in doc["criteria"].items() if not c["passed"]] == ["peak_force_max_n", "in_band_min"]
    assert 0.5 < doc["metrics"]["peak_force_n"] < 1.5 and 0.8 < doc["metrics"]["in_band_fraction"] < 1.0


def test_run_passing_criteria_exit_0_and_bad_input_stays_2(tmp_path, capsys):
    ok = _scenario(tmp_path, "easy", "peak_force_max_n = 3.0\nin_band_min = 0.5")
    assert cli(["run", str(ok), "--no-plot", "--out", str(tmp_path / "o"), "--json"]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and json.loads(cap.out)["criteria"]["in_band_min"]["passed"] is True
    bad = _scenario(tmp_path, "bad", "in_band_minimum = 0.5")
    assert cli(["run", str(bad), "--no-plot", "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "in_band_minimum" in err and err.count("\n") == 1
    assert not (tmp_path / "o2").exists()


# ---------------------------------------------------------------- regress --junit / --json

@pytest.fixture
def suite(tmp_path):
    """Two short scenarios with fresh baselines."""
    d = tmp_path / "scenarios"
    _scenario(d, "alpha", "peak_force_max_n = 3.0")
    _scenario(d, "beta")
    assert cli(["regress", "--scenarios", str(d), "--update"]) == 0
    return d


def test_regress_junit_and_json_on_success(suite, tmp_path):
    junit, js = tmp_path / "reports" / "junit.xml", tmp_path / "reports" / "regress.json"
    assert cli(["regress", "--scenarios", str(suite), "--junit", str(junit), "--json", str(js)]) == 0
    ts = ET.parse(junit).getroot().find("testsuite")
    assert (ts.get("tests"), ts.get("failures"), ts.get("errors")) == ("2", "0", "0")
    assert [tc.get("name") for tc in ts.iter("testcase")] == ["alpha", "beta"]
    assert not list(ts.iter("failure")) and not list(ts.iter("error"))
    doc = json.loads(js.read_text())
    assert doc["passed"] is True and doc["scenarios_checked"] == 2 and doc["scenarios_failed"] == 0
    alpha = doc["scenarios"][0]
    assert alpha["name"] == "alpha" and alpha["baseline"] == str(suite / "baselines" / "alpha.json")
    assert {r["status"] for r in alpha["rows"]} == {"ok"} and len(alpha["rows"]) > 10


def test_regress_junit_and_json_name_the_moved_metrics(suite, tmp_path, capsys):
    path = suite / "baselines" / "beta.json"
    doc = json.loads(path.read_text())
    true_peak = doc["metrics"]["peak_force_n"]
    doc["metrics"]["peak_force_n"] += 0.1
    doc["metrics"]["characters"] += 1
    path.write_text(json.dumps(doc))
    junit, js = tmp_path / "junit.xml", tmp_path / "regress.json"
    assert cli(["regress", "--scenarios", str(suite), "--junit", str(junit), "--json", str(js)]) == 1
    capsys.readouterr()
    ts = ET.parse(junit).getroot().find("testsuite")
    assert (ts.get("tests"), ts.get("failures"), ts.get("errors")) == ("2", "1", "0")
    cases = {tc.get("name"): tc for tc in ts.iter("testcase")}
    assert cases["alpha"].find("failure") is None
    fail = cases["beta"].find("failure")
    assert fail.get("message") == "2 metric(s) moved: peak_force_n, characters"
    peak_line = next(ln for ln in fail.text.splitlines() if ln.startswith("peak_force_n"))
    assert f"current {true_peak:.6g}" in peak_line and "change -0.1" in peak_line and "worse" not in peak_line
    out = json.loads(js.read_text())
    assert out["passed"] is False and out["scenarios_failed"] == 1
    rows = {r["metric"]: r for r in out["scenarios"][1]["rows"]}
    assert rows["peak_force_n"]["status"] == "moved" and rows["peak_force_n"]["current"] == pytest.approx(true_peak)
    assert rows["peak_force_n"]["note"] == "better" and rows["characters"]["status"] == "moved"


def test_regress_junit_reports_missing_baselines_and_criteria(suite, tmp_path, capsys):
    (suite / "baselines" / "beta.json").unlink()
    p = suite / "alpha.toml"
    p.write_text(p.read_text().replace("peak_force_max_n = 3.0", "peak_force_max_n = 0.5"))
    junit = tmp_path / "junit.xml"
    assert cli(["regress", "--scenarios", str(suite), "--junit", str(junit)]) == 1
    capsys.readouterr()
    cases = {tc.get("name"): tc for tc in ET.parse(junit).getroot().iter("testcase")}
    assert cases["alpha"].find("failure").get("message") == "1 metric(s) failed a criterion: peak_force_n"
    assert "expected <= 0.5 ([criteria] peak_force_max_n)" in cases["alpha"].find("failure").text
    assert cases["beta"].find("failure").get("message") == "no baseline beta.json; run with --update"


def test_regress_report_path_that_is_a_folder_fails_before_running(suite, tmp_path, capsys):
    assert cli(["regress", "--scenarios", str(suite), "--junit", str(tmp_path)]) == 2
    cap = capsys.readouterr()
    assert cap.err.startswith("error: --junit") and "is a folder" in cap.err and cap.out == ""


# ---------------------------------------------------------------- list --json

def test_list_json_names_where_each_scenario_comes_from(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _scenario(tmp_path / "scenarios", "mine")
    _scenario(tmp_path / "scenarios", "steady_90wpm")                  # your own copy shadows the shipped one
    assert cli(["list", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    by_name = {s["name"]: s for s in doc["scenarios"]}
    assert [s["name"] for s in doc["scenarios"]][:2] == ["mine", "steady_90wpm"]
    assert by_name["mine"]["from"] == "working folder" and by_name["steady_90wpm"]["from"] == "working folder"
    assert by_name["tremor_90wpm"]["from"] == "library"
    assert by_name["tremor_90wpm"]["file"] == str(ROOT / "scenarios" / "tremor_90wpm.toml")
    assert by_name["tremor_90wpm"]["description"].startswith("Physiological tremor") and \
        by_name["tremor_90wpm"]["error"] is None
    assert len(by_name) == len(list((ROOT / "scenarios").glob("*.toml"))) + 1
    assert "pid" in doc["controllers"] and "lumped" in doc["plant_backends"]
    assert "nominal" in doc["device_presets"]["finger"] and doc["estimator_models"][0].startswith("paper:")
    assert cli(["list"]) == 0
    text = capsys.readouterr().out
    assert "mine" in text and "[./scenarios]" in text and "tremor_90wpm" in text
