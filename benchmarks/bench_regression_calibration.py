"""Calibration of emcee's regression posteriors, per structure and likelihood, on the study's own simulated cases
(``study.run.calibration``: the posteriors in closed form, as ``EmceeSampler.fit`` samples them).

Cases (1 % white noise on every channel, ``noise=low``; trajectories fixed, the noise drawn afresh per dataset):

* ``kt``: the KT Mariner (``kt1_mariner``) identified as a first-order nonlinear Nomoto model (exact truth) from a
  10/10 zigzag sampled every 0.1 s (the simulation step, 0.0048 L/U0); K, T, alpha;
* ``kt_fine``: the same sampled every 0.02 s (simulation step 0.02 s), where euler's O(h) truncation is 5 times
  smaller;
* ``kt_1s``: the same sampled every 1 s (0.048 L/U0), where central's truncation and the regressors' noise bias
  the uncorrected posterior by about a sd together;
* ``kvlcc2``: KVLCC2 (full scale) with its MMG hull model (17 coefficients, exact truth) from the default training
  manoeuvres at half length (10/10 and 20/20 zigzags, random rudder; 0.1 s).

Likelihoods: ``regression`` (the default: the rows' noise modelled, their truncation and the regressors' noise
removed, ``study.identify.row_errors``), ``regression (uncorrected)`` (``correct_rows: false``: the likelihood before
the correction) and ``regression_iid``.

Structures: euler, central, integral, smoothed, diff_center, and diff_center without seed 000's random 80/20 split
and z-score cleaning (``diff_center_nosplit``: the differencing and centring alone). For each: coverage of the
truth and of the structure's noise-free limit by the 90 % intervals, the worst parameter's, median interval width
and error relative to the truth, the limit's bias in posterior sd, and the posterior sd over the actual spread of
the estimates.

``python benchmarks/bench_regression_calibration.py [--n 60] [--cases kt,kt_fine,kt_1s,kvlcc2]`` prints one table and
writes ``benchmarks/results/bench_regression_calibration.json``. Wall time with 60 datasets on this shared 2-core
machine, one thread: kt 2.4 minutes, kt_1s 0.6, kt_fine 4.1 (``benchmarks/results/bench_regression_calibration.json``);
kvlcc2 (``--cases kvlcc2``) about 5 s a corrected dataset (each builds 16 probes' MMG rows), 1.5 s uncorrected: 60
datasets of its six structures and three likelihoods take about 45 minutes (the README's column: 20 datasets).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.run import calibration as cal
from study.configuration.compose import read_config

DIFF_NOSPLIT = {**read_config("structure", "diff_center"), "name": "diff_center_nosplit", "split": {}, "clean": {}}
STRUCTURES = ["euler", "central", "integral", "smoothed", "diff_center", DIFF_NOSPLIT]
#: (likelihood, correct_rows) pairs: the default, the likelihood before the rows' errors were removed, independent rows
ALL = (("regression", True), ("regression", False), ("regression_iid", True))
CORRECTED = (("regression", True), ("regression", False))
CASES = {
    "kt": (dict(vessel="kt1_mariner", model="nomoto1_nl", train=["zigzag_10_10"]), STRUCTURES, ALL),
    "kt_fine": (dict(vessel="kt1_mariner", model="nomoto1_nl", train=["zigzag_10_10"], sim={"dt": 0.02}),
                ["euler", "central", DIFF_NOSPLIT], CORRECTED),
    "kt_1s": (dict(vessel="kt1_mariner", model="nomoto1_nl", train=["zigzag_10_10"], sample_dt=1.0),
              ["euler", "central", "integral", "smoothed", "diff_center", DIFF_NOSPLIT], CORRECTED),
    "kvlcc2": (dict(vessel="kvlcc2", model="mmg_hull", train=["zigzag_10_10", "zigzag_20_20", "random_rudder"],
                    sim={"duration_scale": 0.5}), STRUCTURES, ALL),
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="datasets per structure and likelihood")
    ap.add_argument("--cases", default="kt,kt_fine,kt_1s,kvlcc2")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_regression_calibration.json"))
    a = ap.parse_args(argv)
    pd.set_option("display.width", 250)
    pd.set_option("display.max_columns", 30)
    rows, timings = [], {}
    for name in a.cases.split(","):
        if name not in CASES:
            raise SystemExit(f"--cases: unknown case {name!r}; expected some of {sorted(CASES)}")
        spec, structures, likelihoods = CASES[name]
        case = cal.make_case(name=name, **spec)
        for st in structures:
            for lik, correct in likelihoods:
                t0 = time.perf_counter()
                df = cal.coverage(case, st, n=a.n, likelihood=lik, correct=correct)
                sname = st if isinstance(st, str) else st["name"]
                timings[f"{name}/{sname}/{df['likelihood'].iloc[0]}"] = time.perf_counter() - t0
                s = cal.summary(df)
                print(s.round(3).to_string(header=not rows), flush=True)
                rows.append(s)
    table = pd.concat(rows, ignore_index=True)
    print()
    print(table.round(3).to_markdown(index=False))
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"n_datasets": a.n, "summary": table.to_dict(orient="records"),
                               "seconds": timings}, indent=1))
    print(f"\nwritten: {out}")


if __name__ == "__main__":
    main()
