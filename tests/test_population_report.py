"""Population reports of sweeps and benchmarks: latched faults, criteria shares, false trips,
worst readers, the separating parameters and their figure; the population options' bad input."""
import csv
import json
import math

import pytest

from ebraille_sim.cli import main as cli
from ebraille_sim.commands.sweep import MAX_READERS
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.tools import benchmark as B
from ebraille_sim.tools import report as R
from ebraille_sim.tools import sweep as S


def test_a_latched_fault_is_recorded_with_the_time_it_latched():
    res = run_scenario("fault_motor_stall", duration_s=9.0)
    rec = R.latched_fault(res)
    assert rec["supervisor_fault"] == "motor_stalled"
    assert [t for t, text in res.supervisor["events"] if text == "fault motor_stalled: retract"] == \
        [rec["supervisor_fault_s"]]
    assert 4.0 < rec["supervisor_fault_s"] < 9.0
    assert rec["reading_s"] == pytest.approx(9.0 - res.spec.reading.start_s)
    clean = R.latched_fault(run_scenario("steady_90wpm", duration_s=3.0))
    assert clean["supervisor_fault"] is None and clean["supervisor_fault_s"] is None


def _row(reader, in_band, peak=1.1, fault=None, t=None, error="", h=0.1, scenario="tracking"):
    return {"scenario": scenario, "controller": "pid", "reader": reader, "seed": reader, "in_band_fraction": in_band,
            "peak_force_n": peak, "supervisor_fault": fault, "supervisor_fault_s": t, "reading_s": 1800.0,
            "error": error, "fsr_hysteresis": h, "finger_b_n_per_m": 300.0 + 10.0 * (reader % 2)}


def test_shares_false_trips_per_reading_hour_and_the_worst_readers():
    rows = [_row(0, 0.99, h=0.05), _row(1, 0.95, h=0.06), _row(2, 0.50, h=0.14),
            _row(3, 0.97, peak=3.4, h=0.07), _row(4, 0.21, fault="motor_stalled", t=2.58, h=0.13),
            _row(5, None, peak=None, error="diverged", h=0.12)]
    rows += [_row(k, 0.4, peak=2.0, fault="fsr_stuck" if k else None, t=4.2 if k else None, scenario="stuck")
             for k in range(3)]
    scen = {"tracking": R.PopulationScenario({"in_band_min": 0.9, "peak_force_max_n": 3.0}, False),
            "stuck": R.PopulationScenario({"peak_force_max_n": 3.0}, True)}
    tracking, stuck = R.population_summary(rows, scen, ["fsr_hysteresis", "finger_b_n_per_m"], worst=3)
    assert tracking["shares"] == {"in_band_min": 3 / 6, "peak_force_max_n": 4 / 6, "no_latch": 5 / 6,
                                  "all": 2 / 6}
    assert tracking["false_trips"] == 1 and tracking["false_trip_rate"] == pytest.approx(1 / 6)
    assert tracking["reading_h"] == pytest.approx(3.0) and tracking["false_trips_per_h"] == pytest.approx(1 / 3)
    # an error, then the false trip (out of the band after the retraction), then the lowest in-band share
    assert [r["reader"] for r in tracking["worst"]] == [5, 4, 2]
    assert tracking["worst"][1]["failed_criteria"] == ["in_band_min"]
    # the four failing readers are the units with large hysteresis; the pulp does not separate them
    assert tracking["separating"] == [("fsr_hysteresis", pytest.approx(1.0)), ("finger_b_n_per_m", 0.5)]
    assert stuck["false_trips"] == 0 and stuck["latched"] == 2 and "no_latch" not in stuck["shares"]
    assert stuck["false_trips_per_h"] == 0.0
    text = R.format_population([tracking, stuck], ["fsr_hysteresis"])
    assert "false trips 1/6 (16.7%, 0.333 per reading-hour)" in text
    assert "latched 2/3 (fault scenario)" in text
    assert "reader    4 seed 4: in_band 0.210" in text and "latched motor_stalled at 2.580 s" in text
    assert "failures separated by fsr_hysteresis high (AUC 1.00)" in text


def test_refresh_scenarios_are_judged_on_their_characters_and_fault_scenarios_on_the_peak():
    from ebraille_sim.scenarios.spec import load_scenario
    assert R.population_scenario(load_scenario("refresh_120wpm")).criteria == {"char_in_band_min": 0.9,
                                                                                "peak_force_max_n": 3.0}
    assert R.population_scenario(load_scenario("steady_90wpm")).criteria == {"in_band_min": 0.9,
                                                                             "peak_force_max_n": 3.0}
    stall = R.population_scenario(load_scenario("fault_motor_stall"))
    assert stall.fault and "in_band_min" not in stall.criteria
    onset = R.population_scenario(load_scenario("contact_onset")).criteria
    assert onset["onset_overshoot_max"] == load_scenario("contact_onset").criteria["onset_overshoot_max"]


def test_sweep_records_latches_and_prints_the_population_report(tmp_path, capsys):
    out = tmp_path / "sw"
    code = cli(["sweep", "steady_90wpm", "fault_motor_stall", "--readers", "4", "--duration", "8", "-j", "1",
                "--out", str(out), "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "population report" in text and "worst readers of steady_90wpm dob_wide_1khz 90.0" in text
    assert "fault_motor_stall dob_wide_1khz 90.0" in text and "(fault scenario)" in text
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    stall = [r for r in rows if r["scenario"] == "fault_motor_stall"]
    latched = [r for r in stall if r["supervisor_fault"]]
    assert latched and all(4.0 < float(r["supervisor_fault_s"]) < 8.0 for r in latched)
    assert all(float(r["reading_s"]) == pytest.approx(6.5) for r in rows)
    assert "false trips" in (out / "summary.txt").read_text()
    assert (out / "figures" / "population.png").stat().st_size > 5000


def test_benchmark_rows_carry_the_latch_and_the_drawn_reader(tmp_path, capsys):
    code = cli(["benchmark", "pid", "--suite", "quick", "--readers", "2", "--no-bounds", "--out",
                str(tmp_path / "b"), "-q"])
    assert code == 0
    doc = json.loads((tmp_path / "b" / "benchmark.json").read_text())
    rows = doc["rows"]
    assert {"supervisor_fault", "supervisor_fault_s", "reading_s", "fsr_hysteresis", "r2_ohm"} <= set(rows[0])
    assert rows[0]["fsr_hysteresis"] == 0.1 and rows[1]["fsr_hysteresis"] != 0.1     # nominal, then drawn
    pop = {(s["group"]["scenario"], s["group"]["controller"]): s for s in doc["population"]}
    assert pop[("fault_fsr_open", "pid")]["fault"] and not pop[("reading_120wpm", "pid")]["fault"]
    assert (tmp_path / "b" / "population.png").stat().st_size > 5000


def test_the_standard_suite_has_a_tail():
    suite = B.get_suite("standard")
    assert suite.readers >= 64
    assert math.ceil(B.ALPHA * suite.readers) >= 7
    assert B.cvar_low(list(range(64))) == pytest.approx(3.0)          # the mean of the worst 7, not the worst one


def test_benchmark_on_dask_gives_the_local_numbers():
    distributed = pytest.importorskip("dask.distributed")
    local = B.run_benchmark(["pid"], "quick", readers=2, bounds=False, jobs=1)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        remote = B.run_benchmark(["pid"], "quick", readers=2, bounds=False, scheduler=client)
    assert remote.rows == local.rows


@pytest.mark.parametrize("command", [["sweep", "steady_90wpm"], ["benchmark", "pid", "--suite", "quick"]])
@pytest.mark.parametrize("readers, msg", [
    ("-1", "must be a whole number in"), (str(MAX_READERS + 1), f", {MAX_READERS}]"),
    ("2.5", "expected a whole number, got '2.5'"), ("many", "expected a whole number, got 'many'"),
])
def test_a_population_option_out_of_range_is_one_line_and_writes_nothing(command, readers, msg, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli([*command, "--readers", readers, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "--readers" in err[0] and msg in err[0]
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("readers", [2.5, 0, -3, True, "8"])
def test_the_api_refuses_a_reader_count_that_is_no_whole_number_in_one_line(readers):
    with pytest.raises(ValueError, match=r"^readers must be a whole number >= 1 \(reader 0 is the nominal device\), got"):
        B.run_benchmark(["pid"], "quick", readers=readers, bounds=False)
    with pytest.raises(ValueError, match=r"^readers must be a whole number >= 0, got"):
        S.plan_sweep(["steady_90wpm"], readers=-1 if readers == 0 else readers)
