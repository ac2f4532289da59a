"""MMG standard method: hull, propeller and rudder forces (Yasukawa & Yoshimura 2015).

Yasukawa, H., Yoshimura, Y. (2015). Introduction of MMG standard method for ship maneuvering
predictions. J Mar Sci Technol 20, 37-52. doi:10.1007/s00773-014-0293-y. Equation numbers below
refer to that paper.

Non-dimensionalisation (their Sec. 2): X' = X / (0.5 rho L d U^2), N' = N / (0.5 rho L^2 d U^2),
v' = v_m / U, r' = r L / U; masses by 0.5 rho L^2 d, moments of inertia by 0.5 rho L^4 d.
Origin at midship; delta > 0 turns the ship to starboard.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from .particulars import mass_and_inertia

from . import fastmath as fm

KIND = "mmg"
COEFF_SECTION = "hull"  # the config block that holds the hydrodynamic coefficients
ADDED_MASS_KEYS = ("m_y", "J_z")

PARAM_NAMES = (
    # particulars and masses (SI)
    "rho", "L", "d", "m", "xG", "IzG", "mx", "my", "Jz",
    # hull, non-dimensional (eq. 9-11)
    "R0", "Xvv", "Xvr", "Xrr", "Xvvvv",
    "Yv", "Yr", "Yvvv", "Yvvr", "Yvrr", "Yrrr",
    "Nv", "Nr", "Nvvv", "Nvvr", "Nvrr", "Nrrr",
    # propeller (eq. 12-16)
    "DP", "tP", "wP0", "xP", "k0", "k1", "k2", "C1", "C2_pos", "C2_neg",
    # rudder (eq. 17-25)
    "AR", "tR", "aH", "xH", "xR", "lR", "gR_neg", "gR_pos", "eps", "kappa", "f_alpha", "eta",
)
IDX = {name: i for i, name in enumerate(PARAM_NAMES)}

# Hull derivatives that shallow-water corrections act on (name in this kind -> generic name).
LINEAR_DERIVATIVES = {"Yv": "Y_v", "Yr": "Y_r", "Nv": "N_v", "Nr": "N_r"}


# The model below is written branch-free (conditions become selects) with the pure-arithmetic atan2/exp/sincos
# of ``study.sim.fastmath``, so that the integrator's loop over a batch of parameter sets vectorises
# (AVX2/AVX-512); ``error_model='numpy'`` because Python's division-by-zero checks are branches too. Both
# sides of every select are computed; the unused side may be inf/nan (e.g. 1/U at U = 0) and is discarded.
# Not cached on disk (cache=False): the fastmath functions are inlined here and numba's cache would not notice
# a change in fastmath.py (the integrator, which inlines this, has its own fingerprinted cache key).


@njit(cache=False, inline="always", error_model="numpy")
def thrust(u, v, r, n, P, b):
    """Propeller thrust T [N] and the propeller inflow u_P = (1 - w_P) u (eqs. 13-16)."""
    U = fm.sqrt(u * u + v * v)
    moving = U > 1e-6
    beta = fm.select(moving, fm.atan2(-v, u), 0.0)
    rp = fm.select(moving, r * P[1, b] / U, 0.0)
    T, uP, _ = _thrust(u, beta, rp, n, P, b)
    return T, uP


@njit(cache=False, inline="always", error_model="numpy")
def _thrust(u, beta, rp, n, P, b):
    """(T, u_P, 8 T / (pi rho D^2 u_P^2)) for drift angle beta and r' (eqs. 13-16)."""
    beta_P = beta - P[29, b] * rp
    C2_pos = P[34, b]  # both loaded, then selected: a load under a condition would stop vectorisation
    C2_neg = P[35, b]
    C2 = fm.select(beta_P > 0.0, C2_pos, C2_neg)
    # u_P = u (1 - w_P0) (1 + (1 - exp(-C1 |beta_P|)) (C2 - 1)), written as a + b exp(...)
    uw = u * (1.0 - P[28, b])
    uP = uw * C2 - (uw * (C2 - 1.0)) * fm.exp(-P[33, b] * abs(beta_P))
    D = P[26, b]
    nD = n * D
    # K_T(J) n^2 D^4 expanded so that J -> 0 (ship at rest, propeller running) stays finite
    kt = P[30, b] * nD * nD + (P[31, b] * nD + P[32, b] * uP) * uP
    T = fm.select(n > 0.0, P[0, b] * D * D * kt, 0.0)
    # 8 K_T / (pi J_P^2) = 8 T / (pi rho D^2 u_P^2), from kt directly (one division fewer on the chain)
    jet_load = (8.0 / math.pi) * kt / (uP * uP)
    return T, uP, jet_load


@njit(cache=False, inline="always", error_model="numpy")
def accel(u, v, r, delta, n, Xe, Ye, Ne, P, b):
    """MMG equations of motion (eq. 4) solved for (du, dv, dr); v is the sway velocity at midship.

    Written for a short dependency chain (a single simulation is latency-bound): the rudder normal
    force enters X, Y and N linearly, so its coefficients are folded into the solved accelerations
    before F_N is known, and U_R^2 is formed from u_R^2 so that the two square roots of the rudder
    inflow run side by side.
    """
    rho = P[0, b]; L = P[1, b]; d = P[2, b]
    m = P[3, b]; xG = P[4, b]; IzG = P[5, b]; mx = P[6, b]; my = P[7, b]; Jz = P[8, b]
    U2 = u * u + v * v
    U = fm.sqrt(U2)
    # ---- hull (eqs. 9-11), written with U^2 v'^i r'^j so that U -> 0 stays finite
    moving = U > 1e-6
    vp = fm.select(moving, v / U, 0.0)
    rp = fm.select(moving, r * L / U, 0.0)
    vp2 = vp * vp
    rp2 = rp * rp
    qX = 0.5 * rho * L * d * U2
    qN = qX * L
    XH = qX * (-P[9, b] + P[10, b] * vp2 + P[11, b] * vp * rp + P[12, b] * rp2 + P[13, b] * (vp2 * vp2))
    YH = qX * (P[14, b] * vp + P[15, b] * rp + P[16, b] * (vp2 * vp) + P[17, b] * vp2 * rp
               + P[18, b] * vp * rp2 + P[19, b] * (rp2 * rp))
    NH = qN * (P[20, b] * vp + P[21, b] * rp + P[22, b] * (vp2 * vp) + P[23, b] * vp2 * rp
               + P[24, b] * vp * rp2 + P[25, b] * (rp2 * rp))
    # ---- propeller (eq. 12); the drift angle beta is shared with the rudder inflow below
    beta = fm.select(moving, fm.atan2(-v, u), 0.0)
    T, uP, jet_load = _thrust(u, beta, rp, n, P, b)
    XP = (1.0 - P[27, b]) * T
    # ---- rudder (eqs. 17-25)
    eta = P[47, b]; kappa = P[45, b]; eps = P[44, b]
    # u_R = eps u_P sqrt(eta (1 + kappa s)^2 + 1 - eta), s = sqrt(1 + 8 K_T / (pi J_P^2)) - 1 (eq. 22-23)
    jet = (uP > 1e-6) & (T > 0.0)
    g = (1.0 - kappa) + kappa * fm.sqrt(1.0 + jet_load)  # 1 + kappa s
    f = fm.select(jet, eta * (g * g) + (1.0 - eta), 1.0)
    eu = eps * uP
    uR = eu * fm.sqrt(f)
    beta_R = beta - P[41, b] * rp
    gR_neg = P[42, b]
    gR_pos = P[43, b]
    gR = fm.select(beta_R < 0.0, gR_neg, gR_pos)
    vR = U * gR * beta_R
    UR2 = (eu * eu) * f + vR * vR  # = u_R^2 + v_R^2
    # F_N = 0.5 rho A_R U_R^2 f_alpha sin(alpha_R), alpha_R = delta - atan2(v_R, u_R); with
    # cos(atan2(vR, uR)) = uR / U_R and sin(...) = vR / U_R: U_R^2 sin(alpha_R) = U_R (uR sin d - vR cos d)
    sdl, cdl = fm.sincos(delta)
    FN = (0.5 * rho * P[36, b] * P[46, b]) * ((uR * sdl - vR * cdl) * fm.sqrt(UR2))
    # X_R = -(1 - t_R) F_N sin d, Y_R = -(1 + a_H) F_N cos d, N_R = -(x_R + a_H x_H) F_N cos d
    cXR = -(1.0 - P[37, b]) * sdl
    cYR = -(1.0 + P[38, b]) * cdl
    cNR = -(P[40, b] + P[38, b] * P[39, b]) * cdl
    # ---- equations of motion (eq. 4); the v-r coupling through x_G is solved exactly (2 x 2);
    # the reciprocals depend on the parameters only (off the state's dependency chain)
    inv_mx = 1.0 / (m + mx)
    a11 = m + my
    a12 = xG * m
    a22 = IzG + xG * xG * m + Jz
    inv_det = 1.0 / (a11 * a22 - a12 * a12)
    X0 = XH + XP + Xe + (m + my) * v * r + xG * m * r * r
    Y0 = YH + Ye - (m + mx) * u * r
    N0 = NH + Ne - xG * m * u * r
    du = X0 * inv_mx + (cXR * inv_mx) * FN
    dv = (Y0 * a22 - a12 * N0) * inv_det + ((cYR * a22 - a12 * cNR) * inv_det) * FN
    dr = (a11 * N0 - a12 * Y0) * inv_det + ((a11 * cNR - a12 * cYR) * inv_det) * FN
    return du, dv, dr


def pack(vessel: dict) -> np.ndarray:
    """Turn a resolved vessel config (dict) into the parameter vector in ``PARAM_NAMES`` order
    (SI)."""
    p = vessel["particulars"]
    rho, L, m, IzG = mass_and_inertia(vessel)
    d = float(p["d"])
    q_m = 0.5 * rho * L * L * d
    q_J = 0.5 * rho * L ** 4 * d
    h = vessel["hull"]
    pr = vessel["propeller"]
    rd = vessel["rudder"]
    vals = dict(
        rho=rho, L=L, d=d, m=m, xG=float(p["xG"]), IzG=IzG,
        mx=float(h["m_x"]) * q_m, my=float(h["m_y"]) * q_m, Jz=float(h["J_z"]) * q_J,
        R0=h["R_0"], Xvv=h["X_vv"], Xvr=h["X_vr"], Xrr=h["X_rr"], Xvvvv=h["X_vvvv"],
        Yv=h["Y_v"], Yr=h["Y_r"], Yvvv=h["Y_vvv"], Yvvr=h["Y_vvr"], Yvrr=h["Y_vrr"], Yrrr=h["Y_rrr"],
        Nv=h["N_v"], Nr=h["N_r"], Nvvv=h["N_vvv"], Nvvr=h["N_vvr"], Nvrr=h["N_vrr"], Nrrr=h["N_rrr"],
        DP=pr["D_P"], tP=pr["t_P"], wP0=pr["w_P0"], xP=pr["x_P"], k0=pr["k0"], k1=pr["k1"], k2=pr["k2"],
        C1=pr["C1"], C2_pos=pr["C2_pos"], C2_neg=pr["C2_neg"],
        AR=rd["A_R"], tR=rd["t_R"], aH=rd["a_H"], xH=float(rd["x_H"]) * L, xR=float(rd["x_R"]) * L,
        lR=rd["l_R"], gR_neg=rd["gamma_R_neg"], gR_pos=rd["gamma_R_pos"], eps=rd["epsilon"],
        kappa=rd["kappa"], f_alpha=rd["f_alpha"], eta=rd["eta"],
    )
    return np.array([float(vals[k]) for k in PARAM_NAMES])


@lru_cache(maxsize=1)
def _accel_kernel():
    # accel called from Python would be compiled afresh in every process (2-4 s: accel is not cached on disk);
    # the kernel looping over it is (study.sim.core.make_accel_kernel)
    from .core import make_accel_kernel

    return make_accel_kernel(accel, len(PARAM_NAMES))


def straight_surge_force(params: np.ndarray, u: float, n: float) -> float:
    """Net surge force on a straight course (v = r = delta = 0); zero at the self-propulsion
    point."""
    P = np.ascontiguousarray(params, dtype=np.float64).reshape(-1, 1)
    zero = np.zeros(1)
    out = np.empty((1, 1, 3))
    _accel_kernel()(np.array([float(u)]), zero, zero, zero, np.array([float(n)]), np.zeros((3, 1)), P, out)
    return float(out[0, 0, 0])


def solve_n(params: np.ndarray, U0: float) -> float:
    """Propeller speed [rps] for self-propulsion at U0: net surge force zero on a straight course.

    Solved with scipy's brentq over J_P in (0.05, 2) of the propeller's own open-water range.
    """
    from scipy.optimize import brentq

    D = params[IDX["DP"]]
    uP = U0 * (1.0 - params[IDX["wP0"]])
    lo, hi = uP / (2.0 * D), uP / (0.05 * D)  # J from 2 down to 0.05
    f = lambda n: straight_surge_force(params, U0, n)  # noqa: E731
    if f(lo) * f(hi) > 0:
        raise ValueError(f"no self-propulsion point at U0={U0} m/s for n in [{lo:.3g}, {hi:.3g}] rps")
    return brentq(f, lo, hi, xtol=1e-10)
