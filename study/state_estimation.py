"""State estimation: u, v, r and their time derivatives from positions and heading, by an extended Kalman
filter (EKF) and a Rauch-Tung-Striebel (RTS) smoother on a kinematic model (no hydrodynamics).

:func:`estimate_states` estimates ``u, v, r`` and ``u_dot, v_dot, r_dot`` from ``x0, y0, psi`` alone, or refines
measured ``u, v, r``. Used by ``study.schema.read_record(..., states="auto"|"ekf")`` and by the ``smoothed``
structure with ``smoothing.method: rts``. The model is the Wiener-process-acceleration model of Bar-Shalom, Li &
Kirubarajan (2001, Sec. 6.2.3) in body axes; the smoother the extended RTS smoother (Rauch, Tung & Striebel 1965;
Simon 2006, Sec. 9.4 and 13.2); the process noise is chosen by maximum likelihood (Harvey 1989, Sec. 3.4). The
model, the assumptions [A1]-[A5] the code refers to, and why it is written by hand (numba) rather than taken from
a library are in ``docs/concepts/state-estimation.md``.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numba import njit

#: state order of the filter
STATES = ("x0", "y0", "psi", "u", "v", "r", "u_dot", "v_dot", "r_dot")
#: measured channels (the first six states, in the same order)
CHANNELS = ("x0", "y0", "psi", "u", "v", "r")
#: what ``options`` may hold, with their defaults (see :func:`estimate_states`)
DEFAULTS = {
    "position_std": "auto",  # m, absolute standard deviation of x0 and y0 (GNSS), or "auto"
    "heading_std": "auto",  # rad, of psi, or "auto"
    "u_std": "auto",  # m/s, of a measured u (used only when the record has u), or "auto"
    "v_std": "auto",  # m/s
    "r_std": "auto",  # rad/s
    "use_velocities": True,  # fuse measured u, v, r where the record has them (false: positions and heading only)
    "process": "ml",  # "ml" (maximum likelihood over q_r and q_uv) or {"q_uv": m^2/s^5, "q_r": rad^2/s^5}
}
#: a step longer than this many median steps is split (a dropout bridged by prediction)
GAP_FACTOR = 1.5
#: the largest heading change [rad] of one prediction sub-step
MAX_TURN_STEP = 0.05
#: bandwidth grid of the likelihood search: points per decade of omega
GRID_PER_DECADE = 4


# --------------------------------------------------------------------------------------------- kernels
# (numba: self-contained, cached on disk; small dense 9 x 9 algebra written as loops)

@njit(cache=True)
def _step(x, h, F, Q, q_u, q_v, q_r):
    """One prediction sub-step of length h from state x (in place): x <- f(x), F <- its Jacobian (set), Q <-
    the sub-step's process noise (set)."""
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
    """out = F A for a Jacobian F = I + N with the sparse N of ``_NZ_I, _NZ_K`` (17 row updates, not 729)."""
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
    """The filter over every sample. Z (n, 6): measurements of x0, y0, psi, u, v, r (NaN: none); R (6,)
    variances. Returns (log-likelihood, x_f, P_f, x_p, P_p, Fs); the arrays are filled only with ``store``
    (the smoother's inputs): x_p[k], P_p[k] the prediction at sample k, Fs[k] the Jacobian from k-1 to k."""
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
    """out = A^-1 B for a symmetric positive definite 9 x 9 A (Cholesky, no allocation); returns False if A is
    not positive definite."""
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
    """Extended RTS smoother (Sarkka 2013, Sec. 9.1): states and standard deviations at every sample."""
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
    """Log-likelihood of the heading (and yaw-rate) measurements under the yaw chain [psi, r, r_dot] alone
    (it does not depend on u, v or positions): the ML search of q_r."""
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


# ------------------------------------------------------------------------------------------ helpers

def noise_std(a: np.ndarray, order: int = 4) -> float:
    """The white-noise standard deviation of a smooth signal plus noise (NaN ignored), from its ``order``-th
    differences (the difference method: von Neumann et al. 1941; Hall, Kay & Titterington 1990), robustly by their
    median absolute deviation (1.4826 MAD estimates a normal sd; Rousseeuw & Croux 1993). See [A2] in
    ``docs/concepts/state-estimation.md``."""
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    if len(a) <= order + 2:
        return 0.0
    d = np.diff(a, order)
    norm = math.sqrt(math.comb(2 * order, order))
    mad = float(np.median(np.abs(d - np.median(d))))
    est = 1.4826 * mad / norm
    if est == 0.0:  # quantised data: the plain spread
        est = float(np.std(d)) / norm
    return est


@dataclass
class StateEstimate:
    """The smoothed states at the record's times: ``frame`` (columns ``time`` and :data:`STATES`), ``std``
    (their smoothed standard deviations, same columns), and ``settings`` (what the filter used: the noise
    standard deviations and whether each was estimated, the process noise and how it was chosen, the
    log-likelihood, the seconds taken); JSON-serialisable, as stored in a record's metadata."""

    frame: pd.DataFrame
    std: pd.DataFrame
    settings: dict = field(default_factory=dict)

    def __getitem__(self, key):
        return self.frame[key].to_numpy()


def resolve_options(options: dict | None) -> dict:
    """``options`` merged over :data:`DEFAULTS`; unknown keys refused (a misspelt option must not pass)."""
    opts = dict(DEFAULTS)
    for k, v in (options or {}).items():
        if k not in DEFAULTS:
            raise ValueError(f"state estimation: unknown option '{k}'; known: {sorted(DEFAULTS)}")
        opts[k] = v
    proc = opts["process"]
    if isinstance(proc, str):
        if proc != "ml":
            raise ValueError(f"state estimation: process must be 'ml' or {{q_uv: ..., q_r: ...}}, got '{proc}'")
    else:
        proc = dict(proc)
        bad = sorted(set(proc) - {"q_uv", "q_r"})
        if bad or not {"q_uv", "q_r"} <= set(proc):
            raise ValueError(f"state estimation: process needs exactly q_uv [m^2/s^5] and q_r [rad^2/s^5], got "
                             f"{sorted(proc)}")
        if not all(float(v) > 0 and math.isfinite(float(v)) for v in proc.values()):
            raise ValueError(f"state estimation: process noise must be positive and finite, got {proc}")
        opts["process"] = {k: float(v) for k, v in proc.items()}
    for k in ("position_std", "heading_std", "u_std", "v_std", "r_std"):
        v = opts[k]
        if v is None or v == "auto":
            opts[k] = "auto"
            continue
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"state estimation: {k} must be a number (absolute standard deviation) or 'auto', "
                             f"got {v!r}") from None
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"state estimation: {k} must be positive and finite, got {v}")
        opts[k] = v
    opts["use_velocities"] = bool(opts["use_velocities"])
    return opts


def _column(data, name, n):
    if name in data:
        return np.asarray(data[name], float).reshape(-1)
    return np.full(n, np.nan)


def _lagged(t, a, lag_s):
    """Finite differences over about ``lag_s`` seconds (robust scales and the initial state)."""
    ok = np.isfinite(a)
    tt, aa = t[ok], a[ok]
    if len(tt) < 2:
        return np.zeros(0), np.zeros(0)
    h = float(np.median(np.diff(tt)))
    lag = int(max(1, min(len(tt) - 1, round(lag_s / h))))
    return (aa[lag:] - aa[:-lag]), (tt[lag:] - tt[:-lag])


def _optimise(fun, lo, hi, per_decade=GRID_PER_DECADE):
    """Maximise ``fun(log10 omega)`` on [lo, hi]: a grid, then Brent's method around the best point."""
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


def estimate_states(data, options: dict | None = None, **kw) -> StateEstimate:
    """Estimate ``u, v, r, u_dot, v_dot, r_dot`` (and smoothed ``x0, y0, psi``) from a record's positions and
    heading, refining measured ``u, v, r`` when present. The model, the assumptions [A1]-[A5] and the sources are
    in ``docs/concepts/state-estimation.md``. One function: its steps (the record's scales, measurement noise,
    initial state, process noise, filter and smoother) run once, in order, each using the previous ones' locals.

    Parameters
    ----------
    data : DataFrame or dict of arrays
        ``time`` (s, increasing, any spacing), ``x0``, ``y0`` (m), ``psi`` (rad); optionally ``u``, ``v``
        (m/s), ``r`` (rad/s). NaN marks a missing sample of a channel (its update is skipped).
    options : dict, optional (or keywords)
        :data:`DEFAULTS`: ``position_std``, ``heading_std``, ``u_std``, ``v_std``, ``r_std`` (absolute
        standard deviations or ``"auto"``), ``use_velocities`` (fuse measured u, v, r; default true),
        ``process`` (``"ml"`` or ``{q_uv, q_r}``).

    Returns
    -------
    StateEstimate
    """
    t_start = time.perf_counter()
    opts = resolve_options({**(options or {}), **kw})
    # writable, C-contiguous float64 copies: one compiled signature of each kernel (a read-only or strided
    # array would make numba compile another)
    t = np.array(data["time"], dtype=np.float64, order="C").reshape(-1)
    n = len(t)
    if n < 5:
        raise ValueError(f"state estimation needs at least 5 samples, got {n}")
    dts = np.diff(t)
    if not np.all(dts > 0):
        raise ValueError("state estimation: time must be strictly increasing")
    Z = np.ascontiguousarray(np.column_stack([_column(data, c, n) for c in CHANNELS]), dtype=np.float64)
    for j, c in enumerate(("x0", "y0", "psi")):
        if np.sum(np.isfinite(Z[:, j])) < 5:
            raise ValueError(f"state estimation: column '{c}' has fewer than 5 values; positions x0, y0 and the "
                             "heading psi are needed")
    if not opts["use_velocities"]:
        Z[:, 3:] = np.nan
    has = {c: bool(np.isfinite(Z[:, j]).any()) for j, c in enumerate(CHANNELS)}
    h = float(np.median(dts))
    duration = float(t[-1] - t[0])

    # --- robust scales of the record (initial state, floors): speed and turn rate over ten samples
    lag_s = h * max(1, min(10, n // 20))
    dx, dtx = _lagged(t, Z[:, 0], lag_s)
    dy, _ = _lagged(t, Z[:, 1], lag_s)
    dpsi, dtp = _lagged(t, Z[:, 2], lag_s)
    speeds = np.hypot(dx, dy) / dtx if len(dx) and len(dx) == len(dy) else np.zeros(1)
    U_typ = float(np.percentile(speeds, 90)) if len(speeds) else 0.0
    rates = np.abs(dpsi) / dtp if len(dpsi) else np.zeros(1)
    r_typ = float(np.percentile(rates, 90)) if len(rates) else 0.0

    # --- measurement noise [A2]
    floors = {"x0": 1e-3 * max(U_typ, 1e-6) * h, "psi": 1e-3 * max(r_typ, 1e-6) * h + 1e-7,
              "u": 1e-4 * max(U_typ, 1e-6), "r": 1e-4 * max(r_typ, 1e-6) + 1e-8}
    floors.update(y0=floors["x0"], v=floors["u"])
    std_used, auto = {}, {}
    keys = {"x0": "position_std", "y0": "position_std", "psi": "heading_std", "u": "u_std", "v": "v_std",
            "r": "r_std"}
    for j, c in enumerate(CHANNELS):
        given = opts[keys[c]]
        if given == "auto":
            if c in ("x0", "y0"):
                est = max(noise_std(Z[:, 0]), noise_std(Z[:, 1]))  # one GNSS: one number for both
            else:
                est = noise_std(Z[:, j]) if has[c] else float("nan")
            std_used[c] = max(est, floors[c]) if has[c] else float("nan")
            auto[c] = True
        else:
            std_used[c] = float(given)
            auto[c] = False
    R = np.array([std_used[c] ** 2 if has[c] else 1.0 for c in CHANNELS])

    # --- initial state [A4]
    def first(j):
        ok = np.nonzero(np.isfinite(Z[:, j]))[0]
        return ok[0] if len(ok) else 0

    k0 = max(first(0), first(1), first(2))
    x_init = np.zeros(9)
    x_init[0], x_init[1], x_init[2] = Z[first(0), 0], Z[first(1), 1], Z[first(2), 2]
    m = int(min(n - 1, max(2, round(lag_s / h))))
    win = slice(k0, min(n, k0 + m + 1))
    tw = t[win]
    if len(tw) >= 3:
        def slope(a):
            ok = np.isfinite(a)
            return float(np.polyfit(tw[ok], a[ok], 1)[0]) if ok.sum() >= 2 else 0.0

        vx, vy, rr = slope(Z[win, 0]), slope(Z[win, 1]), slope(Z[win, 2])
        c0, s0 = math.cos(x_init[2]), math.sin(x_init[2])
        x_init[3], x_init[4], x_init[5] = vx * c0 + vy * s0, -vx * s0 + vy * c0, rr
    T0 = max(lag_s, h)
    sd_uv = max(U_typ, 10.0 * std_used["x0"] / T0, 1e-6)
    sd_r = max(r_typ, 10.0 * std_used["psi"] / T0, 1e-8)
    P_init = np.diag(np.array([
        (3 * std_used["x0"]) ** 2 + (U_typ * (t[k0] - t[0])) ** 2,
        (3 * std_used["y0"]) ** 2 + (U_typ * (t[k0] - t[0])) ** 2,
        (3 * std_used["psi"]) ** 2 + (r_typ * (t[k0] - t[0])) ** 2,
        sd_uv ** 2, sd_uv ** 2, sd_r ** 2, (sd_uv / T0) ** 2, (sd_uv / T0) ** 2, (sd_r / T0) ** 2]))
    h_max = GAP_FACTOR * h

    # --- process noise [A3]
    lo = math.log10(2.0 * math.pi / max(duration, 10 * h))
    hi = math.log10(math.pi / h)
    info = {}
    if isinstance(opts["process"], dict):
        q_uv, q_r = opts["process"]["q_uv"], opts["process"]["q_r"]
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

        g_r, ll_r, ev_r = _optimise(yaw_ll, lo, hi)
        q_r = Rp * h * (10.0 ** g_r) ** 6
        Rx = std_used["x0"] ** 2

        def full_ll(g):
            q = Rx * h * (10.0 ** g) ** 6
            return _ekf(t, Z, R, q, q, q_r, x_init, P_init, h_max, False, _NZ_I, _NZ_K)[0]

        g_uv, ll, ev_uv = _optimise(full_ll, lo, hi)
        q_uv = Rx * h * (10.0 ** g_uv) ** 6
        info.update(process_how="maximum likelihood (bandwidth grid + Brent)", bandwidth_r=10.0 ** g_r,
                    bandwidth_uv=10.0 ** g_uv, bandwidth_range=[10.0 ** lo, 10.0 ** hi],
                    at_bound=[name for name, g in (("q_r", g_r), ("q_uv", g_uv))
                              if min(abs(g - lo), abs(g - hi)) < 1e-6],
                    evaluations=int(ev_r + ev_uv))

    ll, x_f, P_f, x_p, P_p, Fs = _ekf(t, Z, R, q_uv, q_uv, q_r, x_init, P_init, h_max, True, _NZ_I, _NZ_K)
    xs, sd = _rts(x_f, P_f, x_p, P_p, Fs)
    frame = pd.DataFrame({"time": t, **{s: xs[:, i] for i, s in enumerate(STATES)}})
    std = pd.DataFrame({"time": t, **{s: sd[:, i] for i, s in enumerate(STATES)}})
    settings = {
        "method": "ekf_rts",
        "measured": [c for c in CHANNELS if has[c]],
        "noise_std": {c: std_used[c] for c in CHANNELS if has[c]},
        "noise_std_estimated": {c: auto[c] for c in CHANNELS if has[c]},
        "process": {"q_uv": float(q_uv), "q_r": float(q_r)},
        **info,
        "log_likelihood": float(ll),
        "samples": int(n),
        "seconds": round(time.perf_counter() - t_start, 4),
        "options": {k: v for k, v in opts.items()},
    }
    return StateEstimate(frame, std, settings)


#: the columns a record gets from the estimate (u, v, r replaced or added; the derivatives added)
RECORD_COLUMNS = ("u", "v", "r", "u_dot", "v_dot", "r_dot")


def apply_to_frame(df: pd.DataFrame, options: dict | None = None) -> tuple[pd.DataFrame, dict]:
    """A copy of a record's table with ``u, v, r`` estimated (replaced, or added after ``time`` when missing)
    and ``u_dot, v_dot, r_dot`` added; positions and heading stay as measured. Returns (frame, settings)."""
    est = estimate_states(df, options)
    out = df.copy()
    for c in RECORD_COLUMNS:
        out[c] = est.frame[c].to_numpy()
    lead = ["time"] + [c for c in ("u", "v", "r") if c not in df.columns]
    rest = [c for c in out.columns if c not in lead]
    return out[lead + rest], est.settings
