"""Benchmark of the state estimator (``study.records.state_estimation``) against Savitzky-Golay, in one run.

Workload: a 35 deg turning circle of the 3 m Esso Osaka model at 10 Hz (positions 1.5 cm, heading 0.15 deg
noise), simulated for 1,000, 4,000 and 16,000 samples (the ship keeps circling), and the 320 m KVLCC2's
20/20 zigzag at 1 Hz (0.7 m). Timed, median of repeats after a warm-up
(numba compiles once and caches on disk):

* ``ekf_rts``: the complete estimate from positions and heading, process noise by maximum likelihood;
* ``ekf_rts_given_q``: the same with the process noise given (one filter and one smoother pass);
* ``savgol``: Savitzky-Golay values and first derivatives of measured u, v, r (window 11, cubic: the
  ``smoothed`` structure's default), which needs u, v, r measured;

and the RMSE of u, v, r (percent of each channel's spread) of the estimate from positions and heading.
``python benchmarks/bench_state_estimation.py`` prints the table and writes
``benchmarks/results/bench_state_estimation.json``.
"""
from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from study.records.state_estimation import estimate_states
from study.identify.structures import savgol_interior  # noqa: E402
from study.records.measure import MeasurementModel
from study.sim import load_vessel, simulate  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "bench_state_estimation.json"


def record(vessel: str, maneuver: str, dt: float, pos_std: float, n: int | None, seed: int = 0):
    """(measured, truth): ``n`` samples of the manoeuvre (simulated that long: a turning circle keeps turning),
    u, v, r with 1 % noise of their RMS, positions and heading with GNSS-like noise."""
    v = load_vessel(vessel)
    sim = simulate(v, maneuver, duration=None if n is None else (n - 1) * dt + 1e-9)
    truth = MeasurementModel(dt=dt).apply(sim)
    meas = MeasurementModel(dt=dt, noise_level={"u": 0.01, "v": 0.01, "r": 0.01}, seed=seed).apply(sim)
    if n is not None:
        truth, meas = truth.iloc[:n], meas.iloc[:n]
    rng = np.random.default_rng(seed)
    for c, sd in (("x0", pos_std), ("y0", pos_std), ("psi", math.radians(0.15))):
        meas[c] = truth[c].to_numpy() + sd * rng.standard_normal(len(meas))
    return meas, truth


def timed(fn, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def main() -> None:
    cases = [("esso_osaka", "turning_35", 0.1, 0.015, 1000), ("esso_osaka", "turning_35", 0.1, 0.015, 4000),
             ("esso_osaka", "turning_35", 0.1, 0.015, 16000), ("kvlcc2", "zigzag_20_20", 1.0, 0.7, None)]
    rows = []
    w = None
    for vessel, man, dt, pos, n in cases:
        meas, truth = record(vessel, man, dt, pos, n)
        pos_only = meas[["time", "x0", "y0", "psi"]]
        est = estimate_states(pos_only)  # warm-up (compiles on the first case)
        q = est.settings["process"]
        reps = 5 if len(meas) <= 4000 else 3
        t_ml = timed(lambda: estimate_states(pos_only), reps)
        t_q = timed(lambda: estimate_states(pos_only, process=q), reps)
        X = meas[["u", "v", "r"]].to_numpy()
        t_sg = timed(lambda: (savgol_interior(X, 11, 3, 0, dt), savgol_interior(X, 11, 3, 1, dt)), 20)
        err = {c: float(np.sqrt(np.mean((est[c] - truth[c].to_numpy()) ** 2)) / truth[c].std() * 100)
               for c in ("u", "v", "r")}
        rows.append({"vessel": vessel, "maneuver": man, "samples": len(meas), "ekf_rts_s": t_ml,
                     "ekf_rts_given_q_s": t_q, "savgol_s": t_sg, "ratio_ekf_to_savgol": t_ml / t_sg,
                     "evaluations": est.settings["evaluations"],
                     **{f"rmse_{c}_pct_of_spread": e for c, e in err.items()}})
        w = max(len(f"{vessel} {man}"), w or 0)
    print(f"{'record':<{w}} {'samples':>8} {'ekf+rts (ML)':>13} {'given q':>9} {'savgol':>9} {'ratio':>7} "
          f"{'u, v, r error (% of spread)':>28}")
    for r in rows:
        print(f"{r['vessel'] + ' ' + r['maneuver']:<{w}} {r['samples']:>8} {r['ekf_rts_s'] * 1e3:>10.1f} ms "
              f"{r['ekf_rts_given_q_s'] * 1e3:>6.1f} ms {r['savgol_s'] * 1e3:>6.2f} ms {r['ratio_ekf_to_savgol']:>7.0f} "
              f"{r['rmse_u_pct_of_spread']:>9.2f} {r['rmse_v_pct_of_spread']:>6.2f} {r['rmse_r_pct_of_spread']:>6.2f}")
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps({"machine": platform.platform(), "processor": platform.processor(),
                               "cpus": os.cpu_count(), "rows": rows}, indent=2) + "\n")
    print(f"written: {OUT}")


if __name__ == "__main__":
    main()
