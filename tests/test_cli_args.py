"""Every command with bad arguments: a generated table, each case one ``error:`` line and exit 2.

For every sub-command the table holds bad values of each option (negative, zero, NaN,
infinities, huge, not a number, missing files, an ``--out`` that is a file or sits in a
folder that is not writable, unknown scenarios and controllers, ...).  Each case runs the
CLI in this process with the simulation, the sweep, the tuning, the identification, the
training and the regression replaced by a function that fails the test: every argument is
checked before any work starts.  A case passes when the exit status is 2, stdout is empty,
stderr is exactly one line starting with ``error:`` that names the problem, and no
traceback appears.
"""
import os
import pathlib
import signal

import pytest

from ebraille_sim.cli import main as cli

HUGE_INT = str(10 ** 30)
SEED_TOO_BIG = str(2 ** 63)
NOT_NUMBERS = ["abc", "", "1,5", "0x10"]


def _floats(lo_bad: list, huge: str | None = "1e300") -> list:
    """Bad values of a float option: the given out-of-range values, NaN, infinities, not numbers, huge."""
    out = lo_bad + ["nan", "inf", "-inf", "1e999"] + NOT_NUMBERS
    return out + ([huge] if huge else [])


def _ints(lo_bad: list, huge: str | None = HUGE_INT) -> list:
    """Bad values of a whole-number option: the given out-of-range values, fractions, not numbers, huge."""
    return lo_bad + ["1.5", "1e3", "nan"] + NOT_NUMBERS + ([huge] if huge else [])


SEEDS = _ints(["-1", "-5"], SEED_TOO_BIG)

# the options of each command with their bad values; {tmp} is the test's temporary folder
OPTIONS = {
    "run": {
        "--seed": SEEDS,
        "--duration": _floats(["0", "-1", "1e-300"], "1e9"),
        "--controller": ["no_such_controller", "{tmp}/missing.toml", "{tmp}/missing.json"],
        "--backend": ["nope", ""],
        "--trace": ["xml", ""],
        "--trace-rate": _floats(["0", "-100"]) + ["300", "5000"],   # must divide the 1 kHz control rate
        "--animate": ["{tmp}/anim.gif"],                    # without --backend pymunk
    },
    "sweep": {
        "--rates": _floats(["0", "-60"], "1e6"),
        "--readers": _ints(["-1"]),
        "--controllers": ["no_such_controller", "{tmp}/missing.toml"],
        "--replicates": _ints(["0", "-1"]),
        "--seed": SEEDS,
        "--duration": _floats(["0", "-1"], "1e9"),
        "--jobs": _ints(["0", "-1"]),
        "--loss": ["no_such_metric", ""],
        "--alpha": _floats(["0", "-0.1", "1.5"], None),
    },
    "tune": {
        "--population": _ints(["-1"]),
        "--seed": SEEDS,
        "--family": ["nope"],
        "--scenarios": ["no_such_scenario", "steady_90wpm,no_such_scenario", "", ",", "nope_unramped"],
        "--evaluations": _ints(["0", "3", "-1"]),
        "--duration": _floats(["0", "-1"], "1e9"),
        "--ms-max": ["1", "0.5", "-1", "nan", "-inf"] + NOT_NUMBERS,        # inf: no bound
        "--ms-gain": _floats(["0", "-1"]),
    },
    "identify": {
        "--csv": ["{tmp}/missing.csv", "{tmp}"],
        "--seed": SEEDS,
        "--starts": _ints(["0", "-1"]),
        "--kinds": ["", "nope", "linear,linear", ","],
        "--orders": ["", "0", "11", "two", "2,2", "2.5"],
        "--baseline-s": _floats(["-1"]),
        "--cutoff-hz": _floats(["-1"]),
        "--no-load-voltage": ["0.5"],                          # without --csv
        "--jobs": _ints(["0", "-1"], "257"),
    },
    "train": {
        "--algo": ["dqn"],
        "--steps": _ints(["0", "-1"]),
        "--seed": SEEDS + [str(2 ** 32)],
        "--envs": _ints(["0", "-1", "257"]),
        "--control-rate": _floats(["0", "-1", "0.5", "3"], "1e9"),
        "--threads": _ints(["0", "-1", "65"]),
        "--estimator": ["nope=1", "hysteresis_compensation", "=true", "hysteresis_deadband_lsb=-1"],
        "--recipe": ["nope", ""],
        "--residual": ["no_such_design", "{tmp}/missing.toml"],
        "--history": _ints(["0", "-1", "65"]),
    },
    "regress": {
        "--only": ["no_such_scenario", "{tmp}/missing.toml"],
        "--scenarios": ["{tmp}/missing_folder", "{tmp}/a_file"],
        "--baselines": ["{tmp}/a_file"],
        "--controller": ["no_such_controller", "{tmp}/missing.toml"],
        "--jobs": _ints(["0", "-1"]),
        "--junit": ["{tmp}", "{tmp}/a_file/junit.xml"],
    },
}

# the valid start of each command's command line (a case adds or replaces one option)
BASE = {
    "run": ["run", "steady_90wpm", "--out", "{tmp}/out"],
    "sweep": ["sweep", "contact_onset", "--readers", "1", "-j", "1", "--out", "{tmp}/out"],
    "tune": ["tune", "steady_90wpm", "--out", "{tmp}/out"],
    "identify": ["identify", "--quick", "--out", "{tmp}/out"],
    "train": ["train", "--steps", "10", "--out", "{tmp}/out"],
    "regress": ["regress", "--only", "steady_90wpm"],
    "list": ["list"],
}

# whole command lines: positionals, output folders, combinations, unknown options
EXTRA = [
    ("run", ["run", "no_such_scenario"], "no_such_scenario"),
    ("run", ["run", "{tmp}/missing.toml"], "missing.toml"),
    ("run", ["run", "{tmp}"], "{tmp}"),
    ("run", ["run"], "scenario"),
    ("run", ["run", "steady_90wpm", "--seed"], "--seed"),
    ("run", ["run", "steady_90wpm", "--no-such-option"], "--no-such-option"),
    ("run", ["run", "steady_90wpm", "--backend", "pymunk", "--animate", "{tmp}", "--out", "{tmp}/o"], "--animate"),
    ("sweep", ["sweep", "no_such_scenario"], "no_such_scenario"),
    ("sweep", ["sweep"], "SCENARIO"),
    ("sweep", ["sweep", "contact_onset", "contact_onset", "--out", "{tmp}/o"], "contact_onset"),
    ("sweep", ["sweep", "contact_onset", "--readers", "1000", "--replicates", "1000", "--out", "{tmp}/o"],
     "episodes"),
    ("tune", ["tune", "no_such_scenario"], "no_such_scenario"),
    ("tune", ["tune", "contact_onset", "--duration", "0.5", "--out", "{tmp}/o"], "before its reading starts"),
    ("identify", ["identify", "--csv", "{tmp}/a_file", "--out", "{tmp}/o"], "a_file"),
    ("regress", ["regress", "--update", "--controller", "pid"], "--controller"),
    ("list", ["list", "extra"], "extra"),
    ("list", ["list", "--seed", "1"], "--seed"),
    (None, ["no_such_command"], "no_such_command"),
    (None, ["--no-such-option"], "--no-such-option"),
]
for _cmd in ("run", "sweep", "tune", "identify", "train"):
    EXTRA += [(_cmd, BASE[_cmd][:-1] + ["{tmp}/a_file"], "is a file"),
              (_cmd, BASE[_cmd][:-1] + ["{tmp}/a_file/sub"], "is a file"),
              (_cmd, BASE[_cmd][:-1] + ["{tmp}/locked/new"], "not writable"),
              (_cmd, BASE[_cmd][:-1] + [""], "--out")]
EXTRA += [("regress", ["regress", "--only", "steady_90wpm", "--json", "{tmp}"], "--json"),
          ("regress", ["regress", "--only", "steady_90wpm", "--junit", "{tmp}/locked/new/j.xml"], "not writable")]


NAMED_BY_VALUE = {"--only"}
"""Options whose message names the bad value (the scenario) instead of the option."""


def _option_cases():
    for cmd, options in OPTIONS.items():
        for option, values in options.items():
            for value in values:
                argv = [a for a in BASE[cmd]]
                if option in argv:                       # replace the base's own value
                    i = argv.index(option)
                    del argv[i:i + 2]
                named = pathlib.PurePath(value).name if option in NAMED_BY_VALUE else option
                yield (f"{cmd} {option}={value}", argv + [f"{option}={value}"], named)


CASES = list(_option_cases()) + [(" ".join(argv), argv, named) for _, argv, named in EXTRA]

# the entry points of the work each command does: reaching one means an argument got through
WORK = ["ebraille_sim.scenarios.runner.run_scenario", "ebraille_sim.tools.sweep.run_sweep",
        "ebraille_sim.analysis.robust.robust_tune", "ebraille_sim.identification.bench.run_profiles",
        "ebraille_sim.commands.identify.identify_all", "ebraille_sim.commands.train.train",
        "ebraille_sim.tools.regress.regress_scenarios"]


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A temporary folder with a file, a locked folder (not writable), and no work allowed."""
    (tmp_path / "a_file").write_text("x")
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if pathlib.Path(p) == locked
                        else real_access(p, mode, **kw))
    monkeypatch.chdir(tmp_path)

    def no_work(*a, **k):
        raise AssertionError("work started although an argument is bad")
    for target in WORK:
        monkeypatch.setattr(target, no_work)

    def too_slow(signum, frame):
        raise AssertionError("the checks took more than 20 s: work started although an argument is bad")
    previous = signal.signal(signal.SIGALRM, too_slow)
    signal.alarm(20)
    yield tmp_path
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def test_the_table_covers_every_command_and_is_large():
    commands = {argv[0] for _, argv, _ in CASES}
    assert {"run", "sweep", "tune", "identify", "train", "regress", "list"} <= commands
    assert len(CASES) >= 250


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_argument_is_one_line_and_exit_2(case, folder, capsys):
    _, argv, named = case
    argv = [a.replace("{tmp}", str(folder)) for a in argv]
    named = named.replace("{tmp}", str(folder))
    code = cli(argv)
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    assert code == 2, (code, cap.err)
    assert cap.out == ""
    lines = cap.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), cap.err
    assert named in lines[0], lines[0]
    assert not list(folder.glob("out*")) and not list(folder.glob("o")), "output written despite the error"
