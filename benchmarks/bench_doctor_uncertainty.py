"""Benchmark of the doctor's prediction intervals: what the effects' nonlinear parameters' posterior and the measured
values' noise cost when a report is written.

Workload: the records of ``bench_doctor.py`` (the 7 m KVLCC2 with a hidden current, 1 % noise, 10 Hz; 10/10 and
20/20 zigzags and a random rudder to train, a 20/10 zigzag and a 35 deg turn to validate), the vessel's own
coefficients (``known``: the current's two components are the only unknowns, so the draws are theirs alone) and
the MMG hull identified and anchored (``mmg_hull``). Each diagnosis runs once; its report is then written three
times in the same process (``unittest.mock`` switches the parts off), in turn: as before these two parts (the
posterior draws of the linear unknowns alone, no measurement noise), with the nonlinear parameters' posterior, and
with both (today's report). Reported: each report's wall time and its ratio to the first, and the final turn's
tactical-diameter interval in each, so that what the time buys is beside it. ``--quick``: 100 s records.
``python benchmarks/bench_doctor_uncertainty.py`` writes ``benchmarks/results/bench_doctor_uncertainty.json``.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from unittest import mock

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_doctor import KNOWN, records  # noqa: E402
from study.configuration.compose import read_config  # noqa: E402
from study.doctor import measurement_noise  # noqa: E402
from study.doctor.diagnose import Doctor  # noqa: E402
from study.doctor.report import write_report  # noqa: E402
from study.identify.with_effects import uncertainty as wu  # noqa: E402
from study.identify.with_effects.problem import EffectsProblem  # noqa: E402


def _linear_only(self, fit, nonlinear=False):
    return wu.posterior(self, fit)


VARIANTS = (("linear unknowns only, no measurement noise", True, True),
            ("+ the nonlinear parameters' posterior", False, True),
            ("+ the measured values' noise (today's report)", False, False))


def _turn_td(rep: dict) -> str:
    rows = [m for m in rep["maneuver_metrics"] if m["metric"] == "tactical_diameter_L"]
    if not rows:
        return "-"
    m = rows[0]
    return f"{m['final']:.3f} ({m.get('final_low', float('nan')):.3f}-{m.get('final_high', float('nan')):.3f})"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    vc, recs = records(100.0 if args.quick else 300.0)
    out = {"platform": platform.platform(), "python": platform.python_version(), "quick": args.quick, "runs": []}
    for model in (KNOWN, read_config("model", "mmg_hull")):
        d = Doctor(vc, model, recs[:3], recs[3:])
        t0 = time.perf_counter()
        d.run()
        diag = time.perf_counter() - t0
        first = None
        for label, linear_only, no_noise in VARIANTS:
            with ExitStack() as patches:
                if linear_only:
                    patches.enter_context(mock.patch.object(EffectsProblem, "posterior", _linear_only))
                if no_noise:
                    patches.enter_context(mock.patch.object(measurement_noise, "record_noise", lambda df: {}))
                for cache in ("_calibrations", "_settings"):  # each variant computes its own parts
                    d.__dict__.pop(cache, None)
                d.problem.__dict__.pop("_joint_posteriors", None)
                with tempfile.TemporaryDirectory() as tmp:
                    t0 = time.perf_counter()
                    write_report(d, Path(tmp), "kvlcc2_l7", model["name"])
                    wall = time.perf_counter() - t0
                    rep = json.loads((Path(tmp) / "report.json").read_text())
            first = first or wall
            row = {"model": model["name"], "variant": label, "report_s": wall, "ratio": wall / first,
                   "diagnosis_s": diag, "turn_td_L": _turn_td(rep),
                   "summary": rep["prediction_uncertainty"]["summary"][-1]}
            out["runs"].append(row)
            print(f"{model['name']:<9} {label:<48} report {wall:6.1f} s  x{wall / first:4.2f}  "
                  f"(diagnosis {diag:5.1f} s)  turn TD {row['turn_td_L']} L")
    res = ROOT / "benchmarks" / "results" / ("bench_doctor_uncertainty_quick.json" if args.quick else
                                             "bench_doctor_uncertainty.json")
    res.parent.mkdir(parents=True, exist_ok=True)
    res.write_text(json.dumps(out, indent=1))
    print(f"written {res}")


if __name__ == "__main__":
    main()
