"""Benchmark of the results store: what reading the records costs now that every record is checked, its code
compared and its run id made canonical, against the store before that change (in the same run).

Workload: N synthetic records shaped like a real run's (the default configuration composed by Hydra, seeds
varied; 165 metrics, 17 parameters, about 17 kB each), in a temp folder. Timed, best of ``--repeat``:

* ``tables``: build both tables from the records (what ``collect`` and ``show`` do), this version and the
  baseline version of ``study/commands/results.py`` (read from git, ``--baseline``; default: the commit before);
* ``collect``: this version, tables written (plus the crash-leftover scan);
* ``fingerprint``: the code fingerprint of one run, first call in a process and cached.

``python benchmarks/bench_results.py [--n 300 1000]`` writes ``benchmarks/results/bench_results.json``.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.store import fingerprint
from study import store as R  # noqa: E402

BASELINE = "62b33f6"  # the commit before canonical run ids, code fingerprints and record checks


def baseline_module(rev: str):
    src = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:study/commands/results.py"], capture_output=True,
                         text=True, check=True).stdout
    path = Path(tempfile.mkdtemp()) / "results_baseline.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("results_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def base_config() -> dict:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return OmegaConf.to_container(compose(config_name="config"), resolve=True)


def make_records(folder: Path, n: int, conf: dict) -> None:
    store = R.ResultStore(folder)
    store.records_dir.mkdir(parents=True, exist_ok=True)
    code = fingerprint.code_fingerprint(conf)
    prov = R.provenance()
    for i in range(n):
        c = {**conf, "seed": i}
        rid = R.run_id(c)
        rec = {"run_id": rid, "status": "ok", "error": None, "seed": i, "started": "2025-01-01T00:00:00+00:00",
               "finished": "2025-01-01T00:00:10+00:00", "config": c,
               "metrics": {f"metric_{k}": 0.001 * k * (i + 1) for k in range(165)},
               "params": [{"equation": "XYN"[k % 3], "name": f"p{k}", "estimate": 0.1 * k, "truth": 0.1 * k + 0.01,
                           "ci_low": None, "ci_high": None, "std": None, "vif": 1.5, "truth_kind": "exact"}
                          for k in range(17)],
               "timings": {"fit": 0.1, "wall": 10.0}, "code": code, "provenance": prov, "artefacts": []}
        (store.records_dir / f"{rid}.json").write_text(json.dumps(rec, indent=1))


def best(fn, repeat: int) -> float:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[300, 1000])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline", default=BASELINE)
    args = ap.parse_args()
    old = baseline_module(args.baseline)
    conf = base_config()

    fingerprint.clear_cache()
    t0 = time.perf_counter()
    fingerprint.code_fingerprint(conf)
    fp_first = time.perf_counter() - t0
    fp_cached = best(lambda: [fingerprint.code_fingerprint(conf) for _ in range(100)], args.repeat) / 100

    rows = []
    for n in args.n:
        folder = Path(tempfile.mkdtemp(prefix="bench_results_"))
        try:
            make_records(folder, n, conf)
            new_store, old_store = R.ResultStore(folder), old.ResultStore(folder)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t_old = best(old_store.tables, args.repeat)
                t_new = best(new_store.tables, args.repeat)
                t_collect = best(new_store.collect, args.repeat)
            row = {"records": n, "tables_baseline_s": t_old, "tables_s": t_new, "ratio": t_new / t_old,
                   "collect_s": t_collect, "per_record_ms": 1000 * t_new / n}
            rows.append(row)
            print(f"{n:6d} records: tables {t_new:6.2f} s (baseline {t_old:6.2f} s, x{t_new / t_old:4.2f}); "
                  f"collect {t_collect:6.2f} s; {row['per_record_ms']:.2f} ms a record")
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    print(f"code fingerprint of a run: {1000 * fp_first:.0f} ms the first time in a process, "
          f"{1e6 * fp_cached:.0f} us cached")
    out = {"platform": platform.platform(), "python": platform.python_version(), "baseline": args.baseline,
           "fingerprint_first_s": fp_first, "fingerprint_cached_s": fp_cached, "runs": rows}
    dest = ROOT / "benchmarks" / "results" / "bench_results.json"
    dest.write_text(json.dumps(out, indent=1) + "\n")
    print(f"written: {dest}")


if __name__ == "__main__":
    main()
