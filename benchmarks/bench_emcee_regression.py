"""Benchmark of emcee on the regression likelihoods: the closed-form proposal (``moves: auto``) against the code
before (``old``: the DE moves with emcee's own snooker move, and the noise model's whitening by scipy's general
banded solve, patched back in for those fits), in the same run, on the same rows, and both against the posterior
in closed form.

Workloads:

* **seed 000's training set** (``bench_identify.py``: the waterjet USV, 16,800 central-difference rows per
  equation, 11 coefficients), target ESS 1,000 (the estimator's default), likelihoods ``regression`` and
  ``regression_iid``.
* **grand-like problems**: the 6 cases of ``grand`` (manoeuvres at half length) on central rows, medium relative
  noise, deep water, sampled at 0.005 and 0.05 L/U0, target ESS 400 (grand's ``estimator_overrides``), the
  ``regression`` likelihood with the structure's noise operators, as a run fits them (``prepare(...,
  operators=True)``).
* **an informative prior** (``prior: {source: offset}``: the MAP estimator's posterior) on KVLCC2's MMG hull.

Per fit (one equation): wall and CPU time of the whole fit (the closed form included) and of the sampling alone
(the fit less the closed form, timed separately, each with its own code), steps, acceptance, tau, ESS; per
problem the ratio new / old.
Posterior: per coefficient the chain's median and 5 %, 95 % quantiles against the closed form's (normal: mean,
mean -+ 1.645 sd; ``regression_iid``: the normal at its most probable noise scale, ``study.run.calibration``), in
units of their Monte Carlo standard error at the chain's reported ESS (1.25 / sqrt(ESS) posterior sd for the
median, 2.11 / sqrt(ESS) for a 5 % quantile): within about 3 of them for 11-15 coefficients if the chain samples
the closed form and its ESS is honest.

``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_emcee_regression.py [--quick]``; figures go to
``benchmarks/results/bench_emcee_regression.json``.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from study.identify.estimators import make_estimator  # noqa: E402
from study.identify.rows import prepare  # noqa: E402

GRAND_CASES = ("kvlcc2_mmg", "kcs_mmg", "usv_full", "mariner_abkowitz", "auv", "kt_nomoto2")
Z95 = 1.6448536269514722
SE_MEDIAN, SE_Q05 = 1.2533, 2.1132  # Monte Carlo sd of a median, of a 5 % quantile, x sqrt(ESS), in posterior sd


def grand_problem(case: str, sample_dt_LU: float, seed: int = 0):
    """(model, structure, records, estimator config) of one grand job: ``case``, central rows, medium relative
    noise, deep water, emcee with grand's overrides (what ``study.run.pipeline.run_study`` builds)."""
    from study.configuration.compose import compose
    from study.identify.models import make_model
    from study.identify.structures import make_structure
    from study.run.pipeline import measurement, simulate_set, vessels_for
    from study.run.common import estimator_config

    conf = compose("config", ["experiment=grand", f"case={case}", "structure=central", "noise=medium_relative",
                              f"noise.sample_dt_LU={sample_dt_LU}", "depth=deep", "estimator=emcee"])
    truth, base = vessels_for(conf)
    model = make_model(conf["model"], base)
    clean = simulate_set(truth, conf["maneuvers"]["train"], conf, seed_base=1000 * seed)
    recs = [measurement(conf, seed=seed * 7919 + i, vessel=truth).apply(df) for i, df in enumerate(clean.values())]
    return model, make_structure(conf["structure"]), recs, estimator_config(conf)


def closed_form(est, X, y, ops, likelihood, prior=None):
    """(mean, sd) of the posterior in closed form, and its wall time."""
    from study.run import calibration as cal
    from study.identify.estimators.prior import gaussian_posterior

    t0 = time.perf_counter()
    Xa, ya = np.asarray(X, float), np.asarray(y, float)
    if prior is not None:
        mean0 = np.array([prior[c][0] for c in X.columns], float)
        sd0 = np.array([prior[c][1] for c in X.columns], float)
        mean, cov, _ = gaussian_posterior(Xa, ya, mean0, sd0)
    elif likelihood == "regression":
        mean, cov, _, _ = est.gaussian_regression(Xa, ya, ops)
    else:
        mean, cov, _ = cal._iid_posterior(Xa, ya, est._default_prior_sd(Xa, ya))
    return mean, np.sqrt(np.diag(cov)), time.perf_counter() - t0


@contextlib.contextmanager
def code_before():
    """The code before this change: emcee's own ``DESnookerMove`` in the DE moves, scipy's ``solve_banded`` (LU of
    the triangle) in the noise model's whitening."""
    import emcee
    from scipy import linalg

    from study.identify import row_noise
    from study.identify.estimators import bayes

    saved = bayes.SnookerMove, row_noise.solve_lower_banded
    bayes.SnookerMove = emcee.moves.DESnookerMove
    row_noise.solve_lower_banded = lambda c, B: linalg.solve_banded((c.shape[0] - 1, 0), c, np.asarray(B, float))
    try:
        yield
    finally:
        bayes.SnookerMove, row_noise.solve_lower_banded = saved


def fit_once(params: dict, X, y, ops, prior=None, before=False):
    est = make_estimator("emcee", **params)
    with code_before() if before else contextlib.nullcontext():
        t0, c0 = time.perf_counter(), time.process_time()
        est.fit(X, y, noise_operators=ops, prior=prior)
        return est, time.perf_counter() - t0, time.process_time() - c0


def compare(est, mean, sd) -> dict:
    """The chain's median and 90 % interval against the closed form, in Monte Carlo standard errors."""
    ess = est.diagnostics_["ess"]
    th = est.samples_all_[:, :len(mean)]
    med = np.median(th, axis=0)
    lo, hi = np.quantile(th, [0.05, 0.95], axis=0)
    dm = (med - mean) / sd
    dq = np.maximum(np.abs(lo - (mean - Z95 * sd)), np.abs(hi - (mean + Z95 * sd))) / sd
    return {"median_diff_sd": float(np.max(np.abs(dm))), "interval_diff_sd": float(np.max(dq)),
            "median_diff_mcse": float(np.max(np.abs(dm)) * np.sqrt(ess) / SE_MEDIAN),
            "interval_diff_mcse": float(np.max(dq) * np.sqrt(ess) / SE_Q05),
            "sd_ratio_min": float(np.min(th.std(axis=0) / sd)), "sd_ratio_max": float(np.max(th.std(axis=0) / sd))}


def bench_problem(label: str, prepared: dict, base_params: dict, likelihood: str, prior=None, repeats: int = 1):
    rows = []
    for eq, p in prepared.items():
        ops = p.noise_operators if likelihood == "regression" and prior is None else None
        eq_prior = None if prior is None else {n: prior[n] for n in p.X.columns}
        ref = make_estimator("emcee", **base_params, likelihood=likelihood)
        closed_form(ref, p.X, p.y, ops, likelihood, eq_prior)  # warm-up (imports)
        mean, sd, t_closed = closed_form(ref, p.X, p.y, ops, likelihood, eq_prior)
        with code_before():
            t_closed_old = closed_form(ref, p.X, p.y, ops, likelihood, eq_prior)[2]
        row = {"problem": label, "equation": eq, "k": int(p.X.shape[1]), "rows": int(len(p.y)),
               "likelihood": likelihood if prior is None else "informative prior", "closed_form_s": t_closed,
               "closed_form_old_s": t_closed_old}
        for name, moves in (("old", "de"), ("new", "auto")):
            ts, cs = [], []
            for _ in range(repeats):  # interleaved with the other's repeats would be fairer; one each is enough
                est, t, c = fit_once({**base_params, "likelihood": likelihood, "moves": moves}, p.X, p.y, ops,
                                     eq_prior, before=name == "old")
                ts.append(t)
                cs.append(c)
            d = est.diagnostics_
            row[name] = {"fit_s": float(np.median(ts)), "fit_cpu": float(np.median(cs)),
                         "sampling_s": max(float(np.median(ts)) - ((t_closed_old if name == "old" else t_closed)
                                                                   if ops is not None else 0.0), 0.0),
                         "moves": est.moves_, **{k: float(d[k]) for k in ("steps", "acceptance", "tau_max", "ess",
                                                                          "converged")},
                         "against_closed_form": compare(est, mean, sd)}
            row[name]["_median"] = np.median(est.samples_all_[:, :len(mean)], axis=0)
        o, n = row["old"], row["new"]
        row["ratio_fit"] = n["fit_s"] / o["fit_s"]
        row["ratio_sampling"] = n["sampling_s"] / o["sampling_s"] if o["sampling_s"] > 0 else float("nan")
        row["new_vs_old_median_sd"] = float(np.max(np.abs(n.pop("_median") - o.pop("_median")) / sd))
        c_o, c_n = o["against_closed_form"], n["against_closed_form"]
        print(f"{label:<34}{eq:>2} k={row['k']:>2} {likelihood if prior is None else 'prior':<14}"
              f"old {o['fit_s']:6.2f}s {o['steps']:>5.0f} st tau {o['tau_max']:5.1f} acc {o['acceptance']:.2f} "
              f"ESS {o['ess']:5.0f} | new {n['fit_s']:5.2f}s {n['steps']:>4.0f} st tau {n['tau_max']:4.2f} "
              f"acc {n['acceptance']:.2f} ESS {n['ess']:5.0f} | ratio {row['ratio_fit']:.2f} "
              f"(sampling {row['ratio_sampling']:.2f}) | closed form: old {c_o['median_diff_mcse']:.1f}/"
              f"{c_o['interval_diff_mcse']:.1f} new {c_n['median_diff_mcse']:.1f}/{c_n['interval_diff_mcse']:.1f} "
              f"mcse, sd ratio old {c_o['sd_ratio_min']:.2f}-{c_o['sd_ratio_max']:.2f} new {c_n['sd_ratio_min']:.2f}-"
              f"{c_n['sd_ratio_max']:.2f}; closed form {t_closed_old:.2f} -> {t_closed:.2f} s", flush=True)
        rows.append(row)
    return rows


def totals(rows: list, label: str) -> dict:
    o = sum(r["old"]["fit_s"] for r in rows)
    n = sum(r["new"]["fit_s"] for r in rows)
    oc = sum(r["old"]["fit_cpu"] for r in rows)
    nc = sum(r["new"]["fit_cpu"] for r in rows)
    so = sum(r["old"]["sampling_s"] for r in rows)
    sn = sum(r["new"]["sampling_s"] for r in rows)
    out = {"fits": len(rows), "old_s": o, "new_s": n, "ratio": n / o, "old_cpu": oc, "new_cpu": nc,
           "ratio_cpu": nc / oc, "old_sampling_s": so, "new_sampling_s": sn, "ratio_sampling": sn / so,
           "closed_form_s": sum(r["closed_form_s"] for r in rows if r["likelihood"] == "regression"),
           "closed_form_old_s": sum(r["closed_form_old_s"] for r in rows if r["likelihood"] == "regression")}
    print(f"== {label}: {len(rows)} fits, old {o:.1f} s (cpu {oc:.1f}), new {n:.1f} s (cpu {nc:.1f}): ratio "
          f"{out['ratio']:.2f} (cpu {out['ratio_cpu']:.2f}); sampling alone old {so:.1f} s, new {sn:.1f} s: ratio "
          f"{out['ratio_sampling']:.3f}; the closed form (rows' noise model) {out['closed_form_old_s']:.1f} -> "
          f"{out['closed_form_s']:.1f} s", 
          flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke run: 300 s of seed 000's record, 2 grand cases")
    args = ap.parse_args(argv)
    from bench_identify import seed000_training

    out = {"platform": platform.platform(), "cpus": os.cpu_count(), "load_before": os.getloadavg(),
           "quick": args.quick}
    _, model, structure, recs = seed000_training(duration=300.0 if args.quick else None)
    prepared = prepare(model, structure, recs, operators=True)
    seed000 = []
    for lik in ("regression", "regression_iid"):
        seed000 += bench_problem(f"seed000 ({lik})", prepared, {}, lik)
    out["seed000"] = {"rows": seed000, "total": totals(seed000, "seed 000 training set, target ESS 1000")}
    grand = []
    cases = GRAND_CASES[:2] if args.quick else GRAND_CASES
    for dt in ((0.005,) if args.quick else (0.005, 0.05)):
        for case in cases:
            model, st, recs, cfg = grand_problem(case, dt)
            params = {k: v for k, v in cfg["params"].items() if k not in ("moves", "likelihood", "prior")}
            grand += bench_problem(f"grand {case} central {dt} L/U0", prepare(model, st, recs, operators=True),
                                   params, "regression")
    out["grand"] = {"rows": grand, "total": totals(grand, "grand-like, central rows, target ESS 400")}
    from study.identify.priors import prior_for

    model, st, recs, cfg = grand_problem("kvlcc2_mmg", 0.005)
    prior = prior_for(model, {"source": "offset", "sd": 0.3, "offset": 0.2})
    params = {k: v for k, v in cfg["params"].items() if k not in ("moves", "likelihood", "prior")}
    inf = bench_problem("kvlcc2_mmg, informative prior", prepare(model, st, recs), params, "regression", prior)
    out["informative"] = {"rows": inf, "total": totals(inf, "informative prior")}
    out["load_after"] = os.getloadavg()
    res = ROOT / "benchmarks" / "results" / ("bench_emcee_regression_quick.json" if args.quick
                                             else "bench_emcee_regression.json")
    res.parent.mkdir(parents=True, exist_ok=True)
    res.write_text(json.dumps(out, indent=1, default=float))
    print(f"load average before/after: {out['load_before']} / {out['load_after']}; written {res}")


if __name__ == "__main__":
    main()
