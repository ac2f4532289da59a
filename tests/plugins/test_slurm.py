"""Sweeps submitted to a real SLURM cluster through ``hydra/launcher=slurm`` (conf/hydra/launcher/slurm.yaml, Hydra's
submitit launcher): every record lands once in the shared results folder and the tables are rebuilt; a job that
fails is recorded as failed while the others complete; a sweep whose jobs are cancelled with ``scancel`` half way is
finished by running the same command again, without recomputing the runs already finished.

The cluster is the throw-away single-node one of ``scripts/slurm_cluster.sh start`` (.ci/run starts it). These tests
never submit to any other cluster (a site's login node): they check ``ClusterName=study`` first. They are skipped
with the reason when that cluster is not up, unless STUDY_REQUIRE_SLURM=1 (set by .ci/run once it has started it),
in which case they fail instead of silently skipping.

Each sweep is launched from a scratch folder outside the repository, with an absolute ``results_dir``, as a
researcher would from a cluster's login node: the jobs find ``conf/`` and the results folder from the compute node
on their own. The runs are tiny (``experiment=tiny``, the exact KT Mariner, a second-order Nomoto model: about a
second each, plus the job's Python start).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pandas as pd
import pytest

import study

pytestmark = [pytest.mark.slurm, pytest.mark.slow]  # the slow tier: a SLURM cluster, started by .ci/run

CLUSTER_NAME = "study"  # scripts/slurm_cluster.sh
UP_STATES = {"idle", "mix", "mixed", "alloc", "allocated", "comp", "completing"}
SWEEP_TIMEOUT = 300  # s; a sweep here takes 20-60 s
# the package under test, wherever it is imported from (an editable install, or PYTHONPATH in a worktree): the
# launcher and, through sbatch's exported environment, the jobs import the same code
CODE_ROOT = str(Path(study.__file__).resolve().parents[1])


def _cluster_or_skip() -> None:
    why = None
    if shutil.which("sinfo") is None or shutil.which("sbatch") is None or shutil.which("scontrol") is None:
        why = "no SLURM client (sinfo, sbatch, scontrol) on PATH; start the throw-away cluster: scripts/slurm_cluster.sh start"
    else:
        try:
            conf = subprocess.run(["scontrol", "show", "config"], capture_output=True, text=True, timeout=20)
            states = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True, timeout=20)
        except subprocess.TimeoutExpired:
            conf = states = None
        if conf is None or conf.returncode != 0:
            err = "timed out" if conf is None else (conf.stderr.strip().splitlines() or ["no output"])[-1]
            why = f"no SLURM controller answers (scontrol show config: {err}); start it: scripts/slurm_cluster.sh start"
        else:
            name = next((ln.split("=", 1)[1].strip() for ln in conf.stdout.splitlines()
                         if ln.split("=", 1)[0].strip() == "ClusterName"), None)
            found = {s.strip().rstrip("*~#$@^-") for s in states.stdout.split()} if states.returncode == 0 else set()
            if name != CLUSTER_NAME:
                why = (f"the SLURM cluster here is '{name}', not the throw-away '{CLUSTER_NAME}' of "
                       "scripts/slurm_cluster.sh: these tests never submit to a real cluster")
            elif not found & UP_STATES:
                why = f"the throw-away SLURM cluster has no node taking jobs (sinfo states: {sorted(found) or 'none'})"
    if why is not None:
        if os.environ.get("STUDY_REQUIRE_SLURM") == "1":
            pytest.fail(f"STUDY_REQUIRE_SLURM=1 but {why}")
        pytest.skip(why)


@pytest.fixture(scope="module")
def cluster():
    _cluster_or_skip()


def _env() -> dict:
    # OMP_NUM_THREADS left out: the jobs get it from the launcher config's setup line
    env = {k: v for k, v in os.environ.items() if k not in ("STUDY_RESULTS_DIR", "OMP_NUM_THREADS")}
    env["PYTHONPATH"] = os.pathsep.join([CODE_ROOT] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.update(OPENBLAS_NUM_THREADS="1", HYDRA_FULL_ERROR="1")
    return env


def _sweep_cmd(results: Path, name: str, *overrides: str, launcher: str = "slurm") -> list[str]:
    """The sweep as a researcher types it (plus a unique job name, so that the test can find and cancel its jobs)."""
    return [sys.executable, "-m", "study", "-m", f"hydra/launcher={launcher}", f"hydra.launcher.name={name}",
            "experiment=tiny", "case=kt_nomoto2", f"results_dir={results}", "progress=false", *overrides]


def _records(results: Path) -> dict[str, dict]:
    """The run records in the results folder, by file name (records/<run_id>.json, results/README.md)."""
    out = {}
    for p in sorted((results / "records").glob("*.json")):
        try:
            out[p.name] = json.loads(p.read_text(encoding="utf-8"))
        except ValueError:  # never expected: records are written atomically
            out[p.name] = {"torn": True}
    return out


def _scancel(name: str) -> None:
    subprocess.run(["scancel", f"--name={name}"], capture_output=True, timeout=30)


def _queued(name: str) -> list[str]:
    r = subprocess.run(["squeue", "-h", f"--name={name}", "-o", "%i %T"], capture_output=True, text=True, timeout=30)
    return r.stdout.splitlines()


def _finish(proc: subprocess.Popen, log: Path, name: str, timeout: float = SWEEP_TIMEOUT) -> int:
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        _scancel(name)
        proc.kill()
        proc.wait()
        pytest.fail(f"the sweep did not end within {timeout} s; its output ends with:\n{_tail(log)}")


def _tail(log: Path, n: int = 40) -> str:
    """The sweep's last lines, without submitit's warnings that sacct does not answer (the throw-away cluster
    keeps no accounting)."""
    if not log.exists():
        return "(no output)"
    lines = [ln for ln in log.read_text(errors="replace").splitlines()
             if "sacct" not in ln and "accounting storage is disabled" not in ln]
    return "\n".join(lines[-n:])


def _run_sweep(cmd: list[str], cwd: Path, log: Path, name: str) -> int:
    with open(log, "ab") as fh:
        proc = subprocess.Popen(cmd, cwd=cwd, env=_env(), stdout=fh, stderr=subprocess.STDOUT)
        try:
            return _finish(proc, log, name)
        finally:
            _scancel(name)  # nothing of this test stays queued, whatever happened


def _sigint_default() -> None:
    """In the sweep's process before Python starts: SIGINT back to its default, so that Python turns it into
    KeyboardInterrupt (Ctrl-C). A process started in the background by a shell without job control (``cmd &`` in
    a script, as CI may run this suite) inherits SIGINT ignored, and Python then never sees the Ctrl-C."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)

def _cancel_once_two_records_land(cmd: list[str], cwd: Path, log: Path, name: str, results: Path) -> int:
    """Start the sweep, scancel its array once two records have landed, end the command; its exit status.

    On a cluster with accounting (sacct) submitit sees the cancelled jobs and the command stops with an error;
    without (the throw-away cluster) it cannot tell and waits: the researcher presses Ctrl-C (SIGINT here).
    The clocks below are guards against a hung cluster (generous multiples of what the step takes), so that a
    broken cluster fails the test instead of hanging CI; they time nothing."""
    with open(log, "ab") as fh:
        proc = subprocess.Popen(cmd, cwd=cwd, env=_env(), stdout=fh, stderr=subprocess.STDOUT,
                                preexec_fn=_sigint_default)
        try:
            give_up = time.monotonic() + SWEEP_TIMEOUT
            while len(_records(results)) < 2:
                if proc.poll() is not None:
                    pytest.fail(f"the sweep ended before any cancel:\n{_tail(log)}")
                if time.monotonic() > give_up:
                    pytest.fail(f"hung: no two records within {SWEEP_TIMEOUT} s:\n{_tail(log)}")
                time.sleep(0.2)
            _scancel(name)
            give_up = time.monotonic() + 60
            while _queued(name) and time.monotonic() < give_up:
                time.sleep(0.5)
            if _queued(name):
                pytest.fail(f"jobs still queued a minute after scancel: {_queued(name)}")
            try:
                return proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.send_signal(signal.SIGINT)
                return _finish(proc, log, name, timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            _scancel(name)


def _sweep_places(tmp_path: Path) -> tuple[str, Path, Path, Path]:
    """A sweep's job name (unique: only this test's jobs are cancelled), its results folder (absolute: the jobs
    resolve it on the compute node), the login folder it is launched from (created) and its log."""
    work = tmp_path / "login"
    work.mkdir()
    return f"study-test-{uuid.uuid4().hex[:8]}", tmp_path / "shared" / "results", work, tmp_path / "sweep.log"


def _check_tables(results: Path, records: dict[str, dict]) -> pd.DataFrame:
    runs = pd.read_parquet(results / "runs.parquet")
    params = pd.read_parquet(results / "params.parquet")
    assert runs["run_id"].is_unique
    assert set(runs["run_id"]) == {r["run_id"] for r in records.values()}
    by_id = runs.set_index("run_id")["status"].to_dict()
    assert by_id == {r["run_id"]: r["status"] for r in records.values()}
    ok = {r["run_id"] for r in records.values() if r["status"] == "ok"}
    assert set(params["run_id"]) == ok  # each run that identified something has its coefficients in the table
    return runs


def test_sweep_lands_every_record_once_and_records_a_failing_job(cluster, tmp_path):
    """Six jobs on the cluster: ls, lssvm and ridge on two seeds, ridge given a grid of alphas whose low end is above
    its high end (it raises when it fits; the settings' checks take any list of numbers). The four others finish ok,
    the two ridge runs are recorded as failed with the error, and the sweep ends with its count of failed runs (exit status 1) and the tables rebuilt from all six records. The sweep goes in batches of
    four (hydra.sweeper.max_batch_size, how a sweep larger than a site's MaxArraySize is submitted): two arrays."""
    name, results, work, log = _sweep_places(tmp_path)
    cmd = _sweep_cmd(results, name, "estimator=ls,lssvm,ridge", "seed=0,1",
                     "+estimator_overrides.ridge.alphas=[10.0,1.0,3]", "hydra.sweeper.max_batch_size=4")
    rc = _run_sweep(cmd, work, log, name)
    # the sweep ends with its count, and exit status 1 for the failed runs (study.configuration.sweep_summary.sweep_finished)
    assert rc == 1 and "[study] sweep finished: 6 jobs, 2 failed, 4 ok" in log.read_text(errors="replace"), _tail(log)
    assert list(results.glob("logs/sweeps/*/*/.submitit")), "the sweep did not go through submitit"

    recs = _records(results)
    assert len(recs) == 6, f"{len(recs)} records: {sorted(recs)}\n{_tail(log)}"
    assert len({r["run_id"] for r in recs.values()}) == 6
    assert all(p == f"{r['run_id']}.json" for p, r in recs.items())
    by = {(r["config"]["estimator"]["name"], r["seed"]): r for r in recs.values()}
    assert set(by) == {(e, s) for e in ("ls", "lssvm", "ridge") for s in (0, 1)}
    for (est, seed), r in by.items():
        if est == "ridge":
            assert r["status"] == "failed"
            assert "alphas must be a number or [lo, hi, num]" in r["error"]
        else:
            assert r["status"] == "ok", r.get("error")
            assert r["params"], f"{est} seed {seed}: no coefficients"
    # each job ran as one task of a SLURM job array (submitit names its folder <array id>_<index>): 4 + 2
    job_dirs = [p.name for p in results.glob("logs/sweeps/*/*/.submitit/*_*") if re.fullmatch(r"\d+_\d+", p.name)]
    arrays = {}
    for d in job_dirs:
        arrays.setdefault(d.split("_")[0], []).append(d)
    assert sorted(len(v) for v in arrays.values()) == [2, 4], sorted(job_dirs)
    # the ready config's setup line: one BLAS/OpenMP thread per CPU the job asked for (cpus_per_task: 1)
    assert all(r["provenance"]["omp_num_threads"] == 1 for r in recs.values())
    assert not list((results / "records" / "failed").glob("*.json"))  # first attempts: nothing retried
    _check_tables(results, recs)


def test_cancelled_sweep_is_finished_by_the_same_command(cluster, tmp_path):
    """Eight jobs; once two records have landed the whole array is cancelled with scancel (jobs killed mid-run,
    others never started). The same command, run again, finishes the sweep: every record present once, and the
    runs finished before the cancel not run again (their records untouched)."""
    name, results, work, log = _sweep_places(tmp_path)
    cmd = _sweep_cmd(results, name, "estimator=ls,lssvm", "seed=0,1,2,3")
    n_runs = 8

    rc_first = _cancel_once_two_records_land(cmd, work, log, name, results)
    assert rc_first != 0, "a sweep whose jobs were cancelled must not end as a success"

    before = _records(results)
    assert 2 <= len(before) < n_runs, f"the cancel did not land half way: {len(before)} of {n_runs} records"
    assert all(r.get("status") == "ok" for r in before.values()), before

    rc = _run_sweep(cmd, work, log, name)
    assert rc == 0, _tail(log)
    after = _records(results)
    assert len(after) == n_runs and len({r["run_id"] for r in after.values()}) == n_runs, sorted(after)
    assert all(r["status"] == "ok" for r in after.values()), [r.get("error") for r in after.values()]
    # not recomputed: the records finished before the cancel are the same records, byte for byte in content
    for p, r in before.items():
        assert after[p] == r, f"{p} was rewritten by the re-run"
    assert not list((results / "records" / "failed").glob("*.json"))
    assert {(r["config"]["estimator"]["name"], r["seed"]) for r in after.values()} == {
        (e, s) for e in ("ls", "lssvm") for s in range(4)}
    # the re-run's jobs said so, each in its own log (the app's line for a run found finished)
    logs = "\n".join(p.read_text(errors="replace") for p in results.glob("logs/sweeps/*/*/.submitit/*/*_log.*"))
    assert logs.count("(already finished, resumed)") == len(before), logs[-3000:]
    _check_tables(results, after)


# ------------------------------------------------------------------------------------------ grouped runs
def _task_logs(results: Path) -> dict[str, str]:
    """Each array task's output (submitit's <array>_<index>/<array>_<index>_0_log.out, under the sweep's folder in
    the results folder's logs), by task."""
    return {p.parent.name: p.read_text(errors="replace")
            for p in results.glob("logs/sweeps/*/*/.submitit/*_*/*_0_log.out")}


def test_grouped_sweep_lands_every_record_once_and_records_a_failing_job(cluster, tmp_path):
    """``hydra/launcher=slurm_grouped``: six jobs (ls, lssvm and ridge on two seeds; ridge given an
    upside-down grid of alphas fails when it fits) in two array tasks of three jobs, each task running its jobs on a pool of two
    worker processes. Every record lands once, the two ridge runs are recorded as failed while the four others
    finish ok, the sweep ends with its count of failed runs (exit status 1) and the tables are rebuilt."""
    name, results, work, log = _sweep_places(tmp_path)
    cmd = _sweep_cmd(results, name, "estimator=ls,lssvm,ridge", "seed=0,1", "+estimator_overrides.ridge.alphas=[10.0,1.0,3]",
                     "hydra.launcher.jobs_per_task=3", "hydra.launcher.cpus_per_task=2", launcher="slurm_grouped")
    rc = _run_sweep(cmd, work, log, name)
    out = log.read_text(errors="replace")
    assert rc == 1 and "[study] sweep finished: 6 jobs, 2 failed, 4 ok" in out, _tail(log)

    recs = _records(results)
    assert len(recs) == 6, f"{len(recs)} records: {sorted(recs)}\n{_tail(log)}"
    assert len({r["run_id"] for r in recs.values()}) == 6
    by = {(r["config"]["estimator"]["name"], r["seed"]): r for r in recs.values()}
    assert set(by) == {(e, s) for e in ("ls", "lssvm", "ridge") for s in (0, 1)}
    for (est, seed), r in by.items():
        if est == "ridge":
            assert r["status"] == "failed" and "alphas must be a number or [lo, hi, num]" in r["error"]
        else:
            assert r["status"] == "ok" and r["params"], r.get("error")
    # one array of two tasks, each of which ran three jobs (its [study] job lines)
    logs = _task_logs(results)
    assert len(logs) == 2 and len({t.split("_")[0] for t in logs}) == 1, sorted(logs)
    assert sorted(t.count("[study] job ") for t in logs.values()) == [3, 3], logs
    jobs = sorted(int(m) for t in logs.values() for m in re.findall(r"\[study\] job (\d+)/6", t))
    assert jobs == [1, 2, 3, 4, 5, 6]
    # each task ran its jobs on a pool of two worker processes (the task's own line), one BLAS thread each
    assert all("study_slurm task: 3 jobs on 2 worker processes" in t for t in logs.values()), logs
    assert all(r["provenance"]["omp_num_threads"] == 1 for r in recs.values())
    _check_tables(results, recs)


def test_grouped_cancelled_sweep_is_finished_by_the_same_command(cluster, tmp_path):
    """Eight jobs in four array tasks of two (one CPU each: the jobs run in the task's own process, one after the
    other); once two records have landed the array is cancelled. The same command finishes the sweep: every record
    once, and the runs finished before the cancel not run again."""
    name, results, work, log = _sweep_places(tmp_path)
    cmd = _sweep_cmd(results, name, "estimator=ls,lssvm", "seed=0,1,2,3", "hydra.launcher.jobs_per_task=2",
                     launcher="slurm_grouped")
    n_runs = 8
    rc_first = _cancel_once_two_records_land(cmd, work, log, name, results)
    assert rc_first != 0, "a sweep whose tasks were cancelled must not end as a success"
    before = _records(results)
    assert 2 <= len(before) < n_runs, f"the cancel did not land half way: {len(before)} of {n_runs} records"
    assert all(r.get("status") == "ok" for r in before.values()), before
    first_logs = set(_task_logs(results))

    rc = _run_sweep(cmd, work, log, name)
    assert rc == 0, _tail(log)
    after = _records(results)
    assert len(after) == n_runs and all(r["status"] == "ok" for r in after.values()), sorted(after)
    for p, r in before.items():
        assert after[p] == r, f"{p} was rewritten by the re-run"
    logs = {k: v for k, v in _task_logs(results).items() if k not in first_logs}
    assert len(logs) == 4 and sorted(t.count("[study] job ") for t in logs.values()) == [2, 2, 2, 2], sorted(logs)
    assert "".join(logs.values()).count("(already finished, resumed)") == len(before)
    _check_tables(results, after)
