"""What removing the rows' errors costs: one emcee regression run (``study.identify.fit.identify``) with the
default ``correct_rows: true`` (the rows' truncation and the regressors' noise removed, ``study.identify.row_errors``)
against ``correct_rows: false`` (the likelihood before), in the same process, on the same records.

Cases (1 % relative noise, ``noise=low_relative``):

* ``kt``: the KT Mariner, first-order nonlinear Nomoto (3 coefficients), 10/10 zigzag at 0.1 s (8,300 rows);
* ``kt_1s``: the same at 1 s;
* ``kvlcc2``: KVLCC2's MMG hull (17 coefficients in 3 equations), the standard training manoeuvres at half length
  (28,100 rows per equation), where building the rows of one probe costs about 70 ms.

Per case and setting: the median wall and CPU time of ``--repeats`` runs (each structure central, target ESS 400),
the time the run spent building the row errors (``t_row_errors``: truncation rows and the probes), and the ratio
corrected / uncorrected.

``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_row_errors.py [--repeats 3]``; figures go to
``benchmarks/results/bench_row_errors.json``.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.run import calibration as cal
from study.configuration.compose import read_config
from study.identify.fit import identify  # noqa: E402
from study.identify.structures import make_structure  # noqa: E402

CASES = {
    "kt": dict(vessel="kt1_mariner", model="nomoto1_nl", train=["zigzag_10_10"]),
    "kt_1s": dict(vessel="kt1_mariner", model="nomoto1_nl", train=["zigzag_10_10"], sample_dt=1.0),
    "kvlcc2": dict(vessel="kvlcc2", model="mmg_hull", train=["zigzag_10_10", "zigzag_20_20", "random_rudder"],
                   sim={"duration_scale": 0.5}),
}


def one_run(case, correct: bool, seed: int) -> dict:
    cfg = dict(read_config("estimator", "emcee"))
    cfg["params"] = dict(cfg["params"], target_ess=400, correct_rows=correct)
    recs = cal.records(case, seed)
    w, c = time.perf_counter(), time.process_time()
    ident = identify(case.model, make_structure("central"), cfg, recs, seed=seed)
    return {"wall": time.perf_counter() - w, "cpu": time.process_time() - c,
            "row_errors": ident.timings.get("row_errors", 0.0), "trusted": ident.metrics.get("intervals_trusted")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_row_errors.json"))
    a = ap.parse_args(argv)
    out = {}
    for name in a.cases.split(","):
        if name not in CASES:
            raise SystemExit(f"--cases: unknown case {name!r}; expected some of {sorted(CASES)}")
        case = cal.make_case(name=name, **CASES[name])
        one_run(case, True, 0)  # warm-up: numba's first calls, the configs read
        res = {}
        for correct in (True, False):
            runs = [one_run(case, correct, s) for s in range(1, a.repeats + 1)]
            res["corrected" if correct else "uncorrected"] = {
                k: statistics.median(r[k] for r in runs) for k in ("wall", "cpu", "row_errors")}
        res["ratio_wall"] = res["corrected"]["wall"] / res["uncorrected"]["wall"]
        res["ratio_cpu"] = res["corrected"]["cpu"] / res["uncorrected"]["cpu"]
        out[name] = res
        print(f"{name:8s} corrected {res['corrected']['wall']:.2f} s wall ({res['corrected']['cpu']:.2f} s CPU, row "
              f"errors {res['corrected']['row_errors']:.2f} s), uncorrected {res['uncorrected']['wall']:.2f} s wall "
              f"({res['uncorrected']['cpu']:.2f} s CPU): ratio {res['ratio_wall']:.2f} wall, {res['ratio_cpu']:.2f} CPU",
              flush=True)
    path = Path(a.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"repeats": a.repeats, "cases": out}, indent=1))
    print(f"written: {path}")


if __name__ == "__main__":
    main()
