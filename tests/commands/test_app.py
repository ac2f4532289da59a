"""The Hydra app end to end: every option of every config group composes; a run lands in the table; a
two-process sweep writes each record once; an interrupted sweep resumes; a failing run is recorded."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from study.commands.app import CONF_DIR
from study.run.pipeline import run_study

REPO = Path(__file__).resolve().parents[2]
GROUPS = ["vessel", "depth", "environment", "noise", "maneuvers", "model", "structure", "estimator"]


def _options(group):
    return sorted(p.stem for p in (Path(CONF_DIR) / group).glob("*.yaml"))


@pytest.mark.parametrize("group, option", [(g, o) for g in GROUPS + ["experiment"] for o in _options(g)])
def test_every_option_composes(group, option):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"{group}={option}"], return_hydra_config=True)
    conf = OmegaConf.to_container(cfg, resolve=False)
    assert conf["seed"] == 0
    if group != "experiment":
        assert conf[group]["name"] == option


def _tiny_conf(tmp_path, **over):
    overrides = ["experiment=tiny"] + [f"{k}={v}" for k, v in over.items()]
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=overrides)
    conf = OmegaConf.to_container(cfg, resolve=False)
    conf["results_dir"] = str(tmp_path)
    return conf


def test_default_pipeline_identifies_and_validates(tmp_path):
    conf = _tiny_conf(tmp_path, **{"noise": "none"})
    out = run_study(conf)
    assert len(out["params"]) == 17
    assert out["metrics"]["drift_median"] < 0.01
    assert out["metrics"]["val_zigzag_35_35_rmse_r"] < 1e-4


def _run_app(args, results, env_extra=None):
    env = dict(os.environ, STUDY_RESULTS_DIR=str(results), NUMBA_NUM_THREADS="1", **(env_extra or {}))
    return subprocess.run([sys.executable, "-m", "study", *args], cwd=results.parent, env=env,
                          capture_output=True, text=True, timeout=900)


def _records(results):
    return {p.stem: json.loads(p.read_text()) for p in (results / "records").glob("*.json")}


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_two_process_sweep_resume_and_failure(tmp_path):
    results = tmp_path / "results"
    sweep = ["-m", "hydra/launcher=local", "hydra.launcher.n_jobs=2", "experiment=tiny", "noise=none,low",
             "structure=euler,central"]
    p = _run_app(sweep, results)
    assert p.returncode == 0, p.stderr[-3000:]
    # each job prints its number out of the sweep's total, also from the launcher's worker processes
    assert sorted(ln.split(":")[0] for ln in p.stdout.splitlines() if ln.startswith("[study] job ")) == \
        [f"[study] job {i}/4" for i in range(1, 5)], p.stdout
    recs = _records(results)
    assert len(recs) == 4 and all(r["status"] == "ok" for r in recs.values())
    runs = pd.read_parquet(results / "runs.parquet")
    assert len(runs) == 4 and runs["run_id"].is_unique
    # interrupt: lose one record, run the sweep again: only that one is computed
    lost = sorted(recs)[0]
    (results / "records" / f"{lost}.json").unlink()
    p = _run_app(sweep, results)
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stdout.count("(already finished, resumed)") == 3
    assert len(_records(results)) == 4
    # a failing run (h/T below every formula's range) is recorded, the sweep goes on, and ends with status 1
    p = _run_app(["-m", "experiment=tiny", "noise=none", "depth.h_T=1.0,2.0"], results)
    assert p.returncode == 1, p.stderr[-3000:]
    assert "sweep finished: 2 jobs, 1 failed, 1 ok" in p.stdout and "h/T = 1.0" in p.stderr
    recs = _records(results)
    failed = [r for r in recs.values() if r["status"] == "failed"]
    assert len(failed) == 1 and "h/T = 1.0" in failed[0]["error"]
    assert len(recs) == 6


def test_experiment_overrides_the_primary_config():
    # the experiment comes after _self_ in the defaults list, so its values win
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        base = compose(config_name="config")
        tiny = compose(config_name="config", overrides=["experiment=tiny"])
    assert base.sim.duration_scale == 1.0 and tiny.sim.duration_scale < 1.0


@pytest.mark.parametrize("environment", _options("environment"))
def test_hidden_effects_flow_through_a_run(tmp_path, environment):
    """Every environment option runs end to end. Current and wind act on the hull equations and bias the
    estimates; a slow steering gear does not, because the record holds the actual rudder angle, not the
    command (only a model driven by the command would see it)."""
    out = run_study(_tiny_conf(tmp_path, noise="none", environment=environment, depth="h_T_2p9"))
    drift = out["metrics"]["drift_median"]
    if environment in ("calm", "rudder_lag"):
        assert drift < 0.01
    else:
        assert drift > 0.01, f"{environment}: a hidden effect left no trace in the estimates"


def test_covering_sweeper_composes_every_value_once():
    from hydra_plugins.study_sweeper.covering_sweeper import covering_jobs
    import itertools
    keys = {"a": "123", "b": "xy", "c": "pqrs"}
    batch = [[f"{k}={v}" for k, v in zip(keys, combo)] for combo in itertools.product(*keys.values())]
    keep = covering_jobs(batch)
    assert {o for job in keep for o in job} == {o for job in batch for o in job}
    assert len(keep) <= sum(len(v) for v in keys.values()) and len(batch) == 24


@pytest.mark.slow
def test_a_bad_value_anywhere_in_a_sweep_fails_before_any_run(tmp_path):
    # the misspelt option is the last value of an inner key: a covering subset still composes it
    results = tmp_path / "results"
    p = _run_app(["-m", "experiment=tiny", "noise=none,low", "structure=euler,centrall"], results)
    assert p.returncode != 0 and "centrall" in p.stderr
    assert not (results / "records").exists() or not list((results / "records").glob("*.json"))
