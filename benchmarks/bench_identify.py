"""Benchmark of the identifiers on seed 000's training set, and of DE and emcee on their own workloads.

Workloads (all figures in one run, with the ratios to least squares):

* **Seed 000's training set**: the waterjet USV (``usv_waterjet``), the continuous 10/10..30/30 zigzag sequence
  (2100 s at 0.1 s, 21,000 samples), 1 % measurement noise, the simplified model of its eq. 13
  (``mmg_simplified``: 11 coefficients, 3 + 5 + 3 per equation), central-difference rows with the seed's 80 %
  training split: 16,800 rows per equation. Every regression estimator fits the three equations; reported:
  fit time (median of repeats), peak memory of the fit (tracemalloc: Python and numpy allocations), and the
  median drift against the truth. libsvm is compared with the QP with an intercept (libsvm always fits one). Targets: ls, ridge, lssvm, tlssvm < 50 ms; svr_eps, svr_nu < 10 s; sindy
  < 2 s. libsvm (scikit-learn's SVR) is timed on the same rows where it finishes within a time limit, and its
  coefficients compared with the primal QP's.
* **DE**: the nonlinear first-order KT model (``nomoto1_nl``) from one 300 s 20/20 zigzag of ``kt1_mariner``
  (1 % noise on r and psi), by output error. Target < 30 s.
* **emcee, regression likelihood**: the 11 coefficients on the 16,800 rows (per equation), until at least 1,000
  effective samples in every equation, with the rows' noise modelled (the default) and as independent rows
  (``regression_iid``). Target < 60 s.
* **emcee, output-error likelihood**: the same 11 coefficients simulated through the 2100 s record (with the
  record's initial u, v, r as nuisance parameters). Target < 10 minutes. Skipped with ``--quick``.

Runs on the machine as it is (2 cores: numba and BLAS may use both). ``python benchmarks/bench_identify.py``
writes ``benchmarks/results/bench_identify.json``; ``--quick`` (a smoke run: 300 s of the sequence, few
repeats, no targets, no output-error emcee) writes ``bench_identify_quick.json``.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import platform
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.identify.estimators import list_estimators, make_estimator  # noqa: E402
from study.identify.fit import identify  # noqa: E402
from study.identify.rows import prepare  # noqa: E402
from study.identify.models import make_model  # noqa: E402
from study.identify.structures import make_structure  # noqa: E402
from study.records.measure import MeasurementModel
from study.configuration.compose import read_config
from study.sim import load_vessel, simulate  # noqa: E402

TARGETS_S = {"ls": 0.05, "ridge": 0.05, "lssvm": 0.05, "tlssvm": 0.05, "svr_eps": 10.0, "svr_nu": 10.0,
             "sindy": 2.0, "de_kt": 30.0, "emcee_regression": 60.0, "emcee_output_error": 600.0}
LIBSVM_LIMIT_S = 120.0


def seed000_training(duration=None):
    v = load_vessel("usv_waterjet")
    clean = simulate(v, "seed000_sequence", duration=duration)
    rec = MeasurementModel(noise_level=0.01, seed=0).apply(clean)
    model = make_model("mmg_simplified", v)
    structure = make_structure({"name": "central_80", "kind": "central",
                                "split": {"train_fraction": 0.8, "how": "random"}})
    return v, model, structure, [rec]


def _fit_all(est_name, prepared, overrides=None):
    coefs = {}
    for eq, p in prepared.items():
        est = make_estimator(est_name, **(overrides or {})).fit(p.X, p.y)
        coefs.update(dict(zip(p.X.columns, np.ravel(est.coef_))))
    return coefs, est


def _drift(coefs, truth):
    rel = [abs(coefs[n] - t) / abs(t) for n, t in truth.items() if t and n in coefs]
    return float(np.median(rel))


def time_regression(prepared, truth, repeats):
    rows = {}
    for name in list_estimators():
        est = make_estimator(name)
        if "regression" not in est.problem_types or name == "emcee":
            continue
        _fit_all(name, prepared)  # warm-up (imports, compilation)
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            coefs, _ = _fit_all(name, prepared)
            ts.append(time.perf_counter() - t0)
        tracemalloc.start()
        _fit_all(name, prepared)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        rows[name] = {"time_s": float(np.median(ts)), "peak_mb": peak / 2 ** 20, "drift_median": _drift(coefs, truth)}
    return rows


def _libsvm_worker(name, X_by_eq, y_by_eq, q):
    out = {}
    t0 = time.perf_counter()
    for eq in X_by_eq:
        est = make_estimator(name, solver="libsvm", fit_intercept=True).fit(X_by_eq[eq], y_by_eq[eq])
        out[eq] = np.ravel(est.coef_).tolist()
    q.put((time.perf_counter() - t0, out))


def time_libsvm(prepared, limit):
    """libsvm on the same rows, in a child process killed after ``limit`` seconds."""
    rows = {}
    for name in ("svr_eps", "svr_nu"):
        if name not in list_estimators():
            continue
        q = mp.Queue()
        X = {eq: p.X for eq, p in prepared.items()}
        y = {eq: p.y for eq, p in prepared.items()}
        proc = mp.Process(target=_libsvm_worker, args=(name, X, y, q))
        proc.start()
        proc.join(limit)
        if proc.is_alive():
            proc.terminate()
            rows[name] = {"libsvm_time_s": None, "note": f"not finished in {limit:.0f} s"}
            continue
        if proc.exitcode != 0 or q.empty():
            rows[name] = {"libsvm_time_s": None, "note": f"libsvm run failed (exit code {proc.exitcode})"}
            continue
        t, coefs = q.get(timeout=10)
        qp = {eq: np.ravel(make_estimator(name, solver="qp", fit_intercept=True).fit(p.X, p.y).coef_)
              for eq, p in prepared.items()}
        diff = max(float(np.max(np.abs(np.array(coefs[eq]) - qp[eq]) / np.max(np.abs(qp[eq])))) for eq in qp)
        rows[name] = {"libsvm_time_s": t, "max_rel_coef_diff_libsvm_vs_qp": diff}
    return rows


def time_de(quick):
    v = load_vessel("kt1_mariner")
    model = make_model("nomoto1_nl", v)
    rec = MeasurementModel(noise_level={"r": 0.01, "psi": 0.01}, seed=1).apply(
        simulate(v, "zigzag_20_20", duration=300))
    t0 = time.perf_counter()
    ident = identify(model, make_structure("output_error"), read_config("estimator", "de"), [rec])
    t = time.perf_counter() - t0
    truth = model.truth()[0]
    err = {p["name"]: abs(p["estimate"] - truth[p["name"]]) / abs(truth[p["name"]]) for p in ident.params}
    return {"time_s": t, "rel_errors": err, "simulations": ident.metrics.get("est_simulations"),
            "samples": ident.metrics.get("oe_samples")}


def time_emcee_regression(prepared, truth, likelihood="regression"):
    """emcee as a run calls it: with the structure's noise operators (``prepare(..., operators=True)``)."""
    t0 = time.perf_counter()
    ess, steps = [], []
    coefs = {}
    for eq, p in prepared.items():
        est = make_estimator("emcee", likelihood=likelihood).fit(p.X, p.y, noise_operators=p.noise_operators)
        ess.append(est.diagnostics_["ess"])
        steps.append(est.diagnostics_["steps"])
        coefs.update(dict(zip(p.X.columns, est.coef_)))
    return {"time_s": time.perf_counter() - t0, "min_ess": float(min(ess)), "steps": steps,
            "drift_median": _drift(coefs, truth)}


def time_emcee_oe(model, records, truth):
    cfg = read_config("estimator", "emcee")
    t0 = time.perf_counter()
    ident = identify(model, make_structure("output_error"), cfg, records, progress=True)
    t = time.perf_counter() - t0
    est = {p["name"]: p["estimate"] for p in ident.params}
    return {"time_s": t, "ess": ident.metrics.get("est_ess"), "steps": ident.metrics.get("est_steps"),
            "converged": ident.metrics.get("est_converged"), "drift_median": _drift(est, truth),
            "simulations": None}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke run: short record, 1 repeat, no OE emcee")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else 5
    v, model, structure, recs = seed000_training(duration=300.0 if args.quick else None)
    truth = model.truth()[0]
    t0 = time.perf_counter()
    prepared = prepare(model, structure, recs)
    t_prep = time.perf_counter() - t0
    n_rows = {eq: int(len(p.y)) for eq, p in prepared.items()}
    print(f"seed 000 training set: {len(recs[0])} samples -> rows per equation {n_rows}; "
          f"{sum(len(c) for c in model.equations.values())} parameters; rows built in {t_prep:.2f} s")
    out = {"workload": "seed000 training set (usv_waterjet, seed000_sequence, 1 % noise, mmg_simplified, "
                       "central, 80 % split)", "rows": n_rows, "quick": args.quick,
           "platform": platform.platform(), "python": platform.python_version()}
    reg = time_regression(prepared, truth, repeats)
    base = reg["ls"]["time_s"]
    print(f"\n{'estimator':<14}{'fit [ms]':>12}{'x ls':>9}{'peak MB':>10}{'drift':>9}  target")
    for name, r in reg.items():
        tgt = TARGETS_S.get(name)
        verdict = "" if tgt is None or args.quick else ("PASS" if r["time_s"] < tgt else "MISS") + f" < {tgt * 1e3:g} ms"
        r["ratio_to_ls"] = r["time_s"] / base
        print(f"{name:<14}{r['time_s'] * 1e3:>12.1f}{r['ratio_to_ls']:>9.1f}{r['peak_mb']:>10.1f}"
              f"{r['drift_median']:>9.3f}  {verdict}")
    out["regression"] = reg
    if not args.quick:
        lib = time_libsvm(prepared, LIBSVM_LIMIT_S)
        for name, r in lib.items():
            print(f"{name} by libsvm: " + (f"{r['libsvm_time_s']:.1f} s, max coefficient difference to the QP "
                                           f"{r['max_rel_coef_diff_libsvm_vs_qp']:.1e}" if r.get("libsvm_time_s")
                                           else r["note"]))
        out["libsvm"] = lib
    de = time_de(args.quick)
    print(f"\nDE, nomoto1_nl from a 300 s zigzag by output error: {de['time_s']:.1f} s "
          f"({de['simulations']} simulations of {de['samples']} samples); errors "
          + ", ".join(f"{k} {v:.3f}" for k, v in de["rel_errors"].items()))
    out["de_kt"] = de
    t0 = time.perf_counter()
    prepared = prepare(model, structure, recs, operators=True)
    t_ops = time.perf_counter() - t0
    for lik in ("regression", "regression_iid"):
        em = time_emcee_regression(prepared, truth, lik)
        print(f"emcee, {lik} likelihood, 11 parameters: {em['time_s']:.1f} s, min ESS {em['min_ess']:.0f}, "
              f"steps {em['steps']}" + (f" (rows and noise operators built in {t_ops:.2f} s)"
                                        if lik == "regression" else ""))
        out["emcee_regression" if lik == "regression" else "emcee_regression_iid"] = em
    if not args.quick:
        eo = time_emcee_oe(model, recs, truth)
        print(f"emcee, output-error likelihood, 11 parameters + 3 initial states: {eo['time_s']:.0f} s, ESS "
              f"{eo['ess']}, steps {eo['steps']}, converged {eo['converged']}")
        out["emcee_output_error"] = eo
    if not args.quick:
        print("\ntargets: " + ", ".join(
            f"{k} {'PASS' if (out.get(k) or {}).get('time_s', 1e9) < v else 'MISS'}"
            for k, v in TARGETS_S.items() if k in ("de_kt", "emcee_regression", "emcee_output_error")))
    res = ROOT / "benchmarks" / "results" / ("bench_identify_quick.json" if args.quick else "bench_identify.json")
    res.parent.mkdir(parents=True, exist_ok=True)
    res.write_text(json.dumps(out, indent=1, default=float))
    print(f"\nwritten {res}")


if __name__ == "__main__":
    main()
