"""Benchmark of replicated runs: what N independent datasets of one configuration cost in one job
(``replicates=N``) against N one-dataset jobs, and what every named study costs at 20 datasets per cell.

Three parts, in one run:

1. **The default case** (``python -m study``: KVLCC2's MMG hull, least squares, central differences), as whole
   processes: one job with ``replicates=1``, one job with ``replicates=20``, and 20 one-dataset jobs as a sweep
   over ``seed`` with the project's own launcher (``hydra/launcher=local``: workers that compose each set of
   group overrides once). Wall time and the CPU time of the processes (``getrusage`` of the children).
2. **grand-like cases** (grand's settings: KVLCC2, half-length manoeuvres, 1 % noise, sampling at 0.05 L/U0,
   central differences) with a cheap estimator (least squares, 20 datasets) and expensive ones (LS-SVM, emcee;
   5 datasets, to keep the benchmark short), the same two ways.
3. **Projection of every named study** (``conf/experiment/*.yaml`` with a sweep) at 20 datasets per cell on 2
   workers: its cells from the sweep's parameters (a ``seed`` axis is the study's own replication and is
   replaced by the replicates), a sample of cells per estimator, structure and sampling interval (``--per-stratum``) timed in this process
   stage by stage (composition; the work shared by the datasets: models, noise-free truth, validation truth;
   the cost of one more dataset: drawing, identifying and validating it, from two datasets), scaled to every
   cell of the stratum. ``projected = sum over cells (compose + shared + 20 x per-dataset) / 2``. For grand,
   which does not fit in an hour, the estimators are ranked by cost and the grid of the cheaper estimators that
   fits is printed with its time. Each projection is printed beside the run time its committed table records
   (the sum of its runs' wall times), as a check of the projection itself.

``python benchmarks/bench_replicates.py [--parts 1,2,3] [--per-stratum 2] [--studies grand,seed000_svr_mmg]``
writes ``benchmarks/results/bench_replicates.json``. Run it on an otherwise idle machine: part 1 and 2's ratios
are measured in the same run, part 3's absolute times are this machine's.
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import random
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

N_CORES = 2
TARGET_REPLICATES = 20
#: the axes a study's cells are grouped by for sampling: what sets a run's cost
STRATA = ("estimator", "structure", "noise.sample_dt_LU")
GRAND_LIMIT_S = 3600.0


# ------------------------------------------------------------------------------------------ whole processes

def _timed(args: list[str], cwd: Path) -> tuple[float, float]:
    """Wall and CPU seconds (user + system of the process and its children) of ``python -m study ...``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    env = dict(os.environ)
    env.pop("STUDY_RESULTS_DIR", None)
    p = subprocess.run([sys.executable, "-m", "study", *args], cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"python -m study {' '.join(args)} failed ({p.returncode}): {p.stderr[-1500:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def compare(name: str, overrides: list[str], n: int, repeat: int) -> dict:
    """One job of ``n`` replicates against one job of one and against ``n`` one-dataset jobs (a sweep)."""
    out = {"case": name, "overrides": overrides, "n": n}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        common = [*overrides, "progress=false", "hydra.output_subdir=null"]

        def run(tag, extra, i):
            folder = tmp / f"{tag}{i}"
            flags = [a for a in extra if a.startswith("-")]  # Hydra's flags before the overrides
            return _timed([*flags, *common, f"results_dir={folder}", f"hydra.run.dir={tmp / 'out'}",
                           f"hydra.sweep.dir={tmp / 'multi' / tag / str(i)}",
                           *[a for a in extra if not a.startswith("-")]], tmp)

        run("warm", [], 0)  # numba's cache and the imports: the first process pays them, no timed one
        one = [run("one", ["replicates=1"], i) for i in range(repeat)]
        many = [run("many", [f"replicates={n}"], i) for i in range(repeat)]
        sweep = [run("sweep", ["-m", f"seed=range({n})", "hydra/launcher=local"], i) for i in range(repeat)]
    for key, vals in (("one", one), ("replicated", many), ("sweep", sweep)):
        walls, cpus = sorted(v[0] for v in vals), sorted(v[1] for v in vals)
        out[key] = {"wall_s": walls[len(walls) // 2], "cpu_s": cpus[len(cpus) // 2]}
    out["replicated_over_one"] = out["replicated"]["wall_s"] / out["one"]["wall_s"]
    out["replicated_over_sweep"] = out["replicated"]["wall_s"] / out["sweep"]["wall_s"]
    out["cpu_replicated_over_sweep"] = out["replicated"]["cpu_s"] / out["sweep"]["cpu_s"]
    print(f"{name:<28} n={n:<3} one job {out['one']['wall_s']:6.1f} s | {n} replicates in one job "
          f"{out['replicated']['wall_s']:6.1f} s wall {out['replicated']['cpu_s']:6.1f} s CPU | {n} one-dataset jobs "
          f"{out['sweep']['wall_s']:6.1f} s wall {out['sweep']['cpu_s']:6.1f} s CPU | replicated/one "
          f"{out['replicated_over_one']:.2f}, replicated/jobs {out['replicated_over_sweep']:.2f} (CPU "
          f"{out['cpu_replicated_over_sweep']:.2f})", flush=True)
    return out


# -------------------------------------------------------------------------------------- study projections

def study_cells(name: str) -> tuple[list[list[str]], int]:
    """The cells of study ``name``'s sweep (each a list of overrides, a ``seed`` axis left out) and how many seeds
    the study itself ran per cell."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from study.configuration.compose import read_config

    parser = OverridesParser.create()

    def expand(items):
        return BasicSweeper.split_arguments(parser.parse_overrides(items), None)[0]

    params = (((read_config("experiment", name) or {}).get("hydra") or {}).get("sweeper") or {}).get("params") or {}
    seeds = 1
    axes = []
    for key, value in params.items():
        if key == "seed":
            seeds = len(expand([f"seed={value}"]))
            continue
        axes.append(f"{key}={value}")
    batches = expand(axes) if axes else [[]]
    return [list(b) for b in batches], seeds


def _stage_times(overrides: list[str]) -> dict:
    """Compose one cell; time its shared work and two datasets. Seconds of each stage."""
    from study.configuration.compose import compose
    from study.run.executor import Replicate, dataset_seed
    from study.run.pipeline import SimulatedJob

    t0 = time.perf_counter()
    conf = compose("config", [*overrides, "progress=false"])
    t_compose = time.perf_counter() - t0
    conf.pop("replicates", None)
    job = SimulatedJob(conf)
    t0 = time.perf_counter()
    skipped = job.prepare()
    t_shared = time.perf_counter() - t0
    if skipped is not None:
        return {"compose": t_compose, "shared": t_shared, "dataset": 0.0, "skipped": True}
    seed = int(conf.get("seed", 0))
    t0 = time.perf_counter()
    parts = [job.identify(Replicate(k, dataset_seed(seed, k), "-")) for k in (1, 2)]
    job.finish(parts)
    return {"compose": t_compose, "shared": t_shared, "dataset": (time.perf_counter() - t0) / 2, "skipped": False}


def _committed_seconds(name: str) -> float | None:
    """The run time of the study's committed table (sum of its runs' wall times, over the cores), or None."""
    import pandas as pd

    path = ROOT / "paper_figs" / name / "table" / "runs.parquet"
    if not path.exists():
        return None
    w = pd.read_parquet(path, columns=["wall_time"])["wall_time"]
    return float(w.sum()) / N_CORES


def project(name: str, per_stratum: int, rng: random.Random) -> dict:
    cells, seeds = study_cells(name)
    strata: dict = {}
    for cell in cells:  # cost depends mostly on the estimator, the structure and the sampling interval
        given = dict(o.split("=", 1) for o in cell)
        key = " ".join(given.get(a, "-") for a in STRATA)  # estimator first
        strata.setdefault(key, []).append(cell)
    rows = {}
    for est, members in strata.items():
        sample = rng.sample(members, min(per_stratum, len(members)))
        times = []
        for cell in sample:
            try:
                times.append(_stage_times([f"experiment={name}", *cell]))
            except Exception as e:  # a cell that fails costs what it cost; say so
                print(f"  {name} {' '.join(cell)}: failed ({type(e).__name__}: {e})", flush=True)
        if not times:
            continue
        mean = {k: sum(t[k] for t in times) / len(times) for k in ("compose", "shared", "dataset")}
        cells_n = len(members)
        one = cells_n * (mean["compose"] + mean["shared"] + mean["dataset"]) * seeds
        rep = cells_n * (mean["compose"] + mean["shared"] + TARGET_REPLICATES * mean["dataset"])
        rows[est] = {"cells": cells_n, "sampled": len(times), **{f"{k}_s": v for k, v in mean.items()},
                     "one_dataset_cpu_s": one, "replicated_cpu_s": rep}
    measured = _committed_seconds(name)
    total_one = sum(r["one_dataset_cpu_s"] for r in rows.values()) / N_CORES
    total_rep = sum(r["replicated_cpu_s"] for r in rows.values()) / N_CORES
    calib = (f"; its committed table's runs took {measured / 60:.1f} min of run time / {N_CORES} cores (projection / "
             f"table {total_one / measured:.2f})" if measured else "")
    print(f"{name}: {len(cells)} cells x {seeds} seed(s) as run today: projected {total_one / 60:6.1f} min on "
          f"{N_CORES} cores{calib}; at {TARGET_REPLICATES} datasets per cell: {total_rep / 60:7.1f} min", flush=True)
    for est, r in sorted(rows.items(), key=lambda kv: -kv[1]["replicated_cpu_s"])[:12]:
        print(f"    {est:<16} {r['cells']:>5} cells, sampled {r['sampled']}: compose {r['compose_s']:.2f} s, shared "
              f"{r['shared_s']:.2f} s, a dataset {r['dataset_s']:.2f} s -> {r['replicated_cpu_s'] / N_CORES / 60:6.1f} "
              f"min at {TARGET_REPLICATES}", flush=True)
    out = {"cells": len(cells), "seeds_today": seeds, "projected_today_s": total_one, "table_run_time_s": measured,
           "projected_replicated_s": total_rep, "per_estimator": rows}
    if total_rep > GRAND_LIMIT_S:
        by_est: dict = {}
        for key, r in rows.items():  # the estimators' whole cost, cheapest first
            est = key.split()[0]
            by_est[est] = by_est.get(est, 0.0) + r["replicated_cpu_s"] / N_CORES
        kept, t = [], 0.0
        for est, c in sorted(by_est.items(), key=lambda kv: kv[1]):
            if t + c > GRAND_LIMIT_S:
                break
            kept.append(est)
            t += c
        out["fits_in_an_hour"] = {"estimators": kept, "projected_s": t, "per_estimator_s": by_est}
        print(f"  {name} at {TARGET_REPLICATES} datasets per cell does not fit in {GRAND_LIMIT_S / 60:.0f} min; "
              "per estimator: " + ", ".join(f"{e} {c / 60:.0f}" for e, c in sorted(by_est.items(),
                                                                                 key=lambda kv: -kv[1]))
              + f" min; the cheapest that fit together: {', '.join(kept)} ({t / 60:.1f} min)", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="1,2,3")
    ap.add_argument("--repeat", type=int, default=1, help="processes per variant in parts 1 and 2 (median)")
    ap.add_argument("--per-stratum", type=int, default=2,
                    help="cells timed per estimator, structure and sampling interval in part 3")
    ap.add_argument("--studies", default=None, help="comma-separated studies for part 3 (default: all named)")
    args = ap.parse_args()
    parts = {int(p) for p in args.parts.split(",")}
    import study.commands.app

    res: dict = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": sys.version.split()[0]}}
    if 1 in parts:
        res["default"] = compare("default (KVLCC2, ls)", [], TARGET_REPLICATES, args.repeat)
    if 2 in parts:
        grand_like = ["case=kvlcc2_mmg", "sim.duration_scale=0.5", "noise=low_relative", "noise.sample_dt_LU=0.05",
                      "structure=central"]
        res["grand_like"] = [compare("grand-like, ls", [*grand_like, "estimator=ls"], TARGET_REPLICATES, args.repeat),
                             compare("grand-like, lssvm", [*grand_like, "estimator=lssvm"], 5, args.repeat),
                             compare("grand-like, emcee", [*grand_like, "estimator=emcee",
                                                           "estimator.params.target_ess=400"], 5,
                                     args.repeat)]
    if 3 in parts:
        from study.configuration.compose import simulated_studies

        names = args.studies.split(",") if args.studies else sorted(s for s in simulated_studies() if s != "smoke")
        rng = random.Random(0)
        res["projection"] = {n: project(n, args.per_stratum, rng) for n in names}
    path = ROOT / "benchmarks" / "results" / "bench_replicates.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    old = json.loads(path.read_text()) if path.exists() else {}  # the parts not run this time are kept
    path.write_text(json.dumps({**old, **res}, indent=1, default=float))
    print(f"written {path}")


if __name__ == "__main__":
    main()
