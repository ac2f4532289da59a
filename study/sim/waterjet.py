"""Waterjet-propelled USV, 3-DOF separated (MMG-type) model of Song et al. (2025).

Song, L., Wang, Y., Peng, W., Li, P., Liu, Y., Zhang, Y. (2025). Hydrodynamic coefficients
identification of ship simplified modular model based on support vector regression. Chinese Journal
of Ship Research 20(1), 65-75, doi:10.19693/j.issn.1673-3185.03832
(``/work/shared/seeds/000_*.txt``). Equation numbers below are the
seed's.

Equations of motion (eq. 1; origin at the centre of gravity, so there is no x_G coupling)::

    (m + m_x) du/dt = (m + m_y) v r + X_H + X_P
    (m + m_y) dv/dt = -(m + m_x) u r + Y_H + Y_P
    (I_zz + J_zz) dr/dt = N_H + N_P

The seed prints ``-(m + m_x) r v`` in the sway equation; its identification equation (eq. 14) uses
``u(k) r(k)``, which is the physically right centripetal term, and that is what is used here.

Hull forces (eq. 2), non-dimensionalised as in the seed's regression (eq. 14): forces by 0.5 rho L
d, the yaw moment by 0.5 rho L^2 d, times the dimensional velocity products of the seed's
regressors::

    X_H = 0.5 rho L d   (X'uu u^2 + X'vv v^2 + X'rr r^2 L^2)
    Y_H = 0.5 rho L d   (Y'v v U + Y'r r U L + Y'vv v|v| + Y'vr |v| r L + Y'rr r|r| L^2)
    N_H = 0.5 rho L^2 d (N'v v U + N'r r U L + N'rr r|r| L^2 + N'vrr v r^2 L^2 / U + N'vvr v^2 r L / U)

with U = sqrt(u^2 + v^2). These are the MMG forms X' U^2 with v' = v/U, r' = r L/U (e.g. Y'vr |v'|
r' U^2 = Y'vr |v| r L). Eq. 14 as printed divides the yaw equation's inertia term (I'zz + J'zz) L^3
dr/dt by 0.5 rho L d but the jet moment by 0.5 rho L^2 d; the second (standard MMG) is used. The
full model's N'vrr, N'vvr have no published regressor; the MMG forms above are used (the simplified
model, eq. 13, drops them).

Waterjet (eq. 3)::

    X_P = rho A_j v_j (v_j - alpha u) cos(delta_s)
    Y_P = rho A_j v_j (v_j - alpha v) sin(delta_s)
    N_P = Y_P x_T

SIGN CONVERSION: with the nozzle aft of the centre of gravity (x_T < 0) the seed's eq. 3 gives N_P <
0, a turn to port, for a positive nozzle angle delta_s. This package's delta > 0 turns to starboard,
so delta_s = -delta: Y_P = -rho A_j v_j (v_j - alpha v) sin(delta), N_P = Y_P x_T > 0 for delta > 0.

Steering with the published hull: the seed's N'v is positive, which puts the hull's sway neutral
point at x = (N'v / Y'v) L = -0.617 L from G. A jet forward of it gives a steady turn opposite to
its own moment, so the config's x_T is an effective lever arm beyond that point (see
conf/vessel/usv_waterjet.yaml).

Actuators: the integrator's propeller input ``n`` is used as the jet velocity v_j in m/s (not
rev/s); the nozzle angle is the integrator's rudder ``delta`` (with the steering gear of the
config's ``actuator`` block). ``solve_n`` gives the v_j of a steady straight run at U0 in closed
form.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .particulars import mass_and_inertia

from . import fastmath as fm

KIND = "waterjet"
COEFF_SECTION = "hull"
ADDED_MASS_KEYS = ("m_y", "J_z")

PARAM_NAMES = (
    # particulars and masses (SI)
    "rho", "L", "d", "m", "Izz", "mx", "my", "Jzz",
    # hull, non-dimensional (eq. 2 with the scaling of eq. 14)
    "Xuu", "Xvv", "Xrr",
    "Yv", "Yr", "Yvv", "Yvr", "Yrr",
    "Nv", "Nr", "Nrr", "Nvrr", "Nvvr",
    # waterjet (eq. 3): nozzle area [m^2], momentum factor [-], thrust point [m, + forward of G]
    "Aj", "alpha", "xT",
)
IDX = {name: i for i, name in enumerate(PARAM_NAMES)}

# generic linear derivative -> key in the config's COEFF_SECTION (for the shallow-water effect)
LINEAR_DERIVATIVES = {"Yv": "Y_v", "Yr": "Y_r", "Nv": "N_v", "Nr": "N_r"}

# indices into P (module constants: numba freezes them as compile-time constants)
I_RHO, I_L, I_D, I_M, I_IZZ, I_MX, I_MY, I_JZZ = (IDX[k] for k in ("rho", "L", "d", "m", "Izz", "mx", "my", "Jzz"))
I_XUU, I_XVV, I_XRR = (IDX[k] for k in ("Xuu", "Xvv", "Xrr"))
I_YV, I_YR, I_YVV, I_YVR, I_YRR = (IDX[k] for k in ("Yv", "Yr", "Yvv", "Yvr", "Yrr"))
I_NV, I_NR, I_NRR, I_NVRR, I_NVVR = (IDX[k] for k in ("Nv", "Nr", "Nrr", "Nvrr", "Nvvr"))
I_AJ, I_ALPHA, I_XT = (IDX[k] for k in ("Aj", "alpha", "xT"))


@njit(cache=False, inline="always", error_model="numpy")  # not cached: would go stale when fastmath changes
def accel(u, v, r, delta, n, Xe, Ye, Ne, P, b):
    """Song et al. (2025) eqs. (1)-(3) solved for (du, dv, dr); ``n`` is the jet velocity v_j
    [m/s]."""
    rho = P[I_RHO, b]; L = P[I_L, b]; d = P[I_D, b]
    U = fm.sqrt(u * u + v * v)
    moving = U > 1e-6
    invU = (1.0 / U) if moving else 0.0  # the 1/U terms (N'vrr, N'vvr) vanish at rest with v, r
    av = abs(v)
    ar = abs(r)
    qF = 0.5 * rho * L * d
    qN = qF * L
    # ---- hull (eq. 2, scaling of eq. 14)
    XH = qF * (P[I_XUU, b] * u * u + P[I_XVV, b] * v * v + P[I_XRR, b] * r * r * L * L)
    YH = qF * (P[I_YV, b] * v * U + P[I_YR, b] * r * U * L + P[I_YVV, b] * v * av
               + P[I_YVR, b] * av * r * L + P[I_YRR, b] * r * ar * L * L)
    NH = qN * (P[I_NV, b] * v * U + P[I_NR, b] * r * U * L + P[I_NRR, b] * r * ar * L * L
               + (P[I_NVRR, b] * v * r * r * L * L + P[I_NVVR, b] * v * v * r * L) * invU)
    # ---- waterjet (eq. 3), nozzle angle delta_s = -delta (see the module docstring)
    sdl, cdl = fm.sincos(delta)
    jet = rho * P[I_AJ, b] * n
    alpha = P[I_ALPHA, b]
    XP = jet * (n - alpha * u) * cdl
    YP = -jet * (n - alpha * v) * sdl
    NP = YP * P[I_XT, b]
    # ---- equations of motion (eq. 1), origin at G
    m = P[I_M, b]; mx = P[I_MX, b]; my = P[I_MY, b]
    du = ((m + my) * v * r + XH + XP + Xe) / (m + mx)
    dv = (-(m + mx) * u * r + YH + YP + Ye) / (m + my)
    dr = (NH + NP + Ne) / (P[I_IZZ, b] + P[I_JZZ, b])
    return du, dv, dr


def pack(vessel: dict) -> np.ndarray:
    """Resolved vessel config -> parameter vector in ``PARAM_NAMES`` order (SI)."""
    p = vessel["particulars"]
    rho, L, m, Izz = mass_and_inertia(vessel)
    d = float(p["d"])
    if abs(float(p.get("xG", 0.0))) > 1e-12:
        raise ValueError(f"vessel '{vessel.get('name')}': the waterjet kind's origin is the centre of gravity "
                         "(Song et al. 2025 eq. 1); particulars.xG must be 0")
    h = vessel["hull"]
    wj = vessel["waterjet"]
    q_m = 0.5 * rho * L * L * d
    q_J = 0.5 * rho * L ** 4 * d
    vals = dict(
        rho=rho, L=L, d=d, m=m, Izz=Izz,
        mx=float(h["m_x"]) * q_m, my=float(h["m_y"]) * q_m, Jzz=float(h["J_z"]) * q_J,
        Xuu=h["X_uu"], Xvv=h["X_vv"], Xrr=h["X_rr"],
        Yv=h["Y_v"], Yr=h["Y_r"], Yvv=h["Y_vv"], Yvr=h["Y_vr"], Yrr=h["Y_rr"],
        Nv=h["N_v"], Nr=h["N_r"], Nrr=h["N_rr"], Nvrr=h["N_vrr"], Nvvr=h["N_vvr"],
        Aj=wj["A_j"], alpha=wj["alpha"], xT=wj["x_T"],
    )
    return np.array([float(vals[k]) for k in PARAM_NAMES])


def solve_n(params: np.ndarray, U0: float) -> float:
    """Jet velocity v_j [m/s] of a steady straight run at U0 (delta = v = r = 0).

    X_H + X_P = 0:  rho A_j v_j (v_j - alpha U0) = -0.5 rho L d X'uu U0^2, the positive root.
    """
    rho, L, d = params[I_RHO], params[I_L], params[I_D]
    Xuu, Aj, alpha = params[I_XUU], params[I_AJ], params[I_ALPHA]
    if Xuu >= 0.0 or Aj <= 0.0:
        raise ValueError(f"no straight-run jet speed: X'uu = {Xuu} must be < 0 and A_j = {Aj} > 0")
    C = -0.5 * rho * L * d * Xuu * U0 * U0 / (rho * Aj)
    return 0.5 * (alpha * U0 + math.sqrt(alpha * alpha * U0 * U0 + 4.0 * C))
