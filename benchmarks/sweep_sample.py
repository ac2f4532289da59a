"""Time a sample of a study's jobs in one process, stage by stage (used by ``bench_sweep.py``).

Each job: Hydra composition of its configuration (what the launcher does again in every job), the run itself
(``run_study``: simulate, measure, regressors, fit, validate, from the record's own timings), and the results
store's part (run id, provenance, the atomic record and artefacts: ``run_guarded`` minus the run). Prints one JSON
line per job; ``STUDY_TREE``: the checkout to time (default this one). Usage: ``python benchmarks/sweep_sample.py RESULTS_DIR 'ov1 ov2 ...' ['ov1 ...' ...]``.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

# the checkout whose code and configs are timed (bench_sweep.py times an older revision with this script)
ROOT = Path(os.environ.get("STUDY_TREE") or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(ROOT))

from hydra import compose, initialize_config_dir  # noqa: E402
from omegaconf import OmegaConf  # noqa: E402

import study.commands.app
from study.run.pipeline import run_study, study_config
from study.run.executor import run_guarded
from study.store import ResultStore  # noqa: E402


def main(argv):
    store = ResultStore(Path(argv[0]))
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        for job in argv[1:]:
            ov = job.split()
            t0, c0 = time.perf_counter(), time.process_time()
            cfg = compose(config_name="config", overrides=ov)
            conf = OmegaConf.to_container(cfg, resolve=True)
            run_conf, data = study_config(conf)
            t1, c1 = time.perf_counter(), time.process_time()
            rec = run_guarded(store, run_conf, lambda: run_study(conf, data=data), seed=int(conf.get("seed", 0)))
            t2, c2 = time.perf_counter(), time.process_time()
            tm = rec.get("timings") or {}
            run_wall = float(tm.get("wall", 0.0) or 0.0)
            print(json.dumps({"job": job, "status": rec.get("status"), "compose_s": t1 - t0, "compose_cpu": c1 - c0,
                              "guarded_s": t2 - t1, "guarded_cpu": c2 - c1, "run_s": run_wall,
                              "stages": {k: v for k, v in tm.items() if k != "wall"}}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
