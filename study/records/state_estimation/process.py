"""Process noise by maximum likelihood [A3]: ``q_r`` from the yaw chain's likelihood (its own
compiled filter), then ``q_uv`` from the full filter's, each over the smoother's bandwidth by a
grid and Brent's method."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from study.records.state_estimation.kernels import _ekf, _NZ_I, _NZ_K
from study.records.state_estimation.options import GRID_PER_DECADE


@njit(cache=True)
def _matmul(A, B, out):
    n = A.shape[0]
    m = B.shape[1]
    kk = A.shape[1]
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for k in range(kk):
                acc += A[i, k] * B[k, j]
            out[i, j] = acc


@njit(cache=True)
def _yaw_loglik(t, psi, r, R_psi, R_r, q_r, x_init, P_init, h_max):
    """Log-likelihood of the heading (and yaw-rate) measurements under the yaw chain [psi, r,
    r_dot] alone (it does not depend on u, v or positions): the ML search of q_r."""
    n = psi.shape[0]
    x = x_init.copy()
    P = P_init.copy()
    F = np.zeros((3, 3))
    Q = np.zeros((3, 3))
    tmp = np.zeros((3, 3))
    loglik = 0.0
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            nsub = max(1, int(math.ceil(dt / h_max - 1e-9)))
            h = dt / nsub
            h2 = 0.5 * h * h
            F[0, 0] = 1.0
            F[0, 1] = h
            F[0, 2] = h2
            F[1, 0] = 0.0
            F[1, 1] = 1.0
            F[1, 2] = h
            F[2, 0] = 0.0
            F[2, 1] = 0.0
            F[2, 2] = 1.0
            Q[0, 0] = q_r * h ** 5 / 20.0
            Q[0, 1] = Q[1, 0] = q_r * h ** 4 / 8.0
            Q[0, 2] = Q[2, 0] = q_r * h ** 3 / 6.0
            Q[1, 1] = q_r * h ** 3 / 3.0
            Q[1, 2] = Q[2, 1] = q_r * h * h / 2.0
            Q[2, 2] = q_r * h
            for _ in range(nsub):
                x0 = x[0] + h * x[1] + h2 * x[2]
                x1 = x[1] + h * x[2]
                x[0] = x0
                x[1] = x1
                _matmul(F, P, tmp)
                for i in range(3):
                    for j in range(3):
                        acc = 0.0
                        for m in range(3):
                            acc += tmp[i, m] * F[j, m]
                        P[i, j] = acc + Q[i, j]
        for j in range(2):
            z = psi[k] if j == 0 else r[k]
            if not math.isfinite(z):
                continue
            nu = z - x[j]
            if j == 0:
                nu = (nu + math.pi) % (2.0 * math.pi) - math.pi
            s = P[j, j] + (R_psi if j == 0 else R_r)
            if not s > 0.0:
                continue
            loglik += -0.5 * (math.log(2.0 * math.pi * s) + nu * nu / s)
            Pj = P[:, j].copy()
            for i in range(3):
                x[i] += Pj[i] / s * nu
            for i in range(3):
                for m in range(3):
                    P[i, m] -= Pj[i] * Pj[m] / s
    return loglik


def _optimise(fun, lo, hi, per_decade=GRID_PER_DECADE):
    """Maximise ``fun(log10 omega)`` on [lo, hi]: a grid, then Brent's method around the best
    point."""
    from scipy.optimize import minimize_scalar

    grid = np.linspace(lo, hi, max(3, int(math.ceil((hi - lo) * per_decade)) + 1))
    vals = np.array([fun(g) for g in grid])
    vals[~np.isfinite(vals)] = -np.inf
    i = int(np.argmax(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    if b > a:
        res = minimize_scalar(lambda g: -fun(g), bounds=(a, b), method="bounded",
                              options={"xatol": 0.01})
        if np.isfinite(res.fun) and -res.fun >= vals[i]:
            return float(res.x), float(-res.fun), len(grid) + int(res.nfev)
    return float(grid[i]), float(vals[i]), len(grid)


def process_noise(process, t, Z, R, std_used, x_init, P_init, h, h_max, duration):
    """The white-jerk spectral densities ``q_uv`` and ``q_r`` [A3]: given, or by maximum likelihood
    over the bandwidth ``omega`` (``q = sigma^2 h omega^6``) from 2 pi / duration to the Nyquist
    frequency.

    Parameters
    ----------
    process : "ml" or dict
        The resolved ``process`` option: ``"ml"`` or ``{q_uv, q_r}``.
    t, Z, R : ndarray
        Times (n,), measurements (n, 6) and their variances (6,), as the filter takes them.
    std_used : dict
        {channel: measurement standard deviation} (``x0`` and ``psi`` scale the bandwidth).
    x_init, P_init : ndarray
        The initial state (9,) and its covariance (9, 9).
    h, h_max, duration : float
        The median step, the longest prediction sub-step and the record's duration [s].

    Returns
    -------
    q_uv, q_r : float
    info : dict
        How they were chosen (the settings' ``process_how`` and, by maximum likelihood, the
        bandwidths, their range, any at its bound, the likelihood evaluations).
    """
    lo = math.log10(2.0 * math.pi / max(duration, 10 * h))
    hi = math.log10(math.pi / h)
    info = {}
    if isinstance(process, dict):
        q_uv, q_r = process["q_uv"], process["q_r"]
        info["process_how"] = "given"
    else:
        Rp = std_used["psi"] ** 2
        psi_m = np.array(Z[:, 2], order="C")
        r_m = np.array(Z[:, 5], order="C")
        Ry = np.array(P_init[np.ix_([2, 5, 8], [2, 5, 8])], order="C")
        xy = np.array([x_init[2], x_init[5], 0.0])
        R_r = R[5]

        def yaw_ll(g):
            q = Rp * h * (10.0 ** g) ** 6
            return _yaw_loglik(t, psi_m, r_m, Rp, R_r, q, xy, Ry, h_max)

        g_r, _, ev_r = _optimise(yaw_ll, lo, hi)
        q_r = Rp * h * (10.0 ** g_r) ** 6
        Rx = std_used["x0"] ** 2

        def full_ll(g):
            q = Rx * h * (10.0 ** g) ** 6
            return _ekf(t, Z, R, q, q, q_r, x_init, P_init, h_max, False, _NZ_I, _NZ_K)[0]

        g_uv, _, ev_uv = _optimise(full_ll, lo, hi)
        q_uv = Rx * h * (10.0 ** g_uv) ** 6
        info.update(process_how="maximum likelihood (bandwidth grid + Brent)", bandwidth_r=10.0 ** g_r,
                    bandwidth_uv=10.0 ** g_uv, bandwidth_range=[10.0 ** lo, 10.0 ** hi],
                    at_bound=[name for name, g in (("q_r", g_r), ("q_uv", g_uv))
                              if min(abs(g - lo), abs(g - hi)) < 1e-6],
                    evaluations=int(ev_r + ev_uv))
    return q_uv, q_r, info
