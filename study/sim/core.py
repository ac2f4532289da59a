"""Fixed-step RK4 integrator shared by every vessel kind, with the manoeuvre controller, the rudder
actuator and the environmental forces inside the compiled loop.

Why a hand-written integrator instead of ``scipy.integrate.solve_ivp``: the zigzag controller
switches the rudder on the simulated heading (a discontinuous, state-dependent input) and the rudder
has a rate limit, a lag and a delay; DE and emcee simulate thousands of candidates, so the loop is
compiled with numba and a whole population is advanced in lock-step in one call.
``benchmarks/bench_sim.py`` compares it with ``solve_ivp``.

Layout of the per-member parameter matrix ``P`` (shape ``(n_params, batch)``, structure-of-arrays so
that the inner loop over the batch is contiguous): first the vessel kind's own parameters (see each
kind's ``PARAM_NAMES``), then the environment and actuator parameters ``ENV_NAMES`` below. Every
member of a batch may differ in any of them; that is what DE populations and emcee walkers need.

State carried by the integrator: ``u_w, v_w`` (velocities relative to the water), ``r``, ``x0, y0``,
``psi``. Output columns (``OUT_NAMES``): ``u, v`` over ground (what GNSS measures), ``r``, ``x0``,
``y0``, ``psi``, ``delta`` (the actual rudder angle), ``n``, ``delta_cmd`` (the steering gear's
command), ``delta`` (actual rudder angle), ``n``.

A kind whose model has no sway velocity (``study.sim.nomoto``: a yaw response model) declares
``KINEMATIC_SWAY = False`` and carries an auxiliary state of its own in the ``v_w`` slot: the
kinematics and the wind then use v_w = 0, and the output ``v`` is the current's contribution only (a
ship without drift). The flag is a compile-time constant of each kind's instance of the loop (LLVM
removes the unused side).
"""
from __future__ import annotations

import hashlib
import math
import sys
import types
from pathlib import Path

import numpy as np
from numba import njit
from numba.core.compiler import Compiler

from study.sim.maneuvers import CTRL_OPEN, CTRL_ZIGZAG
from . import fastmath as fm

# Environment/actuator parameters appended to each kind's parameters. Sources:
#  current: uniform, irrotational; hydrodynamics act on water-relative velocities, kinematics add the drift
#    (Fossen 2011, Handbook of Marine Craft Hydrodynamics and Motion Control, Sec. 10.3, Property 8.1).
#  wind: Fossen 2011 Sec. 8.1, eqs. (8.21)-(8.25): X = q C_X A_F, Y = q C_Y A_L, N = q C_N A_L L_oa with
#    q = 0.5 rho_a V_rw^2, C_X = -c_x cos(g), C_Y = c_y sin(g), C_N = c_n sin(2 g), g = -atan2(v_rw, u_rw).
#  ext_X/Y/N: constant body-fixed forces (propeller walk, asymmetry; the doctor's ``yaw_bias``).
#  rudder: rate limit (IMO MSC.137(76) steering gear, SIMMAN rates per vessel), first-order lag, dead time.
ENV_NAMES = (
    "current_speed", "current_dir",
    "wind_speed", "wind_dir", "wind_cx", "wind_cy", "wind_cn", "wind_AF", "wind_AL", "wind_Loa", "rho_air",
    "ext_X", "ext_Y", "ext_N",
    "rudder_rate", "rudder_lag", "rudder_delay", "delta_max",
)
N_ENV = len(ENV_NAMES)
OUT_NAMES = ("u", "v", "r", "x0", "y0", "psi", "delta", "n", "delta_cmd")



# Flags of the compiled loops. error_model='numpy': no ZeroDivisionError branches (they would stop the batch
# loop from vectorising; a division by zero gives inf/nan in the output instead of raising). fastmath
# 'contract' only (FMA formation: a fused multiply-add rounds once instead of twice, ~1e-16 relative per
# operation); no 'reassoc'/'nnan'/'ninf'/'nsz', which would break the fast math functions' range reduction and
# their special-value selects (see ``study.sim.fastmath``).
JIT_FLAGS = dict(error_model="numpy", fastmath={"contract"})
# below this many members the integrator runs them one after the other (the SIMD width is 4 or 8 doubles)
_SIMD_MIN_BATCH = 8


class _NoAliasCompiler(Compiler):
    """numba's standard pipeline, with the function's array arguments declared ``noalias`` to LLVM.

    The member loops store into several per-member arrays and load from ``P``; without knowing that
    these do not overlap, LLVM would need a run-time overlap check for every pair of them (hundreds:
    every row of ``P`` is a separate pointer) and gives up vectorising. ``_run`` is only called by
    ``integrate`` below, with arrays it allocated itself plus the caller's ``out`` (written only)
    and inputs (read only).
    """

    def define_pipelines(self):
        self.state.flags.noalias = True
        return super().define_pipelines()


@njit(cache=False, inline="always", error_model="numpy")
def _wind_forces(u_w, v_w, cp, sp, P, k0, b, ccd, scd, cwd, swd):
    """Wind forces in body axes for member ``b`` (k0 = offset of the environment block); zero if no
    wind.

    cp, sp = cos/sin of the heading; ccd, scd = cos/sin of current_dir; cwd, swd = cos/sin of
    wind_dir. Branch-free: the wind term is computed for every member and kept where wind_speed > 0.
    The wind angle g = -atan2(v_rw, u_rw) only enters through cos g = u_rw / V, sin g = -v_rw / V,
    sin 2g = 2 sin g cos g.
    """
    Vw = P[k0 + 2, b]
    Vc = P[k0 + 0, b]
    # ground velocity of the ship in body axes = water-relative + current; cos(cd - psi), sin(cd - psi)
    ug = u_w + Vc * (ccd * cp + scd * sp)
    vg = v_w + Vc * (scd * cp - ccd * sp)
    # wind comes FROM wind_dir: the air moves towards wind_dir + pi
    u_rw = ug + Vw * (cwd * cp + swd * sp)
    v_rw = vg + Vw * (swd * cp - cwd * sp)
    V2 = u_rw * u_rw + v_rw * v_rw
    V = fm.sqrt(V2)
    still = V == 0.0
    cg = fm.select(still, 1.0, u_rw / V)
    sg = fm.select(still, 0.0, -v_rw / V)
    q = 0.5 * P[k0 + 10, b] * V2
    on = Vw > 0.0
    wX = q * (-P[k0 + 4, b] * cg) * P[k0 + 7, b]
    wY = q * (P[k0 + 5, b] * sg) * P[k0 + 8, b]
    wN = q * (P[k0 + 6, b] * (2.0 * sg * cg)) * P[k0 + 8, b] * P[k0 + 9, b]
    return fm.select(on, wX, 0.0), fm.select(on, wY, 0.0), fm.select(on, wN, 0.0)


def _templates():
    """The integrator's two functions, as templates: ``make_integrator`` instantiates them per
    vessel kind.

    They read the kind's ``ACCEL``, ``K0`` (offset of the environment block in ``P``) and
    ``KINEMATIC_SWAY`` (is ``v_w`` a sway velocity?) as globals (each instance gets its own globals
    dict) and ``_RUN`` likewise; their only closure variable is ``fingerprint``, which makes the
    on-disk cache key deterministic and specific to the kind and its sources (numba keys a cached
    closure by its code and the pickled closure variables; a pickled dispatcher carries a random
    uuid, so a closure over ``accel`` itself would never be found in the cache again). It is long
    because it holds the time loop ``_run`` whole (see its docstring).
    """
    fingerprint = 0

    # The time loop. Compiled without numba's reference counting (_nrt=False; it allocates nothing): the
    # NRT_incref/decref calls that inlining ``ACCEL(..., P, b)`` leaves in the member loop are calls, which
    # LLVM cannot vectorise. Every array written here is a separate argument (see _NoAliasCompiler).
    def _run(P, dt, nsteps, save_every, cmd, nprop, ctrl, out, u, v, r, x, y, psi, delta,
             wu, wv, wr, wp, su, sv, sr, sx, sy, sp, D, C,
             sign, stage, nsw, psi_ref, started, pulled, hist, hist0):
        """The time loop of ``integrate`` for a batch of members, compiled as one kernel. Kept
        whole: each step's controller, actuator, output row and RK4 stages share the members'
        state arrays, the loop-invariant flags (``has_current``, ``has_wind``) and the no-alias
        declaration of its array arguments."""
        if fingerprint < 0:  # never true; keeps the fingerprint a closure variable (part of the cache key)
            return -1
        k0 = K0
        B = u.shape[0]
        has_current = False
        has_wind = False
        for b in range(B):
            has_current = has_current | (C[4, b] != 0.0) | (C[5, b] != 0.0)
            has_wind = has_wind | (P[k0 + 2, b] > 0.0)
        kind = int(ctrl[0])
        t_start = ctrl[1]
        n_stages = int(ctrl[4])
        n_hist = hist.shape[0]
        h2 = 0.5 * dt
        w6 = dt / 6.0
        j_out = 0
        for k in range(nsteps + 1):
            t = k * dt
            slot = k % n_hist
            n0 = nprop[k]
            do_step = k < nsteps
            zig = kind == CTRL_ZIGZAG
            closed = kind != CTRL_OPEN and t >= t_start - 1e-9
            # open loop: the command series is known ahead, so the actuator heads for the command at the END of
            # the step (a replayed rudder is then linear between samples, as measured, not one step late)
            c_open = cmd[k + 1] if (do_step and kind == CTRL_OPEN) else cmd[k]
            for b in range(B):
                # ---- controller: the command at step k
                c = c_open
                if closed:
                    if not started[b]:
                        started[b] = True
                        psi_ref[b] = psi[b]
                    dpsi = psi[b] - psi_ref[b]
                    if zig:
                        s = stage[b]
                        amp = ctrl[5 + 3 * s]
                        sw = ctrl[6 + 3 * s]
                        if sign[b] * dpsi >= sw:
                            sign[b] = -sign[b]
                            nsw[b] += 1
                            if s + 1 < n_stages and nsw[b] >= int(ctrl[7 + 3 * s]):
                                stage[b] = s + 1
                                nsw[b] = 0
                                amp = ctrl[5 + 3 * (s + 1)]
                        c = sign[b] * amp
                    else:  # turning circle, pull-out after the heading change ctrl[3]
                        if abs(dpsi) >= ctrl[3]:
                            pulled[b] = True
                        c = 0.0 if pulled[b] else sign[b] * ctrl[5]
                hist[slot, b] = c
                if k == 0:
                    hist0[b] = cmd[0] if kind == CTRL_OPEN else c
                if do_step:
                    # ---- actuator: dead time, then first-order lag, then rate limit and saturation
                    kd = k - C[6, b]
                    if kd <= 0.0:
                        c = hist0[b]
                    elif kd != k:  # (no dead time: the command just computed)
                        i0 = int(kd)
                        f = kd - i0
                        c0 = hist[i0 % n_hist, b]
                        c = c0 if f == 0.0 else (1.0 - f) * c0 + f * hist[(i0 + 1) % n_hist, b]
                    d0 = delta[b]
                    target = d0 + (c - d0) * C[7, b] if P[k0 + 15, b] > 0.0 else c
                    step = target - d0
                    lim = P[k0 + 14, b] * dt
                    if lim > 0.0:
                        step = -lim if step < -lim else (lim if step > lim else step)
                    dmax = P[k0 + 17, b]
                    d1 = d0 + step
                    d1 = -dmax if d1 < -dmax else (dmax if d1 > dmax else d1)
                    D[0, b] = d0
                    D[1, b] = 0.5 * (d0 + d1)
                    D[2, b] = d1
            # ---- save the state at step k
            if k % save_every == 0:
                for b in range(B):
                    ug = u[b]
                    vg = v[b] if KINEMATIC_SWAY else 0.0
                    if has_current:
                        s_, c_ = fm.sincos(psi[b])
                        ug = ug + (C[4, b] * c_ + C[5, b] * s_)
                        vg = vg + (C[5, b] * c_ - C[4, b] * s_)
                    out[j_out, 0, b] = ug
                    out[j_out, 1, b] = vg
                    out[j_out, 2, b] = r[b]
                    out[j_out, 3, b] = x[b]
                    out[j_out, 4, b] = y[b]
                    out[j_out, 5, b] = psi[b]
                    out[j_out, 6, b] = delta[b]
                    out[j_out, 7, b] = n0
                    # the steering gear's command at step k (open loop: the series itself; closed loop: what
                    # the controller asked for), so a record can carry both the command and the actual angle
                    out[j_out, 8, b] = cmd[k] if kind == CTRL_OPEN else hist[slot, b]
                j_out += 1
            if not do_step:
                break
            n1 = nprop[k + 1]
            nm = 0.5 * (n0 + n1)
            # ---- RK4 on (u_w, v_w, r, x0, y0, psi); rudder and rps linear within the step
            if B < _SIMD_MIN_BATCH:
                # Few members: one after the other, the four stages in a loop that carries the stage input
                # in registers (a single simulation is latency-bound; a round trip through memory between
                # the stages costs time, and more when the store and the load alias in the low 12 bits)
                for b in range(B):
                    u1 = u[b]
                    v1 = v[b]
                    r1 = r[b]
                    p1 = psi[b]
                    d0 = D[0, b]
                    dm = D[1, b]
                    d1 = D[2, b]
                    us = u1
                    vs = v1
                    rs = r1
                    ps = p1
                    ku = 0.0
                    kv = 0.0
                    kr = 0.0
                    kx = 0.0
                    ky = 0.0
                    kp = 0.0
                    for st in range(4):
                        wt = 1.0 if (st == 0 or st == 3) else 2.0
                        hn = h2 if st < 2 else dt  # the next stage's step fraction
                        ns = n0 if st == 0 else (nm if st < 3 else n1)
                        ds = d0 if st == 0 else (dm if st < 3 else d1)
                        sn, cs = fm.sincos(ps)
                        vk = vs if KINEMATIC_SWAY else 0.0  # the sway velocity of the kinematics
                        X = P[k0 + 11, b]
                        Y = P[k0 + 12, b]
                        N = P[k0 + 13, b]
                        if has_wind:
                            wX, wY, wN = _wind_forces(us, vk, cs, sn, P, k0, b, C[0, b], C[1, b], C[2, b],
                                                      C[3, b])
                            X += wX
                            Y += wY
                            N += wN
                        a, bb, cc = ACCEL(us, vs, rs, ds, ns, X, Y, N, P, b)
                        ku = ku + wt * a
                        kv = kv + wt * bb
                        kr = kr + wt * cc
                        kx = kx + wt * (us * cs - vk * sn + C[4, b])
                        ky = ky + wt * (us * sn + vk * cs + C[5, b])
                        kp = kp + wt * rs
                        us = u1 + hn * a
                        vs = v1 + hn * bb
                        ps = p1 + hn * rs
                        rs = r1 + hn * cc
                    u[b] = u1 + w6 * ku
                    v[b] = v1 + w6 * kv
                    r[b] = r1 + w6 * kr
                    x[b] = x[b] + w6 * kx
                    y[b] = y[b] + w6 * ky
                    psi[b] = p1 + w6 * kp
                    delta[b] = d1
                continue
            # A batch: each stage st is one loop over the members (vectorised), reading its input
            # (y + h_st k_(st-1)) from w*, adding wt k_st into the sums s* (zero at the start of the step) and
            # writing the next stage's input. No loads under a condition and no pointer selects: those would
            # stop the member loop from vectorising.
            for st in range(4):
                wt = 1.0 if (st == 0 or st == 3) else 2.0
                hn = h2 if st < 2 else dt  # the next stage's step fraction
                ns = n0 if st == 0 else (nm if st < 3 else n1)
                row = 0 if st == 0 else (1 if st < 3 else 2)
                for b in range(B):
                    us = wu[b]
                    vs = wv[b]
                    rs = wr[b]
                    ps = wp[b]
                    sn, cs = fm.sincos(ps)
                    vk = vs if KINEMATIC_SWAY else 0.0  # the sway velocity of the kinematics
                    X = P[k0 + 11, b]
                    Y = P[k0 + 12, b]
                    N = P[k0 + 13, b]
                    if has_wind:  # loop-invariant: skipped in scalar code, a masked select in vector code
                        wX, wY, wN = _wind_forces(us, vk, cs, sn, P, k0, b, C[0, b], C[1, b], C[2, b], C[3, b])
                        X += wX
                        Y += wY
                        N += wN
                    a, bb, cc = ACCEL(us, vs, rs, D[row, b], ns, X, Y, N, P, b)
                    xd = us * cs - vk * sn + C[4, b]
                    yd = us * sn + vk * cs + C[5, b]
                    wu[b] = u[b] + hn * a
                    wv[b] = v[b] + hn * bb
                    wr[b] = r[b] + hn * cc
                    wp[b] = psi[b] + hn * rs
                    su[b] = su[b] + wt * a
                    sv[b] = sv[b] + wt * bb
                    sr[b] = sr[b] + wt * cc
                    sx[b] = sx[b] + wt * xd
                    sy[b] = sy[b] + wt * yd
                    sp[b] = sp[b] + wt * rs
            # ---- the new state
            for b in range(B):
                un = u[b] + w6 * su[b]
                vn = v[b] + w6 * sv[b]
                rn = r[b] + w6 * sr[b]
                pn = psi[b] + w6 * sp[b]
                x[b] = x[b] + w6 * sx[b]
                y[b] = y[b] + w6 * sy[b]
                u[b] = un
                v[b] = vn
                r[b] = rn
                psi[b] = pn
                wu[b] = un
                wv[b] = vn
                wr[b] = rn
                wp[b] = pn
                su[b] = 0.0
                sv[b] = 0.0
                sr[b] = 0.0
                sx[b] = 0.0
                sy[b] = 0.0
                sp[b] = 0.0
                delta[b] = D[2, b]
        return j_out

    def integrate(y0, P, dt, nsteps, save_every, cmd, nprop, ctrl, out):
        """Advance ``batch`` members ``nsteps`` RK4 steps of ``dt`` seconds.

        y0 : (6, B) initial [u_w, v_w, r, x0, y0, psi]
        P : (n_params, B) parameters
        cmd : (nsteps + 1,) rudder command (open loop, and before the controller's start time)
        nprop : (nsteps + 1,) propeller speed [rps]
        ctrl : float array, controller programme (see study.sim.maneuvers.encode)
        out : (n_out, 9, B) output (OUT_NAMES), n_out = nsteps // save_every + 1; must not overlap the inputs
        Returns the number of output rows written.
        """
        if fingerprint < 0:
            return -1
        k0 = K0
        B = y0.shape[1]
        # one allocation per dtype (each distinct np.zeros overload costs compile time); rows are passed to
        # _run as separate arrays
        F = np.zeros((20, B))
        u = F[0]; v = F[1]; r = F[2]; x = F[3]; y = F[4]; psi = F[5]  # state
        psi_ref = F[6]; delta = F[7]; sign = F[8]; hist0 = F[9]  # controller, actuator
        wu = F[10]; wv = F[11]; wr = F[12]; wp = F[13]  # stage input (start of a step: the state)
        su = F[14]; sv = F[15]; sr = F[16]; sx = F[17]; sy = F[18]; sp = F[19]  # RK4 sums (start: zero)
        I = np.zeros((2, B), dtype=np.int64)
        stage = I[0]; nsw = I[1]
        Z = np.zeros((2, B), dtype=np.bool_)
        started = Z[0]; pulled = Z[1]
        D = np.zeros((3, B))  # rudder angle at the start, middle and end of the step
        # per-member constants: cos/sin of the current and wind directions, the current's velocity in earth
        # axes, the dead time in steps, the lag's step factor
        C = np.zeros((8, B))
        max_delay = 0.0
        for b in range(B):
            for i in range(6):
                F[i, b] = y0[i, b]
            wu[b] = u[b]; wv[b] = v[b]; wr[b] = r[b]; wp[b] = psi[b]
            psi_ref[b] = psi[b]
            sign[b] = ctrl[2]
            Vc = P[k0 + 0, b]
            C[0, b] = math.cos(P[k0 + 1, b])
            C[1, b] = math.sin(P[k0 + 1, b])
            C[2, b] = math.cos(P[k0 + 3, b])
            C[3, b] = math.sin(P[k0 + 3, b])
            C[4, b] = Vc * C[0, b]
            C[5, b] = Vc * C[1, b]
            tau = P[k0 + 16, b] / dt  # dead time in steps (nan -> none; capped: beyond the run it is all hist0)
            C[6, b] = min(tau, nsteps + 1.0) if tau > 0.0 else 0.0
            max_delay = max(max_delay, C[6, b])
            T = P[k0 + 15, b]
            C[7, b] = (1.0 - math.exp(-dt / T)) if T > 0.0 else 1.0
            delta[b] = min(max(cmd[0], -P[k0 + 17, b]), P[k0 + 17, b])
        # command history for the dead time: a ring buffer long enough for the longest delay
        hist = np.zeros((max(min(int(max_delay) + 2, nsteps + 1), 1), B))
        return _RUN(P, dt, nsteps, save_every, cmd, nprop, ctrl, out, u, v, r, x, y, psi, delta,
                    wu, wv, wr, wp, su, sv, sr, sx, sy, sp, D, C,
                    sign, stage, nsw, psi_ref, started, pulled, hist, hist0)

    return _run, integrate


_RUN_TEMPLATE, _INTEGRATE_TEMPLATE = _templates()


def _kind_tag(accel, n_kind_params: int, kinematic_sway: bool = True) -> str:
    """A short stable name for a kind's integrator: its accel's module and qualname, its
    parameter count and its ``KINEMATIC_SWAY`` flag (a compile-time constant of the loop, so it
    must be part of the cache key)."""
    py = getattr(accel, "py_func", accel)
    h = hashlib.sha256(f"{py.__module__}.{py.__qualname__}:{n_kind_params}:{bool(kinematic_sway)}".encode())
    for cell in py.__closure__ or ():  # accel built by a factory: its closure values (repr) as well
        h.update(repr(cell.cell_contents).encode())
    return f"{py.__module__.rsplit('.', 1)[-1]}_{h.hexdigest()[:10]}"


def _fingerprint(accel, n_kind_params: int, kinematic_sway: bool = True) -> int:
    """A hash of everything the compiled integrator of a kind depends on besides this file's code.

    numba's cache checks this file's time stamp and the function's own code only; functions reached
    through ``accel`` (the kind's module, ``fastmath``, shared helpers) are covered by hashing the
    sources of this package (the controller codes of ``maneuvers.py`` among them) and of the kind's
    module, plus the kind's tag and accel's code.
    """
    py = getattr(accel, "py_func", accel)
    h = hashlib.sha256(_kind_tag(accel, n_kind_params, kinematic_sway).encode())
    h.update(py.__code__.co_code)
    files = set(Path(__file__).resolve().parent.glob("*.py"))
    mod = sys.modules.get(py.__module__)
    if mod is not None and getattr(mod, "__file__", None):
        files.add(Path(mod.__file__).resolve())
    for f in sorted(files):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return int.from_bytes(h.digest()[:7], "little")


def _instantiate(template, tag, fingerprint, **names):
    """A copy of ``template`` with its own globals (``names`` added) and ``fingerprint`` as
    closure cell."""
    assert template.__code__.co_freevars == ("fingerprint",)
    g = dict(globals())
    g.update(names)
    fn = types.FunctionType(template.__code__, g, template.__name__, template.__defaults__,
                            (types.CellType(fingerprint),))
    # a qualname of its own per kind: numba names the compiled symbols after the qualname and a per-process
    # counter, so two kinds' instances with one qualname, compiled in different processes and loaded from the
    # cache into one, could resolve to each other's code; it also gives each kind its own cache index file
    fn.__qualname__ = f"{template.__qualname__}_{tag}"
    fn.__doc__ = template.__doc__
    return fn


def make_integrator(accel, n_kind_params, kinematic_sway: bool = True):
    """Build the compiled batch integrator for one vessel kind (cached on disk by numba).

    Parameters
    ----------
    accel : numba-jitted function
        ``accel(u_w, v_w, r, delta, n, X_ext, Y_ext, N_ext, P, b) -> (du_w, dv_w, dr)``: the kind's
        equations of motion in water-relative velocities, with external forces in newtons
        (newton-metres). Any such function works. Written branch-free with ``study.sim.fastmath``
        and without loads under a condition (as ``study.sim.mmg`` is), the loop over the batch
        vectorises (AVX2/AVX-512); with ``math.*`` calls or data-dependent branches it runs member
        after member, with the same results.
    n_kind_params : int
        Number of the kind's own parameters; the environment block starts there.
    kinematic_sway : bool
        The kind's ``KINEMATIC_SWAY`` (default True: ``v_w`` is the sway velocity through the
        water). False: ``v_w`` is an auxiliary state of the kind's model (integrated like the
        others, e.g. the Nomoto second-order state of ``study.sim.nomoto``); the kinematics, the
        wind and the output ``v`` then take the sway velocity as 0. A constant of the compiled loop:
        the other kinds' code is unchanged.

    Returns the compiled ``integrate(y0, P, dt, nsteps, save_every, cmd, nprop, ctrl, out)``; its
    attribute ``run_loop`` is the compiled time loop (``integrate.run_loop.inspect_asm(...)``).

    Structure of one step: the controller and the rudder actuator (per-member switching, a dead-time
    ring buffer) run in a scalar loop over the members. Then, for a batch (8 members or more), each
    of the four RK4 stages is one loop over the members that reads the stage input from, and adds
    the stage derivative into, per-member arrays -- straight-line code per member, unit-stride loads
    of ``P[i, b]``, so LLVM vectorises it (check with ``integrate.run_loop_asm()``); a last loop
    forms the new state. For fewer members (a single simulation), each member runs its four stages
    in a loop that keeps the stage input in registers. Either way the arithmetic per member is that
    of the textbook RK4 step, in the same order, and ``accel`` has one call site per path (it is
    inlined, so each copy costs compile time).

    The compiled functions are cached on disk (``study/sim/__pycache__``), keyed on the sources of
    this package and of the kind's module: the first call in a new process takes ~0.01 s instead of
    seconds.
    """
    kinematic_sway = bool(kinematic_sway)
    tag = _kind_tag(accel, n_kind_params, kinematic_sway)
    fp = _fingerprint(accel, n_kind_params, kinematic_sway)
    run = njit(cache=True, _nrt=False, pipeline_class=_NoAliasCompiler, **JIT_FLAGS)(
        _instantiate(_RUN_TEMPLATE, tag, fp, ACCEL=accel, K0=n_kind_params, KINEMATIC_SWAY=kinematic_sway))
    # nogil: it touches no Python object, so callers may run batches in threads (output error on both cores)
    integrate = njit(cache=True, nogil=True, **JIT_FLAGS)(
        _instantiate(_INTEGRATE_TEMPLATE, tag, fp, _RUN=run, K0=n_kind_params))
    integrate.run_loop = run
    integrate.run_loop_asm = lambda: _run_loop_asm(run, n_kind_params)
    return integrate


def _kernel_templates():
    """Two small compiled helpers outside the time loop, as templates like the integrator's (same
    globals and ``fingerprint`` closure, so the same on-disk cache key): the accelerations of a
    kind at given states (the regressors of every force model, and self-propulsion) and the wind
    forces. Compiled afresh in every process before (a closure over a dispatcher is never found
    in numba's cache again), they cost 2-5 s per fresh worker: most of a short run
    (``benchmarks/bench_sweep.py``)."""
    fingerprint = 0

    def accel_kernel(u, v, r, d, n, ext, P, out):
        if fingerprint < 0:
            return
        for b in range(P.shape[1]):
            for i in range(u.shape[0]):
                a1, a2, a3 = ACCEL(u[i], v[i], r[i], d[i], n[i], ext[0, b], ext[1, b], ext[2, b], P, b)
                out[b, i, 0] = a1
                out[b, i, 1] = a2
                out[b, i, 2] = a3

    def wind_kernel(u_w, v_w, psi, Vw, wdir, P, k0, out):
        # one member, the wind speed and direction per sample (the compiled integrator's own force function)
        if fingerprint < 0:
            return
        Q = P.copy()
        ccd = math.cos(P[k0 + 1, 0])
        scd = math.sin(P[k0 + 1, 0])
        for i in range(u_w.shape[0]):
            Q[k0 + 2, 0] = Vw[i]
            cp = math.cos(psi[i])
            sp = math.sin(psi[i])
            fx, fy, fn = _wind_forces(u_w[i], v_w[i], cp, sp, Q, k0, 0, ccd, scd, math.cos(wdir[i]),
                                      math.sin(wdir[i]))
            out[i, 0] = fx
            out[i, 1] = fy
            out[i, 2] = fn

    return accel_kernel, wind_kernel


_ACCEL_TEMPLATE, _WIND_TEMPLATE = _kernel_templates()


def make_accel_kernel(accel, n_kind_params, kinematic_sway: bool = True):
    """Compiled ``kernel(u, v, r, delta, n, ext, P, out)``: out[b, i] = accel(state i, member b),
    cached on disk under the same key as the kind's integrator (``_fingerprint``)."""
    tag = _kind_tag(accel, n_kind_params, kinematic_sway)
    fp = _fingerprint(accel, n_kind_params, kinematic_sway)
    return njit(cache=True, error_model="numpy")(_instantiate(_ACCEL_TEMPLATE, tag, fp, ACCEL=accel))


def make_wind_kernel():
    """Compiled ``kernel(u_w, v_w, psi, Vw, wdir, P, k0, out)`` (wind forces of one member per
    sample), cached on disk keyed on this package's sources."""
    fp = _fingerprint(_wind_forces, 0, True)
    return njit(cache=True, error_model="numpy")(_instantiate(_WIND_TEMPLATE, "wind", fp))


def _run_loop_asm(run, n_kind_params: int) -> str:
    """Assembly of the compiled time loop, for the signature ``integrate`` uses.

    To check that the member loop vectorised: packed instructions on zmm/ymm registers
    (``vfmadd...pd``, ``vdivpd``, ``vsqrtpd``) in the loop body. Always compiled afresh (a few
    seconds), with numba's on-disk cache off, for that one signature: numba keeps no assembly of
    code it loaded from its cache, and which overloads a process compiled itself depends on what ran
    before and on the cache's state, so the answer must not come from them (the two quickstart
    commands run one after the other, compile state differing, must both pass).
    """
    run = njit(cache=False, _nrt=False, pipeline_class=_NoAliasCompiler, **JIT_FLAGS)(run.py_func)
    B = 1
    f = lambda *shape: np.zeros(shape)  # noqa: E731
    P = f(n_kind_params + N_ENV, B)
    state = [f(B) for _ in range(17)]  # u .. delta, wu .. wp, su .. sp
    run(P, 0.1, 0, 1, f(1), f(1), np.array([0.0, 0.0, 1.0, 0.0, 0.0]), f(1, len(OUT_NAMES), B), *state,
        f(3, B), f(8, B), f(B), np.zeros(B, np.int64), np.zeros(B, np.int64), f(B),
        np.zeros(B, np.bool_), np.zeros(B, np.bool_), f(2, B), f(B))
    return run.inspect_asm(run.signatures[0])
