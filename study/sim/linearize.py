"""Nomoto (KT) parameters of any vessel: linearisation and steady turns of the kind's own equations.

Sources:
  Nomoto, K., Taguchi, T., Honda, K., Hirano, S. (1957). On the steering qualities of ships.
  International Shipbuilding Progress 4(35), 354-370: the second-order response r/delta = K (1 + T3
  s) / ((1 + T1 s) (1 + T2 s)) of the linear sway-yaw equations, and its first-order equivalent T =
  T1 + T2 - T3. Fossen, T.I. (2011). Handbook of Marine Craft Hydrodynamics and Motion Control,
  Wiley, Sec. 7.2 (the transfer function of the linear sway-yaw model; T1 < 0 for a course-unstable
  ship). Zheng, W., Xiao, C. (2017). Ship Science and Technology 39(9), 129-132
  (``/work/shared/seeds/004_*.txt``): the nonlinear forms T r' + r + alpha r^3 = K delta (eq. 18)
  and its second order (eq. 19), and the step-wise procedure of their ref. [3] (K from small-rudder
  turns, then alpha from steady turns with K fixed), which ``nomoto_alpha`` follows with the steady
  turns of the model itself.

Everything here evaluates the kind's compiled equations (``study.sim.accelerations``); nothing is
re-derived, so any kind (mmg, abkowitz, waterjet, auv, nomoto) and any effect that changes the
vessel's parameters (shallow water) is covered. Calm water: current, wind and yaw bias are not part
of the linearisation or the turns.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from . import Vessel, accelerations

# central-difference step of the linearisation (SI: m/s, rad/s, rad), as the kinds' tests always used
_EPS = 1e-7


def _acc(vessel: Vessel, u, v, r, delta, n=None) -> np.ndarray:
    """(N, 3) accelerations (du, dv, dr) of the vessel's kind at N states, calm water."""
    u = np.atleast_1d(np.asarray(u, float))
    N = u.shape[0]
    full = lambda x: np.broadcast_to(np.asarray(x, float), (N,)).copy()  # noqa: E731
    n = vessel.n0 if n is None else n
    return accelerations(vessel, vessel.params[:, None], u, full(v), full(r), full(delta), full(n))[0]


def linear_sway_yaw(vessel: Vessel, eps: float = _EPS) -> tuple[np.ndarray, np.ndarray]:
    """The linear sway-yaw system d[v, r]/dt = A [v, r] + b delta at straight running.

    Operating point u = U0, v = r = 0, delta = 0, n = vessel.n0; A (2x2) and b (2,) by central
    differences of the kind's own compiled equations (step ``eps``). For the ``nomoto`` kind the
    first state is its auxiliary state z (see ``study.sim.nomoto``), which gives the same r/delta.
    """
    d = np.eye(3) * eps
    # one call: rows (+v, -v, +r, -r, +delta, -delta)
    pts = np.concatenate([d, -d])[[0, 3, 1, 4, 2, 5]]
    a = _acc(vessel, np.full(6, vessel.U0), pts[:, 0], pts[:, 1], pts[:, 2])[:, 1:]
    J = (a[0::2] - a[1::2]).T / (2.0 * eps)  # (2 equations, 3 variables)
    return J[:, :2].copy(), J[:, 2].copy()


def nomoto(A: np.ndarray, b: np.ndarray) -> dict:
    """Second-order Nomoto parameters of a linear sway-yaw system d[v, r]/dt = A [v, r] + b delta.

    r/delta = (n1 s + n0) / (s^2 + a1 s + a0) = K (1 + T3 s) / ((1 + T1 s)(1 + T2 s)), so K = n0 /
    a0, T3 = n1 / n0, T1 + T2 = a1 / a0, T1 T2 = 1 / a0, and the first-order equivalent T = T1 + T2
    - T3 = a1 / a0 - n1 / n0 (Nomoto 1957), real even when the poles are a complex pair.

    Returns dict(K, T1, T2, T3, T, complex_poles). T1, T2 are ordered by magnitude, |T1| >= |T2|
    (the same as T1 >= T2 for a course-stable ship; for a course-unstable one the slow, unstable
    pole gives T1 < 0 and usually K < 0 too: signs are kept, they are meaningful). Complex poles: T1
    = T2 = NaN and ``complex_poles=True``. A pole cancelled by the zero (a mode that r does not see,
    such as the constant auxiliary state of a first-order Nomoto model) is removed: T2 = T3 = 0
    then.
    """
    A = np.asarray(A, float)
    b = np.asarray(b, float)
    a1, a0 = -np.trace(A), np.linalg.det(A)  # s^2 + a1 s + a0
    n1 = b[1]
    n0 = A[1, 0] * b[0] - A[0, 0] * b[1]  # numerator of r/delta: n1 s + n0
    disc = a1 * a1 - 4.0 * a0
    if disc >= 0.0:
        sq = math.sqrt(disc)
        poles = [0.5 * (-a1 + sq), 0.5 * (-a1 - sq)]
        scale = max(abs(p) for p in poles)
        if n1 != 0.0 and scale > 0.0:
            zero = -n0 / n1
            for i, p in enumerate(poles):
                if abs(zero - p) <= 1e-9 * scale:  # pole-zero cancellation: a first-order response
                    q = poles[1 - i]
                    return dict(K=float(-n1 / q), T1=float(-1.0 / q), T2=0.0, T3=0.0, T=float(-1.0 / q),
                                complex_poles=False)
        Ts = sorted((-1.0 / p if p != 0.0 else math.inf for p in poles), key=abs, reverse=True)
        T1, T2 = Ts
        cplx = False
    else:
        T1 = T2 = math.nan
        cplx = True
    K = n0 / a0
    T3 = n1 / n0
    return dict(K=float(K), T1=float(T1), T2=float(T2), T3=float(T3), T=float(a1 / a0 - n1 / n0),
                complex_poles=cplx)


def nomoto_linear(vessel: Vessel) -> dict:
    """Linear Nomoto parameters of a vessel at straight running: dict(K, T1, T2, T3, T,
    complex_poles).

    K [1/s], T's [s]; r/delta = K (1 + T3 s) / ((1 + T1 s)(1 + T2 s)), T = T1 + T2 - T3 (see
    :func:`nomoto`). From :func:`linear_sway_yaw` (central differences of the kind's compiled
    equations at u = U0, v = r = delta = 0, n = n0). For the ``nomoto`` kind this returns its own K,
    T1, T2, T3 (to rounding).
    """
    return nomoto(*linear_sway_yaw(vessel))


# ------------------------------------------------------------------------------------------- steady turns
def _scales(vessel: Vessel):
    U, L = vessel.U0, vessel.L
    xs = np.array([U, U, U / L])  # u, v, r
    fs = np.array([U * U / L, U * U / L, U * U / (L * L)])  # du, dv, dr
    return xs, fs


def _residual_and_jacobian(vessel: Vessel, x: np.ndarray, delta: float, h: float = 1e-6):
    """Scaled (du, dv, dr) at the scaled state x and its central-difference Jacobian, in one
    call."""
    xs, fs = _scales(vessel)
    pts = np.repeat(x[None, :], 7, axis=0)
    for j in range(3):
        pts[1 + 2 * j, j] += h
        pts[2 + 2 * j, j] -= h
    X = pts * xs
    a = _acc(vessel, X[:, 0], X[:, 1], X[:, 2], delta) / fs
    J = np.stack([(a[1 + 2 * j] - a[2 + 2 * j]) / (2.0 * h) for j in range(3)], axis=1)
    return a[0], J


def steady_turn(vessel: Vessel, delta: float, start=None, tol: float = 1e-10):
    """The nonlinear steady turn du = dv = dr = 0 at rudder angle ``delta`` [rad] and n = n0.

    Solved for (u, v, r) with ``scipy.optimize.root`` (Powell's hybrid method, the Jacobian by
    central differences of the kind's compiled equations, everything scaled by U0 and L) from
    ``start`` (SI [u, v, r]; default straight running at U0). States that nothing depends on and
    equations that depend on nothing (the Nomoto kind's constant surge speed; the constant auxiliary
    state of its first order) are held at their start value. Returns (SI state (3,), converged:
    bool). Converged means max |scaled residual| <= tol and u > 0.05 U0.
    """
    from scipy.optimize import root

    xs, _ = _scales(vessel)
    x0 = np.array([1.0, 0.0, 0.0]) if start is None else np.asarray(start, float) / xs
    _, J = _residual_and_jacobian(vessel, x0, delta)
    cols = [j for j in range(3) if np.any(J[:, j] != 0.0)]
    rows = [i for i in range(3) if np.any(J[i, :] != 0.0)]
    if not cols or len(rows) != len(cols):
        return x0 * xs, False

    def fun(y):
        x = x0.copy()
        x[cols] = y
        F, Jf = _residual_and_jacobian(vessel, x, delta)
        return F[rows], Jf[np.ix_(rows, cols)]

    with np.errstate(all="ignore"):
        sol = root(fun, x0[cols], jac=True, method="hybr", options={"xtol": 1e-13})
    x = x0.copy()
    x[cols] = sol.x
    F, _ = _residual_and_jacobian(vessel, x, delta)
    ok = bool(np.all(np.isfinite(x)) and np.max(np.abs(F)) <= tol and x[0] > 0.05)
    return x * xs, ok


def _simulated_turn(vessel: Vessel, delta: float) -> np.ndarray:
    """(u, v_w, r) at the end of a 40 L/U0 run with the rudder held at ``delta`` (calm water): a
    start for :func:`steady_turn` on the branch a ship actually reaches (the stable one)."""
    from . import simulate

    calm = vessel.with_params(current_speed=0.0, wind_speed=0.0, ext_X=0.0, ext_Y=0.0, ext_N=0.0)
    turn = {"name": "steady_turn", "type": "turning", "amp_deg": abs(math.degrees(delta)),
            "first": "starboard" if delta >= 0.0 else "port", "pullout_deg": 1e9, "t_start": 0.0,
            "duration": 40.0 * vessel.L / vessel.U0}
    df = simulate(calm, turn)
    u, v, r = df[["u", "v", "r"]].to_numpy()[-1]
    if not getattr(vessel.kind, "KINEMATIC_SWAY", True):  # the output v is not the kind's v_w slot
        v = float(vessel.kind.aux_state_at_rest(vessel.params, delta))
    return np.array([u, v, r])


def _cubic_r(K: float, alpha: float, rhs: float, near: float) -> float:
    """The real root of r + alpha r^3 = rhs nearest ``near``."""
    roots = np.roots([alpha, 0.0, 1.0, -rhs]) if alpha != 0.0 else np.array([rhs])
    real = roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots.real))].real
    return float(real[np.argmin(np.abs(real - near))]) if real.size else math.nan


def nomoto_alpha(vessel: Vessel, K: float, delta_max_deg: float = 20.0, n_points: int = 8) -> dict:
    """Cubic coefficient alpha [s^2] of the nonlinear Nomoto model, from the vessel's own steady
    turns.

    A DERIVED, APPROXIMATE truth: the vessel's steady turns (du = dv = dr = 0 at fixed rudder and n
    = n0) at rudder angles delta_max_deg k / n_points, k = 1 .. n_points, on both sides, are fitted
    by least squares
    with

        K (delta + delta_0) = r + alpha r^3          (K fixed, alpha and delta_0 fitted)

    the steady state of T r' + r + alpha r^3 = K delta (Zheng & Xiao 2017, eq. 18), following the
    step-wise procedure of their ref. [3] (K first, then alpha from steady turns with K fixed).
    Everything a Nomoto model leaves out is inside this alpha: the speed loss in the turn (the
    vessel's u drops; the Nomoto model keeps U0 and a constant K), the drift angle, and any
    higher-order terms of r(delta); it depends on the fitting range. delta_0 [rad] is a rudder
    offset that absorbs a built-in asymmetry (the Mariner's propeller Y'0, N'0) so that it does not
    bias alpha; it is about 0 for a symmetric vessel. (The alternative, averaging r of the two
    sides, was not used: it needs every turn on both sides to converge.)

    The turns: on each side the largest angle is found from the end of a time simulation with the
    rudder held (the branch a ship reaches, which matters for a course-unstable vessel whose
    r(delta) is S-shaped), polished by :func:`steady_turn` (``scipy.optimize.root`` on the kind's
    compiled equations); each smaller angle continues from the previous angle's solution (inwards: a
    course-unstable vessel stays on the branch that turns with the rudder), falling back to a
    simulation if that fails. Turns that still do not converge are skipped with a warning; fewer
    than 3 converged turns raise ValueError.

    Returns dict(alpha, delta_offset [rad], rms_residual [rad/s]: RMS of K (delta + delta_0) - r -
    alpha r^3, r_rms_error [rad/s]: RMS of the fitted model's steady r minus the vessel's, deltas
    [rad], r_steady [rad/s], u_steady [m/s] of the converged turns (sorted by delta), K, n_skipped).
    """
    if not (math.isfinite(delta_max_deg) and delta_max_deg > 0.0):
        raise ValueError(f"nomoto_alpha: delta_max_deg = {delta_max_deg}; expected a positive angle in degrees")
    if int(n_points) < 2:
        raise ValueError(f"nomoto_alpha: n_points = {n_points}; expected at least 2 rudder angles per side")
    if not (math.isfinite(K) and K != 0.0):
        raise ValueError(f"nomoto_alpha: K = {K}; expected a finite, nonzero gain [1/s]")
    mags = np.radians(delta_max_deg) * np.arange(int(n_points), 0, -1) / int(n_points)  # largest first
    deltas, states, skipped = [], [], []
    for side in (1.0, -1.0):
        x = None
        for dm in mags:
            d = side * dm
            ok = False
            if x is not None:
                sol, ok = steady_turn(vessel, d, x)
            if not ok:
                sol, ok = steady_turn(vessel, d, _simulated_turn(vessel, d))
            if ok:
                deltas.append(d)
                states.append(sol)
                x = sol
            else:
                skipped.append(math.degrees(d))
    if skipped:
        warnings.warn(f"nomoto_alpha: vessel '{vessel.name}': no steady turn found at delta = "
                      f"{', '.join(f'{s:.1f}' for s in skipped)} deg (skipped)", RuntimeWarning, stacklevel=2)
    if len(deltas) < 3:
        raise ValueError(f"nomoto_alpha: vessel '{vessel.name}': only {len(deltas)} of {2 * int(n_points)} steady "
                         f"turns up to {delta_max_deg} deg converged; at least 3 are needed to fit alpha and "
                         "the rudder offset")
    order = np.argsort(deltas)
    deltas = np.array(deltas)[order]
    S = np.array(states)[order]
    r = S[:, 2]
    # K delta - r = alpha r^3 - K delta_0: linear in (alpha, delta_0)
    M = np.stack([r ** 3, -np.full_like(r, K)], axis=1)
    y = K * deltas - r
    sol, *_ = np.linalg.lstsq(M, y, rcond=None)
    alpha, d0 = float(sol[0]), float(sol[1])
    res = y - M @ sol
    r_fit = np.array([_cubic_r(K, alpha, K * (d + d0), ri) for d, ri in zip(deltas, r)])
    return dict(alpha=alpha, delta_offset=d0, rms_residual=float(np.sqrt(np.mean(res ** 2))),
                r_rms_error=float(np.sqrt(np.mean((r_fit - r) ** 2))), deltas=deltas, r_steady=r,
                u_steady=S[:, 0], K=float(K), n_skipped=len(skipped))


# ------------------------------------------------------------------------------------------------ truths
def nomoto_truth(vessel: Vessel, order: int, nonlinear: bool, delta_max_deg: float = 20.0,
                 n_points: int = 8) -> dict:
    """The parameters a Nomoto identification model's truth would be, and how they were obtained.

    order 1: K, T (T = T1 + T2 - T3); order 2: K, T1, T2, T3; plus alpha if ``nonlinear``. The
    string ``how`` says whether the values are exact (the vessel is a ``nomoto`` kind) or derived
    (any other kind: :func:`nomoto_linear` at U0 and :func:`nomoto_alpha` from steady turns,
    approximations of the vessel by a Nomoto model). A second-order truth of a vessel with complex
    poles has T1 = T2 = NaN (no real pair exists; ``how`` says so).
    """
    if order not in (1, 2):
        raise ValueError(f"nomoto_truth: order = {order!r}; expected 1 or 2")
    if vessel.kind_name == "nomoto":
        kp = vessel.kind
        p = {k: float(vessel.params[kp.IDX[k]]) for k in ("K", "T1", "T2", "T3", "alpha")}
        first_order_vessel = p["T2"] == 0.0
        out = {"K": p["K"]}
        if order == 1:
            out["T"] = p["T1"] + p["T2"] - p["T3"]
            how = ("exact: the vessel is a first-order Nomoto model" if first_order_vessel else
                   "exact K (and alpha); T = T1 + T2 - T3, the first-order equivalent of the vessel's "
                   "second-order Nomoto model (an approximation, Nomoto 1957)")
        else:
            out.update(T1=p["T1"], T2=p["T2"], T3=p["T3"])
            how = "exact: the vessel is a Nomoto model" + (" (first order: T2 = T3 = 0)" if first_order_vessel
                                                           else "")
        if nonlinear:
            out["alpha"] = p["alpha"]
        out["how"] = how
        return out
    lin = nomoto_linear(vessel)
    out = {"K": lin["K"]}
    if order == 1:
        out["T"] = lin["T"]
    else:
        out.update(T1=lin["T1"], T2=lin["T2"], T3=lin["T3"])
    how = (f"derived: linearised sway-yaw equations of the {vessel.kind_name} model at U0 = {vessel.U0:g} m/s "
           "(central differences)")
    if order == 2 and lin["complex_poles"]:
        how += "; complex poles: no real T1, T2 (NaN)"
    if nonlinear:
        fit = nomoto_alpha(vessel, lin["K"], delta_max_deg=delta_max_deg, n_points=n_points)
        out["alpha"] = fit["alpha"]
        lo = delta_max_deg / n_points
        how += (f"; alpha from steady turns {lo:g}-{delta_max_deg:g} deg both sides (K fixed, rudder offset "
                f"{math.degrees(fit['delta_offset']):.2f} deg fitted, speed loss inside the fit)")
    out["how"] = how
    return out
