"""A replay's initial state for a record whose u, v, r were estimated from positions and heading.

A replay starts from the record's first state. With measured u, v, r that is a quadratic through the
first samples (``study.identify.output_error.initial_value``). With estimated ones it is not good
enough: a Kalman smoother's estimate is least accurate at a record's ends, where only one side of the
data informs it (measured on the 7 m KVLCC2 model with 1 % noise on the positions: the first v off by
0.04 m/s and r by 0.003 rad/s; a replay of the true model from there has its heading off by 0.7 of
the heading's spread, an error no effect removes, so it dilutes every effect's share of the error).

Here the initial state is estimated as output-error identification treats unknown initial conditions
(Ljung 1999, System Identification, 2nd ed.): the six states (u, v through the water, r, x0, y0,
psi) minimise the misfit of the replay to the MEASURED channels (x0, y0, psi, each over its noise
standard deviation from the state estimator) over the record's first ``WINDOW_L_U`` ship lengths of
travel -- short enough that the model's own error, which is what the replay is to show, has little
time to build up -- or longer when the position noise needs it: a speed fitted to positions of noise
sd sigma sampled every h over a window T is uncertain by sigma sqrt(12 h / T^3) (a straight line's
slope), kept below ``SPEED_PRECISION`` of the approach speed. A weak prior holds each state near the
record's own first estimate (``PRIOR_WIDTH``), so that a state the window does not determine stays
there rather than wander. The model replayed is the fitted one, so the start is consistent with it.
Not handled: a model that is directionally unstable open loop (the AUV) turns away from the record on
the rudder's measurement noise alone, whatever its start.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ...sim import replay

#: The fitting window, in ship lengths travelled at the approach speed (L/U0 each: 6.7 s for the 7 m
#: KVLCC2 model, 40 s for the ship), longer when the position noise asks for it (``SPEED_PRECISION``); at
#: least ``MIN_SAMPLES`` samples and at most a third of the record.
WINDOW_L_U = 3.0
SPEED_PRECISION = 0.01
MIN_SAMPLES = 20
#: The prior's standard deviation about the record's first estimate, in units of 2 % of the speed (u, v), 2 % of
#: U0/L (r) and the noise sd (x0, y0, psi): 5 % of the speed, wider than the smoother's first error on the
#: tests' noisiest records (3.4 %), so that the positions decide wherever they can.
PRIOR_WIDTH = 2.5
MEASURED = ("x0", "y0", "psi")


def noise_sd(meta: dict, L: float) -> np.ndarray:
    """The measured channels' noise standard deviations: the state estimator's (recorded in the
    record's metadata); where it gives none, 1e-3 L and 0.1 deg (assumed: a differential GNSS or a
    tank's tracking, and a gyro)."""
    sd = ((meta or {}).get("state_estimation") or {}).get("noise_std") or {}
    default = {"x0": 1e-3 * L, "y0": 1e-3 * L, "psi": np.radians(0.1)}
    given = {c: float(sd.get(c) or 0.0) for c in MEASURED}
    return np.array([given[c] if given[c] > 0.0 else default[c] for c in MEASURED])


def fitted_initial_state(vessel, tu: np.ndarray, data: dict, state0: list, meta: dict, L: float,
                         U0: float) -> list:
    """``state0`` refined by output error on the measured x0, y0, psi of the record's first window
    (``data``: the record's channels on the uniform time base ``tu``); ``state0`` unchanged when
    the record is too short or the fit does not lower the misfit."""
    h = float(tu[1] - tu[0])
    sd = noise_sd(meta, L)
    # sigma sqrt(12 h / T^3) <= SPEED_PRECISION U0, solved for T
    t_noise = (max(sd[0], sd[1]) * np.sqrt(12.0 * h) / (SPEED_PRECISION * U0)) ** (2.0 / 3.0)
    w = int(round(max(WINDOW_L_U * L / U0, t_noise) / h)) + 1
    w = min(max(w, MIN_SAMPLES), len(tu) // 3)
    if w < MIN_SAMPLES:
        return list(state0)
    t, delta, n = tu[:w], data["delta"][:w], data["n"][:w]
    meas = np.stack([data[c][:w] for c in MEASURED])  # (3, w)
    scale = np.array([0.02 * U0, 0.02 * U0, 0.02 * U0 / L, sd[0], sd[1], sd[2]])
    x_ref = np.asarray(state0, float)
    P = np.asarray(vessel.params, float)

    def simulate(states: np.ndarray) -> np.ndarray:  # (6, B) -> residuals (3 w, B)
        B = states.shape[1]
        with np.errstate(all="ignore"):
            out = replay(vessel, t, delta, n, states, P=np.repeat(P[:, None], B, axis=1))
        pred = out[:, [3, 4, 5], :]  # x0, y0, psi: (w, 3, B)
        res = (pred - meas.T[:, :, None]) / sd[None, :, None]
        return res.reshape(-1, B)

    def fun(z):
        r = simulate((x_ref + z * scale)[:, None])[:, 0]
        return np.concatenate([np.where(np.isfinite(r), r, 1e6), z / PRIOR_WIDTH])

    def jac(z):  # one batched replay: the base and the six perturbed starts (forward differences)
        eps = 1e-2
        states = (x_ref + z * scale)[:, None] + np.hstack([np.zeros((6, 1)), eps * np.diag(scale)])
        r = simulate(states)
        return np.vstack([(r[:, 1:] - r[:, :1]) / eps, np.eye(6) / PRIOR_WIDTH])

    r0 = fun(np.zeros(6))
    if not np.all(np.isfinite(r0)) or np.max(np.abs(r0)) >= 1e6:
        return list(state0)
    sol = least_squares(fun, np.zeros(6), jac=jac, method="lm", max_nfev=50)
    if sol.cost >= 0.5 * float(r0 @ r0):
        return list(state0)
    return list(x_ref + sol.x * scale)
