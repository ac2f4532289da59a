"""The structure's truncation bias of a regression's coefficients, estimated from the run's own
records (never from the truth): one of the checks of whether a regression posterior's intervals can
be trusted (``study.identify.trust`` holds the verdict and its limits, quoted below).

Why: emcee's regression likelihood (``study.identify.row_noise``) models the sampling noise of the
rows; a structure's truncation error is no sampling noise (a noise-free record has it too), so the
posterior covers the structure's noise-free limit, not the truth. Measured on the KT Mariner
(``study.run.calibration``): euler at 0.1 s is biased by 1.55 posterior sd and its 90 % intervals
cover the truth 56 % of the time; at 0.02 s 0.8 sd and 89 %. The same row errors are what emcee's
default likelihood subtracts (``study.identify.row_errors``); then the bias estimated here is what
was removed, and the verdict asks whether the removal can be trusted.

**The row error of truncation, from the structure's own stencil** (Taylor expansion about the row's
time ``t_r``, ``Ops.times``): a derivative operator ``D_p`` (``Structure.noise_operators``, the
exact stencil of the rows) applied to a smooth signal gives

    (D_p x)_r = sum_s x^(s)(t_r) m_s(r) / s!,   m_s(r) = sum_j D_p[r, j] (t_j - t_r)^s,

with ``m_p = p!`` and the lower moments 0 for a consistent stencil, so its truncation is ``sum_(s >
p) x^(s)(t_r) m_s / s!``. Kept: the two leading terms, s = p + 1, p + 2 (``TAYLOR_TERMS``). Forward
differences (euler, rows at t_k): ``m_2 = h``, the classic ``(h/2) x''``; central differences: ``m_3
= h^2``, ``(h^2/6) x'''``; the value operator the same way (euler, central: a node, no truncation;
the integral rows' trapezoid about the interval's midpoint: ``(h^2/8) f''``). Savitzky-Golay
stencils of polyorder 3 have no moment up to 4: their truncation is not seen at this order
(labelled). The derivatives ``x^(s)`` of the measured signals are Savitzky-Golay derivatives
(``scipy.signal.savgol_filter``) over ``SMOOTH_WINDOW_S`` seconds, polyorder ``s + 2`` (at least 3),
interpolated to ``t_r``. A row's truncation error is then that of its target minus the coefficients
(the posterior median) times that of its regressors, carried through the structure's post-processing
(differencing, cleaning, split: the row map).

**Its bias of the coefficients**: through the same generalised-least-squares map the posterior uses,
with the whitening already fitted (``RowNoise``): ``bias = (X_w' X_w)^-1 X_w' e_w``, ``X_w = C^-1
X``, ``e_w = C^-1 e`` (the weak default prior left out: it moves the posterior by far less than its
sd). Expressed in posterior sd per reported parameter (Nomoto: K, T, alpha through the model's own
map from the regression coefficients).

**Where the likelihood removes the truncation and the regressors' noise**
(``study.identify.row_errors``, emcee's default ``correct_rows``), the bias estimated here is what
was removed: the run is trusted unless it exceeds ``CORRECTED_LIMIT_SD`` (the estimate's own error,
assumed at most 2.5 % of it, would then pass half a posterior sd) or the likelihood had to leave the
regressors' noise in (their whitened reliability below ``row_errors.RELIABILITY_MIN``: their noise
is then no small perturbation and a first-order correction does not hold: "cannot tell"). Otherwise
(``correct_rows: false``):

**The verdict**: not trusted when any reported parameter's estimated bias exceeds ``BIAS_LIMIT_SD``
= 1 posterior sd. A bias of b sd leaves a 90 % normal interval covering Phi(1.645 - b) - Phi(-1.645
- b): 74 % at b = 1, 54 % at 1.55 (euler on the KT at 0.1 s, measured 56 %), 80 % at 0.8 (euler at
0.02 s, measured 89 % with intervals 1.07 times the spread); the calibrated structures (central,
integral, smoothed) sit at 84-97 %. 1 sd is the line between the cases measured calibrated and not.
Also not trusted, whatever the bias: rows differenced by the structure with some differenced rows
then dropped (diff_center's random split, z-score cleaning): the gaps keep the whitening from
undoing the differencing, and the errors in its regressors bias it beyond any interval (measured
coverage 11-44 %).

Assumptions (labelled): the signals are smooth on the scale of the window (a rudder's rate corners
are not: there the estimate is rough); two Taylor terms; the regressors' truncation through a
node-wise function taken as the stencil's truncation of the function's values (exact for euler and
central, whose value operator is a node).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.signal import savgol_filter

#: Taylor terms of the truncation kept beyond the derivative's order (the leading two)
TAYLOR_TERMS = 2
#: the time window [s] of the Savitzky-Golay derivatives of the measured signals (see the module docstring)
SMOOTH_WINDOW_S = 3.0




def _moments(L: sp.spmatrix, t: np.ndarray, t_r: np.ndarray, s: int) -> np.ndarray:
    """``m_s(r) = sum_j L[r, j] (t_j - t_r)^s`` of a (rows x nodes) stencil."""
    c = L.tocoo()
    return np.bincount(c.row, weights=c.data * (t[c.col] - t_r[c.row]) ** s, minlength=L.shape[0])


def _derivative_at(X: np.ndarray, t: np.ndarray, t_r: np.ndarray, s: int) -> np.ndarray:
    """The s-th derivative of node-wise ``X`` (axis 0) at the times ``t_r``: Savitzky-Golay over
    ``SMOOTH_WINDOW_S`` (uniform steps assumed within the segment: its median), linearly
    interpolated."""
    X = np.asarray(X, float)
    n = len(t)
    h = float(np.median(np.diff(t)))
    poly = max(3, s + 2)
    w = int(round(SMOOTH_WINDOW_S / h)) | 1
    w = min(max(w, poly + 2 + (poly % 2 == 0)), n - (1 - n % 2))
    if w <= poly:
        return np.zeros((len(t_r),) + X.shape[1:])
    D = savgol_filter(X, w, poly, deriv=s, delta=h, axis=0, mode="interp")
    flat = D.reshape(n, -1)
    out = np.column_stack([np.interp(t_r, t, flat[:, j]) for j in range(flat.shape[1])])
    return out.reshape((len(t_r),) + X.shape[1:])


class TruncationOps:
    """A structure's operators with the rows' values replaced by their truncation errors (module
    docstring): ``d(X, p)`` the truncation of the structure's p-th derivative of ``X``,
    ``value(F)`` that of its value of ``F``. Models build their rows linearly in both
    (``model.rows``), so the same rows come out as the row errors of truncation."""

    def __init__(self, base, operators: list, t: np.ndarray, order: int):
        self.base, self.t, self.order = base, np.asarray(t, float), order
        self.t_r = np.asarray(base.times, float)
        self.rows = base.rows
        self._ops = {p: operators[order - p] for p in range(order, 0, -1)}
        self._ops[0] = operators[-1]

    def __len__(self) -> int:
        return len(self.base)

    @property
    def times(self):
        return self.t_r

    def _trunc(self, X, p: int):
        X = np.asarray(X, float)
        out = np.zeros((len(self.t_r),) + X.shape[1:])
        for s in range(p + 1, p + 1 + TAYLOR_TERMS):
            m = _moments(self._ops[p], self.t, self.t_r, s) / math.factorial(s)
            if np.max(np.abs(m)) == 0.0:
                continue
            out += m.reshape((-1,) + (1,) * (X.ndim - 1)) * _derivative_at(X, self.t, self.t_r, s)
        return out

    def d(self, X, p):
        return self._trunc(X, p)

    def value(self, F):
        return self._trunc(F, 0)


class TruncationStructure:
    """A structure whose operators give the truncation errors of its rows
    (:class:`TruncationOps`); everything else (segments, nodes, measured signals) is the
    structure's own."""

    def __init__(self, structure):
        self._s = structure

    def __getattr__(self, name):
        return getattr(self._s, name)

    def ops(self, seg, order: int):
        operators = self._s.noise_operators(seg, order)
        if operators is None:
            raise ValueError(f"structure '{self._s.name}': no stencil to read its truncation from")
        return TruncationOps(self._s.ops(seg, order), operators, seg.t, order)


def coefficient_bias(noise, X: np.ndarray, e: np.ndarray, centred: bool = False) -> np.ndarray:
    """The coefficients' bias from row errors ``e`` through the posterior's GLS map with the
    fitted whitening ``noise`` (a ``RowNoise``; None: the rows as they are, least squares):
    ``(X_w' X_w)^-1 X_w' e_w``. ``centred``: the rows' free intercept (diff_center) is part of
    the map, as in the posterior."""
    X = np.asarray(X, float)
    k = X.shape[1]
    if centred:
        X = np.column_stack([X, np.ones(len(X))])
    e = np.asarray(e, float)
    Xw, ew = (X, e) if noise is None else (noise.whiten(X), noise.whiten(e))  # None: rows not whitened (LS)
    b, *_ = np.linalg.lstsq(Xw, ew, rcond=None)
    return b[:k]
