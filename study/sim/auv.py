"""Horizontal-plane AUV model of Du et al. (2016): Abkowitz-type hull, rudder and propeller.

Du, W., Xu, F., Xiao, T., Yang, L., Wang, M., Du, X. (2016). Online modeling of underwater vehicles'
maneuvering motion by using support vector machine. Ship Science and Technology 38(6), 81-85
(``/work/shared/seeds/003_*.txt``), after Silvestre & Pascoal (1997), Trans. Inst. Meas. Control
19(3), 126-138 (the MARIUS AUV). Equation numbers below are the seed's.

Equations of motion (eq. 1 restricted to the horizontal plane, y_G = 0)::

    m (du/dt - v r - x_G r^2)        = X_H + X_P + X_d
    m (dv/dt + u r + x_G dr/dt)      = Y_H + Y_d
    I_z dr/dt + m x_G (dv/dt + u r)  = N_H + N_d

Hull (eq. 3), a prime system built on L and the surge speed u (not U)::

    X_H = 0.5 rho [L^3 X'udot du/dt + L^2 (X'uu u^2 + X'vv v^2) + L^4 X'rr r^2 + L^3 X'vr v r]
    Y_H = 0.5 rho [L^3 Y'r u r + L^2 Y'v u v + L^5 Y'rrr r^3 / u + L^4 Y'r|r| r|r| + L^2 Y'v|v| v|v|
                   + L^3 Y'vdot dv/dt + L^4 Y'rdot dr/dt]
    N_H = 0.5 rho [L^4 N'r u r + L^3 N'v u v + L^6 N'rrr r^3 / u + L^5 N'r|r| r|r| + L^3 N'v|v| v|v|
                   + L^4 N'vdot dv/dt + L^5 N'rdot dr/dt]

Rudder (eq. 4): X_d = 0.5 rho L^2 u^2 X'dd d^2, Y_d = 0.5 rho L^2 u^2 Y'd d, N_d = 0.5 rho L^3 u^2
N'd d (the seed prints L^2 in N_d; a moment needs L^3, as in every other N term of eq. 3).

Propeller (eq. 5): X_P = 0.5 rho L^2 u^2 X'p with X'p = eta 8 pi n Q_p / (rho L^2 u^3), i.e. X_P = 4
pi eta n Q_p / u. (This is twice the textbook eta P / u with shaft power P = 2 pi n Q; it is kept as
printed, so Q_p here is a propulsion constant fitted with it, not a measured torque.) Below u_min =
0.05 U0 the 1/u of the propeller and of the r^3/u terms is held at 1/u_min (the model is for forward
motion only).

SIGN CONVERSION: the coefficient set in the configs (REMUS 100, Prestero 2001) uses the convention
in which a positive rudder angle gives a positive side force at the stern (Y'd > 0, N'd < 0), a turn
to port. This package's delta > 0 turns to starboard, so the model's rudder angle is d = -delta.

The integrator's ``n`` is the propeller speed [rev/s]; ``solve_n`` gives the n of a straight run at
U0.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .particulars import mass_and_inertia

KIND = "auv"
COEFF_SECTION = "hull"
ADDED_MASS_KEYS = ("Y_vdot", "N_rdot")

PARAM_NAMES = (
    # SI
    "rho", "L", "m", "Iz", "xG", "U0",
    # non-dimensional (eq. 3) added masses
    "Xudot", "Yvdot", "Yrdot", "Nvdot", "Nrdot",
    # hull (eq. 3)
    "Xuu", "Xvv", "Xrr", "Xvr",
    "Yv", "Yr", "Yrrr", "Yrar", "Yvav",
    "Nv", "Nr", "Nrrr", "Nrar", "Nvav",
    # rudder (eq. 4)
    "Xdd", "Yd", "Nd",
    # propeller (eq. 5): efficiency [-], propulsion torque constant [N m]
    "eta", "Qp",
)
IDX = {name: i for i, name in enumerate(PARAM_NAMES)}

# config key in ``hull`` for each non-dimensional parameter
CONFIG_KEYS = {
    "Xudot": "X_udot", "Yvdot": "Y_vdot", "Yrdot": "Y_rdot", "Nvdot": "N_vdot", "Nrdot": "N_rdot",
    "Xuu": "X_uu", "Xvv": "X_vv", "Xrr": "X_rr", "Xvr": "X_vr",
    "Yv": "Y_v", "Yr": "Y_r", "Yrrr": "Y_rrr", "Yrar": "Y_rar", "Yvav": "Y_vav",
    "Nv": "N_v", "Nr": "N_r", "Nrrr": "N_rrr", "Nrar": "N_rar", "Nvav": "N_vav",
    "Xdd": "X_dd", "Yd": "Y_d", "Nd": "N_d",
}

# generic linear derivative -> key in the config's COEFF_SECTION (for the shallow-water effect)
LINEAR_DERIVATIVES = {"Yv": "Y_v", "Yr": "Y_r", "Nv": "N_v", "Nr": "N_r"}

U_MIN_FRAC = 0.05

(I_RHO, I_L, I_M, I_IZ, I_XG, I_U0, I_XUDOT, I_YVDOT, I_YRDOT, I_NVDOT, I_NRDOT,
 I_XUU, I_XVV, I_XRR, I_XVR, I_YV, I_YR, I_YRRR, I_YRAR, I_YVAV,
 I_NV, I_NR, I_NRRR, I_NRAR, I_NVAV, I_XDD, I_YD, I_ND, I_ETA, I_QP) = range(len(PARAM_NAMES))


@njit(cache=False, inline="always", error_model="numpy")  # not cached: would go stale when fastmath changes
def accel(u, v, r, delta, n, Xe, Ye, Ne, P, b):
    """Du et al. (2016) eqs. (1), (3)-(5) in the horizontal plane, solved for (du, dv, dr) [SI]."""
    rho = P[I_RHO, b]; L = P[I_L, b]
    q2 = 0.5 * rho * L * L
    q3 = q2 * L
    q4 = q3 * L
    q5 = q4 * L
    q6 = q5 * L
    m = P[I_M, b]; xG = P[I_XG, b]
    umin = U_MIN_FRAC * P[I_U0, b]
    inv_u = 1.0 / (u if u > umin else umin)
    dl = -delta  # the coefficient set's own rudder sign (see the module docstring)
    ar = abs(r)
    av = abs(v)
    u2 = u * u
    # ---- hull (eq. 3) without the added-mass terms, rudder (eq. 4), propeller (eq. 5)
    XH = q2 * (P[I_XUU, b] * u2 + P[I_XVV, b] * v * v) + q4 * P[I_XRR, b] * r * r + q3 * P[I_XVR, b] * v * r
    YH = (q3 * P[I_YR, b] * u * r + q2 * P[I_YV, b] * u * v + q5 * P[I_YRRR, b] * r * r * r * inv_u
          + q4 * P[I_YRAR, b] * r * ar + q2 * P[I_YVAV, b] * v * av)
    NH = (q4 * P[I_NR, b] * u * r + q3 * P[I_NV, b] * u * v + q6 * P[I_NRRR, b] * r * r * r * inv_u
          + q5 * P[I_NRAR, b] * r * ar + q3 * P[I_NVAV, b] * v * av)
    Xd = q2 * u2 * P[I_XDD, b] * dl * dl
    Yd = q2 * u2 * P[I_YD, b] * dl
    Nd = q3 * u2 * P[I_ND, b] * dl
    XP = 4.0 * math.pi * P[I_ETA, b] * n * P[I_QP, b] * inv_u
    # ---- equations of motion: rigid body (eq. 1) plus the added-mass terms of eq. 3 on the left
    m11 = m - q3 * P[I_XUDOT, b]
    m22 = m - q3 * P[I_YVDOT, b]
    m23 = m * xG - q4 * P[I_YRDOT, b]
    m32 = m * xG - q4 * P[I_NVDOT, b]
    m33 = P[I_IZ, b] - q5 * P[I_NRDOT, b]
    FX = XH + Xd + XP + Xe + m * (v * r + xG * r * r)
    FY = YH + Yd + Ye - m * u * r
    FN = NH + Nd + Ne - m * xG * u * r
    det = m22 * m33 - m23 * m32
    du = FX / m11
    dv = (m33 * FY - m23 * FN) / det
    dr = (m22 * FN - m32 * FY) / det
    return du, dv, dr


def pack(vessel: dict) -> np.ndarray:
    """Resolved vessel config -> parameter vector in ``PARAM_NAMES`` order (SI; hull/rudder
    non-dimensional)."""
    p = vessel["particulars"]
    rho, L, m, Iz = mass_and_inertia(vessel)
    h = vessel["hull"]
    pr = vessel["propeller"]
    vals = {"rho": rho, "L": L, "m": m, "Iz": Iz, "xG": float(p["xG"]), "U0": float(vessel["operation"]["U0"]),
            "eta": float(pr["eta"]), "Qp": float(pr["Q_p"])}
    for name, key in CONFIG_KEYS.items():
        vals[name] = float(h[key])
    return np.array([float(vals[k]) for k in PARAM_NAMES])


def solve_n(params: np.ndarray, U0: float) -> float:
    """Propeller speed [rev/s] of a straight run at U0: X_P = -0.5 rho L^2 X'uu U0^2 (eq. 3 and
    5)."""
    rho, L, Xuu = params[I_RHO], params[I_L], params[I_XUU]
    eta, Qp = params[I_ETA], params[I_QP]
    if Xuu >= 0.0 or eta * Qp <= 0.0:
        raise ValueError(f"no straight-run propeller speed: X'uu = {Xuu} must be < 0 and eta Q_p = {eta * Qp} > 0")
    return -0.5 * rho * L * L * Xuu * U0 ** 3 / (4.0 * math.pi * eta * Qp)
