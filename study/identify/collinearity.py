"""Multicollinearity of a regressor matrix: correlation matrix, condition numbers, variance
inflation factors.

- Correlation matrix: Pearson correlation of the regressor columns (Song et al. (2025), Fig. 6).
- ``cond_corr``: condition number of the correlation matrix, lambda_max / lambda_min (Song et al.
  (2025) eq. 28, Table 3: 50.2 sway, 7737 surge, 6352 yaw for its USV).
- ``cond_scaled``: condition number of the regressor matrix with every column scaled to unit
  Euclidean norm (Belsley, Kuh & Welsch 1980, Regression Diagnostics, ch. 3: scaling without
  centring, since the models have no intercept and a column's mean is part of what it explains).
- ``vif``: variance inflation factor of each column, the diagonal of the inverse correlation matrix,
  VIF_j = 1 / (1 - R_j^2) (Marquardt 1970); above 10 is the usual warning level.
"""
from __future__ import annotations

import numpy as np


def collinearity(Phi: np.ndarray) -> dict:
    """``{'corr', 'vif', 'cond_corr', 'cond_scaled', 'corr_max'}`` of an (n, k) regressor matrix.

    Constant columns have no correlation: their row and column of ``corr`` and their VIF are NaN,
    and they are left out of ``cond_corr``.
    """
    Phi = np.asarray(Phi, float)
    n, k = Phi.shape
    norms = np.linalg.norm(Phi, axis=0)
    ok = norms > 0
    sv = np.linalg.svd(Phi[:, ok] / norms[ok], compute_uv=False) if ok.any() and n > 0 else np.array([np.nan])
    cond_scaled = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    sd = Phi.std(axis=0)
    var = sd > 1e-14 * np.maximum(1.0, np.abs(Phi).max(axis=0))
    corr = np.full((k, k), np.nan)
    vif = np.full(k, np.nan)
    cond_corr = float("nan")
    if var.sum() >= 1 and n > 1:
        C = np.corrcoef(Phi[:, var], rowvar=False)
        C = np.atleast_2d(C)
        corr[np.ix_(var, var)] = C
        ev = np.linalg.eigvalsh(C)
        cond_corr = float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")
        try:
            vif[var] = np.diag(np.linalg.inv(C))
        except np.linalg.LinAlgError:
            vif[var] = np.inf
    off = np.abs(corr - np.diag(np.diag(corr))) if k > 1 else np.zeros((1, 1))
    corr_max = float(np.nanmax(off)) if k > 1 and np.isfinite(off).any() else float("nan")
    return {"corr": corr, "vif": vif, "cond_corr": cond_corr, "cond_scaled": cond_scaled, "corr_max": corr_max}
