"""Exit codes and machine-readable outputs for CI: run's criteria, regress --junit/--json, list --json."""
import importlib.util
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
[controller]
name = "pid"
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
    # a 1.5 s run of seed 3 peaks at about 1.06 N (onset overshoot fraction about 2.3 %: this
    # seed's press reads its film low) and then stays in band: a zero force limit and a 0.5 %
    # overshoot cannot be met, a half-time band can
    path = _scenario(tmp_path, "impossible",
                     "peak_force_max_n = 0.0\nonset_overshoot_max = 0.005\nin_band_min = 0.5")
    path.write_text(path.read_text().replace("seed = 2", "seed = 3"))
    out = tmp_path / "out"
    assert cli(["run", str(path), "--no-plot", "--out", str(out)]) == 1
    cap = capsys.readouterr()
    lines = cap.err.splitlines()
    assert len(lines) == 2, cap.err
    assert lines[0].startswith("criterion failed: peak_force_n = 1.0") and lines[0].endswith(
        "expected <= 0 ([criteria] peak_force_max_n)")
    assert lines[1].startswith("criterion failed: onset_overshoot_fraction = 0.02") and lines[1].endswith(
        "expected <= 0.005 ([criteria] onset_overshoot_max)")
    assert "criterion in_band_fraction >= 0.5: pass" in cap.out             # the table still prints
    doc = json.loads((out / "metrics.json").read_text())                    # and the outputs are written
    assert [k for k, c in doc["criteria"].items() if not c["passed"]] == ["peak_force_max_n", "onset_overshoot_max"]
    m = doc["metrics"]
    assert 0.5 < m["peak_force_n"] < 1.5 and 0.005 < m["onset_overshoot_fraction"] < 0.15
    assert m["in_band_fraction"] > 0.5


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


# ---------------------------------------------------------------- --json and --quiet on every command

def _csv_record(folder: pathlib.Path) -> pathlib.Path:
    from ebraille_sim.identification import bench
    rec = bench.run_profiles([bench.PAPER_PROFILES["square_0.2hz"]], seed=2)["square_0.2hz"]
    path = folder / "square.csv"
    rec.to_csv(path)
    return path


def _argv(command: str, tmp_path: pathlib.Path, tag: str) -> list:
    """A fast invocation of ``command`` writing under ``tmp_path/tag``."""
    out = str(tmp_path / tag)
    if command == "list":
        return ["list"]
    if command == "run":
        return ["run", str(_scenario(tmp_path / "scen", "plain")), "--no-plot", "--out", out]
    if command == "regress":
        d = tmp_path / "suite"
        if not (d / "baselines" / "alpha.json").exists():
            _scenario(d, "alpha", "peak_force_max_n = 3.0")
            assert cli(["regress", "--scenarios", str(d), "--update", "--quiet"]) == 0
        return ["regress", "--scenarios", str(d)]
    if command == "sweep":
        return ["sweep", "contact_onset", "--rates", "90", "--readers", "2", "--duration", "2.1", "-j", "1",
                "--no-figures", "--out", out]
    if command == "identify":
        csv_path = tmp_path / "square.csv"
        if not csv_path.exists():
            _csv_record(tmp_path)
        return ["identify", "--csv", str(csv_path), "--kinds", "linear", "--orders", "2", "--quick", "--no-plots",
                "--out", out]
    raise AssertionError(command)


def _check_document(command: str, doc: dict) -> None:
    if command == "list":
        assert "pid" in doc["controllers"] and "pymunk" in doc["plant_backends"]
    elif command == "run":
        assert doc["scenario"] == "plain" and doc["seed"] == 2
        assert 0.5 < doc["metrics"]["peak_force_n"] < 1.5
        assert [pathlib.Path(f).name for f in doc["files"]] == ["metrics.json", "trace.csv"]
        assert all(pathlib.Path(f).is_file() for f in doc["files"])
    elif command == "regress":
        assert doc["passed"] is True and doc["scenarios_checked"] == 1
        assert {r["status"] for r in doc["scenarios"][0]["rows"]} == {"ok"}
    elif command == "sweep":
        assert doc["episodes"] == 2 and doc["failed"] == 0 and doc["executor"] == "serial"
        assert doc["summary"][0]["scenario"] == "contact_onset" and doc["summary"][0]["episodes"] == 2
    elif command == "identify":
        assert doc["best"]["kind"] == "linear" and doc["best"]["order"] == 2
        assert doc["best"]["mean_fitness"] > 90.0 and doc["fitness"]["linear"]["2"]["square"] > 90.0


@pytest.mark.parametrize("command", ["list", "run", "regress", "sweep", "identify"])
def test_json_prints_one_document_and_quiet_prints_nothing(command, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli(_argv(command, tmp_path, "a") + ["--json"]) == 0
    cap = capsys.readouterr()
    _check_document(command, json.loads(cap.out))          # the whole of stdout is one document
    assert cli(_argv(command, tmp_path, "b") + ["--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == ""                   # no report, no progress


def test_json_and_quiet_on_tune(tmp_path, capsys):
    out = tmp_path / "t"
    assert cli(["tune", "steady_90wpm", "--population", "0", "--evaluations", "4", "--scenarios", "single",
                "--duration", "2.0", "--out", str(out), "--json", "--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.err == ""                                      # no progress bar under --quiet
    doc = json.loads(cap.out)
    assert doc["scenario"] == "steady_90wpm" and doc["population"] == 5 and doc["ms_max_tuned"] <= doc["ms_bound"] == 1.6
    assert doc["gains"]["kp_v_per_n"] > 0 and set(doc["costs"]) == {"tuned", "hand", "default", "simc"}
    assert 0.0 <= doc["scenarios"]["steady_90wpm"]["tuned"]["worst"] <= 1.0
    names = [pathlib.Path(f).name for f in doc["files"]]
    assert names[0] == "gains.toml" and "gains_hand.toml" in names
    assert all(pathlib.Path(f).is_file() for f in doc["files"])


def test_json_keeps_failed_criteria_and_warnings_on_stderr(tmp_path, capsys):
    path = _scenario(tmp_path, "low", "peak_force_max_n = 0.0")
    path.write_text(path.read_text() + "[setpoint]\nforce_n = 0.15\n")
    assert cli(["run", str(path), "--no-plot", "--out", str(tmp_path / "o"), "--json"]) == 1
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["criteria"]["peak_force_max_n"]["passed"] is False
    err = cap.err.splitlines()
    assert len(err) == 2 and err[0].startswith("warning: low.toml: [setpoint] force_n = 0.15 N is below")
    assert err[1].startswith("criterion failed: peak_force_n")


def test_regress_json_file_still_writes_the_file(tmp_path, capsys):
    d = tmp_path / "suite"
    _scenario(d, "alpha")
    assert cli(["regress", "--scenarios", str(d), "--update", "-q"]) == 0
    js = tmp_path / "r.json"
    assert cli(["regress", "--scenarios", str(d), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "1 of 1 scenario(s) match" in out and f"wrote {js}" in out   # the report; the document in the file
    assert json.loads(js.read_text())["scenarios_checked"] == 1


def test_json_prints_no_document_on_bad_input(tmp_path, capsys):
    assert cli(["run", "no_such_scenario", "--json", "--out", str(tmp_path / "o")]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.startswith("error: ") and cap.err.count("\n") == 1


# ---------------------------------------------------------------- run folders: --force, stale outputs, --trace

def test_run_refuses_an_existing_run_folder_before_simulating(tmp_path, capsys, monkeypatch):
    path = _scenario(tmp_path, "plain")
    out = tmp_path / "o"
    assert cli(["run", str(path), "--no-plot", "--out", str(out), "-q"]) == 0
    before = (out / "metrics.json").read_text()

    def no_simulation(*a, **k):
        raise AssertionError("simulated although the folder is refused")
    monkeypatch.setattr("ebraille_sim.scenarios.runner.run_scenario", no_simulation)
    assert cli(["run", str(path), "--no-plot", "--out", str(out), "--seed", "5"]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.count("\n") == 1
    assert cap.err.startswith(f"error: run folder {str(out)!r} already holds a run (metrics.json, trace.csv)")
    assert "--force" in cap.err and (out / "metrics.json").read_text() == before


def test_force_overwrites_and_clears_stale_outputs(tmp_path, capsys):
    path = _scenario(tmp_path, "plain")
    out = tmp_path / "o"
    assert cli(["run", str(path), "--out", str(out), "-q"]) == 0
    assert (out / "force.png").stat().st_size > 10_000 and (out / "trace.csv").is_file()
    (out / "notes.txt").write_text("mine")                   # not a run output: kept
    (out / "animation.gif").write_bytes(b"GIF89a")           # a run output this run does not write: removed
    assert cli(["run", str(path), "--out", str(out), "--force", "--no-plot", "--trace", "none", "--seed", "5",
                "-q"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "notes.txt"]
    assert json.loads((out / "metrics.json").read_text())["seed"] == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o", "plain.toml"]   # no staging folder left


@pytest.mark.skipif(importlib.util.find_spec("pyarrow") is not None, reason="pyarrow is installed")
def test_trace_parquet_without_pyarrow_is_one_line(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli(["run", str(_scenario(tmp_path, "plain")), "--trace", "parquet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == "error: --trace parquet needs pyarrow, which is not installed; use --trace csv or none\n"
    assert not out.exists()


@pytest.mark.skipif(importlib.util.find_spec("pyarrow") is None, reason="needs pyarrow")
def test_trace_parquet_has_the_csv_columns(tmp_path):
    import pyarrow.parquet as pq

    from ebraille_sim.scenarios.runner import TRACE_COLUMNS
    out = tmp_path / "o"
    assert cli(["run", str(_scenario(tmp_path, "plain")), "--trace", "parquet", "--no-plot", "--out", str(out),
                "-q"]) == 0
    table = pq.read_table(out / "trace.parquet")
    assert table.column_names == list(TRACE_COLUMNS) and table.num_rows > 1000
    assert not (out / "trace.csv").exists()


# ---------------------------------------------------------------- --out problems, before any work

def _out_argv(command: str, out: str) -> list:
    return {"run": ["run", "steady_90wpm", "--duration", "1"],
            "sweep": ["sweep", "contact_onset", "--readers", "1", "-j", "1"],
            "tune": ["tune", "steady_90wpm", "--population", "0", "--evaluations", "4"],
            "identify": ["identify", "--quick"],
            "train": ["train", "--steps", "10"]}[command] + ["--out", out]


@pytest.mark.parametrize("command", ["run", "sweep", "tune", "identify", "train"])
def test_out_problems_are_one_line_before_any_work(command, tmp_path, capsys, monkeypatch):
    import os
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if pathlib.Path(p) == locked
                        else real_access(p, mode, **kw))
    cases = [(str(a_file), f"error: --out {str(a_file)!r} is a file, not a folder"),
             (str(a_file / "sub"), f"error: --out {str(a_file / 'sub')!r}: {str(a_file)!r} is a file, not a folder"),
             (str(locked / "new"), f"error: --out {str(locked / 'new')!r}: folder {str(locked)!r} is not writable")]
    for out, message in cases:
        assert cli(_out_argv(command, out) + ["--json"]) == 2
        cap = capsys.readouterr()
        assert cap.out == "" and cap.err == message + "\n"
    assert list(locked.iterdir()) == []


# ---------------------------------------------------------------- --backend, --animate

def test_backend_help_lists_the_plant_backends(capsys):
    from ebraille_sim.plant.backends import PLANT_BACKENDS
    assert cli(["run", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--backend {" + ",".join(PLANT_BACKENDS) + "}" in text
    assert "plant model: " + ", ".join(PLANT_BACKENDS) + " (default: lumped)" in text
    assert cli(["run", "steady_90wpm", "--backend", "nope"]) == 2
    assert "invalid choice: 'nope'" in capsys.readouterr().err


def test_animate_writes_into_the_run_folder_with_progress(tmp_path, capsys, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    out = tmp_path / "anim"
    argv = ["run", "contact_onset", "--backend", "pymunk", "--duration", "0.3", "--no-plot", "--trace", "none",
            "--out", str(out), "--animate"]
    assert cli(argv) == 0
    cap = capsys.readouterr()
    assert (out / "animation.gif").stat().st_size > 1000 and list(work.iterdir()) == []
    frames = 1 + int(0.3 * 25)                               # 25 frames per simulated second, both ends
    assert cap.err.splitlines() == [f"drawing frames {frames}/{frames}"]
    assert f"{out / 'animation.gif'} ({frames} frames)" in cap.out
    assert cli(argv + ["--force", "--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == "" and (out / "animation.gif").is_file()


def test_frame_progress_counts_in_place_on_a_terminal_and_in_lines_elsewhere():
    import io

    from ebraille_sim.commands import FrameProgress

    class Tty(io.StringIO):
        def isatty(self):
            return True
    tty, log = Tty(), io.StringIO()
    bars = [FrameProgress("frames", stream=tty), FrameProgress("frames", stream=log, every=25),
            FrameProgress("frames", enabled=False, stream=log)]
    for bar in bars:
        for k in range(1, 61):
            bar(k, 60)
        bar.close()
    assert tty.getvalue() == "".join(f"\rframes {k}/60" for k in range(1, 61)) + "\n"
    assert log.getvalue() == "frames 25/60\nframes 50/60\nframes 60/60\n"


def test_tune_refuses_a_duration_that_ends_before_reading(tmp_path):
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "ebraille_sim", "tune", "contact_onset", "--duration", "0.5",
                        "--out", str(tmp_path / "t")], capture_output=True, text=True)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "before its reading starts" in lines[0]
    assert not (tmp_path / "t").exists()


def test_a_reader_that_stops_early_gets_no_traceback():
    """``ebraille-sim list --json | head -c 0``: the closed pipe ends the command quietly."""
    import subprocess
    import sys
    p = subprocess.Popen([sys.executable, "-m", "ebraille_sim", "list", "--json"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()                                  # the reader is gone before anything is written
    err = p.stderr.read().decode()
    p.wait(timeout=60)
    assert "Traceback" not in err and p.returncode == 0, err


# ---------------------------------------------------------------- run: force.png names what it shows

def test_force_figure_names_controller_backend_and_its_vertical_lines(tmp_path, capsys, monkeypatch):
    from ebraille_sim.commands import run as run_command
    from ebraille_sim.tools import report

    monkeypatch.setattr(run_command, "PLOT_PROCESS", False)      # the figure object is drawn here

    seen = {}
    draw = report.force_figure

    def recording(result, controller_file=None, backend=None):
        fig = draw(result, controller_file, backend)
        ax = fig.axes[0]
        seen["title"] = ax.get_title()
        seen["legend"] = [t.get_text() for t in ax.get_legend().get_texts()]
        seen["vlines"] = sorted(float(ln.get_xdata()[0]) for ln in ax.get_lines()
                                if len(ln.get_xdata()) == 2 and ln.get_xdata()[0] == ln.get_xdata()[1])
        seen["starts"] = result.schedule.boundaries_s()
        seen["t_end"] = float(result.trace["t_s"][-1])
        return fig

    monkeypatch.setattr(report, "force_figure", recording)
    path = _scenario(tmp_path, "short")
    out = tmp_path / "out"
    assert cli(["run", str(path), "--out", str(out), "--backend", "lumped", "--controller", "pid"]) == 0
    assert (out / "force.png").stat().st_size > 5000
    assert "controller pid" in seen["title"] and "lumped backend" in seen["title"] and "seed 2" in seen["title"]
    # every vertical line is explained: one legend entry for the character starts, one for reading
    assert seen["legend"].count("character starts") == 1 and seen["legend"].count("reading starts") == 1
    starts = [float(s) for s in seen["starts"] if s <= seen["t_end"]]
    assert len(starts) >= 2
    assert seen["vlines"] == sorted(starts + [0.5])


def _figure_data(n: int = 500) -> dict:
    import numpy as np
    t = np.arange(1, n + 1) * 1e-3
    return {"t_s": t, "setpoint_n": np.ones(n), "force_est_n": 1 - np.exp(-t / 0.05),
            "force_true_n": 1 - np.exp(-t / 0.04), "command_v": np.full(n, 0.5), "starts_s": np.array([0.1, 0.3]),
            "band_fraction": 0.1, "reading_start_s": 0.2, "title": "synthetic: controller pid, seed 1"}


def test_force_plotter_draws_in_its_process_what_draw_force_figure_draws_here():
    from ebraille_sim.tools.forceplot import ForcePlotter, draw_force_figure, png_bytes
    data = _figure_data()
    with ForcePlotter.start() as plotter:
        plotter.send(data)
        png = plotter.png()
    here = png_bytes(draw_force_figure(data))
    assert png is not None and png[:8] == here[:8] == b"\x89PNG\r\n\x1a\n"
    assert png[16:24] == here[16:24]                          # IHDR: the same width and height
    assert plotter._proc.returncode == 0


def test_force_plotter_failure_and_cancel_leave_no_process():
    from ebraille_sim.tools.forceplot import ForcePlotter
    bad = ForcePlotter.start()
    bad.send({"t_s": [0.0]})                                  # missing columns: the helper fails
    assert bad.png() is None and bad._proc.returncode == 1
    idle = ForcePlotter.start()
    idle.close()                                              # never sent: ended, not left behind
    assert idle._proc.returncode is not None and idle.png() is None


def test_run_in_a_fresh_process_draws_force_png_in_the_helper(tmp_path):
    """A run from the command line draws force.png in the helper process (Matplotlib is not
    loaded in the run's own process) and writes the same trace as a run without it."""
    import subprocess
    import sys
    code = ("import sys\n"
            "from ebraille_sim.tools import forceplot\n"
            "sent = []\n"
            "send = forceplot.ForcePlotter.send\n"
            "forceplot.ForcePlotter.send = lambda self, data: (sent.append(1), send(self, data))[1]\n"
            "from ebraille_sim.cli import main\n"
            "code = main(sys.argv[1:])\n"
            "assert sent == [1] and 'matplotlib' not in sys.modules, sorted(sys.modules)\n"
            "sys.exit(code)\n")
    out = tmp_path / "fresh"
    p = subprocess.run([sys.executable, "-c", code, "run", "steady_90wpm", "--duration", "2", "--quiet",
                        "--out", str(out)], cwd=tmp_path, capture_output=True, text=True,
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr
    png = (out / "force.png").read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 5000
    assert cli(["run", "steady_90wpm", "--duration", "2", "--quiet", "--no-plot", "--out", str(tmp_path / "here")]) == 0
    assert (out / "trace.csv").read_bytes() == (tmp_path / "here" / "trace.csv").read_bytes()


# ---------------------------------------------------------------- outputs all at once; interrupts

_PAUSE_IN_WRITE = """
import sys, time
from ebraille_sim.tools import report

def paused(path, trace):
    with open(path, "w") as fh:              # half a trace, then a pause in the write phase
        fh.write("t_s,setpoint_n\\n0.001,1.0\\n")
    print("writing the trace", file=sys.stderr, flush=True)
    time.sleep(120)

report.write_trace_csv = paused
from ebraille_sim.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_sigterm_in_the_write_phase_leaves_the_old_run_and_no_partial_files(tmp_path):
    """SIGTERM while ``run`` writes: exit 143, one line, the earlier run untouched, nothing left over."""
    from ebraille_sim.tools.outputs import STAGING_PREFIX
    import signal
    import subprocess
    import sys
    out = tmp_path / "steady"
    out.mkdir()
    old = {"metrics.json": '{"seed": 7}\n', "trace.csv": "t_s\n0.001\n", "force.png": "png"}
    for name, text in old.items():
        (out / name).write_text(text)
    p = subprocess.Popen([sys.executable, "-c", _PAUSE_IN_WRITE, "run", "steady_90wpm", "--duration", "3",
                          "--out", str(out), "--force"], cwd=tmp_path, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    seen = []
    for line in p.stderr:                                    # wait until the write phase has begun
        seen.append(line)
        if line.startswith("writing the trace"):
            break
    else:
        raise AssertionError("never reached the write phase: " + "".join(seen))
    staging = [q.name for q in out.iterdir() if q.name.startswith(STAGING_PREFIX)]
    assert len(staging) == 1 and (out / staging[0] / "trace.csv").is_file()   # the half-written trace
    p.send_signal(signal.SIGTERM)
    err = p.stderr.read()
    p.wait(timeout=60)
    assert p.returncode == 143 and err == "error: terminated (SIGTERM)\n" and "Traceback" not in err
    assert sorted(q.name for q in tmp_path.iterdir()) == ["steady"]          # nothing beside the folder
    assert {q.name: q.read_text() for q in out.iterdir()} == old             # the earlier run, as it was


def test_an_interrupt_while_writing_a_new_run_leaves_nothing(tmp_path, capsys, monkeypatch):
    from ebraille_sim.tools import report

    def interrupted(path, trace):
        pathlib.Path(path).write_text("t_s\n0.001\n")
        raise KeyboardInterrupt
    monkeypatch.setattr(report, "write_trace_csv", interrupted)
    path = _scenario(tmp_path, "plain")
    assert cli(["run", str(path), "--out", str(tmp_path / "o")]) == 130
    assert capsys.readouterr().err.splitlines()[-1] == "error: interrupted"
    assert sorted(q.name for q in tmp_path.iterdir()) == ["plain.toml"]


def test_staged_moves_in_owned_outputs_and_keeps_the_rest(tmp_path):
    from ebraille_sim.tools.outputs import INCOMPLETE, STAGING_PREFIX, staged
    out = tmp_path / "out"
    owned = {"summary.txt": None, "stale.json": None, "figures": "*.png"}
    with staged(out, owned) as folder:       # staged inside the folder, on its file system
        assert (folder / INCOMPLETE).is_file() and folder.parent == out and folder.name.startswith(STAGING_PREFIX)
        assert [p.name for p in out.iterdir()] == [folder.name]
        (folder / "summary.txt").write_text("one")
        (folder / "figures").mkdir()
        (folder / "figures" / "a.png").write_text("a1")
        (folder / "figures" / "b.png").write_text("b1")
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == ["figures", "figures/a.png",
                                                                      "figures/b.png", "summary.txt"]
    (out / "stale.json").write_text("old")                   # owned, not written next time: removed
    (out / "notes.txt").write_text("mine")                   # not owned: kept
    (out / "figures" / "mine.txt").write_text("mine")        # not an owned pattern: kept
    with staged(out, owned) as folder:
        (folder / "summary.txt").write_text("two")
        (folder / "figures").mkdir()
        (folder / "figures" / "a.png").write_text("a2")
    assert {str(p.relative_to(out)): p.read_text() for p in out.rglob("*") if p.is_file()} == {
        "summary.txt": "two", "notes.txt": "mine", "figures/a.png": "a2", "figures/mine.txt": "mine"}
    with pytest.raises(RuntimeError), staged(out, owned) as folder:
        (folder / "summary.txt").write_text("three")
        raise RuntimeError("failed half-way")
    assert (out / "summary.txt").read_text() == "two" and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_sweep_without_figures_removes_the_old_figures(tmp_path, capsys):
    out = tmp_path / "sw"
    argv = ["sweep", "contact_onset", "--readers", "0", "--duration", "2.1", "-j", "1", "--out", str(out), "-q"]
    assert cli(argv) == 0
    assert list((out / "figures").glob("*.png"))
    first = (out / "results.csv").read_text()
    assert cli(argv + ["--no-figures", "--seed", "3"]) == 0
    assert not (out / "figures").exists() and (out / "results.csv").read_text() != first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sw"]


def test_trace_rate_keeps_every_kth_period_and_the_full_rate_metrics(tmp_path):
    """``--trace-rate 100`` at the 1 kHz control rate: trace.csv holds the ends of periods
    10, 20, ... (the same rows as the full trace's every tenth), metrics.json is unchanged."""
    import csv
    import json
    full, thin = tmp_path / "full", tmp_path / "thin"
    common = ["run", "steady_90wpm", "--duration", "2", "--no-plot", "--quiet"]
    assert cli(common + ["--out", str(full)]) == 0
    assert cli(common + ["--out", str(thin), "--trace-rate", "100"]) == 0
    rows_full = list(csv.reader((full / "trace.csv").open(encoding="utf-8")))
    rows_thin = list(csv.reader((thin / "trace.csv").open(encoding="utf-8")))
    assert rows_thin[0] == rows_full[0]
    assert len(rows_full) - 1 == 2000 and len(rows_thin) - 1 == 200
    assert rows_thin[1:] == rows_full[10::10]
    m_full = json.loads((full / "metrics.json").read_text())["metrics"]
    m_thin = json.loads((thin / "metrics.json").read_text())["metrics"]
    drop = {"wall_time_s", "real_time_factor"}
    assert {k: v for k, v in m_full.items() if k not in drop} == {k: v for k, v in m_thin.items() if k not in drop}


def test_compiled_csv_floats_are_the_bytes_of_percent_9g():
    """The compiled formatter writes every covered float as ``"%.9g" % v`` does: random bit
    patterns, values of every magnitude it covers, ties to even, zeros, infinities, NaN."""
    import numpy as np

    from ebraille_sim.tools.csvformat import FLOAT, csv_body
    rng = np.random.default_rng(7)
    vals = np.concatenate([
        rng.normal(size=60000) * 10.0 ** rng.integers(-18, 9, size=60000),
        rng.integers(-2 ** 63, 2 ** 63 - 1, size=60000, dtype=np.int64).view(np.float64),
        np.arange(1, 20001) * 0.001, rng.integers(0, 4000, 20000) * 0.25, np.round(rng.normal(size=20000), 3),
        [0.0, -0.0, np.nan, -np.nan, np.inf, -np.inf, 1e-5, 1e-4, 9.99999999e-5, 999999999.4, 12345678.25,
         12345678.75, 1234567.125, 1234567.375, 1e8, 99999999.95, 0.1, 1 / 3, 100.0, -2.5e-9]])
    vals = vals[~(np.abs(vals) >= 1e9) & ~((np.abs(vals) < 1e-18) & (vals != 0))]
    assert csv_body([(FLOAT, vals)]) == ("%.9g\r\n" * len(vals) % tuple(vals.tolist())).encode()
    assert csv_body([(FLOAT, np.array([1.0, 999999999.5]))]) is None      # 1e+09: not covered
    assert csv_body([(FLOAT, np.array([1e-20]))]) is None


def test_trace_csv_with_numbers_the_compiled_formatter_leaves_out_is_the_csv_writers(tmp_path):
    import csv

    import numpy as np

    from ebraille_sim.scenarios.runner import TRACE_COLUMNS
    from ebraille_sim.tools.report import write_trace_csv
    n = 50
    tr = {c: np.linspace(-3.0, 4.0, n) for c in TRACE_COLUMNS}
    tr["energy_j"] = np.where(np.arange(n) % 7 == 0, 3.5e12, 1e-25 * np.arange(n))
    tr["setpoint_n"] = np.full(n, 1.25)
    tr["char_index"] = np.arange(n) % 4 - 1
    tr["character"] = np.array(["", "a,b", 'say "hi"', "\u2801"] * (n // 4) + ["", "x"], dtype=object)
    write_trace_csv(tmp_path / "fast.csv", tr)
    with open(tmp_path / "slow.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(TRACE_COLUMNS)
        for k in range(n):
            w.writerow([int(tr[c][k]) if c == "char_index" else str(tr[c][k]) if c == "character"
                        else f"{float(tr[c][k]):.9g}" for c in TRACE_COLUMNS])
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "slow.csv").read_bytes()


def test_trace_csv_is_the_bytes_of_the_row_by_row_csv_writer(tmp_path):
    """trace.csv is written column by column; the file equals what ``csv.writer`` writes row
    by row (9 significant digits, integer char_index, the braille character, CRLF)."""
    import csv

    import numpy as np

    from ebraille_sim.scenarios.runner import TRACE_COLUMNS, run_scenario
    from ebraille_sim.tools.report import write_trace_csv
    tr = dict(run_scenario("steady_90wpm", duration_s=2.0).trace)
    tr["character"] = np.array([*tr["character"][:-3], 'a,b', 'say "hi"', "x\ny"], dtype=object)
    write_trace_csv(tmp_path / "fast.csv", tr)
    with open(tmp_path / "slow.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(TRACE_COLUMNS)
        for k in range(len(tr["t_s"])):
            w.writerow([int(tr[c][k]) if c == "char_index" else str(tr[c][k]) if c == "character"
                        else f"{float(tr[c][k]):.9g}" for c in TRACE_COLUMNS])
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "slow.csv").read_bytes()
