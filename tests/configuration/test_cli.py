"""Every command-line entry point: a problem is one line on stderr naming the setting or file, with exit status 2
and nothing written; settings that make no sense are refused before any work; outputs are never replaced
silently; a failed run exits non-zero and a skipped one says why (study/configuration/cli.py, study/run/settings.py).

The subprocess tests use settings that are refused (or runs that end) within seconds of starting."""
import importlib
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from study.configuration import cli
from study.commands.app import CONF_DIR
from study.run.settings import check_diagnose, check_run, check_simulate

REPO = Path(__file__).resolve().parents[2]


def _cmd(module, *args, cwd, env_extra=None):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(REPO), **(env_extra or {}))
    env.pop("STUDY_VERBOSE", None)
    env.pop("HYDRA_FULL_ERROR", None)
    return subprocess.run([sys.executable, "-m", *module.split(), *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)


def _one_line(p) -> str:
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    return lines[0]


def _compose(name, overrides=()):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name=name, overrides=list(overrides))
    return OmegaConf.to_container(cfg, resolve=True)


# ------------------------------------------------------------------------------ settings refused before work

@pytest.mark.parametrize("override, named", [
    ("sim.dt=0", "sim.dt=0"), ("sim.dt=-0.1", "sim.dt=-0.1"), ("sim.dt=inf", "sim.dt=inf"),
    ("sim.duration_scale=0", "sim.duration_scale=0"), ("sim.duration_scale=nan", "sim.duration_scale=nan"),
    ("noise=low_relative noise.level=-0.01", "noise.level=-0.01"), ("noise.sample_dt=0", "noise.sample_dt=0"),
    ("noise.full_scale.position_m=-1", "noise.full_scale.position_m=-1"),
    ("depth.h_T=-2", "depth.h_T=-2"), ("seed=-1", "seed=-1"),
    ("+estimator_overrides.emcees.target_ess=10", "no estimator 'emcees'"),
    ("+estimator_overrides.emcee.target_es=10", "no hyper-parameter target_es"),
    ("+estimator.params.alpah=1", "no hyper-parameter alpah"),
    ("'environment.effects=[{name: rudder_dynamics, lag: -1}]'", "environment.effects[0].lag=-1"),
])
def test_a_setting_that_makes_no_sense_is_refused_naming_it(override, named):
    conf = _compose("config", override.strip("'").split(" ") if " " in override and "[" not in override
                    else [override.strip("'")])
    with pytest.raises(cli.ConfigError, match=named.replace("[", r"\[").replace(".", r"\.")):
        check_run(conf)


@pytest.mark.slow
def test_the_default_and_every_experiment_pass_the_check():
    for exp in [None] + sorted(p.stem for p in (Path(CONF_DIR) / "experiment").glob("*.yaml")):
        check_run(_compose("config", [f"experiment={exp}"] if exp else []))


def test_the_cli_refuses_zero_in_one_line_with_status_2_and_writes_nothing(tmp_path):
    results = tmp_path / "results"
    p = _cmd("study", "experiment=tiny", "sim.dt=0", f"results_dir={results}", f"hydra.run.dir={tmp_path}/o",
             cwd=tmp_path)
    assert p.returncode == 2
    assert _one_line(p) == "study: error: sim.dt=0: expected a finite number > 0 (null for the default)"
    assert not results.exists()


@pytest.mark.slow
def test_a_sweep_with_one_bad_value_is_refused_before_any_job(tmp_path):
    results = tmp_path / "results"
    p = _cmd("study", "-m", "experiment=tiny", "sim.dt=0.1,-1", f"results_dir={results}",
             f"hydra.sweep.dir={tmp_path}/m", cwd=tmp_path)
    assert p.returncode == 2 and "study: error: sim.dt=-1" in p.stderr, p.stderr
    assert "Launching" not in p.stdout + p.stderr and not results.exists()


def test_verbose_shows_the_traceback(tmp_path):
    p = _cmd("study", "experiment=tiny", "sim.dt=0", "--verbose", f"hydra.run.dir={tmp_path}/o", cwd=tmp_path)
    assert p.returncode == 2 and "Traceback" in p.stderr and "ConfigError" in p.stderr
    assert p.stderr.strip().splitlines()[-1].startswith("study: error: sim.dt=0")


def test_a_config_that_does_not_compose_is_one_line(tmp_path):
    p = _cmd("study", "nosuchkey=1", cwd=tmp_path)
    line = _one_line(p)
    assert p.returncode == 2 and line.startswith("study: error: nosuchkey: no such setting; expected one of ")
    assert "estimator" in line and "hydra," not in line and "+nosuchkey=..." in line


# --------------------------------------------------------------------------------- failed and skipped runs

@pytest.mark.slow
def test_a_failed_run_exits_non_zero_and_a_skipped_run_says_why(tmp_path):
    results = tmp_path / "results"
    common = [f"results_dir={results}", f"hydra.run.dir={tmp_path}/o", "experiment=tiny"]
    p = _cmd("study", "depth.h_T=1.0", *common, cwd=tmp_path)  # below every shallow-water formula's range
    assert p.returncode == 1
    line = _one_line(p)
    assert line.startswith("study: error: run ") and "failed" in line and "h/T = 1.0" in line
    assert (results / "runs.parquet").exists()  # the failure is recorded, the table rebuilt
    p = _cmd("study", "structure=output_error", "estimator=ls", *common, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "skipped: estimator 'LeastSquares' does regression only" in p.stdout + p.stderr


# ---------------------------------------------------------------------------------------- python -m study simulate

@pytest.mark.slow
def test_simulate_checks_out_before_simulating(tmp_path):
    p = _cmd("study simulate", cwd=tmp_path)  # out= not given (was "???: unsupported file type")
    assert p.returncode == 2 and _one_line(p).startswith("study simulate: error: out= is required")
    p = _cmd("study simulate", "out=rec.txt", cwd=tmp_path)
    assert p.returncode == 2 and "unsupported file type '.txt'" in _one_line(p)
    (tmp_path / "rec.csv").write_text("mine")
    p = _cmd("study simulate", "out=rec.csv", "sim.duration=1e9", cwd=tmp_path)  # would take hours to simulate
    assert p.returncode == 2 and "refusing to overwrite" in _one_line(p)
    assert (tmp_path / "rec.csv").read_text() == "mine"
    p = _cmd("study simulate", "out=new.csv", "sim.duration=0", cwd=tmp_path)
    assert p.returncode == 2 and "sim.duration=0" in _one_line(p) and not (tmp_path / "new.csv").exists()


def test_check_simulate_refuses_zero_step_and_bad_rudder_log():
    conf = _compose("simulate", ["out=x.csv"])
    for over, named in (({"sim": {**conf["sim"], "dt": 0}}, "sim.dt=0"), ({"rudder_log": "both_"}, "rudder_log")):
        with pytest.raises(cli.ConfigError, match=named):
            check_simulate({**conf, **over})


def test_two_writers_of_one_record_cannot_replace_each_other(tmp_path):
    """Both pass the 'not there yet' check (as two processes started together do); one file is written, the other
    writer gets FileExistsError and its data are not swapped in."""
    import pandas as pd

    from study.records.schema import Record, read_record, write_record
    from study.sim import load_vessel, simulate

    df = simulate(load_vessel("kvlcc2_l7"), "zigzag_10_10", duration=5.0)
    path = tmp_path / "rec.csv"
    barrier = threading.Barrier(2)
    results = {}
    real_exists = Path.exists

    def writer(name):
        rec = Record(data=df.assign(u=df["u"] * (1.0 if name == "a" else 1.001)), meta={"name": name})  # plausible
        barrier.wait()
        try:
            write_record(rec, path)
            results[name] = "wrote"
        except FileExistsError as e:
            results[name] = str(e)

    Path.exists = lambda self: False if self == path else real_exists(self)  # both see no file
    try:
        threads = [threading.Thread(target=writer, args=(n,)) for n in "ab"]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        Path.exists = real_exists
    assert sorted(results.values(), key=len)[0] == "wrote" and "exists" in sorted(results.values(), key=len)[1]
    winner = next(n for n, r in results.items() if r == "wrote")
    got = read_record(path)
    assert got.meta["name"] == winner
    pd.testing.assert_series_equal(got.data["u"], df["u"] * (1.0 if winner == "a" else 1.001), check_names=False,
                                   atol=1e-9, rtol=1e-12)
    assert [f.name for f in tmp_path.iterdir()] == ["rec.csv"]  # no temporary file left behind


# ---------------------------------------------------------------------------------------- python -m study diagnose

def test_diagnose_refuses_a_folder_holding_any_report_file(tmp_path):
    out = tmp_path / "rep"
    out.mkdir()
    (out / "report.html").write_text("old")  # no report.json beside it (was overwritten)
    p = _cmd("study diagnose", f"train={tmp_path}/none_*.csv", f"out={out}", cwd=tmp_path)
    assert p.returncode == 2 and "report.html" in _one_line(p) and "refusing to overwrite" in _one_line(p)
    assert (out / "report.html").read_text() == "old"
    (out / "report.html").unlink()
    conf = _compose("diagnose", [f"train={tmp_path}/x.csv", f"out={out}"])
    (out / "figures").mkdir()  # empty: what a doctor stopped before it wrote any figure leaves; no report
    assert check_diagnose(conf) == out
    (out / "figures" / "ladder.png").write_bytes(b"png")
    with pytest.raises(cli.OutputExistsError, match="figures"):
        check_diagnose(conf)
    assert check_diagnose({**conf, "overwrite": True}) == out
    (out / "report.json").mkdir()
    with pytest.raises(cli.OutputExistsError, match="report.json"):
        check_diagnose(conf)


def test_diagnose_checks_its_thresholds_and_train():
    conf = _compose("diagnose", ["out=o"])
    with pytest.raises(cli.ConfigError, match="train= is required"):
        check_diagnose(conf)
    conf["train"] = "x.csv"
    for key, bad in (("min_improvement", 1.5), ("alpha", 0.0), ("max_steps", -1), ("anchor", float("nan"))):
        with pytest.raises(cli.ConfigError, match=f"{key}="):
            check_diagnose({**conf, key: bad})


def test_two_doctors_cannot_write_into_one_folder(tmp_path):
    from study.doctor.run import claimed

    with claimed(tmp_path / "rep", overwrite=False):
        with pytest.raises(cli.OutputExistsError, match="another python -m study diagnose"):
            with claimed(tmp_path / "rep", overwrite=False):
                pass
    (tmp_path / "rep" / "report.json").write_text("{}")  # a report finished meanwhile: checked under the lock
    with pytest.raises(cli.OutputExistsError, match="report.json"):
        with claimed(tmp_path / "rep", overwrite=False):
            pass


# ------------------------------------------------------------------------ the commands that write files

def test_examples_honours_help_and_never_writes_into_committed_folders(tmp_path):
    committed = REPO / "paper_figs" / "doctor" / "README.md"
    before = committed.read_bytes()
    p = _cmd("study doctor_examples", "--help", cwd=tmp_path)
    assert p.returncode == 0 and "--out" in p.stdout and "--overwrite" in p.stdout
    assert list(tmp_path.iterdir()) == [] and committed.read_bytes() == before
    from study.doctor import examples

    assert not str(examples.DEFAULT_OUT.resolve()).startswith(str(REPO / "paper_figs"))
    p = _cmd("study doctor_examples", "--out", str(REPO / "paper_figs" / "doctor"), cwd=tmp_path)
    assert p.returncode == 2 and "refusing to overwrite" in _one_line(p)
    assert committed.read_bytes() == before


@pytest.mark.parametrize("module, committed", [("study reality_check", "paper_figs"),
                                               pytest.param("study turn_prediction", "paper_figs/doctor",
                                                            marks=pytest.mark.slow)])
def test_other_writers_default_outside_the_repository_and_refuse_to_overwrite(tmp_path, module, committed):
    p = _cmd(module, "--help", cwd=tmp_path)
    assert p.returncode == 0 and "--out" in p.stdout and "--overwrite" in p.stdout and not list(tmp_path.iterdir())
    p = _cmd(module, "--out", str(REPO / committed), cwd=tmp_path)
    assert p.returncode == 2 and "refusing to overwrite" in _one_line(p)


# ------------------------------------------------------------------------------------------ study.configuration.cli

def _run_in_process(main, capsys, argv=()):
    with pytest.raises(SystemExit) as ex:
        cli.run(main, "study.x", list(argv))
    return ex.value.code, capsys.readouterr()


def test_user_errors_exit_2_and_unexpected_ones_exit_1_with_a_hint(capsys, monkeypatch):
    # setenv, not delenv: monkeypatch then removes the STUDY_VERBOSE=1 that --verbose sets below in this process
    # (a delenv of an absent variable restores nothing, and every later command in the session was verbose)
    monkeypatch.setenv("STUDY_VERBOSE", "")

    def bad_file(args):
        raise FileNotFoundError(2, "No such file or directory", "data/x.csv")

    code, out = _run_in_process(bad_file, capsys)
    assert code == 2 and out.err == "study.x: error: data/x.csv: No such file or directory\n"

    def bug(args):
        return {}["oops"]

    code, out = _run_in_process(bug, capsys)
    assert code == 1 and out.err.count("\n") == 1
    assert out.err.startswith("study.x: error: KeyError: oops (unexpected; run again with --verbose")

    code, out = _run_in_process(bug, capsys, ["--verbose"])
    assert code == 1 and "Traceback" in out.err and "--verbose" not in out.err.splitlines()[-1]

    code, out = _run_in_process(lambda args: 0 if args == ["a"] else 3, capsys, ["a", "--verbose"])
    assert code == 0


def test_every_command_runs_through_the_cli_wrapper():
    """The commands are in one place: only ``study/__main__.py`` has a ``__main__`` block, and each command of
    ``study.commands`` hands its ``command()`` to study.configuration.cli (run or run_hydra)."""
    import inspect

    from study.commands import DEFAULT, names

    mains = [p.relative_to(REPO).as_posix() for p in (REPO / "study").rglob("*.py")
             if "__name__ == \"__main__\"" in p.read_text(encoding="utf-8")]
    assert mains == ["study/__main__.py"]
    assert {"diagnose", "simulate", "results", "figures", "reality_check"} <= set(names())
    for name in [DEFAULT, *names()]:
        src = inspect.getsource(importlib.import_module(f"study.commands.{name}").command)
        assert "run(" in src or "run_hydra(" in src, name


def test_a_word_that_is_no_command_is_refused_in_one_line(tmp_path):
    p = _cmd("study", "diagnoes", cwd=tmp_path)
    assert p.returncode == 2 and _one_line(p).startswith("study: error: 'diagnoes' is neither a command (")
    assert not list(tmp_path.iterdir())


def test_hydra_errors_become_one_line_messages():
    from hydra.errors import MissingConfigException

    exc = MissingConfigException("In 'config': Could not find 'structure/centrall'\n\nAvailable options in "
                                 "'structure':\n\tcentral\n\teuler\nConfig search path:\n\tprovider=hydra", "x")
    assert cli.message(exc) == ("In 'config': Could not find 'structure/centrall'; Available options in "
                                "'structure': central, euler")


@pytest.mark.slow
def test_sweep_progress_shows_the_total(tmp_path):
    results = tmp_path / "results"
    p = _cmd("study", "-m", "experiment=tiny", "structure=output_error", "estimator=ls,ridge",
             f"results_dir={results}", f"hydra.sweep.dir={tmp_path}/m", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "[study] job 1/2: skipped (estimator 'LeastSquares' does regression only" in p.stdout
    assert "[study] job 2/2: skipped" in p.stdout and "sweep finished: 2 jobs, 2 skipped" in p.stdout
    recs = [json.loads(f.read_text()) for f in (results / "records").glob("*.json")]
    assert sorted(r["status"] for r in recs) == ["skipped", "skipped"]


@pytest.mark.parametrize("module,args,expect", [
    ("study", ["estimatr=ridge"], "estimatr: no such setting; did you mean 'estimator'?"),
    ("study", ["sim.dtt=0.1"], "sim.dtt: no such setting; did you mean 'sim.dt'?"),
    ("study", ["estimator=ridg"], "estimator=ridg: no such option; did you mean ridge?"),
    ("study simulate", ["out=x.csv", "manuver=zigzag_10_10"], "manuver: no such setting; did you mean 'maneuver'?"),
])
def test_a_misspelt_setting_gets_did_you_mean_not_the_plus_key_advice(tmp_path, module, args, expect):
    p = _cmd(module, *args, cwd=tmp_path)
    line = _one_line(p)
    assert p.returncode == 2 and line.startswith(f"{module}: error: ") and expect in line, line
    assert "To append to your config" not in line
    assert not any(tmp_path.iterdir())  # refused before anything is written
