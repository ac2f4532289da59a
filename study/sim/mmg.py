"""MMG standard method: hull, propeller and rudder forces (Yasukawa & Yoshimura 2015).

Yasukawa, H., Yoshimura, Y. (2015). Introduction of MMG standard method for ship maneuvering predictions.
J Mar Sci Technol 20, 37-52. doi:10.1007/s00773-014-0293-y. Equation numbers below refer to that paper.

Non-dimensionalisation (their Sec. 2): X' = X / (0.5 rho L d U^2), N' = N / (0.5 rho L^2 d U^2),
v' = v_m / U, r' = r L / U; masses by 0.5 rho L^2 d, moments of inertia by 0.5 rho L^4 d.
Origin at midship; delta > 0 turns the ship to starboard.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

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


@njit(cache=True, inline="always")
def thrust(u, v, r, n, P, b):
    """Propeller thrust T [N] and the propeller inflow u_P = (1 - w_P) u (eqs. 13-16)."""
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
    # K_T(J) n^2 D^4 expanded so that J -> 0 (ship at rest, propeller running) stays finite
    T = P[0, b] * D * D * (P[30, b] * n * n * D * D + P[31, b] * n * uP * D + P[32, b] * uP * uP)
    return T, uP


@njit(cache=True, inline="always")
def accel(u, v, r, delta, n, Xe, Ye, Ne, P, b):
    """MMG equations of motion (eq. 4) solved for (du, dv, dr); v is the sway velocity at midship."""
    rho = P[0, b]; L = P[1, b]; d = P[2, b]
    m = P[3, b]; xG = P[4, b]; IzG = P[5, b]; mx = P[6, b]; my = P[7, b]; Jz = P[8, b]
    U2 = u * u + v * v
    U = math.sqrt(U2)
    # ---- hull (eqs. 9-11), written with U^2 v'^i r'^j so that U -> 0 stays finite
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
    # ---- propeller (eq. 12)
    T, uP = thrust(u, v, r, n, P, b)
    XP = (1.0 - P[27, b]) * T
    # ---- rudder (eqs. 17-25)
    D = P[26, b]
    eta = P[47, b]; kappa = P[45, b]; eps = P[44, b]
    if uP > 1e-6 and T > 0.0:
        # 8 K_T / (pi J_P^2) = 8 T / (pi rho D^2 u_P^2)
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
    # ---- equations of motion (eq. 4); the v-r coupling through x_G is solved exactly (2 x 2)
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


def pack(vessel: dict) -> np.ndarray:
    """Turn a resolved vessel config (dict) into the parameter vector in ``PARAM_NAMES`` order (SI)."""
    p = vessel["particulars"]
    rho = float(p["rho"])
    L = float(p["Lpp"])
    d = float(p["d"])
    ms = vessel["mass"]
    m = float(ms["m"]) if ms.get("m") is not None else rho * float(p["volume"])
    q_m = 0.5 * rho * L * L * d
    q_J = 0.5 * rho * L ** 4 * d
    IzG = float(ms["IzG"]) if ms.get("IzG") is not None else m * (float(ms.get("kzz_L", 0.25)) * L) ** 2
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


def straight_surge_force(params: np.ndarray, u: float, n: float) -> float:
    """Net surge force on a straight course (v = r = delta = 0); zero at the self-propulsion point."""
    P = params.reshape(-1, 1)
    du, _, _ = accel(u, 0.0, 0.0, 0.0, n, 0.0, 0.0, 0.0, P, 0)
    return du


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
