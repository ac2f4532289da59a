"""Replicated runs: one job identifies N independent datasets of one configuration, each a run of its own.

What must hold: replicate k is the same dataset whatever N; raising N computes only the new replicates; a kill
loses at most the chunk in progress and a rerun completes the set without a duplicate; a failing replicate is a
failed row while the others land; the batch replay of a chunk gives the metrics each model gives alone; a bad
``replicates`` is refused in one line before anything is written.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.configuration.compose import compose
from study.run.executor import Replicate, dataset_seed, run_replicated
from study.run.pipeline import SimulatedJob
from study.store import ResultStore, run_id

TINY = ["experiment=tiny", "+artefacts.traces=false"]


def _conf(*overrides):
    conf = compose("config", [*TINY, *overrides])
    conf.pop("replicates", None)
    return conf


# ------------------------------------------------------------------------------------------------- seeds, ids

def test_dataset_seeds_depend_on_seed_and_index_only():
    assert dataset_seed(7, 0) == 7  # replicate 0 is the run a job without replicates makes
    seeds = [dataset_seed(7, k) for k in range(200)]
    assert len(set(seeds)) == 200 and all(0 <= s < 2 ** 31 for s in seeds)
    assert dataset_seed(8, 1) != dataset_seed(7, 1) and dataset_seed(7, 1) == seeds[1]


def test_replicate_run_ids_leave_replicate_zero_and_the_number_asked_alone():
    conf = _conf()
    assert run_id(conf, 0) == run_id(conf) == run_id({**conf, "replicates": 20})
    ids = {run_id(conf, k) for k in range(50)}
    assert len(ids) == 50
    with pytest.raises(ValueError, match="replicate"):
        run_id(conf, -1)


# ------------------------------------------------------------------------------------- the executor, a toy job

class ToyJob:
    """Draws a noisy mean from the dataset seed; counts what it computes; may fail or be interrupted."""

    def __init__(self, fail_at=(), interrupt_at=None, skip=None):
        self.prepared = 0
        self.identified: list[int] = []
        self.fail_at, self.interrupt_at, self.skip = set(fail_at), interrupt_at, skip

    def prepare(self):
        self.prepared += 1
        return None if self.skip is None else {"status": "skipped", "error": self.skip}

    def identify(self, rep):
        if rep.index == self.interrupt_at:
            raise KeyboardInterrupt
        if rep.index in self.fail_at:
            raise RuntimeError(f"replicate {rep.index} diverged")
        self.identified.append(rep.index)
        x = np.random.default_rng(rep.dataset_seed).normal(1.0, 0.1, 50).mean()
        return {"metrics": {"mean": float(x)}, "params": [{"equation": "X", "name": "a", "estimate": float(x),
                                                           "truth": 1.0}], "timings": {}}

    def finish(self, partials):
        return partials


CONF = {"study": None, "seed": 3, "model": {"name": "toy"}}


def test_twenty_replicates_land_then_five_more_and_nothing_twice(tmp_path):
    store = ResultStore(tmp_path)
    job = ToyJob()
    recs = run_replicated(store, CONF, job, 20, seed=3)
    assert [r["status"] for r in recs] == ["ok"] * 20 and job.prepared == 1
    assert [r["replicate"] for r in recs] == list(range(20))
    assert len({r["dataset_seed"] for r in recs}) == 20 and recs[0]["dataset_seed"] == 3
    job2 = ToyJob()
    recs2 = run_replicated(store, CONF, job2, 25, seed=3)
    assert sorted(job2.identified) == [20, 21, 22, 23, 24]  # exactly the new ones
    assert all(r["resumed"] for r in recs2[:20]) and recs2[:20] == [{**r, "resumed": True} for r in recs]
    runs, params = store.collect()
    assert len(runs) == 25 and runs["run_id"].is_unique and sorted(runs["replicate"]) == list(range(25))
    assert runs["dataset_seed"].nunique() == 25 and len(params) == 25
    assert set(params["replicate"]) == set(range(25))
    # nothing to do: the shared work is not even prepared
    job3 = ToyJob()
    run_replicated(store, CONF, job3, 25, seed=3)
    assert job3.prepared == 0 and not job3.identified


def test_a_failing_replicate_is_a_failed_row_and_the_others_land(tmp_path):
    store = ResultStore(tmp_path)
    recs = run_replicated(store, CONF, ToyJob(fail_at={2, 5}), 8, seed=3)
    assert [r["status"] for r in recs] == ["ok", "ok", "failed", "ok", "ok", "failed", "ok", "ok"]
    assert "replicate 5 diverged" in recs[5]["error"] and "Traceback" in recs[5]["error"]
    job = ToyJob()
    run_replicated(store, CONF, job, 8, seed=3)  # the failed ones are retried, the others kept
    assert sorted(job.identified) == [2, 5]
    runs, _ = store.collect()
    assert list(runs["status"]) == ["ok"] * 8 and len(list(store.failed_dir.glob("*.json"))) == 2


def test_shared_work_that_skips_or_fails_applies_to_every_replicate(tmp_path):
    recs = run_replicated(ResultStore(tmp_path / "a"), CONF, ToyJob(skip="no rudder to act on"), 4, seed=3)
    assert [r["status"] for r in recs] == ["skipped"] * 4 and recs[3]["error"] == "no rudder to act on"

    class Broken(ToyJob):
        def prepare(self):
            raise ValueError("truth diverged")

    recs = run_replicated(ResultStore(tmp_path / "b"), CONF, Broken(), 3, seed=3)
    assert [r["status"] for r in recs] == ["failed"] * 3 and all("truth diverged" in r["error"] for r in recs)


def test_an_interrupted_job_keeps_the_finished_chunks_and_a_rerun_completes_them(tmp_path):
    store = ResultStore(tmp_path)
    with pytest.raises(KeyboardInterrupt):
        run_replicated(store, CONF, ToyJob(interrupt_at=7), 12, seed=3)
    kept = {json.loads(p.read_text())["replicate"] for p in store.records_dir.glob("*.json")}
    assert kept and max(kept) < 7 and kept == set(range(len(kept)))  # whole chunks before the interrupted one
    job = ToyJob()
    recs = run_replicated(store, CONF, job, 12, seed=3)
    assert sorted(job.identified) == sorted(set(range(12)) - kept)
    runs, _ = store.collect()
    assert len(runs) == 12 and runs["run_id"].is_unique and not list(store.claims_dir.glob("*.json"))
    assert [r["status"] for r in recs] == ["ok"] * 12


def test_bad_numbers_of_replicates_are_refused(tmp_path):
    for bad in (0, -2, 2.5, True, "3"):
        with pytest.raises(ValueError, match="replicates"):
            run_replicated(ResultStore(tmp_path), CONF, ToyJob(), bad, seed=3)
    assert not tmp_path.joinpath("records").exists()


# -------------------------------------------------------------------------------------- the pipeline's job

def _identify_all(conf, reps):
    job = SimulatedJob(conf)
    assert job.prepare() is None
    return job, [job.identify(r) for r in reps]


def test_replicate_k_is_the_same_dataset_whatever_the_number_asked(tmp_path):
    conf = _conf("seed=4")
    few = run_replicated(ResultStore(tmp_path / "few"), conf, SimulatedJob(conf), 3, seed=4)
    many = run_replicated(ResultStore(tmp_path / "many"), conf, SimulatedJob(conf), 5, seed=4)
    for a, b in zip(few, many[:3]):
        assert a["run_id"] == b["run_id"] and a["dataset_seed"] == b["dataset_seed"]
        assert [p["estimate"] for p in a["params"]] == [p["estimate"] for p in b["params"]]
    # and the datasets differ from each other: every replicate's estimates are its own
    est = np.array([[p["estimate"] for p in r["params"]] for r in many])
    assert len({tuple(row) for row in est}) == 5
    # replicate 0 is the run a job without replicates makes
    from study.run.pipeline import run_study

    one = run_study(compose("config", [*TINY, "seed=4"]))
    assert [p["estimate"] for p in one["params"]] == [p["estimate"] for p in many[0]["params"]]


def test_the_random_rudder_signal_is_drawn_per_dataset_and_the_rest_of_the_truth_once():
    conf = _conf()
    job, _ = _identify_all(conf, [])
    assert job.random == {"random_rudder"} and "random_rudder" not in job.clean_fixed
    a, _ = job.dataset(dataset_seed(0, 1))
    b, _ = job.dataset(dataset_seed(0, 2))
    i = job.train_names.index("random_rudder")
    assert not np.allclose(a[i]["delta"].to_numpy(), b[i]["delta"].to_numpy())  # its own signal
    z = job.train_names.index("zigzag_10_10")
    assert not np.allclose(a[z]["psi"].to_numpy(), b[z]["psi"].to_numpy())  # its own noise
    assert np.allclose(a[z]["psi"].to_numpy(), b[z]["psi"].to_numpy(), atol=np.radians(1.0))  # one truth


def test_a_chunk_replayed_in_one_batch_gives_what_each_model_gives_alone():
    conf = _conf()
    reps = [Replicate(k, dataset_seed(0, k), run_id(conf, k)) for k in range(3)]
    job, parts = _identify_all(conf, reps)
    batch = job.finish(parts)
    job1, parts1 = _identify_all(conf, reps)
    alone = [job1.finish([p])[0] for p in parts1]
    for b, a in zip(batch, alone):
        keys = [k for k in a["metrics"] if k.startswith("val_")]
        assert keys and keys == [k for k in b["metrics"] if k.startswith("val_")]
        for k in keys:
            assert b["metrics"][k] == pytest.approx(a["metrics"][k], rel=1e-9, abs=1e-12, nan_ok=True), k


# ----------------------------------------------------------------------------------------------- the command

def _study(cwd: Path, *args, env=None, **kw):
    env = dict(os.environ if env is None else env)
    env.pop("STUDY_RESULTS_DIR", None)
    return subprocess.run([sys.executable, "-m", "study", *TINY, f"hydra.run.dir={cwd / 'out'}",
                           f"results_dir={cwd / 'results'}", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600, **kw)


@pytest.mark.parametrize("bad", ["0", "-1", "2.5", "abc", "true"])
def test_the_command_refuses_a_bad_number_of_replicates_before_any_work(tmp_path, bad):
    p = _study(tmp_path, f"replicates={bad}")
    assert p.returncode == 2, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("study: error: replicates="), p.stderr
    assert not (tmp_path / "results").exists()


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_the_command_lands_replicates_and_resumes_after_a_kill(tmp_path):
    """``python -m study replicates=N``: killed (SIGKILL) once some replicates have landed, then run again with
    a larger N: every replicate once, none computed twice after it landed."""
    env = dict(os.environ, STUDY_CHUNK_SECONDS="0")  # every replicate written as soon as it is computed
    env.pop("STUDY_RESULTS_DIR", None)
    proc = subprocess.Popen([sys.executable, "-m", "study", *TINY, f"hydra.run.dir={tmp_path / 'out'}",
                             f"results_dir={tmp_path / 'results'}", "replicates=40"], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    records = tmp_path / "results" / "records"
    deadline = time.monotonic() + 300
    try:
        while len(list(records.glob("*.json"))) < 3:
            assert proc.poll() is None, "the job ended before it could be killed"
            if time.monotonic() > deadline:  # a hang guard, not a timing assertion
                pytest.fail("no replicate landed in 300 s: the job hangs")
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=60)
    landed = {p.stem: p.stat().st_mtime_ns for p in records.glob("*.json")}
    assert 3 <= len(landed) < 40
    p = _study(tmp_path, "replicates=45")
    assert p.returncode == 0, p.stderr
    assert (p.stdout + p.stderr).count("(already finished, resumed)") == len(landed)
    after = {q.stem: q.stat().st_mtime_ns for q in records.glob("*.json")}
    assert all(after[k] == v for k, v in landed.items())  # landed replicates were not computed again
    runs = pd.read_parquet(tmp_path / "results" / "runs.parquet")
    assert len(runs) == 45 and runs["run_id"].is_unique and sorted(runs["replicate"]) == list(range(45))
    assert (runs["status"] == "ok").all() and runs["dataset_seed"].nunique() == 45
