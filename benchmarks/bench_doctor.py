"""Benchmark of the model doctor: five records of 300 s at 10 Hz, the full candidate list.

Workload: the 7 m KVLCC2 (kvlcc2_l7) with a hidden current (10 % of the speed), 1 % noise, records of 300 s
sampled at 10 Hz (3,000 samples each): 10/10 and 20/20 zigzags, a random rudder, a 20/10 zigzag and a 35 deg
turning circle. Models: the vessel's own coefficients (``known``) and the MMG hull identified from the records
(``mmg_hull``, anchored to the vessel config's coefficients: the user's normal case). Modes:

* given validation records: train on the first three, validate on the last two (the README's example);
* held out: the five records, each held out in turn (every candidate refitted five more times).

Reported: the wall time of the whole diagnosis (ranking, ladder, report figures excluded), the time per
candidate evaluation, the verdict, and the identified hull's time as a ratio to the known model's in the same
run. Target: under 2 minutes with the identified hull. ``--quick``: 100 s records, given mode only.
``python benchmarks/bench_doctor.py`` writes ``benchmarks/results/bench_doctor.json``.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.doctor.diagnose import Doctor  # noqa: E402
from study.records.measure import MeasurementModel
from study.run.pipeline import resolve_effects
from study.configuration.compose import read_config
from study.sim import load_vessel, simulate  # noqa: E402

TARGET_S = 120.0
MANEUVERS = ("zigzag_10_10", "zigzag_20_20", "random_rudder", "zigzag_20_10", "turning_35")


def records(duration):
    vc = read_config("vessel", "kvlcc2_l7")
    truth = load_vessel(vc, resolve_effects([{"name": "current", "speed_U0": 0.1, "direction_deg": 45.0}],
                                            float(vc["operation"]["U0"])))
    recs = [MeasurementModel(dt=0.1, noise_level=0.01, seed=i).apply(
        simulate(truth, m, duration=duration).drop(columns="delta_cmd")) for i, m in enumerate(MANEUVERS)]
    return vc, recs


KNOWN = {"name": "known", "type": "kind", "equations": {}}


def run(mode, vc, recs, model=KNOWN):
    t0 = time.perf_counter()
    if mode == "given":
        d = Doctor(vc, model, recs[:3], recs[3:])
    else:
        d = Doctor(vc, model, recs)
    d.run()
    rep = d.report()
    wall = time.perf_counter() - t0
    n_eval = len(d.evaluations)
    return {"mode": mode, "model": model["name"], "candidates": len(d.candidates), "wall_s": wall, "evaluations": n_eval, "per_evaluation_s": wall / max(n_eval, 1),
            "verdict": rep["verdict"], "missing_effect": rep["missing_effect"],
            "samples": int(sum(len(r) for r in recs))}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    vc, recs = records(100.0 if args.quick else 300.0)
    Doctor(vc, KNOWN, recs[:2], recs[2:3]).run()  # warm-up (compilation)
    out = {"platform": platform.platform(), "python": platform.python_version(), "quick": args.quick,
           "records": len(recs), "samples_per_record": len(recs[0]), "runs": []}
    cases = [("given", KNOWN), ("given", read_config("model", "mmg_hull"))]
    if not args.quick:
        cases.append(("held_out", KNOWN))
    for mode, model in cases:
        r = run(mode, vc, recs, model)
        out["runs"].append(r)
        verdict = "" if args.quick else ("PASS" if r["wall_s"] < TARGET_S else "MISS") + f" < {TARGET_S:.0f} s"
        print(f"{mode:<9} {model['name']:<9} {r['wall_s']:7.1f} s  {r['evaluations']:3d} evaluations "
              f"({r['per_evaluation_s']:.2f} s each)  {verdict}  -> {r['verdict']}")
    known, ident = out["runs"][0]["wall_s"], out["runs"][1]["wall_s"]
    out["identified_over_known"] = ident / known
    print(f"identified hull / known model (given records): {ident / known:.2f}")
    res = ROOT / "benchmarks" / "results" / ("bench_doctor_quick.json" if args.quick else "bench_doctor.json")
    res.parent.mkdir(parents=True, exist_ok=True)
    res.write_text(json.dumps(out, indent=1))
    print(f"written {res}")


if __name__ == "__main__":
    main()
