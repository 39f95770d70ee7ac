"""Hostile inputs and outputs: links, FIFOs, devices, deep nesting, huge numbers, races.

The first table holds invocations that must be refused before any work: each runs the CLI
in this process with the simulation, sweep, benchmark, tuning, identification, training and
regression replaced by a function that fails the test, under a 20 s alarm (a FIFO read
would hang).  A case passes when the exit status is 2, stdout is empty, stderr is one
``error:`` line of at most 300 characters naming the problem, and no file in the test's
folder (a planted victim, a FIFO, the link itself) changed.  The tests after it run what
must work (a stale staging folder, a held lock, an existing folder in a read-only parent, a
non-ASCII folder on an ASCII terminal) or check the library's own refusals (the env).
"""
import hashlib
import os
import pathlib
import signal
import stat
import subprocess
import sys

import numpy as np
import pytest

from ebraille_sim.cli import main as cli

ROOT = pathlib.Path(__file__).resolve().parent.parent
MAX_LINE = 300

PLAIN = 'name = "plain"\nseed = 2\nduration_s = 1.5\n[reading]\nwpm = 90\nstart_s = 0.5\n'

WORK = ["ebraille_sim.scenarios.runner.run_scenario", "ebraille_sim.tools.sweep.run_sweep",
        "ebraille_sim.tools.benchmark.run_benchmark", "ebraille_sim.analysis.robust.robust_tune",
        "ebraille_sim.identification.bench.run_profiles", "ebraille_sim.commands.identify.identify_all",
        "ebraille_sim.commands.train.train", "ebraille_sim.tools.regress.regress_scenarios"]


def _deep_json(depth: int = 3000) -> str:
    return '{"a": ' * depth + "1" + "}" * depth


def _deep_toml(depth: int = 3000) -> str:
    return "a = " + "[" * depth + "]" * depth + "\n"


# ---------------------------------------------------------------- setups: each returns nothing, builds in tmp

def _victim(tmp):
    (tmp / "victim.txt").write_text("precious")


def _fifo(name):
    def make(tmp):
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        os.mkfifo(tmp / name)
    return make


def _file(name, text):
    def make(tmp):
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp / name).write_text(text)
    return make


def _link(name, target):
    def make(tmp):
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        os.symlink(tmp / target, tmp / name)
    return make


def _scenario_with(extra):
    return _file("s.toml", PLAIN + extra)


def _results(summary) -> str:
    import json
    return json.dumps({"suite": "quick", "suite_version": 1, "summary": summary})


# (id, setups, argv with {tmp}, text the error line names)
CASES = [
    # outputs: never through a link, never over a device, FIFO or folder
    ("regress --junit symlink to a victim", [_victim, _link("r.xml", "victim.txt")],
     ["regress", "--only", "steady_90wpm", "--junit", "{tmp}/r.xml"], "symbolic link"),
    ("regress --json FILE symlink", [_victim, _link("r.json", "victim.txt")],
     ["regress", "--only", "steady_90wpm", "--json", "{tmp}/r.json"], "symbolic link"),
    ("regress --junit FIFO", [_fifo("r.xml")],
     ["regress", "--only", "steady_90wpm", "--junit", "{tmp}/r.xml"], "FIFO"),
    ("regress --junit /dev/null", [],
     ["regress", "--only", "steady_90wpm", "--junit", "/dev/null"], "character device"),
    ("benchmark --out with a planted benchmark.json link", [_victim, _link("o/benchmark.json", "victim.txt")],
     ["benchmark", "pid", "--suite", "quick", "--out", "{tmp}/o"], "symbolic link"),
    ("benchmark --out with leaderboard.md a FIFO", [_fifo("o/leaderboard.md")],
     ["benchmark", "pid", "--suite", "quick", "--out", "{tmp}/o"], "FIFO"),
    ("run --force with metrics.json a link", [_victim, _link("o/metrics.json", "victim.txt")],
     ["run", "steady_90wpm", "--force", "--out", "{tmp}/o"], "symbolic link"),
    ("run --force with trace.csv a FIFO", [_fifo("o/trace.csv")],
     ["run", "steady_90wpm", "--force", "--out", "{tmp}/o"], "FIFO"),
    ("run --out a symlink to a folder", [_file("real/keep.txt", "mine"), _link("o", "real")],
     ["run", "steady_90wpm", "--out", "{tmp}/o"], "symbolic link"),
    ("run --out a FIFO", [_fifo("o")], ["run", "steady_90wpm", "--out", "{tmp}/o"], "FIFO"),
    ("run --out /dev/null", [], ["run", "steady_90wpm", "--out", "/dev/null"], "character device"),
    ("sweep --out with figures a link", [_file("real/a.png", "mine"), _link("o/figures", "real")],
     ["sweep", "contact_onset", "--readers", "1", "-j", "1", "--out", "{tmp}/o"], "symbolic link"),
    ("run --animate PATH a link", [_victim, _link("a.gif", "victim.txt")],
     ["run", "offcentre_press", "--backend", "pymunk", "--animate", "{tmp}/a.gif", "--force", "--out", "{tmp}/o"],
     "symbolic link"),
    ("regress --update with a baseline link", [_file("sc/plain.toml", PLAIN), _victim,
                                               _link("sc/baselines/plain.json", "victim.txt")],
     ["regress", "--scenarios", "{tmp}/sc", "--update"], "symbolic link"),
    # inputs: regular files only, bounded, nesting bounded
    ("run SCENARIO a FIFO", [_fifo("evil.toml")], ["run", "{tmp}/evil.toml"], "evil.toml"),
    ("run NAME of a FIFO in ./scenarios", [_fifo("scenarios/evil.toml")], ["run", "evil"], "FIFO"),
    ("[reading] file a FIFO", [_fifo("text.txt"), _scenario_with('file = "text.txt"\n')],
     ["run", "{tmp}/s.toml", "--out", "{tmp}/o"], "FIFO"),
    ("[reading] file /dev/zero", [_scenario_with('file = "/dev/zero"\n')],
     ["run", "{tmp}/s.toml", "--out", "{tmp}/o"], "character device"),
    ("[reading] file a folder", [_file("d/x", ""), _scenario_with('file = "d"\n')],
     ["sweep", "{tmp}/s.toml", "--readers", "1", "-j", "1", "--out", "{tmp}/o"], "folder"),
    ("regress baseline a FIFO", [_file("sc/plain.toml", PLAIN), _fifo("sc/baselines/plain.json")],
     ["regress", "--scenarios", "{tmp}/sc"], "FIFO"),
    ("gains file nested 3000 deep (JSON)", [_file("g.json", _deep_json())],
     ["run", "steady_90wpm", "--controller", "{tmp}/g.json", "--out", "{tmp}/o"], "deep"),
    ("gains file nested 3000 deep (TOML)", [_file("g.toml", _deep_toml())],
     ["run", "steady_90wpm", "--controller", "{tmp}/g.toml", "--out", "{tmp}/o"], "deep"),
    ("gains file a FIFO", [_fifo("g.toml")],
     ["sweep", "steady_90wpm", "--controllers", "{tmp}/g.toml", "--out", "{tmp}/o"], "FIFO"),
    ("estimator model nested 3000 deep", [_file("m.json", _deep_json()),
                                          _scenario_with('[estimator]\nmodel = "m.json"\n')],
     ["run", "{tmp}/s.toml", "--out", "{tmp}/o"], "deep"),
    ("estimator model a FIFO", [_fifo("m.json"), _scenario_with('[estimator]\nmodel = "m.json"\n')],
     ["run", "{tmp}/s.toml", "--out", "{tmp}/o"], "FIFO"),
    ("benchmark --compare nested 3000 deep", [_file("c.json", _deep_json())],
     ["benchmark", "pid", "--suite", "quick", "--compare", "{tmp}/c.json"], "deep"),
    ("benchmark --compare a FIFO", [_fifo("c.json")],
     ["benchmark", "pid", "--suite", "quick", "--compare", "{tmp}/c.json"], "FIFO"),
    ("benchmark --compare of wrong types", [_file("c.json", _results({"pid": {"score": "high", "scenarios": {}}}))],
     ["benchmark", "pid", "--suite", "quick", "--compare", "{tmp}/c.json"], "score"),
    ("benchmark --compare with a list of scenarios", [_file("c.json", _results({"pid": {"score": 1, "scenarios": []}}))],
     ["benchmark", "pid", "--suite", "quick", "--compare", "{tmp}/c.json"], "scenarios"),
    ("benchmark --estimator model missing", [],
     ["benchmark", "pid", "--suite", "quick", "--estimator", "model={tmp}/none.json"], "none.json"),
    ("benchmark --estimator model nested", [_file("m.json", _deep_json())],
     ["benchmark", "pid", "--suite", "quick", "--estimator", "model={tmp}/m.json"], "deep"),
    ("identify --csv a FIFO", [_fifo("rec.csv")], ["identify", "--csv", "{tmp}/rec.csv", "--out", "{tmp}/o"], "not a file"),
    ("identify --csv /dev/zero", [], ["identify", "--csv", "/dev/zero", "--out", "{tmp}/o"], "not a file"),
    # numbers bounded up front
    ("benchmark --readers 100000000", [], ["benchmark", "pid", "--readers", "100000000"], "--readers"),
    ("benchmark -j 100000", [], ["benchmark", "pid", "-j", "100000"], "--jobs"),
    ("benchmark --readers 10000 x bounds", [], ["benchmark", "pid", "lqg", "--readers", "10000"], "episodes"),
    ("run --trace-rate 1e-300", [], ["run", "steady_90wpm", "--trace-rate", "1e-300", "--out", "{tmp}/o"],
     "--trace-rate"),
    ("run --trace-rate below one sample per run", [],
     ["run", "steady_90wpm", "--duration", "2", "--trace-rate", "0.1", "--out", "{tmp}/o"], "--trace-rate"),
    # exit codes: bad input is 2
    ("regress --only /etc/passwd", [], ["regress", "--only", "/etc/passwd"], "passwd"),
    ("regress on an empty folder", [_file("empty/readme.txt", "")], ["regress", "--scenarios", "{tmp}/empty"],
     "no scenario files"),
    ("no sub-command", [], [], "give a command"),
    # scenario values and long names
    ("[finger] gap_m = -0.01", [_scenario_with("[finger]\ngap_m = -0.01\n")],
     ["run", "{tmp}/s.toml", "--out", "{tmp}/o"], "gap_m"),
    ("a 5000-character scenario name", [_file("s.toml", f'name = "{"x" * 5000}"\n')],
     ["run", "{tmp}/s.toml", "--out", "{tmp}/o"], "name"),
    ("a 5000-character unknown scenario", [], ["run", "y" * 5000], "not found"),
    ("a 5000-character --out below a file", [_file("f", "x")], ["run", "steady_90wpm", "--out", "{tmp}/f/" + "z" * 5000],
     "is a file"),
]


def _tree(root: pathlib.Path) -> dict:
    """Every entry below ``root`` (links not followed): its type and, for a regular file, its bytes' hash."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = pathlib.Path(dirpath) / name
            st = os.lstat(p)
            digest = hashlib.sha256(p.read_bytes()).hexdigest() if stat.S_ISREG(st.st_mode) else None
            out[str(p.relative_to(root))] = (stat.S_IFMT(st.st_mode), digest)
    return out


@pytest.fixture
def sandbox(tmp_path, monkeypatch):
    """The test's folder as the working folder; work fails the test; a hang fails it after 20 s."""
    monkeypatch.chdir(tmp_path)

    def no_work(*a, **k):
        raise AssertionError("work started although an input is refused")
    for target in WORK:
        monkeypatch.setattr(target, no_work)

    def too_slow(signum, frame):
        raise AssertionError("no answer in 20 s: a FIFO or device was read, or work started")
    previous = signal.signal(signal.SIGALRM, too_slow)
    signal.alarm(20)
    yield tmp_path
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def _one_error_line(capsys) -> str:
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and cap.out == "", cap
    lines = cap.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), cap.err
    assert len(lines[0]) <= MAX_LINE, len(lines[0])
    return lines[0]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_refused_in_one_line_before_any_work_and_nothing_changed(case, sandbox, capsys):
    _, setups, argv, named = case
    for make in setups:
        make(sandbox)
    before = _tree(sandbox)
    null = os.stat("/dev/null")
    code = cli([a.replace("{tmp}", str(sandbox)) for a in argv])
    line = _one_error_line(capsys)
    assert code == 2, (code, line)
    assert named in line, line
    assert _tree(sandbox) == before                       # no victim, FIFO, link or folder touched
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode) and os.stat("/dev/null").st_ino == null.st_ino


# ---------------------------------------------------------------- the writer and the lock

def test_report_file_is_replaced_through_a_fresh_temporary_not_a_planted_one(tmp_path):
    """A planted ``FILE.tmp`` link (the old fixed temporary name) is never written through."""
    from ebraille_sim.tools.outputs import write_file
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    for planted in ("r.xml.tmp", ".r.xml.tmp"):
        os.symlink(victim, tmp_path / planted)
    write_file(tmp_path / "r.xml", "<testsuites/>")
    assert (tmp_path / "r.xml").read_text() == "<testsuites/>" and victim.read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == [".r.xml.tmp", "r.xml", "r.xml.tmp", "victim.txt"]
    assert not (tmp_path / "r.xml").is_symlink()


def test_a_second_run_into_a_held_folder_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    from ebraille_sim.tools.outputs import OutputFolder
    monkeypatch.setattr("ebraille_sim.scenarios.runner.run_scenario",
                        lambda *a, **k: (_ for _ in ()).throw(AssertionError("second run simulated")))
    out = tmp_path / "o"
    with OutputFolder(out, ["metrics.json"]):
        assert cli(["run", "steady_90wpm", "--out", str(out)]) == 2
        line = _one_error_line(capsys)
        assert "being written by another ebraille-sim run" in line
    assert not out.exists()                            # the holder created it and left it empty: removed


def test_two_real_runs_into_one_folder_exactly_one_writes(tmp_path):
    """Two ``run`` processes started together into one --out: one writes, the other is refused."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    argv = [sys.executable, "-m", "ebraille_sim", "run", "steady_90wpm", "--duration", "1", "--no-plot", "-q",
            "--out", str(tmp_path / "o")]
    procs = [subprocess.Popen(argv, cwd=tmp_path, stderr=subprocess.PIPE, text=True, env=env) for _ in range(2)]
    results = [(p.wait(timeout=600), p.stderr.read()) for p in procs]
    assert sorted(c != 2 for c, _ in results) == [False, True], results    # 0 or 1 (criteria): it ran
    err = next(e for c, e in results if c == 2)   # the lock, or the finished run, refuses the other
    assert len(err.splitlines()) == 1 and err.startswith("error: ")
    assert "being written by another" in err or "already holds a run" in err
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["metrics.json", "trace.csv"]


def test_stale_staging_folders_of_killed_runs_are_removed_and_reported(tmp_path, capsys):
    from ebraille_sim.tools.outputs import INCOMPLETE, STAGING_PREFIX, staged
    out = tmp_path / "o"
    stale = out / f"{STAGING_PREFIX}deadbeef"
    stale.mkdir(parents=True)
    (stale / INCOMPLETE).write_text("x")
    (stale / "trace.csv").write_text("half")
    legacy = tmp_path / "o.incomplete-0badc0de"            # beside the folder, as earlier versions staged
    legacy.mkdir()
    (legacy / INCOMPLETE).write_text("x")
    with staged(out, ["metrics.json"]) as folder:
        (folder / "metrics.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json"] and not legacy.exists()
    err = capsys.readouterr().err
    assert err.startswith("warning: removed 2 staging folder(s)") and len(err.splitlines()) == 1


def test_staging_is_on_the_file_system_of_the_output_folder(tmp_path, monkeypatch):
    """An existing --out in a parent that cannot be written (a volume's mount point) works:
    the staging folder is made inside it, nothing beside it."""
    from ebraille_sim.tools.outputs import staged
    parent = tmp_path / "parent"
    out = parent / "vol"
    out.mkdir(parents=True)
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if pathlib.Path(p) == parent
                        else real_access(p, mode, **kw))
    real_mkdir = pathlib.Path.mkdir

    def no_mkdir_in_parent(self, *a, **k):
        assert self.parent != parent, f"wrote beside --out: {self}"
        return real_mkdir(self, *a, **k)
    monkeypatch.setattr(pathlib.Path, "mkdir", no_mkdir_in_parent)
    with staged(out, ["metrics.json"]) as folder:
        assert folder.parent == out and os.stat(folder).st_dev == os.stat(out).st_dev
        (folder / "metrics.json").write_text("{}")
    assert sorted(p.name for p in parent.iterdir()) == ["vol"] and (out / "metrics.json").read_text() == "{}"


def test_an_interrupted_claim_removes_the_folder_it_created(tmp_path):
    from ebraille_sim.tools.outputs import OutputFolder
    out = tmp_path / "a" / "b"
    with pytest.raises(KeyboardInterrupt), OutputFolder(out, ["x"]):
        assert out.is_dir()
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- the reader

@pytest.mark.parametrize("kind", ["fifo", "dev", "folder", "big", "deep", "missing"])
def test_the_reader_refuses_in_one_line(kind, tmp_path):
    from ebraille_sim.base.files import read_bytes, read_json
    p = tmp_path / "f.json"
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "dev":
        p = pathlib.Path("/dev/zero")
    elif kind == "folder":
        p.mkdir()
    elif kind == "big":
        p.write_bytes(b" " * 2048)
    elif kind == "deep":
        p.write_text(_deep_json(100))
    err = FileNotFoundError if kind == "missing" else ValueError
    with pytest.raises(err) as info:
        if kind == "big":
            read_bytes(p, "input", limit=1024)
        else:
            read_json(p, "input")
    msg = str(info.value)
    assert "\n" not in msg and len(msg) <= MAX_LINE
    assert {"fifo": "is a FIFO", "dev": "is a character device", "folder": "is a folder",
            "big": "more than the 1 KiB", "deep": "more than 64 deep", "missing": "not found"}[kind] in msg


def test_baseline_nested_too_deep_is_one_line(tmp_path):
    from ebraille_sim.tools.regress import read_baseline
    (tmp_path / "b.json").write_text(_deep_json())
    with pytest.raises(ValueError, match="deep") as info:
        read_baseline(tmp_path / "b.json")
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------- what must work, and exit codes

def test_list_survives_a_fifo_in_the_scenario_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scenarios").mkdir()
    os.mkfifo(tmp_path / "scenarios" / "evil.toml")
    (tmp_path / "scenarios" / "mine.toml").write_text(PLAIN.replace("plain", "mine"))
    signal.alarm(20)
    try:
        assert cli(["list"]) == 0
    finally:
        signal.alarm(0)
    out = capsys.readouterr().out
    evil = next(line for line in out.splitlines() if line.strip().startswith("evil"))
    assert "invalid" in evil and "FIFO" in evil
    assert any(line.strip().startswith("steady_90wpm") for line in out.splitlines())


def test_train_without_its_extra_creates_nothing(tmp_path, monkeypatch, capsys):
    import importlib.util
    if importlib.util.find_spec("stable_baselines3") is not None:
        pytest.skip("the rl extra is installed")
    monkeypatch.chdir(tmp_path)
    assert cli(["train", "--steps", "10"]) == 2
    assert "rl" in _one_error_line(capsys) and list(tmp_path.iterdir()) == []


def test_numba_disable_jit_is_one_line(monkeypatch, capsys):
    monkeypatch.setenv("NUMBA_DISABLE_JIT", "1")
    assert cli(["run", "steady_90wpm"]) == 2
    assert "NUMBA_DISABLE_JIT" in _one_error_line(capsys)


def test_a_sweep_whose_episodes_all_failed_exits_1(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("ebraille_sim.scenarios.runner.run_batch",
                        lambda kws, **k: [ValueError("diverged") for _ in kws])
    code = cli(["sweep", "contact_onset", "--readers", "2", "-j", "1", "--no-figures", "-q", "--out",
                str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 1 and err == "episodes failed: 2 of 2 (first: diverged)\n", err
    assert (tmp_path / "o" / "results.csv").read_text().count("diverged") == 2


def test_benchmark_starts_no_more_workers_than_episodes(monkeypatch):
    import concurrent.futures

    from ebraille_sim.tools import benchmark as bm
    seen = {}

    class Refused(Exception):
        pass

    def pool(max_workers=None, **k):
        seen["workers"] = max_workers
        raise Refused
    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor", pool)
    with pytest.raises(Refused):
        bm.run_benchmark(["pid"], "quick", readers=2, jobs=40, bounds=False)
    assert seen["workers"] == 2 * len(bm.get_suite("quick").scenarios)


def test_non_ascii_out_on_an_ascii_terminal_completes(tmp_path):
    out = tmp_path / "r\u00e9sultat"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONIOENCODING": "ascii"}
    p = subprocess.run([sys.executable, "-m", "ebraille_sim", "run", "steady_90wpm", "--duration", "0.5",
                        "--no-plot", "--out", str(out)], cwd=tmp_path, capture_output=True, text=True, env=env,
                       timeout=600)
    assert p.returncode in (0, 1) and "error" not in p.stderr, p.stderr    # 1: the short run fails a criterion
    assert "r\\xe9sultat" in p.stdout and (out / "metrics.json").is_file()


# ---------------------------------------------------------------- the env's edges

def test_env_edges_are_one_line_value_errors():
    from ebraille_sim.rl.env import ContactForceEnv, check_action, validate_options
    from ebraille_sim.rl.vector_env import ContactForceVectorEnv
    cases = [(lambda: validate_options({"wpm": 5e-324}, 3.0), "wpm"),
             (lambda: ContactForceVectorEnv(num_envs=2 ** 40), "num_envs"),
             (lambda: ContactForceVectorEnv(num_envs=2).reset(seed=True), "seed"),
             (lambda: ContactForceVectorEnv(num_envs=2).reset(seed=[0, -1]), "seed[1]"),
             (lambda: check_action(np.ma.masked_array([np.nan], mask=[True])), "finite"),
             (lambda: check_action(np.full((100, 1), np.nan), 100), "finite")]
    for make, named in cases:
        with pytest.raises(ValueError) as info:
            make()
        msg = str(info.value)
        assert "\n" not in msg and len(msg) <= MAX_LINE and named in msg, msg
    env = ContactForceEnv()
    with pytest.raises(ValueError, match="wpm"):
        env.reset(seed=0, options={"wpm": 5e-324})


def test_the_lock_ends_with_the_command_not_with_its_forked_workers(tmp_path):
    """A sweep killed outright leaves worker processes that finish their task: they must not
    keep the folder locked (they close their copies of the lock at fork)."""
    import time

    from ebraille_sim.tools.outputs import OutputFolder
    out = tmp_path / "o"
    out.mkdir()                                          # kept: the same folder is claimed again
    holder = OutputFolder(out, ["x"]).claim()
    ready_r, ready_w = os.pipe()
    pid = os.fork()
    if pid == 0:                                         # a worker: outlives the command's lock
        os.write(ready_w, b"1")                          # its fork hooks have run by now
        time.sleep(30)
        os._exit(0)
    os.close(ready_w)
    try:
        assert os.read(ready_r, 1) == b"1"
        os.close(ready_r)
        holder.release()
        with OutputFolder(out, ["x"]):                   # the worker is alive, the folder is free
            pass
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
