"""What the trust verdict's omitted-terms check costs: one emcee regression run (``study.identify.fit.identify``)
with the check (the states' monomials the model lacks built on the same rows and tested:
``study.identify.trust.omitted_terms``) against the same run without it (the estimator's ``checks_omitted_terms``
switched off), in the same process, on the same records.

Cases (1 % relative noise, the ``emcee_calibration`` set-up, central rows at 0.005 L/U0, target ESS 400):
KVLCC2's MMG hull (17 coefficients in 3 equations) and the waterjet USV's full model (13).

Per case and setting: the median wall and CPU time of ``--repeats`` runs and the ratio with / without.

``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_trust_checks.py [--repeats 3]``; figures go to
``benchmarks/results/bench_trust_checks.json``.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the repository's hydra_plugins (the sweeper the experiments name)

from study.configuration.compose import compose  # noqa: E402
from study.identify.estimators.bayes import EmceeSampler  # noqa: E402
from study.identify.fit import identify  # noqa: E402
from study.run.pipeline import SimulatedJob  # noqa: E402

CASES = ("kvlcc2_mmg", "usv_full")


def timed(job, records, repeats: int) -> tuple[float, float]:
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        identify(job.model, job.structure, job.est_cfg, records, seed=1)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    out = {}
    for case in CASES:
        job = SimulatedJob(compose("config", ["experiment=emcee_calibration", f"case={case}", "structure=central"]))
        job.prepare()
        records = job.dataset(1)[0]
        identify(job.model, job.structure, job.est_cfg, records, seed=1)  # warm the compiled kernels
        res = {}
        try:  # the class's declaration switched off for the baseline, restored whatever happens
            for setting, flag in (("with the check", True), ("without", False)):
                EmceeSampler.checks_omitted_terms = flag
                res[setting] = timed(job, records, args.repeats)
        finally:
            EmceeSampler.checks_omitted_terms = True
        (w1, c1), (w0, c0) = res["with the check"], res["without"]
        out[case] = {"wall_with": w1, "wall_without": w0, "cpu_with": c1, "cpu_without": c0,
                     "ratio_wall": w1 / w0, "ratio_cpu": c1 / c0}
        print(f"{case}: with the check {w1:.2f} s wall ({c1:.2f} s CPU), without {w0:.2f} s ({c0:.2f} s): "
              f"ratio {w1 / w0:.2f} wall, {c1 / c0:.2f} CPU", flush=True)
    dest = ROOT / "benchmarks" / "results" / "bench_trust_checks.json"
    dest.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
