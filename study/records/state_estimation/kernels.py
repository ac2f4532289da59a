"""The compiled kernels of the extended Kalman filter and the RTS smoother (numba, cached on disk).

Self-contained: small dense 9 x 9 algebra written as loops, state order ``STATES`` of
:mod:`study.records.state_estimation.options`. The model and its sources:
``docs/concepts/state-estimation.md``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _step(x, h, F, Q, q_u, q_v, q_r):
    """One prediction sub-step of length h from state x (in place): x <- f(x), F <- its Jacobian
    (set), Q <- the sub-step's process noise (set)."""
    c = math.cos(x[2])
    s = math.sin(x[2])
    u, v, r, ud, vd, rd = x[3], x[4], x[5], x[6], x[7], x[8]
    xd = u * c - v * s
    yd = u * s + v * c
    xdd = ud * c - vd * s - r * yd
    ydd = ud * s + vd * c + r * xd
    h2 = 0.5 * h * h
    for i in range(9):
        for j in range(9):
            F[i, j] = 0.0
            Q[i, j] = 0.0
        F[i, i] = 1.0
    # position rows
    F[0, 2] = -h * yd + h2 * (-ud * s - vd * c - r * xd)
    F[0, 3] = h * c - h2 * r * s
    F[0, 4] = -h * s - h2 * r * c
    F[0, 5] = -h2 * yd
    F[0, 6] = h2 * c
    F[0, 7] = -h2 * s
    F[1, 2] = h * xd + h2 * (ud * c - vd * s - r * yd)
    F[1, 3] = h * s + h2 * r * c
    F[1, 4] = h * c - h2 * r * s
    F[1, 5] = h2 * xd
    F[1, 6] = h2 * s
    F[1, 7] = h2 * c
    # yaw and velocity chains (linear)
    F[2, 5] = h
    F[2, 8] = h2
    F[3, 6] = h
    F[4, 7] = h
    F[5, 8] = h
    x[0] += h * xd + h2 * xdd
    x[1] += h * yd + h2 * ydd
    x[2] += h * r + h2 * rd
    x[3] += h * ud
    x[4] += h * vd
    x[5] += h * rd
    # white-jerk process noise of a triple integrator (Bar-Shalom et al. 2001, Sec. 6.2.3), body axes frozen
    a5 = h ** 5 / 20.0
    a4 = h ** 4 / 8.0
    a3 = h ** 3 / 6.0
    b3 = h ** 3 / 3.0
    b2 = h * h / 2.0
    eu0, eu1 = c, s  # surge direction in (x0, y0)
    ev0, ev1 = -s, c  # sway direction
    Q[0, 0] = a5 * (q_u * eu0 * eu0 + q_v * ev0 * ev0)
    Q[0, 1] = a5 * (q_u * eu0 * eu1 + q_v * ev0 * ev1)
    Q[1, 1] = a5 * (q_u * eu1 * eu1 + q_v * ev1 * ev1)
    Q[0, 3] = a4 * q_u * eu0
    Q[1, 3] = a4 * q_u * eu1
    Q[0, 6] = a3 * q_u * eu0
    Q[1, 6] = a3 * q_u * eu1
    Q[0, 4] = a4 * q_v * ev0
    Q[1, 4] = a4 * q_v * ev1
    Q[0, 7] = a3 * q_v * ev0
    Q[1, 7] = a3 * q_v * ev1
    Q[3, 3] = b3 * q_u
    Q[3, 6] = b2 * q_u
    Q[6, 6] = h * q_u
    Q[4, 4] = b3 * q_v
    Q[4, 7] = b2 * q_v
    Q[7, 7] = h * q_v
    Q[2, 2] = a5 * q_r
    Q[2, 5] = a4 * q_r
    Q[2, 8] = a3 * q_r
    Q[5, 5] = b3 * q_r
    Q[5, 8] = b2 * q_r
    Q[8, 8] = h * q_r
    for i in range(9):
        for j in range(i):
            Q[i, j] = Q[j, i]


#: the off-diagonal non-zeros (row, column) of a step's Jacobian F - I (rows 0, 1: positions; then the chains)
_NZ_I = np.array([0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 2, 2, 3, 4, 5])
_NZ_K = np.array([2, 3, 4, 5, 6, 7, 2, 3, 4, 5, 6, 7, 5, 8, 6, 7, 8])


@njit(cache=True)
def _left(F, A, out, nzi, nzk):
    """out = F A for a Jacobian F = I + N with the sparse N of ``_NZ_I, _NZ_K`` (17 row updates,
    not 729)."""
    for i in range(9):
        for j in range(9):
            out[i, j] = A[i, j]
    for e in range(nzi.shape[0]):
        i = nzi[e]
        k = nzk[e]
        f = F[i, k]
        for j in range(9):
            out[i, j] += f * A[k, j]


@njit(cache=True)
def _propagate(F, P, Q, tmp, nzi, nzk):
    """P <- F P F' + Q (in place), F sparse as in :func:`_left`; symmetric result."""
    _left(F, P, tmp, nzi, nzk)  # tmp = F P
    for i in range(9):
        for j in range(9):
            P[i, j] = tmp[i, j] + Q[i, j]
    for e in range(nzi.shape[0]):  # (F P) F' = tmp + tmp N'
        j = nzi[e]
        k = nzk[e]
        f = F[j, k]
        for i in range(9):
            P[i, j] += f * tmp[i, k]
    for i in range(9):
        for j in range(i):
            a = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = a
            P[j, i] = a


@njit(cache=True)
def _ekf(t, Z, R, q_u, q_v, q_r, x_init, P_init, h_max, store, nzi, nzk):
    """The filter over every sample. Z (n, 6): measurements of x0, y0, psi, u, v, r (NaN: none);
    R (6,) variances. Returns (log-likelihood, x_f, P_f, x_p, P_p, Fs); the arrays are filled
    only with ``store`` (the smoother's inputs): x_p[k], P_p[k] the prediction at sample k, Fs[k]
    the Jacobian from k-1 to k."""
    n = Z.shape[0]
    nst = n if store else 1
    x_f = np.zeros((nst, 9))
    P_f = np.zeros((nst, 9, 9))
    x_p = np.zeros((nst, 9))
    P_p = np.zeros((nst, 9, 9))
    Fs = np.zeros((nst, 9, 9))
    x = x_init.copy()
    P = P_init.copy()
    F = np.zeros((9, 9))
    Q = np.zeros((9, 9))
    Ft = np.zeros((9, 9))
    tmp = np.zeros((9, 9))
    Pj = np.zeros(9)
    loglik = 0.0
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            nsub = max(1, int(math.ceil(dt / h_max - 1e-9)))
            turn = int(math.ceil(abs(x[5]) * dt / 0.05 - 1e-9))  # MAX_TURN_STEP
            if turn > nsub:
                nsub = min(turn, 1000)
            h = dt / nsub
            for sub in range(nsub):
                _step(x, h, F, Q, q_u, q_v, q_r)
                _propagate(F, P, Q, tmp, nzi, nzk)
                if store:
                    if sub == 0:
                        for i in range(9):
                            for j in range(9):
                                Ft[i, j] = F[i, j]
                    else:  # Ft <- F Ft (a dense product: rare, only over dropouts and fast turns)
                        for i in range(9):
                            for j in range(9):
                                acc = 0.0
                                for m in range(9):
                                    acc += F[i, m] * Ft[m, j]
                                tmp[i, j] = acc
                        for i in range(9):
                            for j in range(9):
                                Ft[i, j] = tmp[i, j]
        if store:
            x_p[k] = x
            P_p[k] = P
            Fs[k] = Ft
        # sequential scalar updates (independent measurement errors)
        for j in range(6):
            z = Z[k, j]
            if not math.isfinite(z):
                continue
            nu = z - x[j]
            if j == 2:  # a heading innovation is an angle
                nu = (nu + math.pi) % (2.0 * math.pi) - math.pi
            s = P[j, j] + R[j]
            if not s > 0.0:
                continue
            loglik += -0.5 * (math.log(2.0 * math.pi * s) + nu * nu / s)
            for i in range(9):
                Pj[i] = P[i, j]
            g = nu / s
            for i in range(9):
                x[i] += Pj[i] * g
            for i in range(9):
                a = Pj[i] / s
                for m in range(9):
                    P[i, m] -= a * Pj[m]
        if store:
            x_f[k] = x
            P_f[k] = P
    return loglik, x_f, P_f, x_p, P_p, Fs


@njit(cache=True)
def _chol_solve(A, B, L, out):
    """out = A^-1 B for a symmetric positive definite 9 x 9 A (Cholesky, no allocation); returns
    False if A is not positive definite."""
    for i in range(9):
        for j in range(i + 1):
            acc = A[i, j]
            for m in range(j):
                acc -= L[i, m] * L[j, m]
            if i == j:
                if not acc > 0.0:
                    return False
                L[i, i] = math.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    for c in range(B.shape[1]):
        for i in range(9):  # forward: L y = b
            acc = B[i, c]
            for m in range(i):
                acc -= L[i, m] * out[m, c]
            out[i, c] = acc / L[i, i]
        for i in range(8, -1, -1):  # backward: L' x = y
            acc = out[i, c]
            for m in range(i + 1, 9):
                acc -= L[m, i] * out[m, c]
            out[i, c] = acc / L[i, i]
    return True


@njit(cache=True)
def _rts(x_f, P_f, x_p, P_p, Fs):
    """Extended RTS smoother (Sarkka 2013, Sec. 9.1): states and standard deviations at every
    sample."""
    n = x_f.shape[0]
    xs = x_f.copy()
    Ps = P_f.copy()
    tmp = np.zeros((9, 9))
    Ct = np.zeros((9, 9))
    L = np.zeros((9, 9))
    dP = np.zeros((9, 9))
    dx = np.zeros(9)
    for k in range(n - 2, -1, -1):
        # C = P_f[k] F' inv(P_p[k+1]):  C' = solve(P_p[k+1], F P_f[k])
        F = Fs[k + 1]
        for i in range(9):
            for j in range(9):
                acc = 0.0
                for m in range(9):
                    acc += F[i, m] * P_f[k, m, j]
                tmp[i, j] = acc
        if not _chol_solve(P_p[k + 1], tmp, L, Ct):
            Ct[:, :] = np.linalg.solve(P_p[k + 1], tmp)
        for i in range(9):
            dx[i] = xs[k + 1, i] - x_p[k + 1, i]
        for i in range(9):
            acc = 0.0
            for j in range(9):
                acc += Ct[j, i] * dx[j]
            xs[k, i] = x_f[k, i] + acc
        for i in range(9):
            for j in range(9):
                dP[i, j] = Ps[k + 1, i, j] - P_p[k + 1, i, j]
        for i in range(9):  # tmp = C dP
            for j in range(9):
                acc = 0.0
                for m in range(9):
                    acc += Ct[m, i] * dP[m, j]
                tmp[i, j] = acc
        for i in range(9):  # Ps[k] = P_f[k] + C dP C'
            for j in range(i + 1):
                acc = 0.0
                for m in range(9):
                    acc += tmp[i, m] * Ct[m, j]
                Ps[k, i, j] = P_f[k, i, j] + acc
                Ps[k, j, i] = Ps[k, i, j]
    sd = np.zeros((n, 9))
    for k in range(n):
        for i in range(9):
            sd[k, i] = math.sqrt(max(Ps[k, i, i], 0.0))
    return xs, sd
