"""Regressors of any vessel kind, built from the kind's own equations of motion.

For a model whose unknown coefficients enter the forces linearly, F = F_known + sum_i theta_i phi_i(x), the
regression is  M (a_measured - a_known) = sum_i theta_i phi_i  per equation (surge X, sway Y, yaw N), with
M the mass matrix. Rather than re-deriving phi_i for every kind (and risking two versions of the physics),
they are read off the compiled ``accel`` of the kind itself:

- a_known: accelerations with every identified coefficient set to zero;
- M^-1: the response to unit external forces (the integrator's Xe, Ye, Ne inputs);
- phi_i = M (a(theta_i = 1) - a_known).

Rows are scaled by 0.5 rho L d U0^2 (X, Y) and 0.5 rho L^2 d U0^2 (N), so the coefficients stay in
the kind's own units (non-dimensional for MMG) while the numbers stay O(1). The sample structure
decides where the rows are (``study.identify.structures``): the node-wise quantities a_known and
phi_i go through its ``value`` operator, the measured velocities through its derivative ``d``.
"""
from __future__ import annotations

import numpy as np

from ..sim import Vessel, accelerations

STATE_RATES = ("u", "v", "r")


def kind_regressors(vessel: Vessel, P0: np.ndarray, idx: list, nodes: dict, raw: dict, ops, scale: np.ndarray):
    """Targets (m, 3) and regressors (m, 3, k) of one segment for the coefficients at ``idx`` of
    ``P0``.

    ``nodes``: the segment's columns where the node-wise functions are evaluated (smoothed or raw);
    ``raw``: the measured columns the derivatives are taken of; ``ops``: the structure's operators.
    """
    k = len(idx)
    B = 4 + k  # columns: 0 known part, 1-3 unit external forces, then one per coefficient
    P = np.repeat(P0[:, None], B, axis=1)
    for j, i in enumerate(idx):
        P[i, 4 + j] = 1.0
    ext = np.zeros((3, B))
    ext[0, 1] = ext[1, 2] = ext[2, 3] = 1.0
    A = accelerations(vessel, P, nodes["u"], nodes["v"], nodes["r"], nodes["delta"], nodes["n"], ext)
    a0 = A[0]
    Minv = np.stack([(A[c][0] - a0[0]) for c in (1, 2, 3)], axis=1)  # columns: response to unit X, Y, N
    M = np.linalg.inv(Minv)
    rates = ops.d(np.column_stack([raw[c] for c in STATE_RATES]), 1)
    y = (rates - ops.value(a0)) @ M.T / scale
    if not k:  # a known model: nothing to identify, the rows are the residual forces
        return y, np.zeros(y.shape + (0,))
    phi = np.stack([ops.value((A[4 + j] - a0) @ M.T / scale) for j in range(k)], axis=2)
    return y, phi
