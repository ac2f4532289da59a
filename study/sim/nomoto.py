"""Nonlinear Nomoto (KT) yaw-response models of the first and second order.

Sources:
  Nomoto, K., Taguchi, T., Honda, K., Hirano, S. (1957). On the steering qualities of ships.
  International Shipbuilding Progress 4(35), 354-370 (the linear first- and second-order response
  models). Zheng, W., Xiao, C. (2017). The parameter identification of KT equations on ship
  maneuverability. Ship Science and Technology 39(9), 129-132 (``/work/shared/seeds/004_*.txt``):
  the nonlinear forms, their eqs. 12, 13, 18 and 19, with T = T1 + T2 - T3 (below eq. 13). Fossen,
  T.I. (2011). Handbook of Marine Craft Hydrodynamics and Motion Control, Wiley, Sec. 7.2 (Nomoto
  models, T1 < 0 for a course-unstable ship).

Equations (r yaw rate [rad/s], delta rudder angle [rad], delta > 0 turns to starboard)::

    first order  (eq. 18):  T r' + r + alpha r^3 = K delta
    second order (eq. 19):  T1 T2 r'' + (T1 + T2) r' + r + alpha r^3 = K delta + K T3 delta'

Parameters are dimensional: K [1/s], T1, T2, T3 [s], alpha [s^2]. The first order is T2 = T3 = 0 (T1
= T).

State realisation. The second order needs a second state and, as printed, the rudder rate delta'. It
is realised without delta' (the integrator's rudder is only piecewise linear) by

    z = T1 T2 r' - K T3 delta:   z' = K delta - r - alpha r^3 - (T1 + T2) r',   r' = (z + K T3 delta) / (T1 T2)

(substitute: T1 T2 r'' = z' + K T3 delta', which is eq. 19). z [rad] is carried in the integrator's
``v_w`` slot: this kind declares ``KINEMATIC_SWAY = False``, so the kinematics use no sway velocity
(the track follows the heading: a ship without drift) and the output ``v`` is the current's
contribution only. z at rest (r' = 0) is -K T3 delta (``aux_state_at_rest``); z = 0 for the first
order (and is then constant).

What the model leaves out (by construction, not approximations of this module):
  - the surge speed is constant (du = 0): the ship keeps the speed it starts with
    (``operation.U0``); no speed loss in turns. The speed enters only the track (x0, y0);
  - the external forces of the integrator (Xe, Ye, Ne: yaw bias, wind) are ignored; a current drifts
    the track (kinematics) but does not act on the yaw response;
  - ``n`` (propeller speed) is unused; ``operation.n`` may be 0;
  - the shallow-water effect cannot act on it (``LINEAR_DERIVATIVES`` is empty: there are no hull
    derivatives; ``ShallowWater`` raises a ValueError for this kind, deep water is a no-op).
The rudder actuator (rate limit, lag, dead time, delta_max) comes from the config's ``actuator``
block as for every kind (``study.sim.effects.default_env``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import fastmath as fm

KIND = "nomoto"
COEFF_SECTION = "nomoto"  # the config block with K, T1, T2, T3, alpha
ADDED_MASS_KEYS = ()
# no hull derivatives: the shallow-water effect has nothing to act on (it raises for this kind)
LINEAR_DERIVATIVES: dict = {}
# the integrator's v_w slot carries z (see the module docstring), not a sway velocity
KINEMATIC_SWAY = False

PARAM_NAMES = (
    "L",  # m, length (kinematics and non-dimensional K' = K L / U0, T' = T U0 / L only)
    "U0",  # m/s, nominal speed at which K, T hold
    "K",  # 1/s
    "T1",  # s
    "T2",  # s (0: first order)
    "T3",  # s (0 for the first order)
    "alpha",  # s^2, cubic yaw-rate term
)
IDX = {name: i for i, name in enumerate(PARAM_NAMES)}
I_L, I_U0, I_K, I_T1, I_T2, I_T3, I_ALPHA = range(len(PARAM_NAMES))


@njit(cache=False, inline="always", error_model="numpy")  # not cached: would go stale when fastmath changes
def accel(u, v, r, delta, n, Xe, Ye, Ne, P, b):
    """(du, dz, dr) of the nonlinear Nomoto model; ``v`` is the auxiliary state z; u, n, Xe, Ye, Ne
    unused.

    Branch-free: the first order (T2 == 0, per member) and the second order are both computed and
    one is selected, so a batch may mix them and the member loop still vectorises. The unused side
    may be inf/nan (1 / (T1 T2) at T2 = 0) and is discarded by the select.
    """
    K = P[I_K, b]
    T1 = P[I_T1, b]
    T2 = P[I_T2, b]
    T3 = P[I_T3, b]
    alpha = P[I_ALPHA, b]
    f = K * delta - r - alpha * (r * r * r)  # K delta - r - alpha r^3
    first = T2 == 0.0
    dr2 = (v + K * T3 * delta) / (T1 * T2)
    dr = fm.select(first, f / T1, dr2)
    dz = fm.select(first, 0.0, f - (T1 + T2) * dr2)
    return 0.0, dz, dr


def aux_state_at_rest(P: np.ndarray, delta) -> np.ndarray:
    """The ``v_w`` slot (z) at r' = 0 with the rudder at ``delta``: z = -K T3 delta.

    P : kind parameters, shape (n_kind_params,) or (n_kind_params, B) (a full packed vector also works: the
    kind's parameters come first). Used by ``study.sim.replay`` and ``simulate`` for the initial
    state.
    """
    P = np.asarray(P, float)
    return -P[I_K] * P[I_T3] * np.asarray(delta, float)


def _get(sec: dict, key: str, name: str, default=None) -> float:
    val = sec.get(key, default)
    if val is None:
        raise ValueError(f"vessel '{name}': nomoto.{key} is missing (expected a number)")
    try:
        val = float(val)
    except (TypeError, ValueError):
        raise ValueError(f"vessel '{name}': nomoto.{key} = {sec.get(key)!r} is not a number") from None
    if not math.isfinite(val):
        raise ValueError(f"vessel '{name}': nomoto.{key} = {val} is not finite")
    return val


def pack(vessel: dict) -> np.ndarray:
    """Resolved vessel config -> parameter vector in ``PARAM_NAMES`` order (SI).

    Reads ``nomoto: {K, T1, T2, T3, alpha}`` (T2, T3, alpha default to 0: first order, linear),
    ``particulars.Lpp`` and ``operation.U0``. Checks: T1 != 0; T1 T2 != 0 unless T2 == 0, and then
    T3 == 0 (a first-order model with T3 would need the rudder rate, which the integrator does not
    carry).
    """
    name = vessel.get("name", "?")
    sec = vessel.get(COEFF_SECTION)
    if not isinstance(sec, dict):
        raise ValueError(f"vessel '{name}' of kind 'nomoto' needs a 'nomoto' block with K, T1 (and T2, T3, "
                         "alpha for the second order / nonlinear model)")
    K = _get(sec, "K", name)
    T1 = _get(sec, "T1", name)
    T2 = _get(sec, "T2", name, 0.0)
    T3 = _get(sec, "T3", name, 0.0)
    alpha = _get(sec, "alpha", name, 0.0)
    if T1 == 0.0:
        raise ValueError(f"vessel '{name}': nomoto.T1 = 0; expected a nonzero time constant [s] "
                         "(negative for a course-unstable ship)")
    if T2 == 0.0 and T3 != 0.0:
        raise ValueError(f"vessel '{name}': nomoto.T3 = {T3} with T2 = 0; a first-order model (T2 = 0) needs "
                         "T3 = 0 (fold T3 into T = T1 + T2 - T3 instead)")
    L = float(vessel["particulars"]["Lpp"])
    U0 = float(vessel["operation"]["U0"])
    if not (L > 0.0 and U0 > 0.0):
        raise ValueError(f"vessel '{name}': Lpp = {L} m and operation.U0 = {U0} m/s must both be > 0")
    vals = dict(L=L, U0=U0, K=K, T1=T1, T2=T2, T3=T3, alpha=alpha)
    return np.array([float(vals[k]) for k in PARAM_NAMES])
