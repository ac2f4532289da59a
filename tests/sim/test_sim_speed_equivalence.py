"""The optimised simulator gives the results of a straightforward one.

The compiled integrator (``study.sim.core``: lock-step batch loop, vectorised across members) and the MMG
model (``study.sim.mmg``: branch-free, with the pure-arithmetic ``study.sim.fastmath`` functions) are
checked against a reference written the plain way -- libm ``math.*``, ``if``/``else``, one member at a time,
the MMG equations as printed (two ``atan2`` and ``sin(alpha_R)``), the textbook RK4 step -- on a full
2100 s KVLCC2 zigzag sequence (21,000 steps), for one parameter set and for a batch of 64 different ones
(with current, wind, rudder lag and dead time among them). The fast math functions are checked against
``math`` on random and special arguments, and the batch loop is checked to be SIMD code.
"""
import math

import numpy as np
import pytest
from numba import njit

from simd_asm import packed_double_ops
from study.sim.maneuvers import get_maneuver
from study.sim import fastmath as fm
from study.sim import initial_state, integrator, load_vessel, run
from study.sim.core import CTRL_OPEN, CTRL_ZIGZAG, ENV_NAMES

# ------------------------------------------------------------------------------------------ reference


@njit(cache=True)
def _ref_thrust(u, v, r, n, P, b):
    L = P[1, b]
    U = math.sqrt(u * u + v * v)
    if U > 1e-6:
        beta = math.atan2(-v, u)
        rp = r * L / U
    else:
        beta = 0.0
        rp = 0.0
    beta_P = beta - P[29, b] * rp
    C2 = P[34, b] if beta_P > 0.0 else P[35, b]
    wfac = (1.0 - P[28, b]) * (1.0 + (1.0 - math.exp(-P[33, b] * abs(beta_P))) * (C2 - 1.0))
    uP = u * wfac
    D = P[26, b]
    if n <= 0.0:
        return 0.0, uP
    T = P[0, b] * D * D * (P[30, b] * n * n * D * D + P[31, b] * n * uP * D + P[32, b] * uP * uP)
    return T, uP


@njit(cache=True)
def _ref_accel(u, v, r, delta, n, Xe, Ye, Ne, P, b):
    """MMG (Yasukawa & Yoshimura 2015), written as printed."""
    rho = P[0, b]; L = P[1, b]; d = P[2, b]
    m = P[3, b]; xG = P[4, b]; IzG = P[5, b]; mx = P[6, b]; my = P[7, b]; Jz = P[8, b]
    U2 = u * u + v * v
    U = math.sqrt(U2)
    if U > 1e-6:
        vp = v / U
        rp = r * L / U
    else:
        vp = 0.0
        rp = 0.0
    qX = 0.5 * rho * L * d * U2
    qN = qX * L
    XH = qX * (-P[9, b] + P[10, b] * vp * vp + P[11, b] * vp * rp + P[12, b] * rp * rp + P[13, b] * vp ** 4)
    YH = qX * (P[14, b] * vp + P[15, b] * rp + P[16, b] * vp ** 3 + P[17, b] * vp * vp * rp
               + P[18, b] * vp * rp * rp + P[19, b] * rp ** 3)
    NH = qN * (P[20, b] * vp + P[21, b] * rp + P[22, b] * vp ** 3 + P[23, b] * vp * vp * rp
               + P[24, b] * vp * rp * rp + P[25, b] * rp ** 3)
    T, uP = _ref_thrust(u, v, r, n, P, b)
    XP = (1.0 - P[27, b]) * T
    D = P[26, b]
    eta = P[47, b]; kappa = P[45, b]; eps = P[44, b]
    if uP > 1e-6 and T > 0.0:
        slip = math.sqrt(1.0 + 8.0 * T / (math.pi * rho * D * D * uP * uP)) - 1.0
        uR = eps * uP * math.sqrt(eta * (1.0 + kappa * slip) ** 2 + (1.0 - eta))
    else:
        uR = eps * uP
    beta = math.atan2(-v, u) if U > 1e-6 else 0.0
    beta_R = beta - P[41, b] * rp
    gR = P[42, b] if beta_R < 0.0 else P[43, b]
    vR = U * gR * beta_R
    UR2 = uR * uR + vR * vR
    alpha_R = delta - math.atan2(vR, uR) if UR2 > 0.0 else delta
    FN = 0.5 * rho * P[36, b] * UR2 * P[46, b] * math.sin(alpha_R)
    cdl = math.cos(delta)
    XR = -(1.0 - P[37, b]) * FN * math.sin(delta)
    YR = -(1.0 + P[38, b]) * FN * cdl
    NR = -(P[40, b] + P[38, b] * P[39, b]) * FN * cdl
    X = XH + XP + XR + Xe
    Y = YH + YR + Ye
    N = NH + NR + Ne
    du = (X + (m + my) * v * r + xG * m * r * r) / (m + mx)
    rhsY = Y - (m + mx) * u * r
    rhsN = N - xG * m * u * r
    a11 = m + my
    a12 = xG * m
    a22 = IzG + xG * xG * m + Jz
    det = a11 * a22 - a12 * a12
    dv = (rhsY * a22 - a12 * rhsN) / det
    dr = (a11 * rhsN - a12 * rhsY) / det
    return du, dv, dr


@njit(cache=True)
def _ref_env(u_w, v_w, psi, P, k0, b):
    Vw = P[k0 + 2, b]
    X = P[k0 + 11, b]
    Y = P[k0 + 12, b]
    N = P[k0 + 13, b]
    if Vw > 0.0:
        Vc = P[k0 + 0, b]
        cd = P[k0 + 1, b]
        ug = u_w + Vc * math.cos(cd - psi)
        vg = v_w + Vc * math.sin(cd - psi)
        wd = P[k0 + 3, b]
        u_rw = ug + Vw * math.cos(wd - psi)
        v_rw = vg + Vw * math.sin(wd - psi)
        g = -math.atan2(v_rw, u_rw)
        q = 0.5 * P[k0 + 10, b] * (u_rw * u_rw + v_rw * v_rw)
        X += q * (-P[k0 + 4, b] * math.cos(g)) * P[k0 + 7, b]
        Y += q * (P[k0 + 5, b] * math.sin(g)) * P[k0 + 8, b]
        N += q * (P[k0 + 6, b] * math.sin(2.0 * g)) * P[k0 + 8, b] * P[k0 + 9, b]
    return X, Y, N


@njit(cache=True)
def _ref_rhs(u, v, r, psi, delta, n, P, k0, b):
    """d/dt (u_w, v_w, r, x0, y0, psi)."""
    X, Y, N = _ref_env(u, v, psi, P, k0, b)
    du, dv, dr = _ref_accel(u, v, r, delta, n, X, Y, N, P, b)
    Vc = P[k0 + 0, b]
    cd = P[k0 + 1, b]
    xd = u * math.cos(psi) - v * math.sin(psi) + Vc * math.cos(cd)
    yd = u * math.sin(psi) + v * math.cos(psi) + Vc * math.sin(cd)
    return du, dv, dr, xd, yd, r


@njit(cache=True)
def _ref_integrate(y0, P, k0, dt, nsteps, cmd, nprop, ctrl):
    """One member after the other: controller, actuator (dead time, lag, rate limit), textbook RK4."""
    B = P.shape[1]
    out = np.empty((nsteps + 1, 8, B))
    for b in range(B):
        s = np.empty(6)
        for i in range(6):
            s[i] = y0[i, b]
        dmax = P[k0 + 17, b]
        delta = min(max(cmd[0], -dmax), dmax)
        hist = np.empty(nsteps + 1)
        sign = ctrl[2]
        stage = 0
        nsw = 0
        started = False
        pulled = False
        psi_ref = 0.0
        for k in range(nsteps + 1):
            c = cmd[k]
            if int(ctrl[0]) != CTRL_OPEN and k * dt >= ctrl[1] - 1e-9:
                if not started:
                    started = True
                    psi_ref = s[5]
                dpsi = s[5] - psi_ref
                if int(ctrl[0]) == CTRL_ZIGZAG:
                    amp = ctrl[5 + 3 * stage]
                    if sign * dpsi >= ctrl[6 + 3 * stage]:
                        sign = -sign
                        nsw += 1
                        if stage + 1 < int(ctrl[4]) and nsw >= int(ctrl[7 + 3 * stage]):
                            stage += 1
                            nsw = 0
                            amp = ctrl[5 + 3 * stage]
                    c = sign * amp
                else:
                    if abs(dpsi) >= ctrl[3]:
                        pulled = True
                    c = 0.0 if pulled else sign * ctrl[5]
            hist[k] = c
            Vc = P[k0 + 0, b]
            cd = P[k0 + 1, b]
            out[k, 0, b] = s[0] + Vc * math.cos(cd - s[5])
            out[k, 1, b] = s[1] + Vc * math.sin(cd - s[5])
            for i in range(2, 6):
                out[k, i, b] = s[i]
            out[k, 6, b] = delta
            out[k, 7, b] = nprop[k]
            if k == nsteps:
                break
            kd = k - P[k0 + 16, b] / dt
            if kd <= 0.0:
                c = hist[0]
            else:
                i0 = int(kd)
                f = kd - i0
                c = hist[i0] if f == 0.0 else (1.0 - f) * hist[i0] + f * hist[i0 + 1]
            T = P[k0 + 15, b]
            target = delta + (c - delta) * (1.0 - math.exp(-dt / T)) if T > 0.0 else c
            step = target - delta
            rate = P[k0 + 14, b]
            if rate > 0.0:
                step = min(max(step, -rate * dt), rate * dt)
            d1 = min(max(delta + step, -dmax), dmax)
            dm = 0.5 * (delta + d1)
            n0 = nprop[k]
            n1 = nprop[k + 1]
            nm = 0.5 * (n0 + n1)
            u, v, r, x, y, psi = s[0], s[1], s[2], s[3], s[4], s[5]
            h = 0.5 * dt
            a1, b1, c1, x1, y1, p1 = _ref_rhs(u, v, r, psi, delta, n0, P, k0, b)
            a2, b2, c2, x2, y2, p2 = _ref_rhs(u + h * a1, v + h * b1, r + h * c1, psi + h * p1, dm, nm, P, k0, b)
            a3, b3, c3, x3, y3, p3 = _ref_rhs(u + h * a2, v + h * b2, r + h * c2, psi + h * p2, dm, nm, P, k0, b)
            a4, b4, c4, x4, y4, p4 = _ref_rhs(u + dt * a3, v + dt * b3, r + dt * c3, psi + dt * p3, d1, n1, P,
                                              k0, b)
            w = dt / 6.0
            s[0] = u + w * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
            s[1] = v + w * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
            s[2] = r + w * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
            s[3] = x + w * (x1 + 2.0 * x2 + 2.0 * x3 + x4)
            s[4] = y + w * (y1 + 2.0 * y2 + 2.0 * y3 + y4)
            s[5] = psi + w * (p1 + 2.0 * p2 + 2.0 * p3 + p4)
            delta = d1
    return out


# ------------------------------------------------------------------------------------------ fixtures

DT = 0.1
NSTEPS = 21000  # 2100 s, the seed000 sequence


@pytest.fixture(scope="module")
def setup():
    v = load_vessel("kvlcc2")
    ctrl, cmd = get_maneuver("seed000_sequence").encode(v, DT, NSTEPS)
    nprop = np.full(NSTEPS + 1, v.n0)
    return v, ctrl, cmd, nprop


def _batch_params(v, B=64, seed=1):
    """64 different parameter sets: hull/propeller/rudder coefficients within +-5 %, and environment and
    actuator variants (current, wind, rudder lag and a dead time that is not a whole number of steps)."""
    rng = np.random.default_rng(seed)
    nk = len(v.kind.PARAM_NAMES)
    P = np.repeat(v.params[:, None], B, axis=1)
    P[9:nk] *= 1.0 + 0.05 * rng.uniform(-1.0, 1.0, (nk - 9, B))
    env = {name: nk + i for i, name in enumerate(ENV_NAMES)}
    P[env["rudder_rate"]] *= rng.uniform(0.7, 1.5, B)
    for j in range(B):
        if j % 4 == 1:  # current
            P[env["current_speed"], j] = rng.uniform(0.2, 1.0)
            P[env["current_dir"], j] = rng.uniform(-math.pi, math.pi)
        if j % 4 == 2:  # wind (with the vessel's windage)
            P[env["wind_speed"], j] = rng.uniform(5.0, 20.0)
            P[env["wind_dir"], j] = rng.uniform(-math.pi, math.pi)
            P[env["wind_cx"], j], P[env["wind_cy"], j], P[env["wind_cn"], j] = 0.7, 0.9, 0.1
            P[env["wind_AF"], j], P[env["wind_AL"], j], P[env["wind_Loa"], j] = 1200.0, 4900.0, 325.0
            P[env["rho_air"], j] = 1.225
        if j % 8 == 3:
            P[env["rudder_lag"], j] = rng.uniform(0.5, 3.0)
        if j % 8 == 7:
            P[env["rudder_delay"], j] = rng.uniform(0.05, 2.0)
        if j % 16 == 5:
            P[env["ext_N"], j] = rng.uniform(-1e7, 1e7)
    return np.ascontiguousarray(P)


def _assert_close(got, ref, v, rtol):
    """Trajectories (n, 8, B) agree to rtol, relative to each column's natural scale (the integrator's ninth
    column, the rudder command, is checked on its own)."""
    if got.shape[1] == ref.shape[1] == 9:
        assert np.array_equal(got[:, 8], ref[:, 8]), "the rudder command differs"
    got, ref = got[:, :8], ref[:, :8]
    scale = np.array([v.U0, v.U0, v.U0 / v.L, v.L, v.L, 1.0, 1.0, 1.0])[None, :, None]
    err = np.abs(got - ref) / np.maximum(np.abs(ref), scale)
    worst = np.unravel_index(np.argmax(err), err.shape)
    assert err.max() < rtol, f"max relative difference {err.max():.3g} at (step, column, member) {worst}"


# ------------------------------------------------------------------------------------------ tests


@pytest.mark.slow
def test_single_full_zigzag_sequence_matches_reference(setup):
    v, ctrl, cmd, nprop = setup
    y0 = initial_state(v)[:, None]
    P = np.ascontiguousarray(v.params[:, None])
    k0 = len(v.kind.PARAM_NAMES)
    ref = _ref_integrate(y0, P, k0, DT, NSTEPS, cmd, nprop, ctrl)
    got = run(v, P, y0, DT, NSTEPS, cmd, nprop, ctrl)
    assert np.isfinite(got).all()
    _assert_close(got, ref, v, 1e-9)
    # it is a real manoeuvre: ten rudder reversals, through the 10, 15 and into the 20 deg stage
    delta = got[:, 6, 0]
    assert np.count_nonzero(np.diff(np.sign(delta[np.abs(delta) > 0.01])) != 0) >= 10
    assert np.degrees(np.abs(delta)).max() == pytest.approx(20.0)


@pytest.mark.slow
def test_batch_of_64_matches_reference_and_single_runs(setup):
    v, ctrl, cmd, nprop = setup
    P = _batch_params(v)
    B = P.shape[1]
    y0 = np.repeat(initial_state(v)[:, None], B, axis=1)
    k0 = len(v.kind.PARAM_NAMES)
    got = run(v, P, y0, DT, NSTEPS, cmd, nprop, ctrl)
    assert np.isfinite(got).all()
    ref = _ref_integrate(y0, P, k0, DT, NSTEPS, cmd, nprop, ctrl)
    _assert_close(got, ref, v, 1e-9)
    # the members really differ from each other (final positions spread over hundreds of metres)
    assert np.ptp(got[-1, 3]) > 100.0 and np.ptp(got[-1, 4]) > 100.0
    # member j of the batch = a run of member j alone (vector lanes vs the scalar path for a few members)
    for j in (0, 1, 2, 3, 7, 13, 63):
        one = run(v, P[:, j:j + 1], y0[:, j:j + 1], DT, NSTEPS, cmd, nprop, ctrl)
        _assert_close(one, got[:, :, j:j + 1], v, 1e-12)
    few = run(v, P[:, 1:6], y0[:, 1:6], DT, NSTEPS, cmd, nprop, ctrl)  # B = 5: the scalar path
    _assert_close(few, got[:, :, 1:6], v, 1e-12)


@pytest.mark.slow
def test_batch_loop_is_simd_code():
    import llvmlite.binding as llvm

    features = llvm.get_host_cpu_features()
    if not features.get("avx2", False):
        pytest.skip("no AVX2 on this CPU")
    packed = packed_double_ops(integrator("mmg").run_loop_asm())
    ops = set(packed)
    # the MMG model in packed double precision: fused multiply-adds, divisions and square roots
    assert any(op.startswith("vfmadd") for op in ops), ops
    assert "vdivpd" in ops and "vsqrtpd" in ops, ops
    assert len(packed) > 300


_ASM_AFTER_CACHE = """
import numpy as np, llvmlite.binding as llvm
from study.sim import integrator, load_vessel, simulate_batch
v = load_vessel("kt_mariner")
simulate_batch(v, "zigzag_10_10", np.repeat(v.params[:, None], 8, axis=1), duration=5.0)  # compiles or loads
asm = integrator(v.kind_name).run_loop_asm()
print(sum(1 for ln in asm.splitlines()
          if ln.split() and ln.split()[0].endswith("pd") and ("ymm" in ln or "zmm" in ln)))
"""


@pytest.mark.slow
def test_the_assembly_is_found_whatever_the_cache_holds(tmp_path):
    """The quickstart's order: a first process fills numba's on-disk cache, a second one loads the
    integrator from it and asks for the loop's assembly; both find the same packed code. A cache of its own
    (NUMBA_CACHE_DIR), so the two states are known. About 20 s of compilation, hence slow."""
    import llvmlite.binding as llvm
    import os
    import subprocess
    import sys

    if not llvm.get_host_cpu_features().get("avx2", False):
        pytest.skip("no AVX2 on this CPU")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), OPENBLAS_NUM_THREADS="1")
    counts = []
    for _ in range(2):
        p = subprocess.run([sys.executable, "-c", _ASM_AFTER_CACHE], env=env, capture_output=True, text=True,
                           timeout=600)
        assert p.returncode == 0, p.stderr[-2000:]
        counts.append(int(p.stdout.split()[-1]))
    assert any(tmp_path.rglob("*.nbi")), "the first process filled no cache"
    assert counts[0] == counts[1] > 20, counts


# ------------------------------------------------------------------------------------------ fast math


@njit(error_model="numpy")  # not cached: numba's cache would not notice a change in study/sim/fastmath.py
def _fm_eval(x, y):
    n = x.shape[0]
    out = np.empty((4, n))
    for i in range(n):
        out[0, i] = fm.exp(x[i])
        s, c = fm.sincos(x[i])
        out[1, i] = s
        out[2, i] = c
        out[3, i] = fm.atan2(y[i], x[i])
    return out


def _ulps(got, ref):
    """|got - ref| in units of the last place of ref (0 where both are the same special value)."""
    got = np.asarray(got, float)
    ref = np.asarray(ref, float)
    same = (got == ref) | (np.isnan(got) & np.isnan(ref))
    with np.errstate(invalid="ignore"):
        err = np.abs(got - ref) / np.spacing(np.abs(ref))
    return np.where(same, 0.0, err)


def _math(fn, *args):
    out = []
    for a in zip(*args):
        try:
            out.append(fn(*a))
        except OverflowError:
            out.append(math.inf)
        except ValueError:  # math.sin(inf)
            out.append(math.nan)
    return np.array(out)


def test_fast_exp_matches_math():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.uniform(-745.2, 709.8, 60000), rng.uniform(-1.0, 1.0, 20000),
                        rng.uniform(-1e-6, 1e-6, 10000), rng.uniform(-745.2, -708.0, 10000)])  # + subnormal range
    got = _fm_eval(x, x)[0]
    assert _ulps(got, _math(math.exp, x)).max() <= 2.0
    special = np.array([0.0, -0.0, 1e-300, -1e-300, 709.78, 709.79, 1000.0, -745.1, -745.2, -1000.0,
                        math.inf, -math.inf, math.nan])
    got = _fm_eval(special, special)[0]
    ref = _math(math.exp, special)
    assert (_ulps(got, ref) <= 2.0).all(), (got, ref)


def test_fast_sin_cos_match_math():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-10.0, 10.0, 50000),
                        rng.choice([-1.0, 1.0], 50000) * np.exp(rng.uniform(-30.0, math.log(0.99e14), 50000)),
                        np.arange(-200, 201) * (math.pi / 2),  # next to the zeros and extrema
                        np.arange(-200, 201) * (math.pi / 2) + 1e-9])
    out = _fm_eval(x, x)
    for got, fn in ((out[1], math.sin), (out[2], math.cos)):
        ref = _math(fn, x)
        # a few ulp of the result; near a zero of sin/cos the reduction's absolute error (< 2^-53) rules
        err = np.abs(got - ref)
        assert (err <= np.maximum(4.0 * np.spacing(np.abs(ref)), 2.0 ** -53)).all(), fn
        assert _ulps(got, ref)[np.abs(ref) > 1e-3].max() <= 4.0, fn
    special = np.array([0.0, -0.0, 5e-324, -1e-310, 1e-9, math.pi, -math.pi, 0.5 * math.pi, 1e13, -9.9e13])
    out = _fm_eval(special, special)
    assert np.array_equal(np.signbit(out[1, :4]), np.signbit(special[:4]))  # sin(-0.0) = -0.0
    assert (_ulps(out[1], _math(math.sin, special)) <= 4.0).all()
    assert (_ulps(out[2], _math(math.cos, special)) <= 4.0).all()
    # outside the documented range (|x| >= 1e14, inf, nan): NaN, not a wrong number
    out = _fm_eval(np.array([1e14, -3e200, math.inf, -math.inf, math.nan]), np.zeros(5))
    assert np.isnan(out[1:3]).all()


def test_fast_atan2_matches_math():
    rng = np.random.default_rng(4)
    n = 100000
    mag = lambda: np.exp(rng.uniform(-300.0, 300.0, n))  # noqa: E731
    x = np.concatenate([rng.standard_normal(n), rng.choice([-1.0, 1.0], n) * mag()])
    y = np.concatenate([rng.standard_normal(n), rng.choice([-1.0, 1.0], n) * mag()])
    got = _fm_eval(x, y)[3]
    assert _ulps(got, _math(math.atan2, y, x)).max() <= 2.0
    # near the octant boundaries |y| = |x| and |y| = 0.66 |x| (the reductions' switch points)
    t = rng.uniform(-1.0, 1.0, n)
    for k in (1.0, 0.66):
        xs = np.concatenate([t, -t])
        ys = np.concatenate([k * t * (1.0 + 1e-15 * rng.standard_normal(n)), k * t])
        got = _fm_eval(xs, ys)[3]
        assert _ulps(got, _math(math.atan2, ys, xs)).max() <= 2.0
    # signed zeros, infinities, NaN, x < 0 (C99 Annex F, as math.atan2)
    sp = [0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 1e308, -1e308, math.inf, -math.inf, math.nan]
    ys = np.array([a for a in sp for _ in sp])
    xs = np.array([b for _ in sp for b in sp])
    got = _fm_eval(xs, ys)[3]
    ref = _math(math.atan2, ys, xs)
    assert (_ulps(got, ref) <= 2.0).all()
    both = ~np.isnan(ref)
    assert np.array_equal(np.signbit(got[both]), np.signbit(ref[both]))


def test_packed_ops_are_counted_on_either_vector_width():
    """LLVM may vectorise on ymm registers on an AVX-512 CPU (its rocketlake tuning prefers 256-bit vectors):
    both widths count as SIMD code, scalar and 128-bit lines do not."""
    asm = "\n".join([
        "\tvfmadd231pd\t%ymm1, %ymm2, %ymm3",
        "\tvdivpd\t%zmm4, %zmm5, %zmm6",
        "\tvmulsd\t%xmm0, %xmm1, %xmm2",  # scalar
        "\tvaddpd\t%xmm0, %xmm1, %xmm2",  # 128-bit packed
        "",
        "\tmovq\t%rax, %rbx",
    ])
    assert packed_double_ops(asm) == ["vfmadd231pd", "vdivpd"]
