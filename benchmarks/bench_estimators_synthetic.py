"""Benchmark of the regression estimators (conf/estimator/*.yaml) on synthetic manoeuvre-like regressors.

Workload: 16,800 samples (seed 000's training set: 21,000 samples at 0.1 s, 80 %) x 5 and x 11 columns, built
like the test data (``tests/identify/test_estimators.py``): smooth correlated signals, columns scaled over 1e-3..1e2,
one pair correlated 0.99; y = X theta + 2 % of std(y) white noise. Default hyper-parameters (the YAMLs).

Reported per estimator and column count:

* fit time, median of repeats after a warm-up fit (imports, numba/BLAS first calls), and its ratio to ``ls``;
* memory: the tracemalloc peak of one fit (Python and numpy allocations; the QP solver's Rust and libsvm's
  C++ buffers are not seen by tracemalloc);
* the largest relative coefficient error (for orientation only: noise and collinearity, not speed);
* PASS/MISS against the targets: ls, ridge, lssvm, tlssvm < 50 ms; svr_eps, svr_nu < 10 s; sindy < 2 s.

Then libsvm (sklearn ``SVR`` / ``NuSVR``) against the primal QP (Clarabel) for both SVRs on the same data,
at C = 0.01, where libsvm finishes in under a minute (its time grows steeply with C: measured at 16,800 x 5,
C = 0.1: 29-45 s; C = 1: 71-113 s); each libsvm fit runs in a child process killed after 60 s.

Everything runs on one core with one BLAS thread, like ``bench_sim.py`` (multi-threaded OpenBLAS on a busy
2-core machine makes tall-skinny QR/SVD 10-20x slower). ``--quick``: 3,000 samples, one repeat, libsvm at
the small size only (a smoke run, no targets).
"""
from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import multiprocessing as mp  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.identify.estimators import make_estimator  # noqa: E402
from study.identify.synthetic import manoeuvre_regressors  # noqa: E402

NAMES = ["ls", "ridge", "lasso", "lssvm", "tlssvm", "lssvm_online", "svr_eps", "svr_nu", "sindy"]
TARGET_S = {"ls": 0.05, "ridge": 0.05, "lssvm": 0.05, "tlssvm": 0.05, "svr_eps": 10.0, "svr_nu": 10.0, "sindy": 2.0}
N_FULL = 16_800
C_LIBSVM = 0.01
LIBSVM_TIMEOUT = 60.0




def _pin_one_core():
    try:
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return cpu
    except (AttributeError, OSError):  # not Linux
        return None


def _data(n, k):
    X, th = manoeuvre_regressors(n=n, k=k, seed=1)
    y = X @ th
    y = y + 0.02 * np.std(y) * np.random.default_rng(0).standard_normal(n)
    return X, y, th


def _time_fit(name, X, y, repeats, **params):
    t0 = time.perf_counter()
    make_estimator(name, **params).fit(X, y)  # warm-up
    if repeats is None:  # 5 repeats, 3 for fits above a second
        repeats = 5 if time.perf_counter() - t0 < 1.0 else 3
    ts = []
    est = None
    for _ in range(repeats):
        est = make_estimator(name, **params)
        t0 = time.perf_counter()
        est.fit(X, y)
        ts.append(time.perf_counter() - t0)
    tracemalloc.start()
    make_estimator(name, **params).fit(X, y)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return float(np.median(ts)), peak / 2 ** 20, est


def _libsvm_child(conn, name, X, y, C):
    est = make_estimator(name, C=C, solver="libsvm")
    t0 = time.perf_counter()
    est.fit(X, y)
    conn.send((time.perf_counter() - t0, est.coef_))
    conn.close()


def _libsvm_vs_qp(name, X, y, C, timeout):
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_libsvm_child, args=(child, name, X, y, C))
    p.start()
    got = parent.recv() if parent.poll(timeout) else None
    if got is None:
        p.kill()
    p.join()
    qp = make_estimator(name, C=C, solver="qp")
    t0 = time.perf_counter()
    qp.fit(X, y)
    t_qp = time.perf_counter() - t0
    if got is None:
        return {"estimator": name, "C": C, "libsvm_s": f"> {timeout:.0f}", "qp_s": t_qp, "max_coef_diff_rel": None}
    t_lib, coef = got
    diff = float(np.max(np.abs(coef - qp.coef_)) / np.max(np.abs(qp.coef_)))
    return {"estimator": name, "C": C, "libsvm_s": t_lib, "qp_s": t_qp, "speed-up": t_lib / t_qp,
            "max_coef_diff_rel": diff}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run: 3,000 samples, one repeat, no targets")
    ap.add_argument("--repeats", type=int, default=None, help="timed fits per case (default 5; 3 above 1 s)")
    ap.add_argument("--names", nargs="*", default=NAMES, help="estimator configs to run")
    ap.add_argument("--libsvm-C", type=float, nargs="*", default=[C_LIBSVM],
                    help=f"C values of the libsvm/QP comparison (default {C_LIBSVM}; libsvm is killed after 60 s)")
    ap.add_argument("--json", type=Path, default=None, help="also write the tables to this JSON file")
    args = ap.parse_args(argv)
    warnings.simplefilter("error")  # a warning in a default fit is a bug worth stopping the benchmark for
    cpu = _pin_one_core()
    n = 3000 if args.quick else N_FULL  # 3000: above max_dual, the default (primal) paths of the full size
    print(f"# estimators on synthetic regressors: n = {n}, one core (cpu {cpu}), one BLAS thread")
    rows = []
    for k in (5, 11):
        X, y, th = _data(n, k)
        t_ls = None
        for name in args.names:
            t, mem, est = _time_fit(name, X, y, 1 if args.quick else args.repeats)
            if name == "ls":
                t_ls = t
            target = TARGET_S.get(name)
            rows.append({"k": k, "estimator": name, "time_ms": 1e3 * t, "x_ls": (t / t_ls) if t_ls else np.nan,
                         "peak_MiB": mem, "max_rel_err": float(np.max(np.abs(est.coef_ - th) / np.abs(th))),
                         "target_ms": 1e3 * target if target else np.nan,
                         "status": ("" if (args.quick or target is None) else ("PASS" if t < target else "MISS")),
                         "note": ", ".join(f"{a}={v:.3g}" if isinstance(v, float) else f"{a}={v}"
                                           for a, v in est.diagnostics_.items()
                                           if a in ("alpha", "lambda", "gamma", "rank", "form", "n_selected",
                                                    "threshold", "solver", "n_converged"))})
            print(f"  k={k:2d} {name:13s} {1e3 * t:10.1f} ms  peak {mem:7.1f} MiB", flush=True)
    table = pd.DataFrame(rows)
    print()
    print(table.to_markdown(index=False, floatfmt=".3g"))
    print()
    n_svm = 300 if args.quick else n
    print(f"# libsvm against the primal QP (Clarabel), n = {n_svm}, C = {args.libsvm_C}, libsvm killed after "
          f"{LIBSVM_TIMEOUT:.0f} s")
    cmp_rows = []
    for C in args.libsvm_C:
        for k in (5, 11):
            X, y, _ = _data(n_svm, k)
            for name in ("svr_eps", "svr_nu"):
                r = _libsvm_vs_qp(name, X, y, C, LIBSVM_TIMEOUT)
                r["k"] = k
                cmp_rows.append(r)
                print(f"  C={C:g} k={k:2d} {name}: libsvm {r['libsvm_s']} s, qp {r['qp_s']:.2f} s, "
                      f"max coef diff {r['max_coef_diff_rel']}", flush=True)
    cmp = pd.DataFrame(cmp_rows)
    print()
    print(cmp.to_markdown(index=False, floatfmt=".3g"))
    if not args.quick:
        missed = table[table["status"] == "MISS"]
        print("\nall targets met" if missed.empty else f"\nMISSED: {missed[['k', 'estimator']].values.tolist()}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"n": n, "fits": rows, "libsvm_vs_qp": cmp_rows}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
