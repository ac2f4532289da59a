"""The project's launchers (hydra_plugins/study_launcher; ``hydra/launcher=local`` and ``slurm_grouped``).

* A job's configuration composed from a shared base (jobs differing only in value overrides) is the one Hydra
  composes, node by node (values, node types, flags, metadata): on a sample of ``grand``'s and
  ``seed001_shallow_water``'s jobs covering every value of every sweep axis with ``-m slow``, on every job of both
  (and of grand without its sampling axis) with ``-m long``;
  and the comparison itself finds a difference when there is one.
* Chunks and array-task groups hold every job exactly once, jobs sharing a composition together.
* Hydra's semantics, against Hydra's own joblib launcher on a toy app: the JobReturns (status, value, the
  exception of a failing task, overrides, task config, job number and id, working dir), the jobs' output
  folders with their ``.hydra`` files and logs, ``hydra.job.chdir``; in worker processes and in this process.
* The study's sweep gives the same records with ``hydra/launcher=local`` as with Hydra's joblib launcher: same
  run ids, every number but the timings identical (SLURM: tests/plugins/test_slurm.py).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from omegaconf import OmegaConf

import study.commands.app
from hydra_plugins.study_launcher.compose import JobComposer, config_differences
from hydra_plugins.study_launcher.launchers import task_groups
from hydra_plugins.study_launcher.runner import make_chunks

REPO = Path(__file__).resolve().parents[2]
CONF = str(REPO / "conf")


# ------------------------------------------------------------------------------------------ composition
def _sweep(experiment: str, extra=()):
    """The master config of ``-m experiment=<name>`` and every job's overrides, as the sweeper makes them."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.types import RunMode

    loader = GlobalHydra.instance().config_loader()
    args = [f"experiment={experiment}", *extra]
    master = loader.load_configuration("config", args + ["hydra/launcher=local"], run_mode=RunMode.MULTIRUN)
    params = [f"{k}={v}" for k, v in (master.hydra.sweeper.params or {}).items()] + args
    jobs = BasicSweeper.split_arguments(OverridesParser.create().parse_overrides(params), None)[0]
    return loader, master, jobs


def _compare(experiment: str, pick, extra=()) -> tuple[int, int, dict]:
    from hydra import initialize_config_dir
    from hydra.core.utils import setup_globals

    setup_globals()
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        loader, master, jobs = _sweep(experiment, extra)
        composer = JobComposer(loader, master)
        chosen = pick(jobs, composer)
        bad = []
        for job in chosen:
            ours = composer.compose(job)
            hydras = loader.load_sweep_config(master, list(job))
            diff = config_differences(hydras, ours)
            if diff:
                bad.append(f"{' '.join(job)}: {diff[:4]}")
        assert not bad, f"{len(bad)} of {len(chosen)} jobs composed differently:\n" + "\n".join(bad[:10])
    return len(chosen), composer.shared, composer.loader.repository.counts


def _shared_sample(jobs, composer, n_keys=3, n_more=6):
    """All jobs of the first ``n_keys`` group-override sets (composed from one base each), a spread of others,
    and enough more that every value of every sweep axis is composed at least once (greedy: the job bringing
    the most values not yet seen, first)."""
    keys = []
    for job in jobs:
        k = composer.group_key(job)
        if k not in keys:
            keys.append(k)
        if len(keys) == n_keys:
            break
    first = [job for job in jobs if composer.group_key(job) in keys]
    step = max(1, len(jobs) // n_more)
    chosen = sorted(first, key=lambda j: keys.index(composer.group_key(j))) + list(jobs[step // 2::step])[:n_more]
    seen = {o for job in chosen for o in job}
    missing = {o for job in jobs for o in job} - seen
    while missing:
        best = max(jobs, key=lambda j: len(missing.intersection(j)))
        chosen.append(best)
        missing -= set(best)
    return chosen


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
@pytest.mark.parametrize("experiment", ["grand", "seed001_shallow_water", "smoke"])
def test_composition_equals_hydras_on_a_sample(experiment):
    n, shared, loads = _compare(experiment, _shared_sample)
    if experiment == "smoke":  # group overrides only: Hydra's composition, on the configs loaded once
        assert shared == 0 and n >= 6
    else:  # the shared path was taken (value overrides: the sampling interval; seed001 also the speed)
        assert shared >= 6 and n >= 12
    assert loads["reused"] > 2 * loads["loaded"] > 0


@pytest.mark.slow
@pytest.mark.long  # about 35 CPU-minutes: Hydra composes each job in about half a second
@pytest.mark.parametrize("experiment, extra", [("grand", ()), ("seed001_shallow_water", ()),
                                               ("grand", ("noise.sample_dt_LU=null",))])
def test_shared_composition_equals_hydras_on_every_job(experiment, extra):
    """Every job (grand: 1080, seed001: 1920; grand without its sampling axis: 540), in the order a worker meets
    them (grouped by group overrides). The slow tier composes a sample covering every value of every axis
    (``test_composition_equals_hydras_on_a_sample``); this exhaustive check is run by hand."""
    def every(jobs, composer):
        return [j for c in make_chunks([(i, j) for i, j in enumerate(jobs)], composer.group_key, 1) for _, j in c]

    n, shared, _ = _compare(experiment, every, extra)
    assert n == {"grand": 540 if extra else 1080, "seed001_shallow_water": 1920}[experiment]
    assert shared == n  # every job has a value override (grand as it was: noise.sample_dt_LU=null)


def test_the_comparison_finds_differences():
    base = OmegaConf.create({"a": 1, "b": {"c": "x", "d": [1, 2]}, "e": "${a}"})
    assert config_differences(base, OmegaConf.create({"a": 1, "b": {"c": "x", "d": [1, 2]}, "e": "${a}"})) == []
    for change in (lambda c: c.b.d.append(3), lambda c: setattr(c.b, "c", "y"), lambda c: setattr(c, "e", "${b.c}"),
                   lambda c: OmegaConf.set_struct(c.b, True), lambda c: setattr(c, "a", 1.0),
                   lambda c: OmegaConf.set_readonly(c.b.d, True)):
        other = OmegaConf.create(OmegaConf.to_container(base))
        change(other)
        assert config_differences(base, other), change
    from dataclasses import dataclass

    @dataclass
    class Typed:
        a: int = 1

    assert config_differences(OmegaConf.create({"t": {"a": 1}}), OmegaConf.create({"t": OmegaConf.structured(Typed)}))


def test_a_value_override_that_fails_fails_as_in_hydra():
    from hydra import initialize_config_dir
    from hydra.core.utils import setup_globals
    from hydra.errors import ConfigCompositionException

    setup_globals()
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        loader, master, _ = _sweep("tiny")
        composer = JobComposer(loader, master)
        for job in (["estimator=ls", "sim.no_such_key=1"], ["estimator=ls", "seed=[1"]):
            errors = []
            for compose in (composer.compose, lambda j: loader.load_sweep_config(master, j)):
                with pytest.raises(Exception) as e:
                    compose(job)
                errors.append(type(e.value))
            assert errors[0] is errors[1], job
        with pytest.raises(ConfigCompositionException):
            composer.compose(["estimator=ls", "sim.no_such_key=1"])


# ------------------------------------------------------------------------------------------ chunks
def test_chunks_keep_groups_together_and_every_job_once():
    jobs = [(i, [f"g={i % 5}", f"v={i}"]) for i in range(103)]
    key = lambda ov: ov[0]  # noqa: E731
    for workers in (1, 2, 7):
        chunks = make_chunks(jobs, key, workers)
        assert sorted(n for c in chunks for n, _ in c) == list(range(103))
        cap = math.ceil(103 / (4 * workers))
        assert all(0 < len(c) <= cap and len({key(ov) for _, ov in c}) == 1 for c in chunks)
        assert len(chunks) == sum(math.ceil(len([j for j in jobs if key(j[1]) == g]) / cap)
                                  for g in {key(j[1]) for j in jobs})
    for n_tasks in (1, 4, 10, 103, 500):
        groups = task_groups(jobs, key, n_tasks)
        assert sorted(n for g in groups for n, _ in g) == list(range(103))
        sizes = [len(g) for g in groups]
        assert len(groups) == min(n_tasks, 103) and max(sizes) - min(sizes) <= 1
        # jobs of one key are consecutive: each key spans at most (its jobs / task size) + 2 tasks
        for g in {key(j[1]) for j in jobs}:
            spans = [t for t, grp in enumerate(groups) if any(key(ov) == g for _, ov in grp)]
            assert spans == list(range(spans[0], spans[-1] + 1))


# ------------------------------------------------------------------------------------------ Hydra's semantics
TOY_APP = '''
import os, sys
from pathlib import Path
import hydra
from hydra.core.hydra_config import HydraConfig

@hydra.main(config_path="conf", config_name="config", version_base="1.3")
def main(cfg):
    if cfg.x == "boom":
        raise RuntimeError(f"job {HydraConfig.get().job.num} failed on purpose")
    Path(cfg.out, f"{HydraConfig.get().job.num}.txt").write_text(f"{cfg.x} {cfg.g.name} {os.getcwd()}")
    return {"x": cfg.x, "g": cfg.g.name, "num": HydraConfig.get().job.num, "pid": os.getpid()}
'''


def _toy(tmp_path: Path) -> Path:
    (tmp_path / "conf" / "g").mkdir(parents=True)
    (tmp_path / "conf" / "config.yaml").write_text("defaults:\n  - g: a\n  - _self_\nx: 0\nout: .\n")
    for g in "ab":
        (tmp_path / "conf" / "g" / f"{g}.yaml").write_text(f"name: {g}\n")
    (tmp_path / "toy_app.py").write_text(TOY_APP)
    return tmp_path


def _launch(app_dir: Path, launcher_overrides: list, jobs: list, sweep_dir: Path, chdir: bool):
    """The jobs launched by Hydra's launcher machinery in this process (what a sweeper does), and the JobReturns."""
    import importlib.util

    from hydra import initialize_config_dir
    from hydra._internal.callbacks import Callbacks
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.hydra_config import HydraConfig
    from hydra.core.plugins import Plugins
    from hydra.core.utils import setup_globals
    from hydra.types import HydraContext, RunMode

    sys.path.insert(0, str(app_dir))
    try:
        spec = importlib.util.spec_from_file_location("toy_app", app_dir / "toy_app.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules["toy_app"] = mod
        spec.loader.exec_module(mod)
        task = mod.main.__wrapped__  # the task function Hydra hands to its launcher
        setup_globals()
        with initialize_config_dir(config_dir=str(app_dir / "conf"), version_base="1.3"):
            loader = GlobalHydra.instance().config_loader()
            cfg = loader.load_configuration("config", [*launcher_overrides, f"hydra.sweep.dir={sweep_dir}",
                                                       f"hydra.job.chdir={chdir}"], run_mode=RunMode.MULTIRUN)
            HydraConfig.instance().set_config(cfg)
            launcher = Plugins.instance().instantiate_launcher(
                hydra_context=HydraContext(config_loader=loader, callbacks=Callbacks(cfg)), task_function=task,
                config=cfg)
            return launcher.launch(jobs, initial_job_idx=3)
    finally:
        sys.path.remove(str(app_dir))
        sys.modules.pop("toy_app", None)


def _summary(ret, sweep_dir: Path) -> dict:
    from hydra.core.utils import JobStatus

    out = {"status": ret.status.name, "overrides": list(ret.overrides), "task_name": ret.task_name,
           "cfg": OmegaConf.to_container(ret.cfg), "num": ret.hydra_cfg.hydra.job.num,
           "id": ret.hydra_cfg.hydra.job.id, "working_dir": os.path.relpath(ret.working_dir, sweep_dir)
           if str(ret.working_dir).startswith(str(sweep_dir)) else "launch dir"}
    if ret.status == JobStatus.COMPLETED:
        out["value"] = {k: v for k, v in ret.return_value.items() if k != "pid"}
    else:
        out["error"] = f"{type(ret._return_value).__name__}: {ret._return_value}"
    return out


def _outputs(sweep_dir: Path) -> list:
    return sorted(str(p.relative_to(sweep_dir)) for p in sweep_dir.rglob("*") if p.is_file()
                  and ".submitit" not in p.parts and p.name != "multirun.yaml")


@pytest.mark.slow
@pytest.mark.parametrize("chdir", [False, True])
def test_same_job_returns_and_outputs_as_hydras_joblib_launcher(tmp_path, chdir):
    app = _toy(tmp_path / "app")
    out = tmp_path / "out"
    out.mkdir()
    jobs = [["g=a", "x=1", f"out={out}"], ["g=b", "x=2", f"out={out}"], ["g=a", "x=boom", f"out={out}"],
            ["g=a", "x=3", f"out={out}"], ["g=b", "x=4", f"out={out}"]]
    seen = {}
    for name, ov in (("joblib", ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]),
                     ("workers", ["hydra/launcher=study_local", "hydra.launcher.n_jobs=2"]),
                     ("here", ["hydra/launcher=study_local", "hydra.launcher.n_jobs=1"])):
        sweep_dir = tmp_path / name
        rets = _launch(app, ov, jobs, sweep_dir, chdir)
        seen[name] = ([_summary(r, sweep_dir) for r in rets], _outputs(sweep_dir),
                      sorted(p.read_text().replace(str(sweep_dir), "<sweep>") for p in out.glob("*.txt")),
                      {r.return_value["pid"] for r in rets if r.status.name == "COMPLETED"})
        for p in out.glob("*.txt"):
            p.unlink()
    ref = seen["joblib"]
    assert [s["status"] for s in ref[0]] == ["COMPLETED", "COMPLETED", "FAILED", "COMPLETED", "COMPLETED"]
    assert ref[0][2]["error"] == "RuntimeError: job 5 failed on purpose"
    assert [s["num"] for s in ref[0]] == [3, 4, 5, 6, 7]
    assert "3/.hydra/config.yaml" in ref[1] and "3/app.log" in ref[1]  # initialize_config_dir's job name: app
    for name in ("workers", "here"):
        assert seen[name][0] == ref[0], name
        assert seen[name][1] == ref[1], name  # the same files in the same job folders
        assert seen[name][2] == ref[2], name  # the task saw the same working directory
    assert os.getpid() not in seen["workers"][3] and len(seen["workers"][3]) <= 2
    assert seen["here"][3] == {os.getpid()}


# ------------------------------------------------------------------------------------------ the study's records
def _study(args: list, results: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, STUDY_RESULTS_DIR=str(results), OPENBLAS_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "study", *args], cwd=results.parent, env=env,
                          capture_output=True, text=True, timeout=900)


def _numbers(results: Path) -> dict:
    """Every record without what differs between two computations of one run: timings, start and end, the code
    and provenance (the same here), the results folder."""
    out = {}
    for p in sorted((results / "records").glob("*.json")):
        r = json.loads(p.read_text())
        for k in ("timings", "started", "finished", "provenance", "code"):
            r.pop(k, None)
        r["config"].pop("results_dir", None)
        out[p.stem] = json.dumps(r, sort_keys=True)  # NaN written as NaN: compared as text
    return out


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_the_study_gives_the_same_records_with_either_launcher(tmp_path):
    """Eight jobs (two estimators, two structures, two seeds: the seeds share their composition) with Hydra's
    joblib launcher and with the project's: the same run ids, the same numbers, the same artefacts; and each job
    said so once (``job i/8``)."""
    sweep = ["-m", "experiment=tiny", "case=kt_nomoto2", "estimator=ls,ridge", "structure=euler,central", "seed=0,1",
             "progress=false"]
    found = {}
    for name in ("joblib", "local"):
        results = tmp_path / name / "results"
        results.parent.mkdir()
        p = _study([*sweep, f"hydra/launcher={name}", "hydra.launcher.n_jobs=2"], results)
        assert p.returncode == 0, p.stderr[-3000:]
        lines = sorted(ln.split(":")[0] for ln in p.stdout.splitlines() if ln.startswith("[study] job "))
        assert lines == sorted(f"[study] job {i}/8" for i in range(1, 9)), p.stdout
        arte = {str(f.relative_to(results / "artefacts")): f.read_bytes()
                for f in (results / "artefacts").rglob("*") if f.is_file()}
        found[name] = (_numbers(results), arte)
    assert len(found["joblib"][0]) == 8
    assert found["local"][0].keys() == found["joblib"][0].keys()
    for rid, rec in found["joblib"][0].items():
        assert found["local"][0][rid] == rec, rid
    assert found["local"][1] == found["joblib"][1]


def test_the_launchers_use_nothing_of_the_study_package():
    """hydra_plugins/study_launcher is a Hydra plugin for any app: it imports Hydra, OmegaConf, joblib's loky,
    submitit and cloudpickle, never ``study`` (the app's callbacks reach it through Hydra's context); the
    import-linter contract (.importlinter) covers ``study`` itself."""
    import ast

    found = []
    for path in sorted((REPO / "hydra_plugins" / "study_launcher").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
            found += [f"{path.name}: {n}" for n in names if n == "study" or n.startswith("study.")]
    assert not found, found
