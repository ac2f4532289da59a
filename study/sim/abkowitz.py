"""Abkowitz-type third-order manoeuvring model, in the form of Fossen's Mariner model (MSS
``mariner.m``).

Source of the model and of its coefficients:
  Chislett, M.S., Stroem-Tejsen, J. (1965). Planar Motion Mechanism Tests and Full-Scale Steering
  and Manoeuvring Predictions for a Mariner Class Vessel. Technical Report Hy-5 (as cited by
  mariner.m), Hydro- and Aerodynamics Laboratory, Lyngby, Denmark; journal version in International
  Shipbuilding Progress 12(129), 1965 (not checked here). As implemented by T. Lauvdal and T.I.
  Fossen in the Marine Systems Simulator: ``mariner.m`` (MSS, github.com/cybergalactic/MSS, file
  CRAFT/SHIP/models/mariner.m, revision 2024-04-19; also VESSELS/mariner.m); Fossen, T.I. (2011).
  Handbook of Marine Craft Hydrodynamics and Motion Control, Wiley (Mariner class vessel).

Non-dimensionalisation (SNAME prime system with L and the instantaneous speed U = sqrt(u^2 + v^2)):
  u' = (u - U0) / U  (the surge *perturbation* about the nominal speed U0, as in mariner.m),
  v' = v / U,  r' = r L / U,
  X' = X / (0.5 rho L^2 U^2), Y' likewise, N' = N / (0.5 rho L^3 U^2),
  m' = m / (0.5 rho L^3), I'z = I_z / (0.5 rho L^5), x'G = x_G / L; added masses likewise.

Equations (mariner.m):
  (m' - X'udot) du'/dt'  = X'
  [m' - Y'vdot,        m' x'G - Y'rdot] [dv'/dt']   [Y']
  [m' x'G - N'vdot,    I'z - N'rdot   ] [dr'/dt'] = [N']
with the force polynomials (delta_a = rudder angle in the model's own sign)
  X' = Xu u + Xuu u^2 + Xuuu u^3 + Xvv v^2 + Xrr r^2 + Xrv r v + Xdd d^2 + Xudd u d^2 + Xvd v d +
  Xuvd u v d Y' = Yv v + Yr r + Yvvv v^3 + Yvvr v^2 r + Yvu v u + Yru r u + Yd d + Yddd d^3 + Yud u
  d + Yuud u^2 d
       + Yvdd v d^2 + Yvvd v^2 d + (Y0 + Y0u u + Y0uu u^2)
  N' = the same terms with N.
The rigid-body centripetal terms are contained in the coefficients (Xrv = m'; Yr, Nr include -m',
-m' x'G), so there are no separate Coriolis terms. Y0, N0 (and their u-terms) are the constant side
force and yaw moment of the propeller (an asymmetry: with delta = 0 the ship turns slowly).

SIGN CONVERSION: in the model's own sign a positive rudder angle gives a negative yaw moment (N'd <
0), a turn to port; mariner.m therefore takes delta_c = -ui. This package's delta > 0 turns to
starboard, so the model's rudder angle is delta_a = -delta (the same as mariner.m's ``delta_c =
-ui``).

The external forces Xe, Ye [N], Ne [N m] of the integrator are added dimensionally (masses from the
primes with the config's rho). No propeller input: ``n`` is unused (the surge equation is the
Abkowitz polynomial in the speed perturbation, with zero net force at u = U0 by construction).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from . import fastmath as fm

KIND = "abkowitz"
COEFF_SECTION = "hull"
ADDED_MASS_KEYS = ("Y_vdot", "N_rdot")

_X_TERMS = ("Xu", "Xuu", "Xuuu", "Xvv", "Xrr", "Xrv", "Xdd", "Xudd", "Xvd", "Xuvd")
_Y_TERMS = ("Yv", "Yr", "Yvvv", "Yvvr", "Yvu", "Yru", "Yd", "Yddd", "Yud", "Yuud", "Yvdd", "Yvvd",
            "Y0", "Y0u", "Y0uu")
_N_TERMS = tuple("N" + t[1:] for t in _Y_TERMS)

PARAM_NAMES = (
    # SI: density, length, nominal speed of the expansion
    "rho", "L", "U0",
    # non-dimensional mass, inertia, centre of gravity, added masses
    "m", "Iz", "xG", "Xudot", "Yvdot", "Yrdot", "Nvdot", "Nrdot",
) + _X_TERMS + _Y_TERMS + _N_TERMS
IDX = {name: i for i, name in enumerate(PARAM_NAMES)}

# generic linear derivative -> key in the config's COEFF_SECTION (for the shallow-water effect)
LINEAR_DERIVATIVES = {"Yv": "Y_v", "Yr": "Y_r", "Nv": "N_v", "Nr": "N_r"}

# config key in ``hull`` for each non-dimensional parameter (Xudot -> X_udot, Yvvr -> Y_vvr, Y0u -> Y_0u, ...)
CONFIG_KEYS = {name: name[0] + "_" + name[1:] for name in PARAM_NAMES[6:] + ("m", "Iz", "xG")}
CONFIG_KEYS.update(m="m", Iz="I_z", xG="x_G")

(I_RHO, I_L, I_U0, I_M, I_IZ, I_XG, I_XUDOT, I_YVDOT, I_YRDOT, I_NVDOT, I_NRDOT) = range(11)
(I_XU, I_XUU, I_XUUU, I_XVV, I_XRR, I_XRV, I_XDD, I_XUDD, I_XVD, I_XUVD) = (IDX[k] for k in _X_TERMS)
(I_YV, I_YR, I_YVVV, I_YVVR, I_YVU, I_YRU, I_YD, I_YDDD, I_YUD, I_YUUD, I_YVDD, I_YVVD,
 I_Y0, I_Y0U, I_Y0UU) = (IDX[k] for k in _Y_TERMS)
(I_NV, I_NR, I_NVVV, I_NVVR, I_NVU, I_NRU, I_ND, I_NDDD, I_NUD, I_NUUD, I_NVDD, I_NVVD,
 I_N0, I_N0U, I_N0UU) = (IDX[k] for k in _N_TERMS)


@njit(cache=False, inline="always", error_model="numpy")  # not cached: would go stale when fastmath changes
def accel(u, v, r, delta, n, Xe, Ye, Ne, P, b):
    """Mariner-type Abkowitz model solved for (du, dv, dr) [SI]; ``n`` is unused."""
    rho = P[I_RHO, b]; L = P[I_L, b]; U0 = P[I_U0, b]
    U2 = u * u + v * v
    U = fm.sqrt(U2)
    moving = U > 1e-6
    invU = (1.0 / U) if moving else 0.0
    up = (u - U0) * invU
    vp = v * invU
    rp = r * L * invU
    dl = -delta  # the model's own rudder sign (mariner.m: delta_c = -ui)
    up2 = up * up
    vp2 = vp * vp
    dl2 = dl * dl
    X = (P[I_XU, b] * up + P[I_XUU, b] * up2 + P[I_XUUU, b] * up2 * up + P[I_XVV, b] * vp2
         + P[I_XRR, b] * rp * rp + P[I_XRV, b] * rp * vp + P[I_XDD, b] * dl2 + P[I_XUDD, b] * up * dl2
         + P[I_XVD, b] * vp * dl + P[I_XUVD, b] * up * vp * dl)
    Y = (P[I_YV, b] * vp + P[I_YR, b] * rp + P[I_YVVV, b] * vp2 * vp + P[I_YVVR, b] * vp2 * rp
         + P[I_YVU, b] * vp * up + P[I_YRU, b] * rp * up + P[I_YD, b] * dl + P[I_YDDD, b] * dl2 * dl
         + P[I_YUD, b] * up * dl + P[I_YUUD, b] * up2 * dl + P[I_YVDD, b] * vp * dl2
         + P[I_YVVD, b] * vp2 * dl + (P[I_Y0, b] + P[I_Y0U, b] * up + P[I_Y0UU, b] * up2))
    N = (P[I_NV, b] * vp + P[I_NR, b] * rp + P[I_NVVV, b] * vp2 * vp + P[I_NVVR, b] * vp2 * rp
         + P[I_NVU, b] * vp * up + P[I_NRU, b] * rp * up + P[I_ND, b] * dl + P[I_NDDD, b] * dl2 * dl
         + P[I_NUD, b] * up * dl + P[I_NUUD, b] * up2 * dl + P[I_NVDD, b] * vp * dl2
         + P[I_NVVD, b] * vp2 * dl + (P[I_N0, b] + P[I_N0U, b] * up + P[I_N0UU, b] * up2))
    # dimensional forces [N, N m] and masses [kg, kg m, kg m^2]
    q = 0.5 * rho * L * L
    qU = q * U2
    FX = qU * X + Xe
    FY = qU * Y + Ye
    FN = qU * L * N + Ne
    qm = q * L
    m = P[I_M, b]; xG = P[I_XG, b]
    m11 = (m - P[I_XUDOT, b]) * qm
    m22 = (m - P[I_YVDOT, b]) * qm
    m23 = (m * xG - P[I_YRDOT, b]) * qm * L
    m32 = (m * xG - P[I_NVDOT, b]) * qm * L
    m33 = (P[I_IZ, b] - P[I_NRDOT, b]) * qm * L * L
    det = m22 * m33 - m23 * m32
    du = FX / m11
    dv = (m33 * FY - m23 * FN) / det
    dr = (m22 * FN - m32 * FY) / det
    return du, dv, dr


def pack(vessel: dict) -> np.ndarray:
    """Resolved vessel config -> parameter vector in ``PARAM_NAMES`` order (rho, L, U0 in SI; the
    rest prime).

    The model's own m', x'G (``hull``) drive the dynamics; ``particulars`` (mass or volume, xG) must
    agree with them (checked to 1 %), so that an edit of one is not silently ignored.
    """
    p = vessel["particulars"]
    rho = float(p["rho"])
    L = float(p["Lpp"])
    U0 = float(vessel["operation"]["U0"])
    h = vessel["hull"]
    vals = {"rho": rho, "L": L, "U0": U0}
    for name in PARAM_NAMES[3:]:
        vals[name] = float(h[CONFIG_KEYS[name]])
    # consistency of the particulars with the primes
    ms = vessel.get("mass", {}) or {}
    m_si = float(ms["m"]) if ms.get("m") is not None else rho * float(p["volume"])
    m_model = vals["m"] * 0.5 * rho * L ** 3
    if abs(m_si / m_model - 1.0) > 0.01:
        raise ValueError(f"vessel '{vessel.get('name')}': mass {m_si:.6g} kg from the particulars differs from "
                         f"m' 0.5 rho L^3 = {m_model:.6g} kg by more than 1 %")
    if abs(float(p["xG"]) - vals["xG"] * L) > 0.01 * L:
        raise ValueError(f"vessel '{vessel.get('name')}': particulars.xG = {p['xG']} m differs from "
                         f"x'G L = {vals['xG'] * L:.4g} m")
    return np.array([float(vals[k]) for k in PARAM_NAMES])
