"""Regressors of any vessel kind, built from the kind's own equations of motion.

For a model whose unknown coefficients enter the forces linearly, F = F_known + sum_i theta_i phi_i(x), the
regression is  M (a_measured - a_known) = sum_i theta_i phi_i  per equation (surge X, sway Y, yaw N), with
M the mass matrix. Rather than re-deriving phi_i for every kind (and risking two versions of the physics),
they are read off the compiled ``accel`` of the kind itself:

- a_known: accelerations with every identified coefficient set to zero;
- M^-1: the response to unit external forces (the integrator's Xe, Ye, Ne inputs);
- phi_i = M (a(theta_i = 1) - a_known).

Rows are scaled by 0.5 rho L d U0^2 (X, Y) and 0.5 rho L^2 d U0^2 (N), so the coefficients stay in the kind's
own units (non-dimensional for MMG) while the numbers stay O(1). Known parts (mass, added mass, propeller,
rudder) come from the vessel; which coefficients are unknown comes from the model config.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sim import Vessel, accelerations
from .structures import get_structure

EQUATIONS = ("X", "Y", "N")


@dataclass
class Regression:
    """Per equation: regressor matrix, target, parameter names, truth values."""

    Phi: dict
    y: dict
    names: dict
    truth: dict
    n_samples: int


def force_scales(vessel: Vessel) -> np.ndarray:
    p = vessel.cfg["particulars"]
    q = 0.5 * float(p["rho"]) * float(p["Lpp"]) * float(p["d"]) * vessel.U0 ** 2
    return np.array([q, q, q * float(p["Lpp"])])


def check_model(vessel: Vessel, model: dict) -> None:
    names = vessel.param_names
    for eq, coefs in model["equations"].items():
        if eq not in EQUATIONS:
            raise ValueError(f"model '{model['name']}': unknown equation '{eq}', expected one of {EQUATIONS}")
        bad = [c for c in coefs if c not in names]
        if bad:
            raise ValueError(f"model '{model['name']}': coefficients {bad} are not parameters of vessel kind "
                             f"'{vessel.kind_name}' (known: {list(vessel.kind.PARAM_NAMES)})")
    if model.get("kind") and model["kind"] != vessel.kind_name:
        raise ValueError(f"model '{model['name']}' is for vessel kind '{model['kind']}', "
                         f"but vessel '{vessel.name}' is of kind '{vessel.kind_name}'")


def build(vessel: Vessel, model: dict, records, structure: str) -> Regression:
    """Stack the regression of every record for the model's equations."""
    check_model(vessel, model)
    names = list(vessel.param_names)
    coefs = [c for eq in EQUATIONS for c in model["equations"].get(eq, [])]
    idx = [names.index(c) for c in coefs]
    P0 = vessel.params.copy()
    P0[idx] = 0.0
    # columns: 0 known part, 1-3 unit external forces, then one per coefficient
    B = 4 + len(coefs)
    P = np.repeat(P0[:, None], B, axis=1)
    for j, i in enumerate(idx):
        P[i, 4 + j] = 1.0
    ext = np.zeros((3, B))
    ext[0, 1] = ext[1, 2] = ext[2, 3] = 1.0
    scale = force_scales(vessel)
    rows_phi, rows_y = [], []
    fn = get_structure(structure)
    for rec in records:
        df = rec.data if hasattr(rec, "data") else rec
        st, rates = fn(df)
        A = accelerations(vessel, P, st["u"], st["v"], st["r"], st["delta"], st["n"], ext)
        a0 = A[0]
        Minv = np.stack([(A[k][0] - a0[0]) for k in (1, 2, 3)], axis=1)  # columns: response to unit X, Y, N
        M = np.linalg.inv(Minv)
        y = (rates - a0) @ M.T / scale  # (N, 3)
        phi = np.stack([(A[4 + j] - a0) @ M.T / scale for j in range(len(coefs))], axis=2)  # (N, 3, k)
        rows_phi.append(phi)
        rows_y.append(y)
    phi = np.concatenate(rows_phi)
    y = np.concatenate(rows_y)
    out = Regression({}, {}, {}, {}, int(y.shape[0]))
    for e, eq in enumerate(EQUATIONS):
        eq_coefs = model["equations"].get(eq, [])
        if not eq_coefs:
            continue
        cols = [coefs.index(c) for c in eq_coefs]
        out.Phi[eq] = phi[:, e, cols]
        out.y[eq] = y[:, e]
        out.names[eq] = list(eq_coefs)
        out.truth[eq] = [float(vessel.params[names.index(c)]) for c in eq_coefs]
    return out
