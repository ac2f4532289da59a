"""Fixed-step RK4 integrator shared by every vessel kind, with the manoeuvre controller, the rudder
actuator and the environmental forces inside the compiled loop.

Why a hand-written integrator instead of ``scipy.integrate.solve_ivp``: the zigzag controller switches the
rudder on the simulated heading (a discontinuous, state-dependent input) and the rudder has a rate limit, a
lag and a delay; DE and emcee simulate thousands of candidates, so the loop is compiled with numba and a whole
population is advanced in lock-step in one call. ``benchmarks/bench_sim.py`` compares it with ``solve_ivp``.

Layout of the per-member parameter matrix ``P`` (shape ``(n_params, batch)``, structure-of-arrays so that
the inner loop over the batch is contiguous): first the vessel kind's own parameters (see each kind's
``PARAM_NAMES``), then the environment and actuator parameters ``ENV_NAMES`` below. Every member of a batch
may differ in any of them; that is what DE populations and emcee walkers need.

State carried by the integrator: ``u_w, v_w`` (velocities relative to the water), ``r``, ``x0, y0``, ``psi``.
Output columns (``OUT_NAMES``): ``u, v`` over ground (what GNSS measures), ``r``, ``x0``, ``y0``, ``psi``,
``delta`` (actual rudder angle), ``n``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

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
OUT_NAMES = ("u", "v", "r", "x0", "y0", "psi", "delta", "n")

# Controller codes (see ``study.maneuvers``): 0 open loop (command series), 1 zigzag programme,
# 2 turning circle with pull-out.
CTRL_OPEN, CTRL_ZIGZAG, CTRL_TURN = 0, 1, 2


@njit(cache=True, inline="always")
def _env_forces(u_w, v_w, psi, P, k0, b):
    """Wind forces in body axes for member ``b`` (k0 = offset of the environment block)."""
    Vw = P[k0 + 2, b]
    X = P[k0 + 11, b]
    Y = P[k0 + 12, b]
    N = P[k0 + 13, b]
    if Vw > 0.0:
        # ground velocity of the ship in body axes = water-relative + current
        Vc = P[k0 + 0, b]
        cd = P[k0 + 1, b]
        ug = u_w + Vc * math.cos(cd - psi)
        vg = v_w + Vc * math.sin(cd - psi)
        # wind comes FROM wind_dir: the air moves towards wind_dir + pi
        wd = P[k0 + 3, b]
        u_rw = ug + Vw * math.cos(wd - psi)
        v_rw = vg + Vw * math.sin(wd - psi)
        g = -math.atan2(v_rw, u_rw)
        q = 0.5 * P[k0 + 10, b] * (u_rw * u_rw + v_rw * v_rw)
        X += q * (-P[k0 + 4, b] * math.cos(g)) * P[k0 + 7, b]
        Y += q * (P[k0 + 5, b] * math.sin(g)) * P[k0 + 8, b]
        N += q * (P[k0 + 6, b] * math.sin(2.0 * g)) * P[k0 + 8, b] * P[k0 + 9, b]
    return X, Y, N


def make_integrator(accel, n_kind_params):
    """Build the compiled batch integrator for one vessel kind.

    Parameters
    ----------
    accel : numba-jitted function
        ``accel(u_w, v_w, r, delta, n, X_ext, Y_ext, N_ext, P, b) -> (du_w, dv_w, dr)``: the kind's
        equations of motion in water-relative velocities, with external forces in newtons (newton-metres).
    n_kind_params : int
        Number of the kind's own parameters; the environment block starts there.
    """
    k0 = n_kind_params

    @njit(cache=False, fastmath=False)
    def integrate(y0, P, dt, nsteps, save_every, cmd, nprop, ctrl, out):
        """Advance ``batch`` members ``nsteps`` RK4 steps of ``dt`` seconds.

        y0 : (6, B) initial [u_w, v_w, r, x0, y0, psi]
        P : (n_params, B) parameters
        cmd : (nsteps + 1,) rudder command (open loop, and before the controller's start time)
        nprop : (nsteps + 1,) propeller speed [rps]
        ctrl : float array, controller programme (see study.maneuvers.encode)
        out : (n_out, 8, B) output, n_out = nsteps // save_every + 1
        """
        B = y0.shape[1]
        kind = int(ctrl[0])
        t_start = ctrl[1]
        n_stages = int(ctrl[4])
        u = y0[0].copy()
        v = y0[1].copy()
        r = y0[2].copy()
        x = y0[3].copy()
        y = y0[4].copy()
        psi = y0[5].copy()
        delta = np.empty(B)
        sign = np.full(B, ctrl[2])
        stage = np.zeros(B, dtype=np.int64)
        nsw = np.zeros(B, dtype=np.int64)
        psi_ref = psi.copy()
        started = np.zeros(B, dtype=np.bool_)
        pulled = np.zeros(B, dtype=np.bool_)
        hist = np.empty((nsteps + 1, B))  # command history, for the dead time
        for b in range(B):
            delta[b] = min(max(cmd[0], -P[k0 + 17, b]), P[k0 + 17, b])
        j_out = 0
        for k in range(nsteps + 1):
            t = k * dt
            # ---- controller: the command at step k for every member
            for b in range(B):
                c = cmd[k]
                if kind != CTRL_OPEN and t >= t_start - 1e-9:
                    if not started[b]:
                        started[b] = True
                        psi_ref[b] = psi[b]
                    dpsi = psi[b] - psi_ref[b]
                    if kind == CTRL_ZIGZAG:
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
                hist[k, b] = c
            # ---- save the state at step k
            if k % save_every == 0:
                for b in range(B):
                    Vc = P[k0 + 0, b]
                    cd = P[k0 + 1, b]
                    out[j_out, 0, b] = u[b] + Vc * math.cos(cd - psi[b])
                    out[j_out, 1, b] = v[b] + Vc * math.sin(cd - psi[b])
                    out[j_out, 2, b] = r[b]
                    out[j_out, 3, b] = x[b]
                    out[j_out, 4, b] = y[b]
                    out[j_out, 5, b] = psi[b]
                    out[j_out, 6, b] = delta[b]
                    out[j_out, 7, b] = nprop[k]
                j_out += 1
            if k == nsteps:
                break
            n0 = nprop[k]
            n1 = nprop[k + 1]
            nm = 0.5 * (n0 + n1)
            for b in range(B):
                # ---- actuator: dead time, then first-order lag, then rate limit and saturation.
                dmax = P[k0 + 17, b]
                tau = P[k0 + 16, b]
                kd = k - tau / dt
                if kd <= 0.0:
                    c = hist[0, b]
                else:
                    i0 = int(kd)
                    f = kd - i0
                    c = hist[i0, b] if f == 0.0 else (1.0 - f) * hist[i0, b] + f * hist[i0 + 1, b]
                T = P[k0 + 15, b]
                if T > 0.0:
                    target = delta[b] + (c - delta[b]) * (1.0 - math.exp(-dt / T))
                else:
                    target = c
                rate = P[k0 + 14, b]
                step = target - delta[b]
                if rate > 0.0:
                    lim = rate * dt
                    step = min(max(step, -lim), lim)
                d0 = delta[b]
                d1 = min(max(d0 + step, -dmax), dmax)
                dm = 0.5 * (d0 + d1)
                # ---- RK4 on (u_w, v_w, r, x0, y0, psi); rudder and rps linear within the step
                Vc = P[k0 + 0, b]
                cd = P[k0 + 1, b]
                cx = Vc * math.cos(cd)
                cy = Vc * math.sin(cd)
                u1 = u[b]; v1 = v[b]; r1 = r[b]; p1 = psi[b]
                X, Y, N = _env_forces(u1, v1, p1, P, k0, b)
                a1, b1, c1 = accel(u1, v1, r1, d0, n0, X, Y, N, P, b)
                cp = math.cos(p1); sp = math.sin(p1)
                xd1 = u1 * cp - v1 * sp + cx; yd1 = u1 * sp + v1 * cp + cy; pd1 = r1
                h2 = 0.5 * dt
                u2 = u1 + h2 * a1; v2 = v1 + h2 * b1; r2 = r1 + h2 * c1; p2 = p1 + h2 * pd1
                X, Y, N = _env_forces(u2, v2, p2, P, k0, b)
                a2, b2, c2 = accel(u2, v2, r2, dm, nm, X, Y, N, P, b)
                cp = math.cos(p2); sp = math.sin(p2)
                xd2 = u2 * cp - v2 * sp + cx; yd2 = u2 * sp + v2 * cp + cy; pd2 = r2
                u3 = u1 + h2 * a2; v3 = v1 + h2 * b2; r3 = r1 + h2 * c2; p3 = p1 + h2 * pd2
                X, Y, N = _env_forces(u3, v3, p3, P, k0, b)
                a3, b3, c3 = accel(u3, v3, r3, dm, nm, X, Y, N, P, b)
                cp = math.cos(p3); sp = math.sin(p3)
                xd3 = u3 * cp - v3 * sp + cx; yd3 = u3 * sp + v3 * cp + cy; pd3 = r3
                u4 = u1 + dt * a3; v4 = v1 + dt * b3; r4 = r1 + dt * c3; p4 = p1 + dt * pd3
                X, Y, N = _env_forces(u4, v4, p4, P, k0, b)
                a4, b4, c4 = accel(u4, v4, r4, d1, n1, X, Y, N, P, b)
                cp = math.cos(p4); sp = math.sin(p4)
                xd4 = u4 * cp - v4 * sp + cx; yd4 = u4 * sp + v4 * cp + cy; pd4 = r4
                w = dt / 6.0
                u[b] = u1 + w * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
                v[b] = v1 + w * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                r[b] = r1 + w * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
                x[b] = x[b] + w * (xd1 + 2.0 * xd2 + 2.0 * xd3 + xd4)
                y[b] = y[b] + w * (yd1 + 2.0 * yd2 + 2.0 * yd3 + yd4)
                psi[b] = p1 + w * (pd1 + 2.0 * pd2 + 2.0 * pd3 + pd4)
                delta[b] = d1
        return j_out

    return integrate
