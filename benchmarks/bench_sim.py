"""Benchmark of the compiled simulator (``study.sim``) on one core, against scipy's ``solve_ivp``.

Workload: KVLCC2, full-scale MMG, rudder rate limit 2.32 deg/s, the continuous zigzag sequence
``seed000_sequence``, 2100 s with fixed-step RK4 at dt = 0.1 s (21,000 steps), all 21,001 samples kept.

Reported (medians of several repeats, after a warm-up call):

* one simulation (``study.sim.run``, B = 1): ms and ns per RK4 step;
* a batch of 64 different parameter sets in one call (what DE populations and emcee walkers need);
* the same 64 one after another;
* ``scipy.integrate.solve_ivp`` (RK45) on the same model: a Python right-hand side calling the compiled
  ``accel`` of the kind for one member, with the rudder angle of the fixed-step run (its recorded history,
  linearly interpolated) as an input. The fixed-step reference is that run: within a step the integrator
  takes the rudder linear between the samples, i.e. the same interpolated input. rtol is searched from 1e-4
  to 1e-10 (atol = rtol times each state's scale) and the loosest one whose final position is within 0.1 m
  of the fixed-step result is timed;
* the first-call compile time, in a fresh process with an empty numba cache, and the first call when the
  compiled integrator is loaded from numba's on-disk cache;
* the ratios, and PASS/MISS against the targets (one simulation < 12 ms, batch of 64 < 150 ms).

Everything runs on one core: the process is pinned to one CPU and numba/BLAS/OpenMP thread pools are
limited to one thread. ``python benchmarks/bench_sim.py`` writes ``benchmarks/results/bench_sim.json``;
``--quick`` (CI smoke test: 210 s of manoeuvre, fewer repeats, no targets) writes ``bench_sim_quick.json``.
"""
from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from study.sim.maneuvers import get_maneuver, open_loop_ctrl
from study.sim import initial_state, load_vessel, run  # noqa: E402
from study.sim.core import ENV_NAMES  # noqa: E402

VESSEL = "kvlcc2"
MANEUVER = "seed000_sequence"
DT = 0.1
TARGET_SINGLE_MS = 12.0
TARGET_BATCH_MS = 150.0
RTOLS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
TOL_M = 0.1


def _pin_one_core():
    try:
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return cpu
    except (AttributeError, OSError):  # not Linux
        return None


def _median_time(fn, repeats):
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), float(np.min(ts))


def _batch_params(v, B, seed=0):
    """B parameter sets: hydrodynamic coefficients within +-5 % (as a DE population would spread them)."""
    rng = np.random.default_rng(seed)
    nk = len(v.kind.PARAM_NAMES)
    P = np.repeat(v.params[:, None], B, axis=1)
    P[9:nk] *= 1.0 + 0.05 * rng.uniform(-1.0, 1.0, (nk - 9, B))
    return np.ascontiguousarray(P)


_COMPILE_SNIPPET = """
import time
t0 = time.perf_counter()
import numpy as np
from study.sim import load_vessel, run, initial_state
from study.sim.maneuvers import get_maneuver
v = load_vessel("kvlcc2")
ctrl, cmd = get_maneuver("seed000_sequence").encode(v, 0.1, 10)
t1 = time.perf_counter()
run(v, v.params, initial_state(v), 0.1, 10, cmd, np.full(11, v.n0), ctrl)
t2 = time.perf_counter()
print(t1 - t0, t2 - t1)
"""


def compile_times():
    """First call of the integrator in a fresh process (pinned like this one): with an empty numba cache, then
    from the cache it wrote."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        cmd = [sys.executable, "-c", _COMPILE_SNIPPET]
        out = []
        for _ in range(2):
            res = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, check=True)
            imp, first = (float(s) for s in res.stdout.split())
            out.append((imp, first))
    return {"import_s": out[0][0], "first_call_cold_cache_s": out[0][1], "first_call_cached_s": out[1][1]}


def solve_ivp_baseline(v, res_fixed, nsteps, quick):
    """solve_ivp (RK45) on the same model with the recorded rudder as input; loosest rtol within TOL_M."""
    from scipy.integrate import solve_ivp

    kind = v.kind
    accel = kind.accel
    nk = len(kind.PARAM_NAMES)
    P = np.ascontiguousarray(v.params[:, None])
    Xe, Ye, Ne = (float(v.params[nk + ENV_NAMES.index(k)]) for k in ("ext_X", "ext_Y", "ext_N"))
    n_prop = v.n0
    t_grid = np.arange(nsteps + 1) * DT
    delta_hist = np.ascontiguousarray(res_fixed[:, 6, 0])
    T_end = t_grid[-1]

    # The fixed-step reference: the run itself. Within each step its integrator takes the rudder linear
    # between the recorded samples (stages at d0, (d0 + d1) / 2, d1), which is exactly the piecewise-linear
    # interpolation of the history that solve_ivp gets below, so both integrate the same ODE and input.
    x_ref, y_ref = res_fixed[-1, 3, 0], res_fixed[-1, 4, 0]
    # check of that claim: an open-loop replay of the history (actuator off; at step k the rudder moves to
    # the command of step k, hence the history shifted by one sample) reproduces the closed-loop run
    P_ref = P.copy()
    for k in ("rudder_rate", "rudder_lag", "rudder_delay"):
        P_ref[nk + ENV_NAMES.index(k), 0] = 0.0
    cmd_replay = np.append(delta_hist[1:], delta_hist[-1])
    rep = run(v, P_ref, initial_state(v), DT, nsteps, cmd_replay, np.full(nsteps + 1, n_prop), open_loop_ctrl())
    replay_vs_closed_loop = float(np.hypot(rep[-1, 3, 0] - x_ref, rep[-1, 4, 0] - y_ref))

    def rhs(t, s):
        delta = np.interp(t, t_grid, delta_hist)
        du, dv, dr = accel(s[0], s[1], s[2], delta, n_prop, Xe, Ye, Ne, P, 0)
        c, sn = math.cos(s[5]), math.sin(s[5])
        return [du, dv, dr, s[0] * c - s[1] * sn, s[0] * sn + s[1] * c, s[2]]

    y0 = initial_state(v)
    scale = np.array([v.U0, v.U0, v.U0 / v.L, v.L, v.L, 1.0])
    rows = []
    chosen = None
    for rtol in (RTOLS[:4] if quick else RTOLS):
        t0 = time.perf_counter()
        sol = solve_ivp(rhs, (0.0, T_end), y0, method="RK45", rtol=rtol, atol=rtol * scale)
        el = time.perf_counter() - t0
        err = float(np.hypot(sol.y[3, -1] - x_ref, sol.y[4, -1] - y_ref))
        rows.append({"rtol": rtol, "ms": el * 1e3, "nfev": int(sol.nfev), "final_pos_err_m": err,
                     "success": bool(sol.success)})
        if chosen is None and sol.success and err <= TOL_M:
            chosen = rtol
            break
    timed = None
    if chosen is not None:
        med, _ = _median_time(lambda: solve_ivp(rhs, (0.0, T_end), y0, method="RK45", rtol=chosen,
                                                atol=chosen * scale), 1 if quick else 3)
        timed = med * 1e3
    return {"rtol": chosen, "ms": timed, "search": rows, "replay_vs_closed_loop_m": replay_vs_closed_loop}


def simd_summary():
    """Packed double-precision instructions on zmm/ymm registers in the compiled time loop."""
    import re
    from collections import Counter

    from study.sim import integrator

    asm = integrator(load_vessel(VESSEL).kind_name).run_loop_asm()
    ops = Counter()
    for line in asm.splitlines():
        parts = line.split()
        if parts and re.fullmatch(r"v\w+pd", parts[0]) and ("zmm" in line or "ymm" in line):
            ops[parts[0]] += 1
    return {"packed_ops": sum(ops.values()), "zmm": asm.count("zmm"), "ymm": asm.count("ymm"),
            "top": dict(ops.most_common(8))}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="CI smoke run: short manoeuvre, few repeats")
    ap.add_argument("--out", type=Path, default=None, help="JSON output path")
    ap.add_argument("--no-compile-time", action="store_true", help="skip the fresh-process compile timing")
    ap.add_argument("--asm", action="store_true", help="also count packed SIMD instructions in the loop")
    args = ap.parse_args(argv)
    quick = args.quick
    name = "bench_sim_quick.json" if quick else "bench_sim.json"
    out_path = args.out or ROOT / "benchmarks" / "results" / name
    cpu = _pin_one_core()

    v = load_vessel(VESSEL)
    duration = 210.0 if quick else 2100.0
    nsteps = int(round(duration / DT))
    ctrl, cmd = get_maneuver(MANEUVER).encode(v, DT, nsteps)
    nprop = np.full(nsteps + 1, v.n0)
    y0 = initial_state(v)
    B = 64
    P64 = _batch_params(v, B)
    y64 = np.repeat(y0[:, None], B, axis=1)
    reps = 3 if quick else 15
    reps_b = 2 if quick else 7

    t0 = time.perf_counter()
    res1 = run(v, v.params, y0, DT, nsteps, cmd, nprop, ctrl)  # warm-up (compile or load from cache)
    first_call_here = time.perf_counter() - t0
    run(v, P64, y64, DT, nsteps, cmd, nprop, ctrl)

    single, single_min = _median_time(lambda: run(v, v.params, y0, DT, nsteps, cmd, nprop, ctrl), reps)
    batch, batch_min = _median_time(lambda: run(v, P64, y64, DT, nsteps, cmd, nprop, ctrl), reps_b)
    cols = [np.ascontiguousarray(P64[:, j:j + 1]) for j in range(B)]

    def sequential():
        for j in range(B):
            run(v, cols[j], y0, DT, nsteps, cmd, nprop, ctrl)

    seq, seq_min = _median_time(sequential, 1 if quick else 3)
    ivp = solve_ivp_baseline(v, res1, nsteps, quick)
    comp = None if args.no_compile_time else compile_times()
    simd = simd_summary() if args.asm else None

    r = {
        "workload": {"vessel": VESSEL, "maneuver": MANEUVER, "dt_s": DT, "duration_s": duration,
                     "steps": nsteps, "batch": B, "saved_samples": nsteps + 1, "quick": quick},
        "machine": {"cpu": platform.processor() or platform.machine(), "pinned_cpu": cpu,
                    "python": platform.python_version(), "numba_threads": os.environ["NUMBA_NUM_THREADS"]},
        "single_ms": single * 1e3, "single_min_ms": single_min * 1e3,
        "single_ns_per_step": single / nsteps * 1e9,
        "batch64_ms": batch * 1e3, "batch64_min_ms": batch_min * 1e3, "batch64_ms_per_member": batch / B * 1e3,
        "sequential64_ms": seq * 1e3,
        "solve_ivp": ivp,
        "first_call_in_this_process_s": first_call_here,
        "compile": comp,
        "simd": simd,
    }
    r["ratio_solve_ivp_over_single"] = (ivp["ms"] / r["single_ms"]) if ivp["ms"] else None
    r["ratio_sequential_over_batch"] = r["sequential64_ms"] / r["batch64_ms"]
    r["speedup_batch_per_member_vs_single"] = r["single_ms"] / r["batch64_ms_per_member"]
    if quick:
        r["targets"] = "not checked (--quick)"
    else:
        r["targets"] = {
            "single_lt_12ms": "PASS" if r["single_ms"] < TARGET_SINGLE_MS else "MISS",
            "batch64_lt_150ms": "PASS" if r["batch64_ms"] < TARGET_BATCH_MS else "MISS",
        }

    tgt = r["targets"] if isinstance(r["targets"], dict) else {}
    lines = [
        f"bench_sim: {VESSEL} / {MANEUVER}, {duration:.0f} s, dt {DT} s, {nsteps} RK4 steps, one core"
        + (" (QUICK)" if quick else ""),
        f"{'case':<44}{'median':>12}{'detail':>34}",
        f"{'one simulation':<44}{r['single_ms']:>9.2f} ms{r['single_ns_per_step']:>22.0f} ns/step  "
        f"{tgt.get('single_lt_12ms', '')}",
        f"{'batch of 64 in one call':<44}{r['batch64_ms']:>9.1f} ms{r['batch64_ms_per_member']:>19.2f} ms/member  "
        f"{tgt.get('batch64_lt_150ms', '')}",
        f"{'64 one after another':<44}{r['sequential64_ms']:>9.1f} ms",
    ]
    if ivp["ms"] is not None:
        lines.append(f"{'solve_ivp RK45, rtol %.0e (within %.1f m)' % (ivp['rtol'], TOL_M):<44}"
                     f"{ivp['ms']:>9.1f} ms")
    else:
        lines.append(f"{'solve_ivp RK45':<44}{'no rtol in range reached %.1f m' % TOL_M:>34}")
    if comp:
        lines.append(f"{'first call, empty numba cache (compile)':<44}{comp['first_call_cold_cache_s']:>10.2f} s")
        lines.append(f"{'first call, from numba on-disk cache':<44}{comp['first_call_cached_s']:>10.2f} s")
    lines.append("ratios: solve_ivp / one simulation = %s;  64 sequential / batch = %.1f;  "
                 "batch per member vs one simulation = %.1fx"
                 % ("%.1f" % r["ratio_solve_ivp_over_single"] if r["ratio_solve_ivp_over_single"] else "n/a",
                    r["ratio_sequential_over_batch"], r["speedup_batch_per_member_vs_single"]))
    if not quick:
        lines.append(f"targets: one simulation < {TARGET_SINGLE_MS:.0f} ms: {tgt['single_lt_12ms']};  "
                     f"batch of 64 < {TARGET_BATCH_MS:.0f} ms: {tgt['batch64_lt_150ms']}")
    if simd:
        lines.append(f"SIMD: {simd['packed_ops']} packed double ops on zmm/ymm in the time loop; {simd['top']}")
    lines.append("solve_ivp rtol search: " + ", ".join(
        "%.0e: %.3g m, %d fev, %.0f ms" % (s["rtol"], s["final_pos_err_m"], s["nfev"], s["ms"])
        for s in ivp["search"]))
    print("\n".join(lines))

    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(r, indent=2) + "\n")
    print(f"written {out_path.relative_to(ROOT) if out_path.is_relative_to(ROOT) else out_path}")
    return r


if __name__ == "__main__":
    main()
