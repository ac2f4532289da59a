"""Sample structures: how measured records become the rows of a regression (or, for
``output_error``, how a model is compared with the records by simulating it).

A record is first cut into *segments* at its gaps (a time step above 1.5 times the median:
dropouts), so records with missing samples stay usable. On one segment a structure gives the
*operators* a model builds its rows from (``Ops``): ``value(F)`` (a node-wise quantity at the rows:
the regressors) and ``d(X, p)`` (the p-th time derivative of a measured signal at the rows: the
targets). A model equation ``D^p x = sum_i theta_i f_i`` becomes the rows ``d(x, p) = sum_i theta_i
value(f_i(nodes))``:

- ``euler``: forward differences, state at k (Song et al. 2025, eq. 14); O(h) truncation error.
- ``central``: central differences, state at k (Zheng & Xiao 2017, eqs. 14-17); O(h^2). Written for
  a non-uniform grid (the three-point formulas), so jittered time stamps stay exact to O(h^2).
- ``integral``: the equation integrated over each sample interval by the trapezoidal rule: value =
  (f_k + f_k+1)/2, d(x, 1) = (x_k+1 - x_k)/h (Du et al. 2016, Sec. 3.2: inputs x_k + x_k+1, output
  x_k+1 - x_k; the same rows divided by h so the coefficients keep their units). This is also the
  weak form of SINDy with box test functions (Messenger & Bortz 2021). A second-order equation
  (Nomoto 2) is integrated against a hat function over two intervals instead, so that again no
  derivative of the data is taken.
- ``smoothed``: Savitzky-Golay (Savitzky & Golay 1964; ``scipy.signal.savgol_filter``): the
  regressors are evaluated on the smoothed states, the derivatives are the filter's derivatives of
  the raw signals; the half window at each end is dropped (the end fits are one-sided). With
  ``smoothing.method: rts`` the states ``u, v, r`` and their derivatives come instead from an
  extended Kalman filter with a Rauch-Tung-Striebel smoother over the segment's positions, heading
  and measured ``u, v, r`` (``study.records.state_estimation``; options under ``smoothing.rts``);
  every other signal (rudder, propeller, wind...) is smoothed and differentiated by Savitzky-Golay
  as before, and the same rows are kept (the half window at each end dropped), so the two methods
  differ only in the states.
- ``diff_center``: a base structure (``euler`` as in Song et al. (2025)), then its rows differenced,
  y_k - rho y_k-1 = (phi_k - rho phi_k-1) theta (Song et al. (2025) eqs. 15-17, rho = 1), then
  centred (eq. 18: every column minus its mean over the training rows).
- ``output_error``: no rows; the model is simulated through the records with their measured inputs
  (Zheng & Xiao's (2017) "integral" method; see ``study.identify.output_error``). Only estimators
  that simulate can use it.

Every regression structure takes the seed-000 cleaning steps (eqs. 4-9), each selectable in its
config (``clean:``): non-finite rows dropped, rows with a z-score above a limit in any column
dropped, duplicated rows dropped, rows whose target is smaller than a threshold dropped, and a
train/test split of the rows (``split:``); ``select: {n_rows: k}`` keeps k evenly spaced training
rows (Du et al. (2016) uses 100 of 600). They act per equation on that equation's rows.
"""
from __future__ import annotations

from functools import lru_cache
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import scipy.sparse as sp

#: a time step above this many times the median starts a new segment (a dropout)
GAP_FACTOR = 1.5


@dataclass
class Segment:
    """A contiguous piece of one record: node times and the record's columns there."""

    t: np.ndarray
    data: dict
    record: int
    source: str = ""  # the record's file (or name), for messages

    @property
    def where(self) -> str:
        return self.source or f"record {self.record}"


def segments(df: pd.DataFrame, record: int, min_len: int = 3) -> list[Segment]:
    """Cut a record at its gaps (time steps above ``GAP_FACTOR`` x the median step)."""
    t = df["time"].to_numpy(float)
    if len(t) < 2:
        return []
    dt = np.diff(t)
    h = float(np.median(dt))
    cuts = np.nonzero(dt > GAP_FACTOR * h)[0] + 1
    out = []
    for idx in np.split(np.arange(len(t)), cuts):
        if len(idx) >= min_len:
            # numeric columns only: a record may carry extra columns of text, which the schema keeps
            out.append(Segment(t[idx], {c: df[c].to_numpy(float)[idx] for c in df.columns
                                        if c != "time" and pd.api.types.is_numeric_dtype(df[c])}, record,
                               str(df.attrs.get("source") or "")))
    return out


class Ops:
    """Row operators of one segment (see the module docstring). ``times`` are the rows' times."""

    def __init__(self, t: np.ndarray, rows: np.ndarray):
        self.t = t
        self.rows = rows

    @property
    def times(self) -> np.ndarray:
        return self.t[self.rows]

    def __len__(self) -> int:
        return len(self.rows)

    def value(self, F):
        raise NotImplementedError

    def d(self, X, p: int):
        raise NotImplementedError


def _h(t):
    return np.diff(t)


def _d1_nodes(X: np.ndarray, t: np.ndarray) -> np.ndarray:
    """First derivative at the interior nodes 1..n-2 by the three-point formula on a non-uniform
    grid."""
    h1 = (t[1:-1] - t[:-2]).reshape((-1,) + (1,) * (X.ndim - 1))
    h2 = (t[2:] - t[1:-1]).reshape(h1.shape)
    return (h1 * h1 * X[2:] - h2 * h2 * X[:-2] - (h1 * h1 - h2 * h2) * X[1:-1]) / (h1 * h2 * (h1 + h2))


def _d2_nodes(X: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Second derivative at the interior nodes 1..n-2 (three-point, non-uniform)."""
    h1 = (t[1:-1] - t[:-2]).reshape((-1,) + (1,) * (X.ndim - 1))
    h2 = (t[2:] - t[1:-1]).reshape(h1.shape)
    return 2.0 * (h1 * X[2:] - (h1 + h2) * X[1:-1] + h2 * X[:-2]) / (h1 * h2 * (h1 + h2))


class EulerOps(Ops):
    def __init__(self, t, order):
        super().__init__(t, np.arange(0, len(t) - order))
        self.order = order

    def value(self, F):
        return np.asarray(F)[self.rows]

    def d(self, X, p):
        X = np.asarray(X)
        m = len(self.rows)
        h = _h(self.t).reshape((-1,) + (1,) * (X.ndim - 1))
        if p == 1:
            return (X[1:m + 1] - X[:m]) / h[:m]
        if p == 2:
            h1, h2 = h[:m], h[1:m + 1]
            return 2.0 * ((X[2:m + 2] - X[1:m + 1]) / h2 - (X[1:m + 1] - X[:m]) / h1) / (h1 + h2)
        raise ValueError(f"euler: derivative order {p} not supported (1 or 2)")


class CentralOps(Ops):
    def __init__(self, t, order):
        if order > 2:
            raise ValueError(f"central: derivative order {order} not supported (1 or 2)")
        super().__init__(t, np.arange(1, len(t) - 1))

    def value(self, F):
        return np.asarray(F)[self.rows]

    def d(self, X, p):
        X = np.asarray(X)
        if p == 1:
            return _d1_nodes(X, self.t)
        if p == 2:
            return _d2_nodes(X, self.t)
        raise ValueError(f"central: derivative order {p} not supported (1 or 2)")


class IntegralOps(Ops):
    """Rows = the equation integrated against a test function, so that no derivative of a measured
    signal is taken. Order 1: a box over [t_k, t_k+1] (Du et al.'s (2016) trapezoidal rows). Order
    2: a hat over [t_k-1, t_k+1] (peak 1 at t_k); integrating by parts puts both derivatives on the
    hat, int(hat x'') = x_k+1/h2 - x_k (1/h1 + 1/h2) + x_k-1/h1, and int(hat f) is exact for
    piecewise-linear f: (h1 f_k-1 + 2 (h1 + h2) f_k + h2 f_k+1) / 6. Rows are divided by the test
    function's integral, so the coefficients keep their units (the weak form of Messenger & Bortz
    2021 with the simplest test functions).
    """

    def __init__(self, t, order):
        if order > 2:
            raise ValueError(f"integral: derivative order {order} not supported (1 or 2)")
        n = len(t)
        self.order = order
        k = np.arange(0, n - 1) if order == 1 else np.arange(1, n - 1)
        super().__init__(t, k)

    @property
    def times(self):
        if self.order == 1:
            return 0.5 * (self.t[self.rows] + self.t[self.rows + 1])
        return self.t[self.rows]

    def _h12(self, ndim):
        k = self.rows
        shape = (-1,) + (1,) * (ndim - 1)
        return (self.t[k] - self.t[k - 1]).reshape(shape), (self.t[k + 1] - self.t[k]).reshape(shape)

    def value(self, F):
        F = np.asarray(F)
        k = self.rows
        if self.order == 1:
            return 0.5 * (F[k] + F[k + 1])
        h1, h2 = self._h12(F.ndim)
        return (h1 * F[k - 1] + 2.0 * (h1 + h2) * F[k] + h2 * F[k + 1]) / (3.0 * (h1 + h2))

    def d(self, X, p):
        X = np.asarray(X)
        k = self.rows
        if self.order == 1:
            if p != 1:
                raise ValueError("integral: a first-order row has no second derivative")
            h = (self.t[k + 1] - self.t[k]).reshape((-1,) + (1,) * (X.ndim - 1))
            return (X[k + 1] - X[k]) / h
        h1, h2 = self._h12(X.ndim)
        if p == 1:  # int(hat x') = -int(hat' x) = (mean of x right - mean of x left), trapezoidal
            return (X[k + 1] - X[k - 1]) / (h1 + h2)
        if p == 2:
            return 2.0 * (X[k + 1] / h2 - X[k] * (1.0 / h1 + 1.0 / h2) + X[k - 1] / h1) / (h1 + h2)
        raise ValueError(f"integral: derivative order {p} not supported (1 or 2)")


class SavGolOps(Ops):
    def __init__(self, t, window: int, polyorder: int):
        n = len(t)
        half = window // 2
        super().__init__(t, np.arange(half, n - half))
        self.window = window
        self.polyorder = polyorder
        self.h = float(np.median(np.diff(t)))

    def value(self, F):
        return np.asarray(F)[self.rows]

    def d(self, X, p):
        if p > self.polyorder:
            raise ValueError(f"smoothed: derivative order {p} needs polyorder >= {p}, got {self.polyorder}")
        return savgol_interior(np.asarray(X, float), self.window, self.polyorder, p, self.h)[self.rows]


class RtsOps(SavGolOps):
    """Savitzky-Golay rows whose derivatives of the measured ``u, v, r`` are the RTS smoother's
    ``u_dot, v_dot, r_dot`` (``smoothing.method: rts``). A column of ``X`` is recognised as one
    of the segment's measured ``u, v, r`` by its values; any other signal (rudder, propeller, or
    a column an effect has transformed, such as the doctor's water-relative velocities) is
    differentiated by Savitzky-Golay as in :class:`SavGolOps`. A second derivative is the
    Savitzky-Golay first derivative of the smoother's (smooth) first derivative. ``raw``: the
    measured ``u, v, r`` the smoother used; ``est``: its states and derivatives."""

    def __init__(self, t, window: int, polyorder: int, raw: dict, est: dict):
        super().__init__(t, window, polyorder)
        self.raw = raw
        self.est = est

    def _channel(self, col: np.ndarray):
        for c in ("u", "v", "r"):
            a = self.raw.get(c)
            if a is not None and a.shape == col.shape and np.array_equal(a, col):
                return c
        return None

    def _d_col(self, col: np.ndarray, p: int) -> np.ndarray:
        c = self._channel(col)
        if c is None:
            return savgol_interior(col, self.window, self.polyorder, p, self.h)[self.rows]
        d1 = self.est[c + "_dot"]
        if p == 1:
            return d1[self.rows]
        return savgol_interior(d1, self.window, self.polyorder, p - 1, self.h)[self.rows]

    def d(self, X, p):
        if p > self.polyorder:
            raise ValueError(f"smoothed: derivative order {p} needs polyorder >= {p}, got {self.polyorder}")
        X = np.asarray(X, float)
        if X.ndim == 1:
            return self._d_col(X, p)
        flat = X.reshape(len(X), -1)
        out = np.column_stack([self._d_col(flat[:, j], p) for j in range(flat.shape[1])])
        return out.reshape((len(self.rows),) + X.shape[1:])


@lru_cache(maxsize=64)
def _savgol_coeffs(window: int, polyorder: int, deriv: int, delta: float) -> np.ndarray:
    from scipy.signal import savgol_coeffs

    return savgol_coeffs(window, polyorder, deriv=deriv, delta=delta)


def savgol_interior(X: np.ndarray, window: int, polyorder: int, deriv: int = 0, delta: float = 1.0) -> np.ndarray:
    """``scipy.signal.savgol_filter`` along axis 0, exact at the interior nodes (the rows): the
    same coefficients and convolution, but the coefficients cached and the edges by the "nearest"
    mode instead of "interp"'s polynomial fits, which no row uses (measured: most of the model
    doctor's smoothing time)."""
    from scipy.ndimage import convolve1d

    return convolve1d(X, _savgol_coeffs(int(window), int(polyorder), int(deriv), float(delta)), axis=0,
                      mode="nearest")


# ------------------------------------------------------------------------------------------- structures

@dataclass
class Structure:
    """A sample structure built from its config (``conf/structure/<name>.yaml``)."""

    name: str
    kind: str = "central"  # euler | central | integral | smoothed | output_error (diff_center: kind of base)
    simulates: bool = False
    base: str | None = None
    difference: dict | None = None  # {rho: 1.0}
    center: bool = False
    clean: dict = field(default_factory=dict)
    split: dict = field(default_factory=dict)
    smoothing: dict = field(default_factory=dict)
    output_error: dict = field(default_factory=dict)
    select: dict = field(default_factory=dict)  # {n_rows: k}: k evenly spaced training rows (Du et al. 2016: 100)
    rate_from_heading: bool = False  # r replaced by the central difference of psi (Zheng & Xiao 2017 eq. 14)
    source: str = ""
    _rts_cache: dict = field(default_factory=dict, repr=False, compare=False)

    # -- smoothing method of the smoothed structure: savgol (default) or rts
    @property
    def method(self) -> str:
        return str((self.smoothing or {}).get("method") or "savgol")

    def rts_states(self, seg: Segment) -> tuple[dict, dict] | None:
        """``(inputs, states)`` of a segment: the measured ``u, v, r`` the estimate used, and
        ``u, v, r, u_dot, v_dot, r_dot`` from the EKF + RTS smoother (``smoothing.rts`` options).
        Cached on the segment's times, positions and heading, so that a segment whose ``u, v`` an
        effect has changed (the doctor's water-relative velocities) reuses the estimate of the
        measured one; None when the segment has no positions and heading (a partial segment of
        changed columns: smoothed by Savitzky-Golay)."""
        need = ("x0", "y0", "psi")
        if not all(c in seg.data for c in need):
            return None
        from study.records.state_estimation import estimate_states

        key = (len(seg.t), hash(np.asarray(seg.t, float).tobytes()),
               tuple(hash(np.asarray(seg.data[c], float).tobytes()) for c in need))
        hit = self._rts_cache.get(key)
        if hit is None:
            cols = [c for c in ("x0", "y0", "psi", "u", "v", "r") if c in seg.data]
            data = {"time": seg.t, **{c: seg.data[c] for c in cols}}
            est = estimate_states(data, (self.smoothing or {}).get("rts") or {})
            hit = ({c: np.array(seg.data[c], float) for c in ("u", "v", "r") if c in seg.data},
                   {c: est.frame[c].to_numpy() for c in ("u", "v", "r", "u_dot", "v_dot", "r_dot")})
            if len(self._rts_cache) >= 256:
                self._rts_cache.pop(next(iter(self._rts_cache)))
            self._rts_cache[key] = hit
        return hit

    # -- segments and operators
    def min_nodes(self, order: int) -> int:
        if self.kind == "smoothed":
            return self.window_samples(None) + 2
        return order + 3

    def window_samples(self, t: np.ndarray | None) -> int:
        sm = self.smoothing or {}
        if sm.get("window_s") is not None and t is not None:
            h = float(np.median(np.diff(t)))
            w = int(round(float(sm["window_s"]) / h))
        else:
            w = int(sm.get("window", 11))
        w = max(w, int(sm.get("polyorder", 3)) + 2)
        return w + 1 - w % 2  # odd

    def ops(self, seg: Segment, order: int) -> Ops:
        t = seg.t
        if self.kind == "euler":
            return EulerOps(t, order)
        if self.kind == "central":
            return CentralOps(t, order)
        if self.kind == "integral":
            return IntegralOps(t, order)
        if self.kind == "smoothed":
            dt = np.diff(t)
            h = float(np.median(dt))
            if np.max(np.abs(dt - h)) > 0.05 * h:
                raise ValueError(f"structure 'smoothed': Savitzky-Golay needs a uniform time step; a segment of "
                                 f"{seg.where} has steps from {dt.min():.4g} to {dt.max():.4g} s "
                                 "(resample it first)")
            w, p = self.window_samples(t), int((self.smoothing or {}).get("polyorder", 3))
            hit = self.rts_states(seg) if self.method == "rts" else None
            if hit is not None:
                return RtsOps(t, w, p, *hit)
            return SavGolOps(t, w, p)
        raise ValueError(f"structure '{self.name}' ({self.kind}) builds no regression rows")

    def measured(self, seg: Segment) -> Segment:
        """The segment as the rows see it: with ``rate_from_heading`` the yaw rate is the
        three-point central difference of the heading (Zheng & Xiao (2017) eq. 14: r, r', r'' all
        from psi, as when no gyro is logged)."""
        if not self.rate_from_heading:
            return seg
        data = dict(seg.data)
        r = np.empty_like(data["psi"])
        r[1:-1] = _d1_nodes(data["psi"], seg.t)
        r[0] = (data["psi"][1] - data["psi"][0]) / (seg.t[1] - seg.t[0])
        r[-1] = (data["psi"][-1] - data["psi"][-2]) / (seg.t[-1] - seg.t[-2])
        data["r"] = r
        return Segment(seg.t, data, seg.record, seg.source)

    def nodes(self, seg: Segment) -> dict:
        """Node values for the model's node-wise functions: the raw samples, or smoothed ones."""
        if self.kind != "smoothed":
            return seg.data
        w = self.window_samples(seg.t)
        p = int((self.smoothing or {}).get("polyorder", 3))
        hit = self.rts_states(seg) if self.method == "rts" else None
        out = {}
        for c, a in seg.data.items():
            a = np.asarray(a, float)
            if hit is not None and c in hit[0] and np.array_equal(a, hit[0][c]):
                out[c] = hit[1][c]  # the smoother's state (a column an effect changed: Savitzky-Golay below)
            else:
                out[c] = savgol_interior(a, w, p)
        return out

    def noise_operators(self, seg: Segment, order: int) -> list | None:
        """How white noise on the segment's samples reaches its rows: ``[D_order, ..., D_1, V]``,
        sparse (rows x nodes) matrices, ``D_p`` the structure's p-th derivative operator and ``V``
        its value operator (after the smoothing of :meth:`nodes`). A row's noise is ``D_order w_a +
        ... + V w_b`` for node-wise noises ``w`` (the target's derivative of the measured signal,
        the regressors' values); the regression likelihood of ``estimator=emcee`` models its
        covariance with them (``study.identify.row_noise``).

        Read off the structure's own operators by applying them to comb signals (1 on every C-th
        node, C wider than any stencil: the grouping of Curtis, Powell & Reid 1974 for sparse
        Jacobians), so each structure gives its own stencils and a change to an operator changes its
        noise model with it; checked on a random signal. None where the rows are no fixed linear
        stencil of the samples: the RTS smoother's states, and ``rate_from_heading`` (r is itself a
        difference of psi, and the other channels are not).
        """
        if self.rate_from_heading or (self.kind == "smoothed" and self.method == "rts"):
            return None
        n = len(seg.t)
        ops = self.ops(seg, order)
        half = self.window_samples(seg.t) // 2 if self.kind == "smoothed" else 0
        w = order + 1 + half  # no stencil reaches further from its row's node
        C = 2 * w + 1
        E = np.zeros((n, C))
        E[np.arange(n), np.arange(n) % C] = 1.0

        def value(F):
            if self.kind != "smoothed":
                return ops.value(F)
            nd = self.nodes(Segment(seg.t, {j: F[:, j] for j in range(F.shape[1])}, seg.record))
            return ops.value(np.column_stack([nd[j] for j in range(F.shape[1])]))

        maps = [lambda F, p=p: ops.d(F, p) for p in range(order, 0, -1)] + [value]
        m = len(ops)
        off = np.arange(-w, w + 1)
        cols = ops.rows[:, None] + off[None, :]
        rows = np.repeat(np.arange(m)[:, None], len(off), axis=1)
        ok = (cols >= 0) & (cols < n)
        probe = np.random.default_rng(0).standard_normal((n, 1))
        out = []
        for f in maps:
            R = np.asarray(f(E)).reshape(m, C)
            M = sp.csr_matrix((R[rows[ok], cols[ok] % C], (rows[ok], cols[ok])), shape=(m, n))
            M.eliminate_zeros()
            ref = np.asarray(f(probe)).reshape(m)
            if not np.allclose(M @ probe[:, 0], ref, rtol=1e-8, atol=1e-8 * (np.max(np.abs(ref)) + 1.0)):
                raise RuntimeError(f"structure '{self.name}': its operators are not a stencil within {w} nodes of "
                                   "each row (noise_operators)")
            out.append(M)
        return out

    # -- rows after the model built them (per equation)
    def postprocess(self, Phi: np.ndarray, y: np.ndarray, seg_id: np.ndarray, seed: int = 0):
        """Differencing, cleaning, split and centring (each as configured). Returns a dict of
        arrays: ``Phi, y`` (training rows), ``Phi_test, y_test`` (held-out rows, maybe empty),
        ``report`` (counts), and ``rows``: the sparse (training rows x built rows) map of the
        differencing, cleaning, split and selection (training rows before centring = ``rows @
        built rows``), which carries the built rows' noise model over."""
        report = {"rows_built": int(len(y))}
        rows = sp.identity(len(y), format="csr")
        if self.difference:
            rho = float(self.difference.get("rho", 1.0))
            same = seg_id[1:] == seg_id[:-1]  # consecutive rows of one segment only
            Phi = (Phi[1:] - rho * Phi[:-1])[same]
            y = (y[1:] - rho * y[:-1])[same]
            seg_id = seg_id[1:][same]
            i = np.nonzero(same)[0]
            j = np.arange(len(i))
            rows = sp.csr_matrix((np.r_[np.ones(len(i)), np.full(len(i), -rho)], (np.r_[j, j], np.r_[i + 1, i])),
                                 shape=(len(i), len(same) + 1))
        keep = np.ones(len(y), dtype=bool)
        c = self.clean or {}
        if c.get("missing", True):
            keep &= np.all(np.isfinite(Phi), axis=1) & np.isfinite(y)
        report["rows_nonfinite"] = int((~keep).sum())
        if c.get("zscore") is not None:
            Z = np.column_stack([Phi, y])
            mu = np.nanmean(Z[keep], axis=0)
            sd = np.nanstd(Z[keep], axis=0)
            sd[sd == 0] = 1.0
            out = np.any(np.abs((Z - mu) / sd) > float(c["zscore"]), axis=1)
            report["rows_zscore"] = int((out & keep).sum())
            keep &= ~out
        if c.get("duplicates"):
            Z = np.column_stack([Phi, y])
            _, first = np.unique(Z, axis=0, return_index=True)
            dup = np.ones(len(y), dtype=bool)
            dup[first] = False
            report["rows_duplicate"] = int((dup & keep).sum())
            keep &= ~dup
        if c.get("min_abs") is not None:
            # Song et al. 2025 eq. 8, |z_i| >= Lambda, read as a threshold on the target relative to its spread
            small = np.abs(y) < float(c["min_abs"]) * np.std(y[keep])
            report["rows_small"] = int((small & keep).sum())
            keep &= ~small
        Phi, y, rows = Phi[keep], y[keep], rows[np.nonzero(keep)[0]]
        s = self.split or {}
        frac = float(s.get("train_fraction", 1.0))
        test = np.zeros(len(y), dtype=bool)
        if frac < 1.0:
            n_test = int(round((1.0 - frac) * len(y)))
            if s.get("how", "random") == "tail":
                test[len(y) - n_test:] = True
            else:
                rng = np.random.default_rng(int(s.get("seed", seed)))
                test[rng.choice(len(y), n_test, replace=False)] = True
        Pt, yt, Pv, yv = Phi[~test], y[~test], Phi[test], y[test]
        rows = rows[np.nonzero(~test)[0]]
        n_sel = (self.select or {}).get("n_rows")
        if n_sel and int(n_sel) < len(yt):  # Du et al. 2016 Sec. 3.3: 100 equally spaced pairs of the 600
            idx = np.unique(np.round(np.linspace(0, len(yt) - 1, int(n_sel))).astype(int))
            Pt, yt, rows = Pt[idx], yt[idx], rows[idx]
            report["rows_selected"] = int(len(idx))
        if self.center:
            mx, my = Pt.mean(axis=0), yt.mean()
            Pt, yt = Pt - mx, yt - my
            Pv, yv = Pv - mx, yv - my
        report["rows_train"] = int(len(yt))
        report["rows_test"] = int(len(yv))
        return {"Phi": Pt, "y": yt, "Phi_test": Pv, "y_test": yv, "report": report, "rows": rows}


STRUCTURE_KINDS = ("euler", "central", "integral", "smoothed", "output_error")
#: how the smoothed structure gets its states and derivatives
SMOOTHING_METHODS = ("savgol", "rts")


def make_structure(cfg) -> Structure:
    """A :class:`Structure` from its config dict (or config name)."""
    if isinstance(cfg, str):
        from study.configuration.compose import read_config

        cfg = read_config("structure", cfg)
    cfg = dict(cfg)
    name = cfg.get("name")
    kind = cfg.get("kind", name if name in STRUCTURE_KINDS else None)
    base = cfg.get("base")
    if base is not None:
        kind = base
    if kind not in STRUCTURE_KINDS:
        raise ValueError(f"structure '{name}': unknown kind '{kind}'; expected one of {STRUCTURE_KINDS} "
                         "(or a 'base' structure with 'difference'/'center')")
    known = {"name", "kind", "base", "difference", "center", "clean", "split", "smoothing", "output_error",
             "source", "select", "rate_from_heading"}
    extra = sorted(set(cfg) - known)
    if extra:
        raise ValueError(f"structure '{name}': unknown key(s) {extra}; known: {sorted(known)}")
    sm = dict(cfg.get("smoothing") or {})
    method = sm.get("method") or "savgol"
    if method not in SMOOTHING_METHODS:
        raise ValueError(f"structure '{name}': smoothing.method '{method}'; expected one of {SMOOTHING_METHODS}")
    if method == "rts":
        if kind != "smoothed":
            raise ValueError(f"structure '{name}': smoothing.method rts belongs to the smoothed structure, not "
                             f"'{kind}'")
        from study.records.state_estimation import resolve_options

        resolve_options(sm.get("rts"))  # a misspelt option fails here, before any run
    return Structure(name=name, kind=kind, simulates=kind == "output_error", base=base,
                     difference=cfg.get("difference"), center=bool(cfg.get("center", False)),
                     clean=dict(cfg.get("clean") or {}), split=dict(cfg.get("split") or {}),
                     smoothing=dict(cfg.get("smoothing") or {}), output_error=dict(cfg.get("output_error") or {}),
                     select=dict(cfg.get("select") or {}), rate_from_heading=bool(cfg.get("rate_from_heading")),
                     source=str(cfg.get("source", "")))


def list_structures() -> list[str]:
    from study.configuration.compose import list_configs

    return list_configs("structure")


def get_structure(name: str) -> Structure:  # kept for older callers
    return make_structure(name)

