"""The results store: stable run ids, atomic strict writes, resume, failures recorded, two processes writing
and collecting at once, corrupt records skipped, the CLI."""
import json
import math
import multiprocessing as mp
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from study.run.executor import run_guarded
from study.store import (NON_SCIENTIFIC_KEYS, ResultsFolderError, ResultStore, provenance, read_table, run_id,
                         validate_record)

REPO = Path(__file__).resolve().parents[2]


def _conf(**over):
    conf = {"seed": 0, "vessel": {"name": "kvlcc2", "L": 320.0}, "model": {"name": "mmg_hull"},
            "estimator": {"name": "ls", "params": {}}, "structure": {"name": "central"},
            "noise": {"name": "low", "level": 0.01}, "maneuvers": {"train": ["zz10", "zz20"]},
            "depth": {"h_T": None}, "results_dir": "/somewhere", "progress": True}
    conf.update(over)
    return conf


def _result(value=1.0):
    return {"metrics": {"drift_median": 0.01, "n_samples": 100, "flag": True},
            "params": [{"equation": "X", "name": "Xvv", "estimate": value, "truth": 0.5},
                       {"equation": "Y", "name": "Yv", "estimate": -0.3, "truth": None, "std": 0.1},
                       {"equation": "N", "name": "Nr", "estimate": 0.2, "truth": 0.0, "ci_low": 0.1, "ci_high": 0.3}],
            "timings": {"fit": 0.1}}


def _record(conf, status="ok", error=None, **over):
    rec = {"run_id": run_id(conf), "status": status, "config": conf, **_result(), "seed": conf["seed"],
           "error": error, "started": "2024-01-01T00:00:00+00:00", "finished": "2024-01-01T00:00:01+00:00"}
    rec.update(over)
    return rec


# ------------------------------------------------------------------------------------------------ run_id

def test_run_id_stable_and_scientific():
    a = _conf()
    b = dict(reversed(list(a.items())))
    b["vessel"] = dict(reversed(list(a["vessel"].items())))
    assert run_id(a) == run_id(b)
    assert len(run_id(a)) == 16 and int(run_id(a), 16) >= 0
    # non-scientific keys are ignored, whatever their value
    c = dict(a, results_dir="/elsewhere", out="x.csv", launcher="slurm", progress=False, n_jobs=8,
             hydra={"run": {"dir": "outputs/now"}})
    assert {"hydra", "results_dir", "out", "launcher", "progress", "n_jobs"} <= NON_SCIENTIFIC_KEYS
    assert run_id(c) == run_id(a)
    # any scientific change changes it
    assert run_id(_conf(seed=1)) != run_id(a)
    assert run_id(_conf(noise={"name": "low", "level": 0.02})) != run_id(a)
    assert run_id(_conf(maneuvers={"train": ["zz20", "zz10"]})) != run_id(a)
    # and it is the same in another process (no hash randomisation)
    code = ("import json,sys; from study.store import run_id; "
            "print(run_id(json.loads(sys.argv[1])))")
    out = subprocess.run([sys.executable, "-c", code, json.dumps(a)], capture_output=True, text=True, cwd=REPO)
    assert out.stdout.strip() == run_id(a), out.stderr


def test_provenance_fields_and_cache():
    p = provenance()
    for k in ("git_rev", "python", "numpy", "pandas", "hydra-core", "platform", "hostname", "threads"):
        assert k in p
    assert p["git_rev"] == "unknown" or len(p["git_rev"].split("-")[0]) == 40
    p["hostname"] = "changed"
    assert provenance()["hostname"] != "changed"  # callers get a copy of the cached value


# ------------------------------------------------------------------------------------------------ write

def test_validate_rejects_malformed():
    conf = _conf()
    with pytest.raises(ValueError, match="status"):
        validate_record(_record(conf, status="done"))
    with pytest.raises(ValueError, match="run_id"):
        validate_record(_record(conf, run_id="0" * 16))
    with pytest.raises(ValueError, match="lacks 'truth'"):
        validate_record(_record(conf, params=[{"equation": "X", "name": "a", "estimate": 1.0}]))
    with pytest.raises(ValueError, match="scalar"):
        validate_record(_record(conf, metrics={"a": [1, 2]}))
    with pytest.raises(ValueError, match="reason"):
        validate_record(_record(conf, status="failed", error=None))
    with pytest.raises(ValueError, match="missing field 'seed'"):
        validate_record({k: v for k, v in _record(conf).items() if k != "seed"})


def test_write_is_atomic_and_strict(tmp_path):
    store = ResultStore(tmp_path)
    conf = _conf()
    rec = _record(conf)
    path = store.write(rec)
    assert path == tmp_path / "records" / f"{rec['run_id']}.json"
    saved = json.loads(path.read_text())
    assert saved["provenance"]["python"] and saved["config"] == conf and store.finished(rec["run_id"])
    # no temp file left behind, only the record (the per-run lock lives in a hidden folder)
    assert sorted(p.name for p in (tmp_path / "records").iterdir() if not p.name.startswith(".")) == [path.name]
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match=path.name):
        store.write(_record(conf, metrics={"drift_median": 99.0}))
    with pytest.raises(FileExistsError):
        store.write(_record(conf, status="failed", error="boom"))
    assert path.read_bytes() == before
    # a failed write (unserialisable would be caught before; here an invalid record) changes nothing either
    with pytest.raises(ValueError):
        store.write(_record(conf, status="bogus"))
    assert path.read_bytes() == before
    # explicit overwrite is allowed
    store.write(_record(conf, metrics={"drift_median": 99.0}), overwrite=True)
    assert json.loads(path.read_text())["metrics"] == {"drift_median": 99.0}


def test_failed_record_replaced_and_kept(tmp_path):
    store = ResultStore(tmp_path)
    conf = _conf(seed=3)
    rid = run_id(conf)
    store.write(_record(conf, status="failed", error="Traceback ...\nValueError: first"),
                artefacts={"log.txt": b"first attempt"})
    assert not store.finished(rid)
    store.write(_record(conf, status="failed", error="Traceback ...\nValueError: second"))
    store.write(_record(conf), artefacts={"sub/data.bin": b"\x00\x01"})
    assert store.finished(rid)
    assert json.loads(store.record_path(rid).read_text())["status"] == "ok"
    kept = sorted((tmp_path / "records" / "failed").glob(f"{rid}.*.json"))
    assert len(kept) == 2
    errors = sorted(json.loads(p.read_text())["error"].splitlines()[-1] for p in kept)
    assert errors == ["ValueError: first", "ValueError: second"]
    # the artefacts of the failed attempt are kept too; the ok run has its own folder
    assert (store.artefact_dir(rid) / "sub" / "data.bin").read_bytes() == b"\x00\x01"
    old = list((tmp_path / "artefacts" / "failed").glob(f"{rid}.*/log.txt"))
    assert len(old) == 1 and old[0].read_bytes() == b"first attempt"
    runs, _ = store.collect()
    assert len(runs) == 1 and runs.loc[0, "status"] == "ok"


# ------------------------------------------------------------------------------------------- run_guarded

def test_run_guarded_resume_failure_skip_artefacts(tmp_path):
    store = ResultStore(tmp_path)
    calls = {"n": 0}
    src = tmp_path / "big.npy"
    src.write_bytes(b"x" * 1000)

    def fn():
        calls["n"] += 1
        return {**_result(), "artefacts": {"trace.npy": src, "note.txt": b"hello"}}

    conf = _conf()
    rec = run_guarded(store, conf, fn, seed=0)
    assert rec["status"] == "ok" and calls["n"] == 1 and not rec.get("resumed")
    assert rec["timings"]["wall"] >= 0 and rec["timings"]["fit"] == 0.1
    assert rec["artefacts"] == ["note.txt", "trace.npy"]
    assert (store.artefact_dir(rec["run_id"]) / "trace.npy").stat().st_size == 1000 and not src.exists()
    again = run_guarded(store, dict(conf, progress=False), fn, seed=0)  # a non-scientific change: same run
    assert again["resumed"] is True and calls["n"] == 1 and again["run_id"] == rec["run_id"]

    # a failure is recorded with its traceback and not raised
    def boom():
        calls["n"] += 1
        raise ValueError("h/T = 1.0 is below the range of every formula")

    bad = run_guarded(store, _conf(seed=5), boom, seed=5)
    assert bad["status"] == "failed" and "Traceback" in bad["error"] and "h/T = 1.0" in bad["error"]
    assert bad["metrics"] == {} and bad["params"] == [] and "wall" in bad["timings"]
    assert not store.finished(bad["run_id"])
    # ... and rerun next time (it failed), here successfully
    good = run_guarded(store, _conf(seed=5), lambda: _result(), seed=5)
    assert good["status"] == "ok" and not good.get("resumed")
    assert len(list((tmp_path / "records" / "failed").glob("*.json"))) == 1

    # a malformed result is a failure too
    bad2 = run_guarded(store, _conf(seed=6), lambda: {"metrics": {"a": [1]}, "params": [], "timings": {}}, seed=6)
    assert bad2["status"] == "failed" and "scalar" in bad2["error"]

    # skipped: recorded with its reason, and counts as finished
    skip = {"n": 0}

    def nonsense():
        skip["n"] += 1
        return {"status": "skipped", "error": "AUV has no rudder", "metrics": {}, "params": [], "timings": {}}

    s = run_guarded(store, _conf(seed=7), nonsense, seed=7)
    assert s["status"] == "skipped" and s["error"] == "AUV has no rudder"
    assert run_guarded(store, _conf(seed=7), nonsense, seed=7)["resumed"] and skip["n"] == 1

    runs, params = store.collect()
    assert dict(runs["status"].value_counts()) == {"ok": 2, "failed": 1, "skipped": 1}
    assert runs["run_id"].is_unique and len(params) == 6


# ------------------------------------------------------------------------------------------------ tables

def test_collect_columns(tmp_path):
    store = ResultStore(tmp_path)
    rec = run_guarded(store, _conf(), lambda: _result(0.6), seed=0)
    # a second run whose config differs in shape (a leaf that is a list here and a scalar there)
    run_guarded(store, _conf(seed=1, depth={"h_T": 1.5}, extra=[1, 2]), lambda: _result(0.4), seed=1)
    run_guarded(store, _conf(seed=2, extra="text"), lambda: _result(0.5), seed=2)
    runs, params = store.collect()
    for c in ("run_id", "status", "error", "seed", "started", "finished", "wall_time", "prov_git_rev",
              "prov_python", "prov_numpy", "prov_hostname", "prov_threads", "cfg_vessel.name", "cfg_noise.level",
              "cfg_maneuvers.train", "m_drift_median", "m_n_samples", "t_fit", "t_wall"):
        assert c in runs, c
    assert "cfg_hydra" not in runs and not any(c.startswith("cfg_hydra.") for c in runs)
    assert json.loads(runs.loc[0, "cfg_maneuvers.train"]) == ["zz10", "zz20"]
    assert runs["wall_time"].notna().all() and str(runs["started"].dtype).startswith("datetime64")
    row = params[(params.run_id == rec["run_id"]) & (params.name == "Xvv")].iloc[0]
    assert row["rel_error"] == pytest.approx((0.6 - 0.5) / 0.5) and row["abs_error"] == pytest.approx(0.1)
    assert row["cfg_vessel.name"] == "kvlcc2" and row["cfg_noise.level"] == 0.01
    assert math.isnan(params[params.name == "Yv"]["rel_error"].iloc[0])  # truth unknown
    assert math.isnan(params[params.name == "Nr"]["rel_error"].iloc[0])  # truth zero
    assert params[params.name == "Nr"]["ci_high"].iloc[0] == 0.3
    for c in ("run_id", "equation", "name", "estimate", "truth", "rel_error", "abs_error", "ci_low", "ci_high",
              "std", "cfg_model.name", "cfg_estimator.name", "cfg_structure.name"):
        assert c in params, c
    # the files round-trip and load() reads them
    r2, p2 = store.load()
    assert len(r2) == 3 and len(p2) == 9 and list(r2.columns) == list(runs.columns)


def test_collect_empty_and_load_collects(tmp_path):
    store = ResultStore(tmp_path / "fresh")
    runs, params = store.load()
    assert len(runs) == 0 and len(params) == 0 and store.runs_path.exists() and store.params_path.exists()
    assert "run_id" in read_table(store.runs_path)


def test_collect_skips_corrupt_record(tmp_path):
    store = ResultStore(tmp_path)
    run_guarded(store, _conf(), lambda: _result(), seed=0)
    bad = tmp_path / "records" / "0123456789abcdef.json"
    bad.write_text('{"run_id": "0123456789abcdef", "status": "ok", "config": {"a"')  # truncated
    empty = tmp_path / "records" / "fedcba9876543210.json"
    empty.write_text("")
    with pytest.warns(RuntimeWarning) as w:
        runs, _ = store.collect()
    msgs = " ".join(str(x.message) for x in w)
    assert bad.name in msgs and empty.name in msgs
    assert len(runs) == 1
    # a torn record does not count as finished, and the next attempt keeps it under failed/
    assert not store.finished("0123456789abcdef")


# ----------------------------------------------------------------------------------- two processes at once

N_OWN, N_SHARED = 50, 10


def _writer(root, who, barrier, won):
    store = ResultStore(root)
    barrier.wait()  # start together so the shared runs really race
    for i in range(N_OWN + N_SHARED):
        if i < N_SHARED:
            conf = _conf(seed=10_000 + i)  # the same run in both processes
        else:
            conf = _conf(seed=1000 * (who + 1) + i)
        rec = run_guarded(store, conf, lambda: _result(float(who)), seed=conf["seed"])
        assert rec["status"] == "ok", rec.get("error")
        if i < N_SHARED and not rec.get("resumed"):
            won.put(rec["run_id"])  # this process's record is the one that stands
    _exit_child(won)


def _exit_child(queue):
    """Flush the queue, then leave without interpreter finalisation: pyarrow's C++ thread pool can abort a
    spawned child at exit ("terminate called without an active exception", seen once in 20 CI-like runs),
    which would fail the test for a reason that has nothing to do with the store."""
    queue.close()
    queue.join_thread()
    os._exit(0)


def _collector(root, stop, errors):
    store = ResultStore(root)
    n = 0
    while not stop.is_set() or n < 2:
        try:
            store.collect()
            read_table(store.runs_path)
            read_table(store.params_path)
        except Exception as e:  # pragma: no cover - reported to the parent
            errors.put(repr(e))
            break  # one report is enough (and an unread flood would keep this process from exiting)
        n += 1
    _exit_child(errors)


@pytest.mark.slow
def test_two_processes_write_and_collect(tmp_path):
    ctx = mp.get_context("spawn")
    root = str(tmp_path / "results")
    ResultStore(root).collect()  # the tables exist from the start, so every read below must succeed
    barrier, stop, errors, won = ctx.Barrier(2), ctx.Event(), ctx.Queue(), ctx.Queue()
    writers = [ctx.Process(target=_writer, args=(root, w, barrier, won), daemon=True) for w in range(2)]
    collectors = [ctx.Process(target=_collector, args=(root, stop, errors), daemon=True) for _ in range(2)]
    try:
        for p in collectors + writers:
            p.start()
        store = ResultStore(root)
        reads = 0
        deadline = time.time() + 120
        while any(p.is_alive() for p in writers) and time.time() < deadline:
            runs = read_table(store.runs_path)  # never torn, whatever the collectors are doing
            read_table(store.params_path)
            assert runs["run_id"].is_unique
            reads += 1
        winners = []  # drained before joining: a child exits only once its queue is flushed
        while len(winners) < N_SHARED + 5:
            try:
                winners.append(won.get(timeout=2))
            except Exception:
                break
        for p in writers:
            p.join(timeout=max(1, deadline - time.time()))
        stop.set()
        for p in collectors:
            p.join(timeout=60)
    finally:
        for p in writers + collectors:  # never leave a child behind, even when an assert fired
            if p.is_alive():
                p.terminate()
                p.join(5)
    assert all(p.exitcode == 0 for p in writers + collectors), [p.exitcode for p in writers + collectors]
    assert errors.empty(), errors.get(timeout=5)
    assert reads > 0
    # each shared run was claimed by exactly one process (the other resumed or lost the race cleanly)
    assert len(winners) == N_SHARED and len(set(winners)) == N_SHARED

    records = sorted((tmp_path / "results" / "records").glob("*.json"))
    assert len(records) == 2 * N_OWN + N_SHARED
    parsed = [json.loads(p.read_text()) for p in records]
    assert all(r["status"] == "ok" for r in parsed)
    assert {r["run_id"] for r in parsed} == {p.stem for p in records}
    assert not (tmp_path / "results" / "records" / "failed").exists()
    assert not list((tmp_path / "results").rglob("*.tmp"))
    runs, params = store.collect()
    assert len(runs) == 110 and runs["run_id"].is_unique and (runs["status"] == "ok").all()
    assert len(params) == 3 * 110


# ------------------------------------------------------------------------------------------------------ CLI

@pytest.mark.slow
def test_cli_rebuild_and_show(tmp_path):
    store = ResultStore(tmp_path / "res")
    run_guarded(store, _conf(), lambda: _result(), seed=0)
    run_guarded(store, _conf(seed=1), lambda: 1 / 0, seed=1)
    run_guarded(store, _conf(seed=2), lambda: {"status": "skipped", "error": "no sense", "metrics": {},
                                                "params": [], "timings": {}}, seed=2)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.run([sys.executable, "-m", "study", "results", "rebuild", "--root", str(tmp_path / "res")],
                       capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "3 runs (1 ok, 1 failed, 1 skipped)" in p.stdout and "runs.parquet" in p.stdout
    runs = pd.read_parquet(tmp_path / "res" / "runs.parquet")
    assert len(runs) == 3 and len(pd.read_parquet(tmp_path / "res" / "params.parquet")) == 3
    p = subprocess.run([sys.executable, "-m", "study", "results", "show", "--root", str(tmp_path / "res")],
                       capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "1 ok, 1 failed, 1 skipped" in p.stdout and "ZeroDivisionError" in p.stdout


# ------------------------------------------------------------------------ a store that never stalls or lies

def _write_raw(store, name, rec):
    store.records_dir.mkdir(parents=True, exist_ok=True)
    path = store.records_dir / name
    path.write_text(json.dumps(rec))
    return path


def _cli(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "study", "results", *args], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=300)


@pytest.mark.slow
def test_malformed_misnamed_and_unknown_status_records_are_skipped_named_and_counted(tmp_path):
    store = ResultStore(tmp_path / "res")
    good = run_guarded(store, _conf(), lambda: _result(), seed=0)
    # valid JSON of the wrong shape: this stalled rebuild and show with an AttributeError naming no file
    bad_conf = _conf(seed=1)
    oops = _write_raw(store, f"{run_id(bad_conf)}.json", _record(bad_conf, params="oops"))
    status_conf = _conf(seed=2)
    done = _write_raw(store, f"{run_id(status_conf)}.json", _record(status_conf, status="done"))
    prov_conf = _conf(seed=3)
    prov = _write_raw(store, f"{run_id(prov_conf)}.json", _record(prov_conf, provenance="laptop"))
    # a copy of a good record under another name: it would be a second row of one run
    copy = store.records_dir / "copy of record.json"
    copy.write_text(store.record_path(good["run_id"]).read_text())
    with pytest.warns(RuntimeWarning) as w:
        runs, params = store.collect()
    msgs = " ".join(str(x.message) for x in w)
    for p in (oops, done, prov, copy):
        assert p.name in msgs
    assert "params must be a list" in msgs and "status 'done'" in msgs and "does not match its run_id" in msgs
    assert len(runs) == 1 and runs.loc[0, "run_id"] == good["run_id"] and len(params) == 3
    assert sorted(p.name for p, _ in store.report.skipped) == sorted(p.name for p in (oops, done, prov, copy))
    # the resume path does not take a malformed 'ok' record for a finished run: it is recomputed, and kept
    again = run_guarded(store, bad_conf, lambda: _result(), seed=1)
    assert again["status"] == "ok" and not again.get("resumed")
    kept = list(store.failed_dir.glob(f"{run_id(bad_conf)}.*.json"))
    assert len(kept) == 1 and json.loads(kept[0].read_text())["params"] == "oops"
    # the CLI names each file and counts them; --strict turns them into exit status 1
    p = _cli("rebuild", "--root", str(store.root), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "2 runs" in p.stdout and "3 record(s) left out" in p.stdout
    for f in (done, prov, copy):
        assert f.name in p.stderr
    assert _cli("rebuild", "--strict", "--root", str(store.root), cwd=tmp_path).returncode == 1
    p = _cli("show", "--root", str(store.root), cwd=tmp_path)
    assert p.returncode == 0 and "3 record(s) left out" in p.stdout and done.name in p.stderr


def test_unknown_status_is_refused_on_write(tmp_path):
    store = ResultStore(tmp_path)
    with pytest.raises(ValueError, match="status 'done'"):
        store.write(_record(_conf(), status="done"))
    assert not store.record_path(run_id(_conf())).exists()


def test_rebuild_never_replaces_a_table_with_an_empty_one(tmp_path):
    store = ResultStore(tmp_path / "res")
    for s in range(3):
        run_guarded(store, _conf(seed=s), lambda: _result(), seed=s)
    store.collect()
    before = store.runs_path.read_bytes()
    # the records are gone (a wrong --root holding someone's tables, a deleted folder): the table stays
    os.rename(store.records_dir, tmp_path / "elsewhere")
    with pytest.raises(ResultsFolderError, match=r"refusing to replace .*runs.parquet \(3 runs\)"):
        store.collect()
    assert store.runs_path.read_bytes() == before
    p = _cli("rebuild", "--root", str(store.root), cwd=tmp_path)
    assert p.returncode == 1 and "refusing to replace" in p.stderr and "--allow-empty" in p.stderr
    assert store.runs_path.read_bytes() == before
    # only malformed records left: the same refusal, which says so
    _write_raw(store, "0123456789abcdef.json", {"run_id": "0123456789abcdef", "status": "ok"})
    with pytest.warns(RuntimeWarning), pytest.raises(ResultsFolderError, match="1 malformed record"):
        store.collect()
    # asked for explicitly, it is done
    p = _cli("rebuild", "--allow-empty", "--root", str(store.root), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert len(read_table(store.runs_path)) == 0


def _crash_while_writing(root, rid, ready):
    """A writer that dies mid-run: it holds the run's claim and has a temp record and table half written."""
    from study.store.files import tmp_path as _tmp_path

    store = ResultStore(root)
    claim = store.claim(rid)
    assert claim.acquire(wait=False)
    store.records_dir.mkdir(parents=True, exist_ok=True)
    _tmp_path(store.records_dir, f"{rid}.json").write_text('{"run_id": "feedf')
    _tmp_path(store.root, "runs.parquet").write_bytes(b"PAR1")
    ready.set()
    time.sleep(600)


def test_crash_leftovers_are_reported_and_cleaned_and_a_dead_claim_is_recovered(tmp_path):
    from study.store.files import tmp_path as _tmp_path

    root = tmp_path / "res"
    store = ResultStore(root)
    run_guarded(store, _conf(), lambda: _result(), seed=0)
    victim = _conf(seed=777)
    rid = run_id(victim)
    ctx = mp.get_context("spawn")
    ready = ctx.Event()
    child = ctx.Process(target=_crash_while_writing, args=(str(root), rid, ready), daemon=True)
    child.start()
    try:
        assert ready.wait(120)
        # while the writer lives, its files are its own and its run is claimed: a sweep leaves it to it
        assert not [p for p, _, removable in store.leftovers() if removable]
        busy = run_guarded(store, victim, lambda: _result(), seed=777, wait=False)
        assert busy["status"] == "claimed" and busy["claimed_by"]["pid"] == child.pid
        os.kill(child.pid, 9)  # SIGKILL: no cleanup of any kind
        child.join(30)
    finally:
        if child.is_alive():
            child.kill()
    mine = _tmp_path(store.records_dir, "x.json")  # a live writer's (this process's) temp file: kept
    mine.write_text("{")
    old = store.records_dir / ".abc.json.4242.0123456789ab.tmp"  # the earlier naming, two hours old: removed
    old.write_text("{")
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    foreign = store.records_dir / ".abc.json~othernode~77~0123456789ab.tmp"  # another host's, recent: kept
    foreign.write_text("{")
    art = _tmp_path(store.artefacts_root, rid)  # a half-built artefact folder of the dead process
    art.mkdir(parents=True)
    (art / "trace.csv").write_text("t\n")
    os.rename(art, art.with_name(art.name.replace(f"~{os.getpid()}~", f"~{child.pid}~")))
    # `show` reports them without touching anything
    p = _cli("show", "--root", str(root), cwd=tmp_path)
    assert p.returncode == 0 and "crash leftover" in p.stderr and old.name in p.stderr and old.exists()
    runs, _ = store.collect()
    removed = {p.name for p, _ in store.report.removed}
    kept = {p.name for p, _ in store.report.kept}
    assert any(n.startswith(f".{rid}.json~") for n in removed)
    assert any(n.startswith(".runs.parquet~") for n in removed)
    assert any(n.startswith(f".{rid}~") for n in removed)  # the artefact folder
    assert old.name in removed and f"{rid}.json" in removed  # the dead process's claim
    assert mine.name in kept and foreign.name in kept
    assert mine.exists() and foreign.exists() and not old.exists()
    assert any("has ended" in why for _, why in store.report.removed)
    assert any("removed crash leftover" in line for line in store.report.lines())
    assert len(runs) == 1
    # the claim of the killed process is no obstacle: its run is computed at once, not left to a dead owner
    rec = run_guarded(store, victim, lambda: _result(), seed=777, wait=False)
    assert rec["status"] == "ok" and not rec.get("resumed")


def test_an_unwritable_results_folder_is_refused(tmp_path):
    blocker = tmp_path / "a file"
    blocker.write_text("not a folder")
    with pytest.raises(ResultsFolderError, match="not writable.*results_dir"):
        ResultStore(blocker / "results").check_writable()
    ResultStore(tmp_path / "fine").check_writable()
    assert not [p for p in (tmp_path / "fine").rglob("*") if p.is_file()]  # the probe leaves nothing behind
    if os.geteuid() != 0:  # root writes through permission bits
        ro = tmp_path / "ro"
        (ro / "records").mkdir(parents=True)
        os.chmod(ro / "records", 0o555)
        try:
            with pytest.raises(ResultsFolderError, match="not writable"):
                ResultStore(ro).check_writable()
        finally:
            os.chmod(ro / "records", 0o755)


def _run_app(args, cwd, results):
    env = dict(os.environ, PYTHONPATH=str(REPO), NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env.pop("STUDY_RESULTS_DIR", None)
    return subprocess.run([sys.executable, "-m", "study", *args, f"results_dir={results}"], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=900)


# a run the store records in seconds: a regression estimator on output_error is 'skipped' before simulating
_QUICK = ["experiment=tiny", "structure=output_error", "noise=none"]


def test_app_refuses_an_unwritable_folder_before_any_job(tmp_path):
    blocker = tmp_path / "a file"
    blocker.write_text("")
    p = _run_app(["-m", *_QUICK, "seed=0,1"], tmp_path, blocker / "results")
    assert p.returncode == 2 and "not writable" in p.stderr, p.stderr[-2000:]
    assert "#0" not in p.stdout + p.stderr  # Hydra launched no job
    assert len(p.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_app_resumes_other_spellings_and_a_failed_collect_exits_nonzero(tmp_path):
    results = tmp_path / "results"
    p = _run_app(_QUICK, tmp_path, results)
    assert p.returncode == 0, p.stderr[-2000:]
    assert len(list((results / "records").glob("*.json"))) == 1
    # the table cannot be written (here: a folder in its place); the run itself is found under another spelling
    (results / "runs.parquet").unlink()
    (results / "runs.parquet").mkdir()
    p = _run_app([*_QUICK, "noise.level=0", "vessel.particulars.Lpp=320"], tmp_path, results)
    assert "(already finished, resumed)" in p.stderr + p.stdout
    assert p.returncode == 1 and "results table was not rebuilt" in p.stderr, p.stderr[-2000:]
    assert len(list((results / "records").glob("*.json"))) == 1


def test_failed_collect_callback_exits_nonzero(tmp_path, capsys):
    from omegaconf import OmegaConf

    from study.commands.app import CollectResults

    store = ResultStore(tmp_path)
    run_guarded(store, _conf(), lambda: _result(), seed=0)
    store.runs_path.mkdir()
    with pytest.raises(SystemExit) as e:
        CollectResults()._collect(OmegaConf.create({"results_dir": str(tmp_path)}))
    assert e.value.code == 1 and "results table was not rebuilt" in capsys.readouterr().err
    # and an empty records folder beside a full table: refused, not emptied
    store.runs_path.rmdir()
    store.collect()
    os.rename(store.records_dir, tmp_path / "moved")
    with pytest.raises(SystemExit) as e:
        CollectResults()._collect(OmegaConf.create({"results_dir": str(tmp_path)}))
    assert e.value.code == 1 and "refusing to replace" in capsys.readouterr().err
    assert len(read_table(store.runs_path)) == 1


# ------------------------------------------------------------------------------------------ canonical run ids

def test_run_id_does_not_depend_on_how_numbers_are_spelt():
    import numpy as np

    base = _conf(noise={"name": "none", "level": 0.0}, sim={"duration_scale": 1.0})
    same = [_conf(noise={"name": "none", "level": 0}, sim={"duration_scale": 1}),
            _conf(noise={"name": "none", "level": -0.0}, sim={"duration_scale": np.float64(1.0)}),
            _conf(noise={"name": "none", "level": np.int64(0)}, sim={"duration_scale": 1.0}, seed=0.0)]
    for c in same:
        assert run_id(c) == run_id(base)
    # different science, or not a number, stays different
    for c in (_conf(noise={"name": "none", "level": 1e-12}, sim={"duration_scale": 1.0}),
              _conf(noise={"name": "none", "level": "0.0"}, sim={"duration_scale": 1.0}),
              _conf(noise={"name": "none", "level": False}, sim={"duration_scale": 1.0}),
              _conf(noise={"name": "none", "level": None}, sim={"duration_scale": 1.0})):
        assert run_id(c) != run_id(base)
    assert run_id(_conf(seed=2**53 + 1)) != run_id(_conf(seed=2**53))  # ints beyond a float's reach stay exact


def test_run_id_of_composed_spellings_and_explicit_defaults():
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from study.commands.app import CONF_DIR

    spellings = [["noise=none"], ["noise=none", "noise.level=0"], ["noise=none", "noise.level=0.0"],
                 ["noise=none", "sim.duration_scale=1"], ["noise=none", "depth=deep", "depth.formula=kijima_1990"],
                 ["noise=none", "vessel.particulars.Lpp=320", "seed=0", "estimator.params.rcond=null"]]
    ids = set()
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        for ov in spellings:
            conf = OmegaConf.to_container(compose(config_name="config", overrides=ov), resolve=True)
            ids.add(run_id(conf))
        other = OmegaConf.to_container(compose(config_name="config", overrides=["noise=low"]), resolve=True)
    assert len(ids) == 1 and run_id(other) not in ids


# --------------------------------------------------------------------------------------- resume knows the code

def _code(**components):
    comps = {"simulator": "s1", "model": "m1", "structure": "t1", "estimator": "e1", "pipeline": "p1", **components}
    return {"fingerprint": "/".join(f"{k}={v}" for k, v in sorted(comps.items())), "components": comps,
            "files": {}}


def test_code_change_invalidates_resume_and_force_reruns(tmp_path):
    store = ResultStore(tmp_path)
    calls = []

    def fn(v=1.0):
        calls.append(v)
        return _result(v)

    conf = _conf()
    first = run_guarded(store, conf, fn, seed=0, code=_code())
    assert first["code"] == _code() and len(calls) == 1
    assert run_guarded(store, conf, fn, seed=0, code=_code())["resumed"] and len(calls) == 1
    # an estimator fixed since: the run is computed again and the old record kept aside
    fixed = run_guarded(store, conf, lambda: fn(2.0), seed=0, code=_code(estimator="e2"))
    assert not fixed.get("resumed") and calls == [1.0, 2.0] and fixed["code"]["components"]["estimator"] == "e2"
    aside = list(store.superseded_dir.glob("*.json"))
    assert len(aside) == 1 and json.loads(aside[0].read_text())["code"] == _code()
    # resume=config takes any finished record; force recomputes even an up-to-date one
    assert run_guarded(store, conf, fn, seed=0, code=_code(model="m9"), resume="config")["resumed"]
    forced = run_guarded(store, conf, lambda: fn(3.0), seed=0, code=_code(estimator="e2"), force=True)
    assert not forced.get("resumed") and calls[-1] == 3.0 and len(list(store.superseded_dir.glob("*.json"))) == 2
    assert store.read(run_id(conf))["params"][0]["estimate"] == 3.0
    with pytest.raises(ValueError, match="resume='always'"):
        run_guarded(store, conf, fn, seed=0, resume="always")


def test_the_table_marks_rows_made_by_other_code(tmp_path):
    from study.store import fingerprint

    store = ResultStore(tmp_path)
    now = run_guarded(store, _conf(seed=1), lambda: _result(), seed=1)  # the current code's fingerprint
    assert now["code"] == fingerprint.code_fingerprint(_conf(seed=1))
    current = now["code"]["components"]
    run_guarded(store, _conf(seed=2), lambda: _result(), seed=2,
                code={**now["code"], "fingerprint": "older", "components": {**current, "estimator": "older"}})
    _write_raw(store, f"{run_id(_conf(seed=3))}.json", _record(_conf(seed=3)))  # written before fingerprints
    runs, _ = store.collect()
    by_seed = runs.set_index("seed")
    assert bool(by_seed.loc[1, "code_current"]) and by_seed.loc[1, "code_changed"] == ""
    assert not bool(by_seed.loc[2, "code_current"]) and by_seed.loc[2, "code_changed"] == "estimator"
    assert not bool(by_seed.loc[3, "code_current"]) and by_seed.loc[3, "code_changed"] == "unknown"
    assert by_seed.loc[1, "code_fingerprint"] == now["code"]["fingerprint"]
    assert store.report.stale == 2 and any("changed since" in line for line in store.report.lines())


def test_records_hashed_on_bytes_are_restamped_only_where_the_code_is_unchanged(tmp_path, capsys):
    """A record written before the executed-source fingerprint holds its files' bytes' fingerprint: restamped
    when today's bytes are the same (the same code ran), left for a re-run when they are not."""
    from study.store import fingerprint
    from study.commands.results import main

    store = ResultStore(tmp_path)
    now = run_guarded(store, _conf(seed=1), lambda: _result(), seed=1)["code"]
    legacy = {k: now["bytes"][k] for k in ("fingerprint", "components")}
    for seed, code in ((2, legacy), (3, {**legacy, "fingerprint": "older",
                                          "components": {**legacy["components"], "estimator": "older"}})):
        run_guarded(store, _conf(seed=seed), lambda: _result(), seed=seed, code=code)
    assert main(["restamp", "--root", str(tmp_path)]) == 0
    assert "1 record(s) restamped; 1 computed by code that has changed since" in capsys.readouterr().out
    two, three = store.read(run_id(_conf(seed=2))), store.read(run_id(_conf(seed=3)))
    assert two["code"]["scheme"] == fingerprint.SCHEME and two["code"]["restamped_from"] == legacy["fingerprint"]
    assert not fingerprint.changed_components(two["code"], now)
    assert "scheme" not in three["code"]
    runs = pd.read_parquet(store.runs_path).set_index("seed")
    assert bool(runs.loc[2, "code_current"]) and not bool(runs.loc[3, "code_current"])
    assert store.restamp(fingerprint.code_fingerprint, lambda a, b: True) == (1, 0)  # only 3 was left


@pytest.mark.slow
def test_fingerprint_follows_the_source_of_the_components_a_run_uses(tmp_path, monkeypatch):
    import shutil

    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from study.store import fingerprint
    from study.commands.app import CONF_DIR

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        confs = {ov: OmegaConf.to_container(compose(config_name="config", overrides=[ov] if ov else []),
                                            resolve=True)
                 for ov in ("", "estimator=svr_eps", "vessel=mariner", "model.effects=[current]")}
    copy = tmp_path / "repo"
    shutil.copytree(REPO / "study", copy / "study", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO / "conf", copy / "conf")
    monkeypatch.setattr(fingerprint, "REPO_ROOT", copy)
    fingerprint.clear_cache()
    try:
        def fps():
            fingerprint.clear_cache()
            return {k: fingerprint.code_fingerprint(c) for k, c in confs.items()}

        before = fps()
        files = before[""]["files"]
        assert "study/identify/estimators/linear.py" in files and "study/sim/mmg.py" in files
        assert "study/identify/estimators/svr.py" not in files and "study/sim/abkowitz.py" not in files
        assert not any(f.startswith(("study/store", "study/executor", "study/figures")) for f in files)
        assert "conf/maneuver/zigzag_10_10.yaml" in files  # read by name at run time
        assert any(f.startswith("study/identify/effects/") for f in before["model.effects=[current]"]["files"])
        assert not any(f.startswith(("study/doctor", "study/identify/effects/", "study/identify/with_effects"))
                       for f in files)  # identification with effects runs only with model.effects

        def edit(rel, text):
            p = copy / rel
            p.write_bytes(p.read_bytes() + text.encode())

        edit("study/identify/estimators/svr.py", "\n_FIX = 1\n")
        after = fps()
        assert after["estimator=svr_eps"]["fingerprint"] != before["estimator=svr_eps"]["fingerprint"]
        assert fingerprint.changed_components(before["estimator=svr_eps"], after["estimator=svr_eps"]) == \
            ["estimator"]
        for k in ("", "vessel=mariner", "model.effects=[current]"):
            assert after[k] == before[k], k
        edit("study/sim/abkowitz.py", "\n_FIX = 1\n")
        after2 = fps()
        assert fingerprint.changed_components(after["vessel=mariner"], after2["vessel=mariner"]) == ["simulator"]
        assert after2[""] == before[""]
        edit("study/identify/fit.py", "\n_FIX = 1\n")  # one identification: imported by the pipeline
        after3 = fps()
        assert fingerprint.changed_components(after2[""], after3[""]) == ["pipeline"]
        edit("study/identify/models.py", "\n_FIX = 1\n")  # what is identified: the model, and the pipeline imports it
        after4 = fps()
        assert fingerprint.changed_components(after3[""], after4[""]) == ["model", "pipeline"]
        edit("study/store/store.py", "\n_NOT_PART_OF_ANY_RUN = 1\n")
        assert fps() == after4
        # line endings do not matter (a Windows checkout), contents do
        mmg = copy / "study/sim/mmg.py"
        mmg.write_bytes(mmg.read_bytes().replace(b"\n", b"\r\n"))
        assert fps() == after4
        # documenting a component leaves its runs current: comments, docstrings, blank lines are not executed
        edit("study/identify/models.py", '\n\n# a note\n"""a string statement"""\n')
        fit = copy / "study/identify/fit.py"
        fit.write_text(fit.read_text().replace('"""', '"""Reworded. ', 1))
        after5 = fps()
        assert after5[""]["fingerprint"] == after4[""]["fingerprint"]
        assert after5[""]["bytes"]["fingerprint"] != after4[""]["bytes"]["fingerprint"]
        # a record written before that rule holds the bytes' fingerprint: current until any byte changes
        legacy = {k: after4[""]["bytes"][k] for k in ("fingerprint", "components")}
        assert fingerprint.changed_components(legacy, after4[""]) == []
        assert fingerprint.changed_components(legacy, after5[""]) == ["model", "pipeline"]
        assert fingerprint.same_code(legacy["fingerprint"], after4[""])
        assert not fingerprint.same_code(legacy["fingerprint"], after5[""])
    finally:
        fingerprint.clear_cache()


# ----------------------------------------------------------------------------- overlapping sweeps: claims

N_OVERLAP = 12


def _overlapping_sweep(root, who, wait, barrier, out):
    """One of several sweeps over the same runs, each run taking a while; every computation is logged."""
    store = ResultStore(root)
    log = Path(root) / "computed.log"
    barrier.wait()
    statuses = []
    for i in range(N_OVERLAP):
        conf = _conf(seed=500 + i)

        def fn(i=i):
            with open(log, "a") as fh:  # O_APPEND: one whole line per computation
                fh.write(f"{i} {who}\n")
            time.sleep(0.3)
            return _result(float(who))

        rec = run_guarded(store, conf, fn, seed=conf["seed"], wait=wait, code=_code())
        statuses.append(rec["status"])
    out.put((who, statuses))
    _exit_child(out)


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
@pytest.mark.parametrize("wait", [True, False], ids=["wait", "skip"])
def test_overlapping_sweeps_compute_each_run_once(tmp_path, wait):
    ctx = mp.get_context("spawn")
    root = tmp_path / "res"
    ResultStore(root).check_writable()
    barrier, out = ctx.Barrier(4), ctx.Queue()
    procs = [ctx.Process(target=_overlapping_sweep, args=(str(root), w, wait, barrier, out), daemon=True)
             for w in range(4)]
    try:
        for p in procs:
            p.start()
        results = dict(out.get(timeout=300) for _ in procs)
        for p in procs:
            p.join(60)
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
                p.join(5)
    assert all(p.exitcode == 0 for p in procs), [p.exitcode for p in procs]
    computed = (root / "computed.log").read_text().split()
    runs_computed = computed[::2]
    assert sorted(runs_computed) == sorted(str(i) for i in range(N_OVERLAP)), "a run was computed twice or never"
    statuses = [s for st in results.values() for s in st]
    if wait:  # every sweep ends with every run: its own or another's record
        assert statuses.count("ok") == 4 * N_OVERLAP
    else:  # a sweep leaves a run another live sweep is computing to it
        assert set(statuses) <= {"ok", "claimed"} and statuses.count("ok") >= N_OVERLAP
    runs, _ = ResultStore(root).collect()
    assert len(runs) == N_OVERLAP and (runs["status"] == "ok").all()
    assert not list((root / "records" / ".claims").glob("*.json"))  # every claim released


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_app_recomputes_a_run_after_its_estimator_changed(tmp_path):
    """The issue's case end to end, on a copy of the code: after an edit of another estimator the run is
    resumed; after an edit of its own estimator it is computed again, and the table says the old row is gone."""
    import shutil

    repo = tmp_path / "repo"
    for d in ("study", "conf", "hydra_plugins"):
        shutil.copytree(REPO / d, repo / d, ignore=shutil.ignore_patterns("__pycache__"))
    results = tmp_path / "results"

    def run(*extra):
        env = dict(os.environ, PYTHONPATH=str(repo), NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
        env.pop("STUDY_RESULTS_DIR", None)
        p = subprocess.run([sys.executable, "-m", "study", *_QUICK, *extra, f"results_dir={results}"], cwd=tmp_path,
                           env=env, capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, p.stderr[-2000:]
        return p.stdout + p.stderr

    def edit(rel):
        with open(repo / rel, "a") as fh:
            fh.write("\n_FIX = 1\n")

    assert "resumed" not in run()
    edit("study/identify/estimators/svr.py")  # not used by this run (estimator ls)
    assert "(already finished, resumed)" in run()
    edit("study/identify/estimators/linear.py")  # the module of ls
    out = run()
    assert "(already finished, resumed)" not in out and ": skipped" in out
    assert len(list((results / "records").glob("*.json"))) == 1
    assert len(list((results / "records" / "superseded").glob("*.json"))) == 1
    runs = pd.read_parquet(results / "runs.parquet")
    assert len(runs) == 1 and bool(runs.loc[0, "code_current"])
    assert "(already finished, resumed)" in run("force=false")


def test_a_full_disk_names_the_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    import errno

    from study.store import files

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files.os, "fsync", full)
    target = tmp_path / "runs.parquet"
    with pytest.raises(OSError) as e:
        files.atomic_write_bytes(target, b"data")
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(target) and str(target) in str(e.value)
    assert not list(tmp_path.iterdir())


def test_a_corrupt_table_is_named_and_the_figures_command_says_so_in_one_line(tmp_path):
    from study.store import TableError

    (tmp_path / "records").mkdir()
    for name in ("runs.parquet", "params.parquet"):
        (tmp_path / name).write_bytes(b"not a parquet file")
    with pytest.raises(TableError, match=r"runs\.parquet: not a readable parquet table .*python -m study results "
                                         r"rebuild"):
        read_table(tmp_path / "runs.parquet")
    p = subprocess.run([sys.executable, "-m", "study", "figures", "--results", str(tmp_path), "--out",
                        str(tmp_path / "figs")], capture_output=True, text=True, cwd=tmp_path, timeout=300,
                       env=dict(os.environ, PYTHONPATH=str(REPO)))
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2 and len(lines) == 1, p.stderr
    assert lines[0].startswith("study figures: error: ") and "runs.parquet" in lines[0]
    assert not (tmp_path / "figs").exists()
