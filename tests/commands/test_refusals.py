"""Refused means nothing written, nothing accepted silently, one clear line before any work, a trusted-code boundary
(study/configuration/cli.py run_hydra's precheck, study/run/settings.py, study/configuration/compose.py check_target, the store's record checks).

Each command-line refusal runs in an empty launch folder, without overriding Hydra's output folder, and the folder
must still be empty afterwards; the property tests generate malformed records and settings and find neither a
silent acceptance nor a traceback."""
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from study.configuration import cli
from study.configuration.compose import UntrustedCodeError, check_target, check_targets, compose
from study.run.settings import ENUMS, check_diagnose, check_run, check_simulate

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "docs" / "examples" / "effects"


def _cmd(module, *args, cwd, env_extra=None):
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(REPO), **(env_extra or {})}
    for k in ("STUDY_VERBOSE", "HYDRA_FULL_ERROR", "STUDY_RESULTS_DIR", "STUDY_EFFECT_PATH"):
        env.pop(k, None)
    return subprocess.run([sys.executable, "-m", *module.split(), *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)


def _tree(folder: Path) -> list:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    """Two simulated model-scale KVLCC2 records, and a copy of one with a single wild sample (u = 1e300)."""
    from study.records.schema import Record, write_record
    from study.sim import load_vessel, simulate

    d = tmp_path_factory.mktemp("records")
    v = load_vessel("kvlcc2_l7")
    for man in ("zigzag_10_10", "zigzag_20_20"):
        df = simulate(v, man, duration=60.0)
        write_record(Record(data=df, meta={"name": man}), d / f"{man}.csv")
    bad = d / "wild"
    bad.mkdir()
    df = simulate(v, "zigzag_10_10", duration=60.0)
    df.loc[100, "u"] = 1e300
    write_record(Record(data=df, meta={"name": "wild"}), bad / "wild.csv")
    write_record(Record(data=simulate(v, "zigzag_20_20", duration=60.0), meta={"name": "ok"}), bad / "ok.csv")
    return d


# -------------------------------------------------------------------------------- refusals write nothing

EVIL = "import pathlib; pathlib.Path(__file__).with_name('IMPORTED').write_text('ran')\nclass X: pass\n"

REFUSALS = [
    # (command, arguments, what the line must name); {rec} is the records folder, {evil} a folder on PYTHONPATH
    ("study", ["experiment=tiny", "resume=bogus"], "resume='bogus'"),
    ("study", ["experiment=tiny", "checks=maybe"], "checks='maybe'"),
    ("study", ["experiment=tiny", "states=bogus"], "states='bogus'"),
    ("study", ["experiment=tiny", "force=maybe"], "force='maybe'"),
    ("study", ["experiment=tiny", "sim.dt=1000"], "sim.dt=1000"),
    ("study", ["experiment=tiny", "noise.sample_dt=1e-6"], "noise.sample_dt=1e-06"),
    ("study", ["experiment=tiny", "estimator=ridge", "estimator.params.n_splits=-3"], "estimator.params.n_splits=-3"),
    ("study", ["experiment=tiny", "estimator._target_=evilmod.X"], "estimator._target_=evilmod.X"),
    ("study", ["experiment=tiny", "+hydra.callbacks.x._target_=shutil.copyfile", "+hydra.callbacks.x.src=a",
               "+hydra.callbacks.x.dst=b"], "hydra.callbacks.x._target_=shutil.copyfile"),
    ("study", ["experiment=tiny", "train=/no/such/folder/x.csv"], "train=/no/such/folder/x.csv"),
    ("study", ["train=/no", "such/x.csv"], "'such/x.csv'"),  # a path with spaces, unquoted
    ("study", ["train={rec}/wild", "vessel=kvlcc2_l7"], "column 'u', row 101"),
    ("study", ["train={rec}/zigzag_10_10.csv", "vessel=kvlcc2_l7", "checks=eror"], "checks='eror'"),
    ("study", ["train={rec}/zigzag_10_10.csv", "vessel=kvlcc2_l7", "results_dir=/proc/results"], "results_dir"),
    ("study", ["-m", "experiment=tiny", "sim.dt=0.1,-1"], "sim.dt=-1"),
    ("study", ["-m", "experiment=tiny", "seed=1,2", "hydra/launcher=local", "+hydra.launcher._target_=os.makedirs"],
     "os.makedirs"),
    ("study simulate", ["out=/proc/x.csv"], "folder /proc"),
    ("study simulate", ["out=a.csv", "rudder_log=bogus"], "rudder_log='bogus'"),
    ("study simulate", ["out=a.csv", "sim.dt=1000"], "sim.dt=1000"),
    ("study simulate", ["out=a.csv", "overwrite=yes please"], "overwrite='yes please'"),
    ("study diagnose", ["train={rec}", "checks=eror"], "checks='eror'"),
    ("study diagnose", ["train={rec}", "candidates=[nosuch]"], "'nosuch'"),
    ("study diagnose", ["train={rec}", "effect_path=/no/such/folder"], "effect_path=/no/such/folder"),
    ("study diagnose", ["train={rec}", "out=/proc/report"], "out=/proc/report"),
    ("study diagnose", ["train={rec}", "state_options.process=fast"], "state_options.process='fast'"),
    ("study diagnose", ["train={rec}/wild", "vessel=kvlcc2_l7", "checks=off", "out=rep"], "column 'u', row 101"),
    ("study diagnose", ["train={rec}/zigzag_10_10.csv", "vessel=kvlcc2_l7", "out=rep"], "at least two records"),
    ("study results", ["show", "--root", "missing"], "--root missing"),
    ("study results", ["rebuild", "--root", "missing"], "--root missing"),
    ("study results", ["shwo"], "invalid choice"),
    ("study figures", ["--results", "missing"], "--results missing"),
]


#: the refusals the default tier runs (each command, the trusted-code boundary, a bad sweep value): each is a process
#: start of some seconds, so the slow tier runs the whole list (malformed records are refused in-process by default:
#: tests/records/test_schema.py)
DEFAULT_TIER = {"resume='bogus'", "estimator._target_=evilmod.X", "hydra.callbacks.x._target_=shutil.copyfile",
                "sim.dt=-1", "os.makedirs", "folder /proc", "'nosuch'", "invalid choice", "--results missing"}


@pytest.mark.parametrize("module, args, named", [
    pytest.param(m, a, n, id=f"{m} {' '.join(a)}",
                 marks=() if n in DEFAULT_TIER else pytest.mark.slow)
    for m, a, n in REFUSALS])
def test_a_refusal_leaves_the_launch_folder_empty(tmp_path, records, module, args, named):
    launch = tmp_path / "launch"
    launch.mkdir()
    evil = tmp_path / "evil"
    evil.mkdir()
    (evil / "evilmod.py").write_text(EVIL)
    before = _tree(records)
    args = [a.format(rec=records) for a in args]
    p = _cmd(module, *args, cwd=launch, env_extra={"PYTHONPATH": f"{REPO}{os.pathsep}{evil}"})
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2, p.stderr
    assert len(lines) == 1 and lines[0].startswith(f"{module}: error: ") and named in lines[0], p.stderr
    assert "Traceback" not in p.stderr and "Exception" not in lines[0]
    assert _tree(launch) == [], "a refusal wrote into the launch folder"
    assert _tree(records) == before
    assert not (evil / "IMPORTED").exists(), "a refused module was imported"


def test_a_refusal_inside_the_task_removes_the_folder_hydra_made(tmp_path, monkeypatch):
    """A refusal the precheck cannot see (a record check of the run itself) still leaves no outputs/ folder."""
    monkeypatch.chdir(tmp_path)
    run_dir = tmp_path / "outputs" / "2024-01-01" / "00-00-00"
    (run_dir / ".hydra").mkdir(parents=True)
    (run_dir / ".hydra" / "config.yaml").write_text("a: 1")
    (run_dir / "app.log").write_text("")
    cli._remove_refused_output(str(run_dir), time.time())
    assert _tree(tmp_path) == []
    keep = tmp_path / "outputs" / "x"
    (keep / ".hydra").mkdir(parents=True)
    (keep / "result.csv").write_text("mine")  # anything else there: left alone
    cli._remove_refused_output(str(keep), time.time())
    assert (keep / "result.csv").exists()
    cli._remove_refused_output(str(tmp_path), time.time())  # never the launch folder itself
    assert (keep / "result.csv").exists()


def test_argparse_errors_are_one_line_with_status_2(tmp_path):
    p = _cmd("study results", "rebuild", "--bogus", cwd=tmp_path)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and p.stderr.startswith("study results: error: ")
    assert "usage:" not in p.stderr


# ------------------------------------------------------------------------------------ trusted-code boundary

def test_a_target_outside_the_project_is_refused_before_it_is_imported(tmp_path, monkeypatch):
    (tmp_path / "marker_mod.py").write_text(EVIL)
    monkeypatch.syspath_prepend(str(tmp_path))
    for target in ("marker_mod.X", "shutil.copyfile", "builtins.open", "os.makedirs", "hydra.utils.call",
                   "not a path", "x"):
        with pytest.raises(UntrustedCodeError, match="trusted code"):
            check_target(target)
    assert not (tmp_path / "IMPORTED").exists() and "marker_mod" not in sys.modules
    check_target("study.identify.estimators.linear.Ridge")
    check_target("hydra_plugins.study_launcher.launchers.StudyLocalLauncher")
    # a module in an effect folder the user names is trusted; the same module, the folder not named, is not
    check_target("marker_mod.X", plugin_dirs=[tmp_path])
    with pytest.raises(UntrustedCodeError):
        check_target("marker_mod.X", plugin_dirs=[EXAMPLES])
    assert not (tmp_path / "IMPORTED").exists()


def test_every_target_of_the_composed_configuration_is_checked_hydras_too():
    conf = compose("config", ["hydra/launcher=local"], hydra=True)
    check_targets(conf)  # the project's own configuration passes
    conf["hydra"]["job_logging"]["handlers"]["file"]["()"] = "shutil.copyfile"
    with pytest.raises(UntrustedCodeError, match=r"hydra\.job_logging\.handlers\.file\.\(\)"):
        check_targets(conf)
    with pytest.raises(UntrustedCodeError, match=r"model\.effects\[0\]\._target_"):
        check_targets({"model": {"effects": [{"_target_": "subprocess.run"}]}})


def test_an_effect_whose_target_lies_outside_its_folder_is_refused_before_import(tmp_path, monkeypatch):
    from study.identify.effects import make_effect

    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "evil_effect.py").write_text(EVIL)
    (tmp_path / "effects").mkdir()
    (tmp_path / "effects" / "bad.yaml").write_text("name: bad\n_target_: evil_effect.X\nparams: []\n")
    monkeypatch.syspath_prepend(str(tmp_path / "elsewhere"))
    with pytest.raises(UntrustedCodeError, match="bad.yaml"):
        make_effect("bad", [str(tmp_path / "effects")])
    assert not (tmp_path / "elsewhere" / "IMPORTED").exists()
    conf = compose("diagnose", ["train=x.csv", f"out={tmp_path / 'rep'}", f"effect_path=[{tmp_path / 'effects'}]"])
    with pytest.raises(UntrustedCodeError):
        check_diagnose(conf)
    monkeypatch.syspath_prepend(str(EXAMPLES))  # the documented example: its module lies in its folder
    conf = compose("diagnose", ["train=x.csv", f"out={tmp_path / 'rep'}", f"effect_path=[{EXAMPLES}]"])
    check_diagnose(conf)


# ------------------------------------------------------------------------------------- enumerated settings

def test_the_enumerations_are_the_codes_own():
    from study.records.measure import NOISE_KINDS
    from study.run.records_run import CHECK_MODES
    from study.run.executor import RESUME_MODES
    from study.records.schema import STATES
    from study.sim.effects import LINEAR_FORMULAS

    assert ENUMS["study"]["resume"][0] == RESUME_MODES
    assert ENUMS["study"]["checks"][0] == CHECK_MODES == ENUMS["study diagnose"]["checks"][0]
    assert ENUMS["study"]["states"][0] == STATES == ENUMS["study diagnose"]["states"][0]
    assert ENUMS["study"]["noise.kind"][0] == NOISE_KINDS
    assert set(ENUMS["study"]["depth.formula"][0]) == set(LINEAR_FORMULAS)


_COMMANDS = {"study": ("config", [], check_run), "study simulate": ("simulate", ["out=x.csv"], check_simulate),
             "study diagnose": ("diagnose", ["train=x.csv", "out=rep"], check_diagnose)}


@pytest.mark.parametrize("command", sorted(ENUMS))
def test_every_enumerated_setting_is_refused_outside_its_values(command, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    name, over, check = _COMMANDS[command]
    base = compose(name, over)
    check(base)
    for key, (allowed, _) in ENUMS[command].items():
        for bad in ("bogus", "maybe", 5, "ERROR"):
            conf = json.loads(json.dumps(base))
            node = conf
            *parents, last = key.split(".")
            for p in parents:
                node = node.setdefault(p, {}) if isinstance(node.get(p), dict) or p not in node else node[p]
            node[last] = bad
            with pytest.raises(cli.ConfigError, match=key.replace(".", r"\.")):
                check(conf)


# ------------------------------------------------------------------------------------ records and the store

def test_a_value_outside_the_physical_envelope_names_file_column_and_row():
    from study.records.schema import Record
    from study.sim import simulate
    from study.records.vessel_checks import RecordCheckError, check_envelope

    from study.configuration.compose import read_config

    vessel = read_config("vessel", "kvlcc2_l7")
    df = simulate("kvlcc2_l7", "zigzag_10_10", duration=30.0)
    check_envelope(vessel, [Record(data=df, path="ok.csv")])
    for col, value in (("u", 1e300), ("r", -50.0), ("delta", 35.0), ("y0", 1e7)):
        bad = df.copy()
        bad.loc[7, col] = value
        with pytest.raises(RecordCheckError, match=rf"^bad\.csv: column '{col}', row 8 .*expected"):
            check_envelope(vessel, [Record(data=df, path="ok.csv"), Record(data=bad, path="bad.csv")])


def test_an_extra_text_column_is_kept_and_ignored_by_identification():
    from study.identify.structures import segments
    from study.records.schema import Record
    from study.sim import simulate

    df = simulate("kvlcc2_l7", "zigzag_10_10", duration=10.0).assign(note="bar")
    rec = Record(data=df, path="with_note.csv")
    (seg,) = segments(rec.data, 0)
    assert "note" not in seg.data and "u" in seg.data and seg.where == "with_note.csv"
    assert rec.data["note"].eq("bar").all()


def _record(seed: int, metrics: dict, status="ok"):
    from study.store import run_id

    conf = {"seed": seed, "vessel": {"name": "kvlcc2"}, "estimator": {"name": "ls"}}
    return {"run_id": run_id(conf), "status": status, "config": conf, "metrics": metrics, "params": [],
            "timings": {"fit": 0.1}, "seed": seed, "error": None, "started": "2024-01-01T00:00:00+00:00",
            "finished": "2024-01-01T00:00:01+00:00"}


def _write_records(root: Path, recs: list) -> None:
    (root / "records").mkdir(parents=True, exist_ok=True)
    for i, r in enumerate(recs):
        rid = r.get("run_id") if isinstance(r, dict) and isinstance(r.get("run_id"), str) else f"bad{i}"
        (root / "records" / f"{rid}.json").write_text(json.dumps(r))


def test_a_metric_of_the_wrong_type_leaves_its_record_out_by_name(tmp_path):
    from study.store import ResultStore

    _write_records(tmp_path, [_record(0, {"rmse": 0.1, "note": "a"}), _record(1, {"rmse": 0.2, "note": "b"}),
                              _record(2, {"rmse": "abc", "note": "c"})])
    store = ResultStore(tmp_path)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        runs, _ = store.collect()
    assert len(runs) == 2 and runs["m_rmse"].dtype == float and sorted(runs["m_note"]) == ["a", "b"]
    (path, why), = store.report.skipped
    assert path.name == f"{_record(2, {})['run_id']}.json" and "metric 'rmse' is text ('abc')" in why
    assert any(str(path) in str(x.message) for x in w)


def test_a_number_among_text_metrics_leaves_its_record_out_not_the_others(tmp_path):
    """The kind most records hold decides: a number where the others hold text is the stray one."""
    from study.store import ResultStore

    _write_records(tmp_path, [_record(0, {"rmse": 0.1, "note": "a"}), _record(1, {"rmse": 0.2, "note": "b"}),
                              _record(2, {"rmse": 0.3, "note": 0})])
    store = ResultStore(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs, _ = store.collect()
    assert sorted(runs["m_note"]) == ["a", "b"]
    (path, why), = store.report.skipped
    assert path.name == f"{_record(2, {})['run_id']}.json" and "metric 'note' is a number (0)" in why


def test_progress_counts_a_record_with_a_status_of_another_type(tmp_path):
    from study.commands.app import _folder_counts

    _write_records(tmp_path, [_record(0, {}), {**_record(1, {}), "status": 5}, [1, 2]])
    counts = _folder_counts(tmp_path)
    assert counts == {"ok": 1, "malformed": 2}
    assert ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))  # the progress line can be made


_json_value = st.recursive(st.none() | st.booleans() | st.integers(-10, 10) | st.floats(allow_nan=False)
                           | st.text(max_size=5), lambda c: st.lists(c, max_size=3) | st.dictionaries(
                               st.text(max_size=5), c, max_size=3), max_leaves=6)
_FIELDS = ("run_id", "status", "config", "metrics", "params", "timings", "seed", "error", "started", "finished")


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(_FIELDS + ("metrics.rmse", "metrics.note", "params.0", "timings.fit")),
       value=_json_value)
def test_property_a_malformed_record_is_left_out_by_name_never_silently_taken(tmp_path_factory, field, value):
    from study.store import ResultStore

    root = tmp_path_factory.mktemp("store")
    good = [_record(0, {"rmse": 0.1, "note": "a"}), _record(1, {"rmse": 0.2, "note": "b"})]
    bad = _record(2, {"rmse": 0.3, "note": "c"})
    bad["params"] = [{"equation": "X", "name": "Xu", "estimate": 1.0, "truth": None}]
    top, _, sub = field.partition(".")
    if sub == "0":
        bad[top][0] = value
    elif sub:
        bad[top][sub] = value
    else:
        bad[top] = value
    _write_records(root, good + [bad])
    store = ResultStore(root)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs, params = store.collect()  # never a traceback
    skipped = {p.name for p, _ in store.report.skipped}
    assert len(runs) + len(skipped) == 3  # every record is in the table or named as left out
    assert runs["m_rmse"].dtype == float  # one record cannot change a column's type for the others
    if "m_note" in runs:
        assert all(isinstance(v, str) for v in runs["m_note"].dropna())
    if len(runs) == 3:  # taken: then the changed field was of an acceptable kind
        row = runs.loc[~runs["run_id"].isin({r["run_id"] for r in good})]  # its seed may be what was changed
        assert len(row) == 1 and row["status"].iloc[0] in ("ok", "failed", "skipped", "claimed")


_SETTINGS = {
    "sim.dt": st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=4), st.booleans()),
    "seed": st.one_of(st.integers(-5, 5), st.floats(allow_nan=True), st.text(max_size=3)),
    "noise.sample_dt": st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.none()),
    "resume": st.one_of(st.text(max_size=6), st.integers(), st.none()),
    "checks": st.one_of(st.text(max_size=6), st.booleans()),
    "force": st.one_of(st.text(max_size=6), st.booleans(), st.integers(0, 2)),
    "estimator.params.n_splits": st.one_of(st.integers(-5, 8), st.floats(allow_nan=True), st.text(max_size=3)),
}


@pytest.fixture(scope="module")
def ridge_conf():
    return compose("config", ["estimator=ridge"])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(sorted(_SETTINGS)), data=st.data())
def test_property_a_setting_is_accepted_only_when_it_makes_sense(ridge_conf, key, data):
    value = data.draw(_SETTINGS[key])
    conf = json.loads(json.dumps(ridge_conf))
    node = conf
    *parents, last = key.split(".")
    for p in parents:
        node = node[p]
    node[last] = value
    try:
        check_run(conf)
    except cli.ConfigError as e:  # refused: in one line naming the setting
        assert key.split(".")[-1] in str(e) and "\n" not in str(e)
        return
    # accepted: then the value is one that makes sense (no other exception type escapes either)
    num = isinstance(value, (int, float)) and not isinstance(value, bool)
    if key == "sim.dt":
        assert num and math.isfinite(value) and 0 < value <= 4.02
    elif key == "seed":
        assert num and value >= 0 and float(value).is_integer()
    elif key == "noise.sample_dt":
        assert value is None or (num and math.isfinite(value) and value >= 0.1)
    elif key == "resume":
        assert value in (None, "code", "config")
    elif key == "checks":
        assert value in ("error", "warn", "off")
    elif key == "force":
        assert isinstance(value, bool)
    elif key == "estimator.params.n_splits":
        assert num and float(value).is_integer() and value >= 2


# ------------------------------------------------------------------------------------------------ faults

_PARENT = """
import subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", "import os, sys, time; sys.path.insert(0, %(repo)r);"
    "from hydra_plugins.study_launcher.runner import die_with_parent; die_with_parent(os.getppid());"
    "print('ready', flush=True); time.sleep(600)"], stdout=subprocess.PIPE, text=True)
child.stdout.readline()
print(child.pid, flush=True)
time.sleep(600)
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "\nState:\tZ" not in state


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_worker_ends_when_its_parent_is_killed():
    parent = subprocess.Popen([sys.executable, "-c", _PARENT % {"repo": str(REPO)}], stdout=subprocess.PIPE,
                              text=True)
    child = int(parent.stdout.readline())
    assert _alive(child)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    for _ in range(600):  # the kernel signals at once; bounded wait, not a timing assertion
        if not _alive(child):
            break
        time.sleep(0.05)
    gone = not _alive(child)
    if not gone:
        os.kill(child, signal.SIGKILL)
    assert gone


def test_an_interrupted_doctor_leaves_a_folder_a_rerun_accepts(tmp_path):
    from study.doctor.run import PARTIAL_FIGURES, claimed

    out = tmp_path / "rep"
    (out / "figures").mkdir(parents=True)  # an older doctor stopped after making figures/ (nothing in it)
    (out / PARTIAL_FIGURES).mkdir()  # or while it wrote its figures
    (out / PARTIAL_FIGURES / "ladder.png").write_bytes(b"png")
    (out / ".report.lock").write_text("")
    conf = compose("diagnose", ["train=x.csv", f"out={out}"])
    assert check_diagnose(conf) == out
    with claimed(out, overwrite=False):
        assert not (out / PARTIAL_FIGURES).exists()


def test_a_refused_doctor_leaves_no_folder_it_made(tmp_path):
    from study.doctor.run import claimed

    out = tmp_path / "a" / "rep"
    with pytest.raises(RuntimeError):
        with claimed(out, overwrite=False):
            raise RuntimeError("refused inside")
    assert _tree(tmp_path) == []
