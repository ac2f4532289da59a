"""How the results store's one folder of JSON records scales with the number of runs.

Records are copies of real ones (``--source``: a results folder, e.g. one ``bench_sweep.py`` or a sweep wrote),
each with its own run id, written into a fresh store of N records for N in ``--sizes``. Timed per N:

* ``write``: one more record written by ``ResultStore.write`` (lock, atomic rename) into the folder of N;
* ``status scan``: what the sweep's progress line did after every job before the status index (list the folder, read
  each record's first 256 bytes), and ``scan (seen)``: what it does now in a worker that has read the records
  before (``ResultStore.status_counts``: the listing, and only new or changed records read);
* ``collect``: ``ResultStore.collect()`` (parse every record, build and write both parquet tables), the step run
  at the end of every run and sweep.

``python benchmarks/bench_store.py --source results --sizes 1000,10000,30000``; figures go to
``benchmarks/results/bench_store.json``. Needs about 15 kB x the largest size of disk in the temp folder.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.store import ResultStore, run_id  # noqa: E402


def fill(store: ResultStore, sources: list[dict], n: int) -> None:
    d = store.root / "records"
    d.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        rec = dict(sources[i % len(sources)])
        rec["run_id"] = f"{i:016x}"
        (d / f"{rec['run_id']}.json").write_text(json.dumps(rec), encoding="utf-8")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", default=str(ROOT / "results"))
    ap.add_argument("--sizes", default="1000,10000,30000")
    args = ap.parse_args(argv)
    src = sorted((Path(args.source) / "records").glob("*.json"))
    if not src:
        sys.exit(f"bench_store: no records in {Path(args.source) / 'records'}; run a sweep or bench_sweep.py first")
    sources = [json.loads(p.read_text(encoding="utf-8")) for p in src]
    size = sum(p.stat().st_size for p in src) / len(src)
    out = {"record_kb": size / 1024, "sizes": {}}
    print(f"{len(sources)} source records, mean {size / 1024:.1f} kB")
    print(f"{'records':>9}{'write one':>12}{'status scan':>13}{'scan (seen)':>13}{'collect':>10}{'per record':>12}")
    for n in [int(s) for s in args.sizes.split(",")]:
        with tempfile.TemporaryDirectory() as tmp:
            store = ResultStore(Path(tmp))
            fill(store, sources, n)
            rec = dict(sources[0], config=dict(sources[0]["config"], seed=10 ** 9))
            rec["run_id"] = run_id(rec["config"])
            t0 = time.perf_counter()
            store.write(rec)
            t_write = time.perf_counter() - t0
            t0 = time.perf_counter()
            counts = {}
            for f in (store.root / "records").glob("*.json"):
                st = ResultStore._peek_status(f)
                counts[st] = counts.get(st, 0) + 1
            t_scan = time.perf_counter() - t0
            store.status_counts()  # a worker's first job reads every record once
            t0 = time.perf_counter()
            assert sum(store.status_counts().values()) == n + 1
            t_scan_seen = time.perf_counter() - t0
            t0 = time.perf_counter()
            runs, _ = store.collect()
            t_collect = time.perf_counter() - t0
            assert len(runs) == n + 1
            out["sizes"][n] = {"write_s": t_write, "scan_s": t_scan, "scan_seen_s": t_scan_seen,
                               "collect_s": t_collect}
            print(f"{n:>9}{t_write * 1e3:>10.1f}ms{t_scan:>12.2f}s{t_scan_seen:>12.3f}s{t_collect:>9.1f}s"
                  f"{t_collect / n * 1e3:>10.2f}ms", flush=True)
            shutil.rmtree(tmp, ignore_errors=True)
    res = ROOT / "benchmarks" / "results" / "bench_store.json"
    res.parent.mkdir(parents=True, exist_ok=True)
    res.write_text(json.dumps(out, indent=1))
    print(f"written {res}")


if __name__ == "__main__":
    main()
