"""The study on the user's own records (``python -m study train=<files> validate=<files> ...``,
``study/run/records_run.py``): a run on files lands in the results table like any other, named by the records'
names and checksums; no simulation, no truth; each validation record replayed; bad input refused in one line.

The records are simulated here (KVLCC2, noise-free, sampled at 0.5 s), so the test knows the truth the run does
not: the vessel config's own hull coefficients.
"""
import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from study.commands.app import CONF_DIR
from study.run.pipeline import run_study, study_config
from study.run.records_run import FILE_KEYS, RecordsInputError
from study.run.executor import run_guarded
from study.store import ResultStore, run_id

REPO = Path(__file__).resolve().parents[2]
VESSEL = "kvlcc2"
TRAIN = {"train_zz10": ("zigzag_10_10", 0), "train_zz20": ("zigzag_20_20", 0), "train_rr": ("random_rudder", 0)}
VALIDATE = {"val_turn35": ("turning_35", 1), "val_zz35": ("zigzag_35_35", 1)}


def _compose(name: str, overrides: list) -> dict:
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    return OmegaConf.to_container(cfg, resolve=True)


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    from study.records.schema import write_record
    from study.commands.simulate import make_record

    d = tmp_path_factory.mktemp("records")
    for name, (man, seed) in {**TRAIN, **VALIDATE}.items():
        conf = _compose("simulate", [f"vessel={VESSEL}", f"maneuver={man}", "noise=none", "noise.sample_dt=0.5",
                                     f"seed={seed}", "out=unused"])
        write_record(make_record(conf), d / f"{name}.csv")
    return d


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _conf(data: Path, *over, validate=True) -> dict:
    args = [f"vessel={VESSEL}", f"train={data}/train_*.csv", "progress=false", *over]
    if validate:
        args.append(f"validate={data}/val_*.csv")
    return _compose("config", args)


def _run(tmp_path, conf):
    store = ResultStore(tmp_path / "results")
    run_conf, records = study_config(conf)
    rec = run_guarded(store, run_conf, lambda: run_study(conf, data=records), seed=0)
    runs, params = store.collect()
    return rec, runs, params


def _truth() -> dict:
    """What the run does not know: the coefficients the records were simulated with."""
    from study.identify.models import make_model
    from study.sim import load_vessel

    return make_model("mmg_hull", load_vessel(VESSEL)).truth()[0]


@pytest.mark.slow
def test_a_run_on_files_lands_in_the_table_with_its_records_and_replays(tmp_path, data):
    rec, runs, params = _run(tmp_path, _conf(data))
    assert rec["status"] == "ok", rec["error"]
    assert len(runs) == 1 and runs.loc[0, "status"] == "ok"
    row = runs.iloc[0]
    # which data: the records' names and checksums, in the configuration (and so in the run id)
    files = sorted(data.glob("train_*.csv"))
    assert json.loads(row["cfg_train"]) == [{"name": f.stem, "sha256": _sha(f)} for f in files]
    assert json.loads(row["cfg_validate"]) == [{"name": f.stem, "sha256": _sha(f)}
                                               for f in sorted(data.glob("val_*.csv"))]
    assert json.loads(row["m_train_files"]) == [str(f) for f in files]
    # no simulation: its axes are not in the configuration, the metrics say where the data came from
    assert not [c for c in runs.columns if c.split(".")[0] in ("cfg_noise", "cfg_environment", "cfg_maneuvers",
                                                               "cfg_sim", "cfg_checks")]
    assert row["m_data_source"] == "files" and "nothing simulated" in row["m_notes"]
    assert row["m_record_checks"] == "error: passed"
    # no truth: NaN in the table, no drift metrics; the estimates are near the truth the test knows
    assert params["truth"].isna().all() and (params["truth_kind"] == "none (measured records)").all()
    assert not [c for c in runs.columns if c.startswith("m_drift") or c == "m_truth_exact"]
    truth = _truth()
    est = params.set_index("name")["estimate"]
    assert set(est.index) == set(truth)
    scale = max(abs(v) for v in truth.values())
    worst = max(abs(est[k] - v) for k, v in truth.items()) / scale
    assert worst < 0.02, f"largest error {worst:.3g} of the largest coefficient"
    assert row["m_config_rel_diff_median"] < 0.01
    # each validation record replayed: errors per record and channel, manoeuvre metrics measured against model
    for name in VALIDATE:
        assert row[f"m_val_{name}_diverged"] == 0.0
        for c in ("u", "v", "r", "psi"):
            assert 0.0 <= row[f"m_val_{name}_nrmse_{c}"] < 0.01
            assert np.isfinite(row[f"m_val_{name}_rmse_{c}"])
    td = row["m_val_val_turn35_measured_tactical_diameter"]
    assert td > 0 and abs(row["m_val_val_turn35_model_tactical_diameter"] / td - 1) < 0.01
    assert abs(row["m_val_val_zz35_model_first_overshoot"] - row["m_val_val_zz35_measured_first_overshoot"]) < 0.5
    assert row["m_val_records"] == 2 and row["m_val_diverged_records"] == 0 and row["m_val_nrmse_mean"] < 0.01
    trace = pd.read_csv(tmp_path / "results" / "artefacts" / rec["run_id"] / "validation" / "val_turn35.csv")
    assert {"measured_r", "model_r"} <= set(trace.columns)
    # the figures rebuild with such a row in the table: no named study claims it, so it gets the generic comparison
    # (the held-out records' heading errors; no truth, so no coefficient-error figure)
    from study.figures import build

    written = {o.path for o in build(tmp_path / "results", tmp_path / "figs").written}
    assert "sweep_results/validation_val_turn35.{png,pdf}" in written
    assert not any("drift" in w for w in written)


def test_without_validation_records_the_metrics_say_so_and_a_failure_is_recorded(tmp_path, data, monkeypatch):
    import study.identify.fit as fit_mod

    def boom(*a, **k):
        raise RuntimeError("estimator exploded")

    conf = _conf(data, validate=False)
    monkeypatch.setattr(fit_mod, "identify", boom)
    rec, runs, _ = _run(tmp_path, conf)
    assert rec["status"] == "failed" and "estimator exploded" in rec["error"]
    monkeypatch.undo()
    rec, runs, _ = _run(tmp_path, conf)  # the failed run reruns; its earlier attempt is kept
    assert rec["status"] == "ok" and len(runs) == 1
    assert len(list((tmp_path / "results" / "records" / "failed").glob("*.json"))) == 1
    row = runs.iloc[0]
    assert row["m_val_skipped"] == 1.0 and "no held-out replay" in row["m_val_skipped_reason"]
    assert pd.isna(row["cfg_validate"])
    assert not [c for c in runs.columns if c.startswith("m_val_") and "_rmse_" in c]


def test_the_run_id_follows_the_files_not_their_place_nor_the_simulation_axes(tmp_path, data):
    rid = run_id(study_config(_conf(data))[0])
    # the simulated truth's axes do not apply to files: the same run
    same = _conf(data, "noise=high", "environment=current", "maneuvers=seed000", "sim.duration_scale=0.3",
                 "checks=warn")
    assert run_id(study_config(same)[0]) == rid
    # the same bytes elsewhere: the same run; one file changed: another run
    moved = tmp_path / "moved"
    shutil.copytree(data, moved)
    assert run_id(study_config(_conf(moved))[0]) == rid
    f = moved / "train_zz20.csv"
    f.write_text(f.read_text().replace("\n0,", "\n0.0,", 1))  # the same numbers, other bytes: still a change
    cfg, _ = study_config(_conf(moved))
    assert run_id(cfg) != rid
    assert [r["sha256"] == _sha(data / f"{r['name']}.csv") for r in cfg["train"]] == [True, True, False]
    # the identification's own axes do count
    assert run_id(study_config(_conf(data, "estimator=ridge"))[0]) != rid
    # a simulated run: the file keys are not in its configuration, so its run id is what it was before them
    sim = _compose("config", [])
    cfg, records = study_config(sim)
    assert records is None and cfg == {k: v for k, v in sim.items() if k not in FILE_KEYS}
    assert not set(FILE_KEYS) & set(cfg)


def _error(conf) -> str:
    with pytest.raises(RecordsInputError) as e:
        study_config(conf)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


def test_bad_input_is_refused_in_one_line_naming_the_problem(tmp_path, data):
    msg = _error(_compose("config", [f"train={tmp_path}/nothing_*.csv"]))
    assert f"{tmp_path}/nothing_*.csv" in msg and "no file matches" in msg
    bad = tmp_path / "bad.csv"
    bad.write_text("time,u,v\n" + "".join(f"{i},1,0\n" for i in range(30)))
    msg = _error(_compose("config", [f"train={bad}"]))
    assert str(bad) in msg and "'psi'" in msg
    # a record of another vessel: the full-scale records against the 7 m model
    msg = _error(_conf(data, "vessel=kvlcc2_l7"))
    assert "train_rr.csv" in msg and "'u', 'v'" in msg and "kvlcc2_l7" in msg and "vessel=kvlcc2" in msg
    # a flipped rudder
    flipped = tmp_path / "flipped"
    flipped.mkdir()
    df = pd.read_csv(data / "train_zz10.csv", comment="#")
    df["delta"] = -df["delta"]
    df.to_csv(flipped / "train_zz10.csv", index=False)
    msg = _error(_compose("config", [f"vessel={VESSEL}", f"train={flipped}"]))
    assert "train_zz10.csv" in msg and "'delta'" in msg and "delta = -delta" in msg
    cfg, records = study_config(_compose("config", [f"vessel={VESSEL}", f"train={flipped}", "checks=warn"]))
    assert len(records.problems) == 1 and records.checks == "warn"
    # validating on a training record is refused, under its own name or another
    msg = _error(_conf(data, f"validate={data}/train_zz10.csv", validate=False))
    assert "already a training record" in msg
    (tmp_path / "copy").mkdir()
    shutil.copy(data / "train_zz10.csv", tmp_path / "copy" / "held_out.csv")
    msg = _error(_conf(data, f"validate={tmp_path}/copy/held_out.csv", validate=False))
    assert "held_out.csv" in msg and "same content" in msg and "train_zz10.csv" in msg


def _cli(args, cwd):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    env.pop("STUDY_RESULTS_DIR", None)
    return subprocess.run([sys.executable, "-m", "study", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.slow
def test_the_command_line_end_to_end(tmp_path, data):
    results = tmp_path / "results"
    p = _cli([f"train={data}/train_zz*.csv", f"validate={data}/val_zz35.csv", f"results_dir={results}"], tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    runs = pd.read_parquet(results / "runs.parquet")
    assert len(runs) == 1 and runs.loc[0, "status"] == "ok"
    assert [r["name"] for r in json.loads(runs.loc[0, "cfg_train"])] == ["train_zz10", "train_zz20"]
    assert runs.loc[0, "m_val_val_zz35_diverged"] == 0.0
    before = (results / "runs.parquet").read_bytes()
    # a pattern matching nothing: one line naming it, a non-zero exit, nothing written or lost
    p = _cli([f"train={data}/nope_*.csv", f"results_dir={results}"], tmp_path)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{data}/nope_*.csv" in lines[0] and "no file matches" in lines[0], p.stderr
    assert (results / "runs.parquet").read_bytes() == before
    assert len(list((results / "records").glob("*.json"))) == 1


SLOW = pytest.mark.slow


@pytest.mark.parametrize("over", [["model=nomoto1_nl"], ["model=known"],
                                  pytest.param(["model=nomoto1", "structure=output_error", "estimator=de",
                                                "estimator.params.maxiter=30"], marks=SLOW),
                                  pytest.param(["model.effects=[current]"], marks=SLOW),
                                  pytest.param(["estimator=sindy"], marks=SLOW)])
def test_other_models_and_estimators_on_files(tmp_path, data, over):
    rec, runs, params = _run(tmp_path, _conf(data, *over))
    assert rec["status"] == "ok", rec["error"]
    row = runs.iloc[0]
    assert len(params) == 0 or params["truth"].isna().all()
    for name in VALIDATE:
        assert row[f"m_val_{name}_diverged"] == 0.0
    if over == ["model=known"]:  # the vessel config's own model, replayed at the records' 0.5 s step
        assert len(params) == 0 and row["m_val_nrmse_mean"] < 0.01
    if over == ["model.effects=[current]"]:  # no current in the records
        est = params.set_index("name")["estimate"]
        assert abs(est["current_speed"]) < 0.01 and params.set_index("name").loc["current_speed", "equation"] == "effect"
