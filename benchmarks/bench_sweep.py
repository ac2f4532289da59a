"""Benchmark of the work users wait for: a fresh worker, the output-error emcee fit, the big sweeps.

Three parts, each printing today's figure (the baseline, measured in the same run) next to the new one and the
ratio, so that a loaded machine slows both alike:

* ``startup`` -- **a fresh worker ready to run**: a new Python process imports what a run imports (the app, the
  pipeline, the identification, the results store) and loads the compiled code of a vessel kind (the
  integrator, the accelerations kernel the regressors and MMG self-propulsion use), with numba's cache warm.
  Baseline: the same child in a checkout of ``--baseline-rev`` (the code before the speed work; a temporary git
  worktree, its cache warmed first). Target < 2 s.
* ``emcee`` -- **the output-error emcee fit** of ``bench_identify.py``: seed 000's training record (2100 s at
  0.1 s, 1 % noise), 11 coefficients + 3 initial states (+ 3 noise scales), until 1,000 effective samples and
  50 autocorrelation times. Baseline: ``moves='de'`` on one thread (today's path, unchanged in this code);
  new: the default (``moves='auto'`` -> 'laplace', batches split over two threads). Printed: time, CPU time,
  steps, simulations, ESS, and both posteriors against self-normalised importance sampling from the new run's
  frozen proposal (independent draws: no chain has to mix), and against each other. Target < 120 s.
* ``sweep`` -- **grand and seed001_shallow_water**: a stratified sample of each study's jobs timed in one
  process, stage by stage (``sweep_sample.py``: Hydra composition, simulate, measure, regressors, fit, validate,
  the store's record), in the baseline checkout and in this one, after one untimed short run per case (compiled
  code loaded); the full sweep's core-seconds extrapolated per estimator from CPU time (mean of the distinct
  sampled jobs of an estimator x that estimator's jobs in the sweep, skipped jobs counted at their measured
  cost), plus the CPU per job that Hydra's joblib launcher adds (measured on 24 short jobs run as a real sweep
  and in one process) and the per-process cost measured by ``startup`` for each of the two workers (joblib
  reuses them), divided by the 2 cores: the wall time of the sweep on an idle 2-core machine. Target for grand:
  < 600 s.

* ``launcher`` -- **the launchers** (the grouped launch): CPU per job that Hydra's joblib launcher and
  the project's ``hydra/launcher=local`` (hydra_plugins/study_launcher; with and without compositions shared
  between jobs that differ only in value overrides) spend around the job, from the slope between two sweep sizes
  of resumed jobs (fixed costs cancel), against the same jobs in one process; then grand as it was (1188 jobs)
  and seed001 estimated on 2 idle cores with each launcher (the runs' CPU from a sample per estimator).

``python benchmarks/bench_sweep.py [--part startup,emcee,sweep,launcher] [--baseline-rev REV] [--sample N]``; figures
go to ``benchmarks/results/bench_sweep.json``. Run with ``OPENBLAS_NUM_THREADS=1``.
"""
from __future__ import annotations

import argparse
import collections
import itertools
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
BASELINE_REV = "62b33f6"  # main before the speed work (compiled kernels, grouped launches)
TARGETS = {"startup_s": 2.0, "emcee_oe_s": 120.0, "grand_s": 600.0}

READY_CHILD = r"""
import time
t0 = time.perf_counter()
import study.commands.app, study.run.pipeline, study.identify.fit, study.commands.results  # what a worker imports
c1 = time.process_time(); t1 = time.perf_counter()
from study.sim import accelerations, integrator, load_vessel
v = load_vessel("kvlcc2")  # MMG self-propulsion
integrator(v.kind_name)
accelerations(v, v.params[:, None], [1.0], [0.0], [0.0], [0.0], [1.0])
c2 = time.process_time(); t2 = time.perf_counter()
print("READY", t1 - t0, c1, t2 - t1, c2 - c1, flush=True)
"""


def _env(tree):
    return dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1")


def baseline_tree(rev: str) -> Path:
    """A checkout of ``rev`` in a temporary git worktree (made once, reused)."""
    path = Path(os.environ.get("TMPDIR", "/tmp")) / f"study-bench-baseline-{rev}"
    if not path.exists():
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), rev], check=True,
                       capture_output=True)
    return path


def ready_once(tree: Path) -> dict:
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-c", READY_CHILD], cwd=tree, env=_env(tree), stdout=subprocess.PIPE,
                         stderr=subprocess.DEVNULL, text=True)
    for line in p.stdout:
        if line.startswith("READY"):
            wall = time.perf_counter() - t0
            _, imp_w, imp_c, load_w, load_c = line.split()
            p.wait()
            return {"ready_s": wall, "import_s": float(imp_w), "import_cpu": float(imp_c),
                    "compiled_s": float(load_w), "compiled_cpu": float(load_c),
                    "ready_cpu": float(imp_c) + float(load_c)}
    p.wait()
    raise RuntimeError(f"the ready child failed in {tree}")


def part_startup(base: Path, repeats: int) -> dict:
    out = {}
    for name, tree in (("baseline", base), ("new", ROOT)):
        ready_once(tree)  # warm the tree's numba cache
    runs = {"baseline": [], "new": []}
    for _ in range(repeats):  # interleaved: the machine's load falls on both alike
        for name, tree in (("baseline", base), ("new", ROOT)):
            runs[name].append(ready_once(tree))
    for name, rs in runs.items():
        out[name] = {k: statistics.median(r[k] for r in rs) for k in rs[0]}
    b, n = out["baseline"], out["new"]
    print(f"\nfresh worker ready (median of {repeats}, cache warm):\n"
          f"{'':10}{'ready wall':>12}{'ready cpu':>11}{'imports cpu':>13}{'compiled code cpu':>19}")
    for name in ("baseline", "new"):
        r = out[name]
        print(f"{name:10}{r['ready_s']:>11.2f}s{r['ready_cpu']:>10.2f}s{r['import_cpu']:>12.2f}s"
              f"{r['compiled_cpu']:>18.2f}s")
    out["ratio_wall"] = n["ready_s"] / b["ready_s"]
    out["ratio_cpu"] = n["ready_cpu"] / b["ready_cpu"]
    out["pass"] = bool(n["ready_s"] < TARGETS["startup_s"])
    print(f"new / baseline: wall {out['ratio_wall']:.2f}, cpu {out['ratio_cpu']:.2f}; target ready < 2 s: "
          f"{'PASS' if out['pass'] else 'MISS'} (wall {n['ready_s']:.2f} s, cpu {n['ready_cpu']:.2f} s)")
    return out


def part_emcee(baseline: bool) -> dict:
    from bench_identify import seed000_training

    from study.identify.estimators import make_estimator
    from study.identify.fit import make_problem
    from study.identify.structures import make_structure

    v, model, structure, recs = seed000_training()
    prob = make_problem(model, make_structure("output_error"), recs)
    prob.sse(prob.x0[:, None])  # compiled code loaded
    out, fits = {}, {}
    cases = [("new", {}, True)] + ([("baseline", {"moves": "de"}, False)] if baseline else [])
    for name, kw, threads in cases:
        prob.threads = threads
        n0 = prob.n_sim
        t0, c0 = time.perf_counter(), time.process_time()
        est = make_estimator("emcee", **kw).fit_output_error(prob)
        d = est.diagnostics_
        fits[name] = est
        out[name] = {"time_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
                     "simulations": prob.n_sim - n0, "moves": est.moves_,
                     **{k: d[k] for k in ("ess", "steps", "tau_max", "acceptance", "converged")}}
        r = out[name]
        print(f"emcee output error, {name} ({r['moves']} moves, threads {threads}): {r['time_s']:.0f} s "
              f"(cpu {r['cpu_s']:.0f} s), {r['steps']} steps, {r['simulations']} simulations, ESS {r['ess']:.0f}, "
              f"tau {r['tau_max']:.1f}, acceptance {r['acceptance']:.2f}", flush=True)
    prob.threads = True
    n = out["new"]
    n["pass"] = bool(n["time_s"] < TARGETS["emcee_oe_s"] and n["ess"] >= 1000)
    if fits["new"].proposal_ is not None:  # the reference: importance sampling from the frozen proposal
        q = fits["new"].proposal_
        k, nobs = prob.k, prob.n_obs.astype(float)
        x = q.draw(6000, np.random.RandomState(3))
        sse = prob.sse(x[:, :k].T)
        lw = np.sum(-(nobs[:, None] * x[:, k:].T) - 0.5 * sse / np.exp(2 * x[:, k:].T), axis=0) - q.log_density(x)
        w = np.exp(lw - lw.max())
        w /= w.sum()
        m = w @ x[:, :k]
        sd = np.sqrt(w @ (x[:, :k] - m) ** 2)
        out["importance"] = {"ess": float(1 / np.sum(w ** 2))}
        for name, f in fits.items():
            dz = (f.samples_.mean(axis=0) - m) / sd
            rs = f.coef_std_ / sd
            out["importance"][name] = {"max_abs_mean_diff_sd": float(np.max(np.abs(dz))),
                                       "sd_ratio_min": float(rs.min()), "sd_ratio_max": float(rs.max())}
            print(f"{name} against importance sampling (6,000 draws, effective {out['importance']['ess']:.0f}): "
                  f"means within {np.max(np.abs(dz)):.2f} sd, sd ratio {rs.min():.2f}-{rs.max():.2f}")
    if baseline:
        b, fb, fn = out["baseline"], fits["baseline"], fits["new"]
        dz = (fn.coef_ - fb.coef_) / fb.coef_std_
        rs = fn.coef_std_ / fb.coef_std_
        out["ratio_time"] = n["time_s"] / b["time_s"]
        out["ratio_cpu"] = n["cpu_s"] / b["cpu_s"]
        out["posterior"] = {"max_abs_median_diff_sd": float(np.max(np.abs(dz))),
                            "sd_ratio_min": float(rs.min()), "sd_ratio_max": float(rs.max()),
                            "names": list(prob.names), "median_diff_sd": dz.tolist(), "sd_ratio": rs.tolist()}
        print(f"new / baseline: time {out['ratio_time']:.3f} ({1 / out['ratio_time']:.1f}x faster), cpu "
              f"{out['ratio_cpu']:.3f}; posterior: medians within {np.max(np.abs(dz)):.2f} baseline sd, sd ratio "
              f"{rs.min():.2f}-{rs.max():.2f}")
    print(f"target < {TARGETS['emcee_oe_s']:.0f} s with ESS >= 1000: {'PASS' if n['pass'] else 'MISS'}")
    return out


# ------------------------------------------------------------------------------------------------ sweeps
STUDIES = {
    "grand": {"jobs": 1188, "axes": {
        "case": "kvlcc2_mmg,kcs_mmg,usv_full,mariner_abkowitz,auv,kt_nomoto2", "depth": "deep,h_T_2p9,h_T_1p46",
        "noise": "low,medium", "structure": "euler,central,integral",
        "estimator": "ls,ridge,lasso,lssvm,tlssvm,lssvm_online,svr_eps,svr_nu,sindy,de,emcee"}},
    "seed001_shallow_water": {"jobs": 1920, "axes": {
        "case": "kcs_nomoto1,kcs_nomoto2,kt1_nomoto1,kt_nomoto2", "depth": "deep,h_T_5p6,h_T_2p9,h_T_1p46,h_T_1p32",
        "vessel.operation.U0": "12.35,8.23", "estimator": "tlssvm,ls,lssvm,svr_nu", "structure": "central,smoothed",
        "noise": "none,low,medium", "noise.sample_dt_LU": "0.0054,0.054"}},
}


def sample_jobs(study: str, per_estimator: int, seed: int = 0, studies: dict = STUDIES) -> list[str]:
    """``per_estimator`` jobs of each estimator, the other axes drawn at random (seeded) from the sweep's."""
    axes = {k: v.split(",") for k, v in studies[study]["axes"].items()}
    rng = np.random.default_rng(seed)
    jobs = []
    for est in axes["estimator"]:
        mine = []
        while len(mine) < per_estimator:  # distinct jobs (a repeated one would be resumed, not run)
            job = " ".join([f"experiment={study}"] + [f"{k}={vals[rng.integers(len(vals))]}" for k, vals in
                                                      axes.items() if k != "estimator"] + [f"estimator={est}"])
            if job not in mine:
                mine.append(job)
        jobs += mine
    return jobs


def warmup_jobs(study: str) -> list[str]:
    """One short run per case of the study: loads (or compiles, in a cold checkout) every vessel kind's compiled
    code before the timed jobs, so that per-process costs are not charged to the first job of each kind (they are
    counted once per worker process, from ``startup``)."""
    cases = STUDIES[study]["axes"]["case"].split(",")
    return [f"experiment=tiny case={c} estimator=ls seed=987654" for c in cases]


def time_sample(tree: Path, study: str, jobs: list[str], results: Path) -> list[dict]:
    env = _env(tree)
    env["STUDY_RESULTS_DIR"] = str(results)
    env["STUDY_TREE"] = str(tree)
    script = ROOT / "benchmarks" / "sweep_sample.py"  # this tree's script, the tree's code (PYTHONPATH)
    warm = warmup_jobs(study)
    p = subprocess.run([sys.executable, str(script), str(results), *warm, *jobs], cwd=tree, env=env,
                       capture_output=True, text=True)
    rows = [json.loads(line) for line in p.stdout.splitlines() if line.startswith("{")]
    if len(rows) != len(warm) + len(jobs):
        raise RuntimeError(f"sweep sample in {tree} failed: {p.stderr[-2000:]}")
    return rows[len(warm):]


def extrapolate(study: str, rows: list[dict], studies: dict = STUDIES) -> dict:
    """Core-seconds of the full sweep from the sample: per estimator, the mean CPU time of its sampled jobs
    (compose + run + store) times its number of jobs in the sweep; the stages likewise (the records' wall timings
    of each stage scaled by the job's CPU / wall)."""
    n_est = len(studies[study]["axes"]["estimator"].split(","))
    per_est = studies[study]["jobs"] / n_est
    by = collections.defaultdict(list)
    stages = collections.Counter()
    w = per_est / len(rows) * n_est  # each sampled job stands for this many jobs of the sweep
    for r in rows:
        est = r["job"].rsplit("estimator=", 1)[1]
        cpu = r["compose_cpu"] + r["guarded_cpu"]  # CPU time: the machine's load does not inflate it
        by[est].append(cpu)
        f = r["guarded_cpu"] / r["guarded_s"] if r["guarded_s"] > 0 else 1.0  # the run's stages: wall -> cpu
        for k, v in r["stages"].items():
            stages[k] += v * f * w
        stages["compose"] += r["compose_cpu"] * w
        stages["store"] += max(r["guarded_s"] - r["run_s"], 0.0) * f * w
    total = sum(np.mean(v) * per_est for v in by.values())
    guarded = collections.defaultdict(list)
    for r in rows:
        guarded[r["job"].rsplit("estimator=", 1)[1]].append(r["guarded_cpu"])
    return {"core_s": float(total), "by_estimator_core_s": {k: float(np.mean(v) * per_est) for k, v in by.items()},
            "by_stage_core_s": dict(stages),
            "run_core_s": float(sum(np.mean(v) * per_est for v in guarded.values()))}  # without composition


LAUNCHER_JOBS = ("experiment=grand case=kvlcc2_mmg,kcs_mmg depth=deep,h_T_2p9 noise=low,medium "
                 "structure=euler,central,integral estimator=ls")


def part_launcher(tree: Path, tmp: Path) -> dict:
    """CPU per job that Hydra's joblib launcher adds to a job run in-process: the same 24 short jobs as a real
    sweep (``-m ... hydra/launcher=local``; CPU of the whole process tree) and in one process
    (``sweep_sample.py``), the difference less one process start, per job."""
    import resource

    env = _env(tree)
    env["STUDY_RESULTS_DIR"] = str(tmp / "launcher-real")
    env["STUDY_TREE"] = str(tree)
    axes = dict(kv.split("=", 1) for kv in LAUNCHER_JOBS.split())
    jobs = [" ".join(f"{k}={v}" for k, v in zip(axes, combo))
            for combo in itertools.product(*[v.split(",") for v in axes.values()])]

    def children_cpu():
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    c0, t0 = children_cpu(), time.perf_counter()
    subprocess.run([sys.executable, "-m", "study", "-m", *LAUNCHER_JOBS.split(), "hydra/launcher=local",
                    f"hydra.sweep.dir={tmp / 'multirun'}"], cwd=tree, env=env, check=True, capture_output=True)
    real_cpu, real_wall = children_cpu() - c0, time.perf_counter() - t0
    env["STUDY_RESULTS_DIR"] = str(tmp / "launcher-inproc")
    c0 = children_cpu()
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "sweep_sample.py"), str(tmp / "launcher-inproc"),
                    *jobs], cwd=tree, env=env, check=True, capture_output=True)
    inproc_cpu = children_cpu() - c0
    return {"jobs": len(jobs), "real_cpu": real_cpu, "real_wall": real_wall, "inproc_cpu": inproc_cpu}


def part_sweep(base: Path, per_estimator: int, tmp: Path, startup: dict | None) -> dict:
    out = {"launcher": {}}
    for name, tree in (("baseline", base), ("new", ROOT)):
        la = part_launcher(tree, tmp / f"launcher-{name}")
        ready = (startup or {}).get(name, {}).get("ready_cpu", 0.0)
        la["per_job_cpu"] = max(la["real_cpu"] - la["inproc_cpu"] - ready, 0.0) / la["jobs"]
        out["launcher"][name] = la
        print(f"launcher ({name}): {la['jobs']} short jobs as a sweep {la['real_cpu']:.1f} s of CPU, in one process "
              f"{la['inproc_cpu']:.1f} s: {la['per_job_cpu']:.2f} s of CPU per job added by the launcher", flush=True)
    for study in STUDIES:
        jobs = sample_jobs(study, per_estimator)
        res = {}
        for name, tree in (("baseline", base), ("new", ROOT)):
            rows = time_sample(tree, study, jobs, tmp / f"{study}-{name}")
            res[name] = {"sample": rows, **extrapolate(study, rows)}
        b, n = res["baseline"], res["new"]
        workers = 2  # joblib on this machine: one per core, reused for every job
        for name in ("baseline", "new"):
            per_proc = (startup or {}).get(name, {}).get("ready_cpu", 0.0)
            launch = out["launcher"][name]["per_job_cpu"] * STUDIES[study]["jobs"]
            res[name]["launcher_core_s"] = launch
            res[name]["wall_estimate_s"] = (res[name]["core_s"] + launch + workers * per_proc) / 2.0
        res["ratio"] = n["wall_estimate_s"] / b["wall_estimate_s"]
        print(f"\n{study}: {len(jobs)} sampled jobs ({per_estimator} per estimator), extrapolated to "
              f"{STUDIES[study]['jobs']} jobs on 2 cores")
        print(f"{'':10}{'wall':>9}  launcher  " + "  ".join(f"{k}" for k in sorted(n["by_stage_core_s"])))
        for name in ("baseline", "new"):
            r = res[name]
            print(f"{name:10}{r['wall_estimate_s']:>8.0f}s  {r['launcher_core_s'] / 2:>8.0f}  " + "  ".join(
                f"{r['by_stage_core_s'].get(k, 0) / 2:.0f}" for k in sorted(n["by_stage_core_s"])) + "  (s of wall)")
        print("by estimator (new, s of wall): " + ", ".join(
            f"{k} {v / 2:.0f}" for k, v in sorted(n["by_estimator_core_s"].items(), key=lambda kv: -kv[1])))
        if study == "grand":
            res["pass"] = bool(n["wall_estimate_s"] < TARGETS["grand_s"])
            print(f"new / baseline {res['ratio']:.2f}; target grand < 600 s: {'PASS' if res['pass'] else 'MISS'}")
        else:
            print(f"new / baseline {res['ratio']:.2f}")
        out[study] = res
    return out


# ------------------------------------------------------------------------------------------------ launchers
#: the sweeps whose resumed jobs measure a launcher's cost per job, each at two sizes (36 and 108 jobs: the slope is
#: the cost per job, fixed costs cancel). "distinct": every job its own set of group overrides (grand's case);
#: "shared": 18 sets of group overrides x the seeds, a value override (seed001's case: jobs share a composition)
_TINY = ["experiment=tiny", "structure=euler,central,integral", "noise=none,low_relative,medium_relative",
         "progress=false"]
OVERHEAD_SWEEPS = {
    "distinct": (_TINY + ["case=kt_nomoto2,kt1_nomoto1,kcs_nomoto1,kcs_nomoto2"], ["estimator=ls"],
                 ["estimator=ls,ridge,lssvm"]),
    "shared": (_TINY + ["case=kt_nomoto2", "estimator=ls,ridge"], ["seed=0,1"], ["seed=0,1,2,3,4,5"]),
}
LAUNCHERS = {"joblib": ["hydra/launcher=joblib"],  # Hydra's joblib launcher, the project's `local` before
             "local_plain": ["hydra/launcher=local", "hydra.launcher.share_composition=false"],
             "local": ["hydra/launcher=local"]}
#: the studies as the launcher part samples them, with the jobs of one group-override set (``shared``): grand as
#: it was at 62b33f6 (1188 jobs; its noise levels then were the relative ones), seed001 as it is
LAUNCH_STUDIES = {
    "grand": {"jobs": 1188, "shared": 1, "axes": dict(STUDIES["grand"]["axes"], noise="low_relative,medium_relative")},
    "seed001_shallow_water": {"jobs": 1920, "shared": 4, "axes": dict(
        STUDIES["seed001_shallow_water"]["axes"], noise="none,low_relative,medium_relative")},
}


def _children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _timed(cmd: list[str], env: dict, cwd: Path) -> tuple[float, float, str]:
    """CPU of the whole process tree (every worker is a child that has ended) and wall time of a command."""
    c0, t0 = _children_cpu(), time.perf_counter()
    p = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:8])} ...: exit {p.returncode}: {p.stderr[-2000:]}")
    return _children_cpu() - c0, time.perf_counter() - t0, p.stdout


def _grid(args: list[str]) -> list[str]:
    """The jobs of a sweep's command-line arguments (cartesian product, in Hydra's order)."""
    axes = [a.split("=", 1) for a in args]
    return [" ".join(g) for g in itertools.product(*[[f"{k}={v}" for v in vals.split(",")] for k, vals in axes])]


def launcher_overheads(tmp: Path) -> dict:
    """CPU per job that each launcher spends around the job itself, on jobs already finished (resumed: the job's
    own work is a results-store lookup, about a millisecond), from the slope between two sweep sizes (fixed costs --
    the workers' start, the sweeper's validation, the table rebuilt at the end -- cancel); two workers. Reference:
    the same jobs in one process (``sweep_sample.py``: Hydra's compose API, then the results store)."""
    env = _env(ROOT)
    env["STUDY_TREE"] = str(ROOT)
    out = {}
    for kind, (common, small, large) in OVERHEAD_SWEEPS.items():
        res = tmp / f"overhead-{kind}"
        env["STUDY_RESULTS_DIR"] = str(res)

        def sweep(size, launcher):
            return [sys.executable, "-m", "study", "-m", *common, *size, *LAUNCHERS[launcher],
                    f"hydra.sweep.dir={tmp / 'multirun' / f'{kind}-{launcher}-{len(_grid(common + size))}'}"]

        _timed(sweep(large, "local"), env, tmp)  # every run computed once: the measured sweeps resume them
        o = {"jobs": [len(_grid(common + small)), len(_grid(common + large))], "cpu": {}, "wall": {}, "job_cpu": []}
        for size in (small, large):
            n = len(_grid(common + size))
            for name in LAUNCHERS:  # interleaved: the machine's load falls on every launcher alike
                cpu, wall, stdout = _timed(sweep(size, name), env, tmp)
                assert stdout.count("(already finished, resumed)") == n, stdout[-2000:]
                o["cpu"].setdefault(name, []).append(cpu)
                o["wall"].setdefault(name, []).append(wall)
            cpu, wall, stdout = _timed([sys.executable, str(ROOT / "benchmarks" / "sweep_sample.py"), str(res),
                                        *_grid(common + size)], env, tmp)
            rows = [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]
            o["cpu"].setdefault("in_process", []).append(cpu)
            o["wall"].setdefault("in_process", []).append(wall)
            o["job_cpu"].append(float(np.mean([r["guarded_cpu"] for r in rows])))
        dn = o["jobs"][1] - o["jobs"][0]
        job = float(np.mean(o["job_cpu"]))
        o["per_job_cpu"] = {k: (v[1] - v[0]) / dn for k, v in o["cpu"].items()}
        o["fixed_cpu"] = {k: v[0] - o["per_job_cpu"][k] * o["jobs"][0] for k, v in o["cpu"].items()}
        o["overhead_cpu"] = {k: v - job for k, v in o["per_job_cpu"].items()}  # around the job's own work
        print(f"\nlaunchers, {kind} jobs: CPU per job from {o['jobs'][0]} and {o['jobs'][1]} resumed jobs (the job's "
              f"own work {job * 1000:.0f} ms)\n{'':14}{'per job':>9}{'fixed':>9}")
        for k in o["per_job_cpu"]:
            print(f"{k:14}{o['per_job_cpu'][k]:>8.3f}s{o['fixed_cpu'][k]:>8.1f}s")
        out[kind] = o
    return out


def part_launchers(tmp: Path, per_estimator: int, startup: dict | None) -> dict:
    """The per-job overhead of Hydra's joblib launcher against the project's (``launcher_overheads``), and the
    wall time of grand (as it was: 1188 jobs) and seed001 on 2 idle cores with each: the runs' own CPU (a sample per
    estimator in one process, extrapolated), plus jobs x the launcher's CPU around each job (the project's with
    ``shared`` jobs per set of group overrides: the shared cost + (the distinct cost - the shared cost) / shared),
    plus the two workers' start."""
    out = {"overhead": launcher_overheads(tmp)}
    dist, shar = out["overhead"]["distinct"]["overhead_cpu"], out["overhead"]["shared"]["overhead_cpu"]
    ready = (startup or {}).get("new", {}).get("ready_cpu")
    if ready is None:
        ready = statistics.median(ready_once(ROOT)["ready_cpu"] for _ in range(3))
    out["ready_cpu"] = ready
    for study, spec in LAUNCH_STUDIES.items():
        jobs = sample_jobs(study, per_estimator, studies=LAUNCH_STUDIES)
        rows = time_sample(ROOT, study, jobs, tmp / f"{study}-launch")
        ext = extrapolate(study, rows, studies=LAUNCH_STUDIES)
        k = spec["shared"]
        per_job = {"joblib": dist["joblib"], "local": shar["local"] + (dist["local"] - shar["local"]) / k}
        res = {"sample": rows, "run_core_s": ext["run_core_s"], "by_estimator_core_s": ext["by_estimator_core_s"]}
        for name, o in per_job.items():
            res[name] = {"overhead_per_job_cpu": o, "overhead_core_s": o * spec["jobs"],
                         "wall_estimate_s": (ext["run_core_s"] + o * spec["jobs"] + 2 * ready) / 2.0}
        res["ratio"] = res["local"]["wall_estimate_s"] / res["joblib"]["wall_estimate_s"]
        print(f"\n{study} ({spec['jobs']} jobs, {k} per set of group overrides): the runs themselves "
              f"{ext['run_core_s'] / 2:.0f} s of wall on 2 cores (from a sample of {len(jobs)})")
        for name in per_job:
            r = res[name]
            print(f"  {name:8} {r['overhead_per_job_cpu']:.3f} s CPU a job around the run: "
                  f"{r['overhead_core_s'] / 2:.0f} s of wall; the sweep {r['wall_estimate_s']:.0f} s")
        print(f"  local / joblib: {res['ratio']:.2f}" + (f"; target grand < 600 s: "
              f"{'PASS' if res['local']['wall_estimate_s'] < TARGETS['grand_s'] else 'MISS'}" if study == "grand"
                                                        else ""))
        out[study] = res
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="startup,emcee,sweep,launcher")
    ap.add_argument("--baseline-rev", default=BASELINE_REV)
    ap.add_argument("--repeats", type=int, default=5, help="startup: child processes per tree")
    ap.add_argument("--sample", type=int, default=3, help="sweep: sampled jobs per estimator")
    ap.add_argument("--no-baseline-emcee", action="store_true", help="emcee: skip the 6-minute baseline fit")
    ap.add_argument("--keep-baseline", action="store_true",
                    help="keep the baseline checkout (and its compiled code) for the next run")
    args = ap.parse_args(argv)
    parts = args.part.split(",")
    out = {"platform": platform.platform(), "cpus": os.cpu_count(), "load_before": os.getloadavg(),
           "baseline_rev": args.baseline_rev}
    base = baseline_tree(args.baseline_rev) if {"startup", "sweep"} & set(parts) else None
    if "startup" in parts:
        out["startup"] = part_startup(base, args.repeats)
    if "emcee" in parts:
        out["emcee"] = part_emcee(not args.no_baseline_emcee)
    if "sweep" in parts:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            out["sweep"] = part_sweep(base, args.sample, Path(tmp), out.get("startup"))
    if "launcher" in parts:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            out["launcher"] = part_launchers(Path(tmp), args.sample, out.get("startup"))
    if base is not None and not args.keep_baseline:  # the temporary worktree is registered in the repository
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], capture_output=True)
    out["load_after"] = os.getloadavg()
    res = ROOT / "benchmarks" / "results" / "bench_sweep.json"
    res.parent.mkdir(parents=True, exist_ok=True)
    old = json.loads(res.read_text()) if res.exists() else {}
    old.update(out)
    res.write_text(json.dumps(old, indent=1, default=float))
    print(f"\nload average before/after: {out['load_before']} / {out['load_after']}; written {res}")


if __name__ == "__main__":
    main()
