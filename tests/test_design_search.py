"""The design search of ``ebraille-sim tune --search``: objective, optimiser, journal, design file, bad input."""
import json

import pytest

from ebraille_sim.cli import main as cli
from ebraille_sim.tools import benchmark as bm
from ebraille_sim.tools.design_search import (Arm, DesignSearch, Param, SearchSpace, check_space, check_statistic,
                                              default_space, training_devices)


def _space(start):
    """pid_dob on the 1 kHz firmware, proportional and integral gains searched, one start point."""
    return check_space(SearchSpace((Arm("pid_dob", "fast_1khz",
                                        (Param("kp_v_per_n", 0.05, 6.0), Param("ki_v_per_ns", 0.05, 12.0)),
                                        {"hold_damping_v_per_v": 0.5}, (start,)),)))


BAD = {"kp_v_per_n": 0.05, "ki_v_per_ns": 0.05}


def _search(journal=None, evaluations=10, jobs=1, start=BAD, seed=3, optimiser="de"):
    return DesignSearch(_space(start), suite="quick", readers=1, seed=seed, evaluations=evaluations, jobs=jobs,
                        journal=journal, optimiser=optimiser)


def test_the_search_beats_a_deliberately_bad_start():
    res = _search(evaluations=10).run()
    start = res.starts[0]
    assert start["gains"]["kp_v_per_n"] == 0.05 and start["gains"]["ki_v_per_ns"] == 0.05
    assert res.evaluations == 10
    assert res.train_value > start["value"] + 10.0, (res.train_value, start["value"])
    assert res.best.gains["hold_damping_v_per_v"] == 0.5          # fixed gains stay


def test_same_seed_same_design_and_jobs_do_not_matter(tmp_path):
    a = _search(evaluations=10, jobs=1).run()
    b = _search(evaluations=10, jobs=2).run()
    assert a.best == b.best and a.history == b.history
    c = _search(evaluations=10, seed=4).run()
    assert c.history != a.history


def test_the_optuna_optimiser_starts_from_the_start_points_and_repeats_itself():
    pytest.importorskip("optuna")
    a = _search(evaluations=6, optimiser="optuna").run()
    assert a.history[0]["gains"]["kp_v_per_n"] == 0.05 and a.evaluations == 6
    assert a.train_value > a.history[0]["value"]
    b = _search(evaluations=6, optimiser="optuna", jobs=2).run()
    assert a.history == b.history


def test_a_rerun_continues_from_the_journal(tmp_path):
    journal = tmp_path / "journal.jsonl"
    first = _search(journal, evaluations=6).run()
    assert first.cached == 0
    lines = journal.read_text().splitlines()
    assert len(lines) == 1 + 6
    journal.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:20] + "\n")     # the last line cut by a kill
    again = _search(journal, evaluations=10).run()
    fresh = _search(None, evaluations=10).run()
    assert again.history == fresh.history and again.best == fresh.best
    assert again.cached == 5                          # the population from the journal, not run again
    with pytest.raises(ValueError, match="journal of another search"):
        _search(journal, evaluations=10, seed=5).run()


def test_training_readers_are_not_the_benchmarks():
    sc = bm.SUITES["quick"].scenarios[0]
    train = training_devices(sc.scenario, 0, 3)
    held = bm.scenario_devices(sc, 4)
    assert len(train) == 3 and not any(t == h for t in train for h in held)
    with pytest.raises(ValueError, match="benchmark's reader seed"):
        training_devices(sc.scenario, bm.POPULATION_SEED, 3)


def test_the_default_space_starts_from_the_shipped_designs():
    space = default_space()
    dob = {a.firmware: a for a in space.arms if a.controller == "pid_dob"}
    assert dob["fast_1khz"].starts == ("dob_hold_1khz", "dob_learn_1khz")
    assert dob["paper_100hz"].starts == ("dob_100hz",)
    assert "refresh_learning_gain" in {p.name for p in dob["fast_1khz"].params}
    assert {a.controller for a in space.arms} == {"pid_dob", "pid_scheduled"}
    # an arm's coordinates decode to its own gains (rounded to 4 digits)
    x = space.encode(0, {"kp_v_per_n": 2.9, "ki_v_per_ns": 5.1})
    cand = space.decode(x)
    assert (cand.controller, cand.firmware) == (space.arms[0].controller, space.arms[0].firmware)
    assert cand.gains["kp_v_per_n"] == 2.9 and cand.gains["ki_v_per_ns"] == 5.1


def test_tune_search_writes_a_design_that_run_and_benchmark_take(tmp_path, capsys):
    out = tmp_path / "search"
    space = tmp_path / "space.toml"
    space.write_text('[[arm]]\ncontroller = "pid_dob"\nfirmware = "fast_1khz"\nstarts = ["dob_hold_1khz"]\n'
                     '[arm.gains]\nhold_damping_v_per_v = 0.5\n'
                     '[arm.ranges]\nkp_v_per_n = [1.0, 5.0]\nq_time_constant_s = [0.001, 0.01, "log"]\n')
    args = ["tune", "--search", str(space), "--suite", "quick", "--readers", "1", "--evaluations", "5",
            "--validate", "3", "--out", str(out), "--name", "mine", "--json", "-q"]
    assert cli(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["validation_statistic"] is not None and "Chosen on 2 validation readers" in (out / "report.md").read_text()
    assert doc["evaluations"] == 5 and doc["from_journal"] == 0
    assert doc["reference"]["design"] == "dob_learn_1khz"
    assert sorted(p.name for p in out.iterdir()) == ["design.toml", "journal.jsonl", "report.json", "report.md"]
    from controllers.designs import get_design
    d = get_design(out / "design.toml")
    assert (d.name, d.controller, d.firmware, d.benchmark["suite"]) == ("mine", "pid_dob", "fast_1khz", "quick")
    assert d.benchmark["score"] == doc["held_out_score"]
    assert "| mine |" in (out / "report.md").read_text()           # the leaderboard names the design
    # the held-out score is the benchmark's own number for the file
    again = bm.summarise(bm.run_benchmark([str(out / "design.toml")], "quick", bounds=False))
    assert again[str(out / "design.toml")]["score"] == d.benchmark["score"]
    from ebraille_sim.scenarios.runner import run_scenario
    assert run_scenario("refresh_120wpm", controller=str(out / "design.toml"), duration_s=1.0).spec.device.estimator \
        .hysteresis_compensation is True                    # runs on its own firmware
    # a rerun continues: every evaluation from the journal, the same design
    assert cli(args) == 0
    doc2 = json.loads(capsys.readouterr().out)
    assert doc2["from_journal"] == 5 and doc2["design"] == doc["design"]


@pytest.mark.parametrize("extra, named", [
    (["--evaluations", "0"], "--evaluations"),
    (["--statistic", "mean"], "mean"),
    (["--suite", "huge"], "huge"),
    (["--optimiser", "annealing"], "annealing"),
    (["--seed", str(bm.POPULATION_SEED)], "--seed"),
    (["--firmware", "no_such_preset"], "no_such_preset"),
    (["--family", "pid"], "--family"),
    (["steady_90wpm"], "steady_90wpm"),
    (["--name", "dob_100hz"], "dob_100hz"),
    (["--validate", "-1"], "--validate"),
    (["--validation-readers", "0"], "--validation-readers"),
])
def test_bad_search_input_is_one_line_and_writes_nothing(tmp_path, capsys, extra, named):
    out = tmp_path / "o"
    assert cli(["tune", "--search", "--out", str(out)] + extra) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and named in err[0], err
    assert not out.exists()


@pytest.mark.parametrize("space, named", [
    ("arm = []\n", "empty"),
    ('[[arm]]\ncontroller = "pid_dob"\n', "empty"),
    ('[[arm]]\ncontroller = "pid_dob"\n[arm.ranges]\nkp_v_per_n = [3.0, 1.0]\n', "kp_v_per_n [3, 1] is inverted"),
    ('[[arm]]\ncontroller = "pid_dob"\n[arm.ranges]\nkp_v_per_n = [1.0, 1.0]\n', "kp_v_per_n [1, 1] is empty"),
    ('[[arm]]\ncontroller = "pid_dob"\n[arm.ranges]\nkp_v_per_n = [0.0, 1.0, "log"]\n', "log range kp_v_per_n"),
    ('[[arm]]\ncontroller = "pid_dob"\n[arm.ranges]\nno_such_gain = [0.0, 1.0]\n', "no_such_gain"),
    ('[[arm]]\ncontroller = "nope"\n[arm.ranges]\nkp_v_per_n = [0.0, 1.0]\n', "nope"),
])
def test_a_bad_search_space_is_one_line_naming_it(tmp_path, capsys, space, named):
    f = tmp_path / "space.toml"
    f.write_text(space)
    out = tmp_path / "o"
    assert cli(["tune", "--search", str(f), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and named in err[0], err
    assert not out.exists()


def test_the_api_refuses_bad_input_in_one_line():
    with pytest.raises(ValueError, match="unknown statistic 'mean'"):
        check_statistic("mean")
    with pytest.raises(ValueError, match="at least 1 evaluation"):
        _search(evaluations=0)


def test_validation_chooses_among_the_best_on_other_readers(tmp_path):
    journal = tmp_path / "journal.jsonl"
    s = DesignSearch(_space(BAD), suite="quick", readers=1, seed=3, evaluations=8, validate=3, journal=journal)
    res = s.run()
    top = sorted({(h["value"], i): h for i, h in enumerate(res.history)}.items(), key=lambda kv: (-kv[0][0], kv[0][1]))
    firsts = []
    for _, h in top:
        if h["gains"] not in [f["gains"] for f in firsts]:
            firsts.append(h)
    assert [h["gains"] for h in sorted(res.validated, key=lambda h: h["training_rank"])] == \
        [h["gains"] for h in firsts[:3]]                          # the three best distinct on the training readers
    vals = [h["validation_value"] for h in res.validated]
    assert vals == sorted(vals, reverse=True) and res.validation_value == vals[0]
    assert res.best.gains == res.validated[0]["gains"] and res.train_value == res.validated[0]["value"]
    # the validation readers are neither the training readers nor the benchmark's
    for sc in s.suite.scenarios:
        assert not any(v == t for v in s.validation_devices[sc.key] for t in s.devices[sc.key])
        assert not any(v == h for v in s.validation_devices[sc.key] for h in bm.scenario_devices(sc, 4))
    # journalled: a rerun runs nothing and gives the same choice
    again = DesignSearch(_space(BAD), suite="quick", readers=1, seed=3, evaluations=8, validate=3,
                         journal=journal).run()
    assert again.cached == 8 and again.validated == res.validated and again.best == res.best
    # other validation settings reuse the search's evaluations and run their own validation
    other = DesignSearch(_space(BAD), suite="quick", readers=1, seed=3, evaluations=8, validate=2,
                         validation_readers=3, journal=journal).run()
    assert other.cached == 8 and len(other.validated) == 2 and other.history == res.history
    assert sum(1 for line in journal.read_text().splitlines() if '"validation/3:' in line) == 2
    with pytest.raises(ValueError, match="validate"):
        DesignSearch(_space(BAD), suite="quick", readers=1, validate=-1)
    with pytest.raises(ValueError, match="validation readers"):
        DesignSearch(_space(BAD), suite="quick", readers=1, validate=2, validation_readers=0)
