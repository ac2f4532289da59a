"""The noise of regression rows built from noisy samples, modelled with the sample structure's own
operators, and the posterior of the coefficients under it (emcee's default regression likelihood,
``likelihood: regression``).

Why: a structure turns white measurement noise into correlated row noise. Central differences of
white noise are correlated at lag 2 with coefficient -0.5; forward differences at lag 1;
Savitzky-Golay derivatives over the window. Counted as independent rows, the derivative noise
(variance ~ sigma^2 / h^2 per row) looks far larger than what reaches the estimate, where the
differences telescope (measured on the KT Mariner at 0.1 s, 1 % noise: posterior sd 17-154 times the
actual spread of the estimates). And a regressor's noise that also enters the target (euler: the
state at k in both) biases least squares by hundreds of its standard deviations.

The model: a row's noise is ``e = D_p w_0 + ... + D_1 w_(p-1) + V w_p`` with ``D_q`` the structure's
q-th derivative operator, ``V`` its value operator (``Structure.noise_operators``, restricted to the
training rows by the post-processing's row map: differencing, cleaning, split) and ``w`` node-wise
white noises with an unknown joint covariance ``Q`` (m x m, positive definite): the target's
derivative of the measured states, the regressors' values (their noise through each regressor's
local gain), and how the two correlate (euler: the same sample in both). So

    Cov(e) = Sigma(Q) = sum_ij Q_ij L_i L_j^T,   L = (D_p, ..., D_1, V),

banded (no stencil reaches far), positive definite because ``D_p`` has full row rank. ``Q`` (up to
the scale, profiled out) and the coefficients are estimated together by maximum likelihood: for a
given ``Q`` the coefficients are generalised least squares (GLS) and the likelihood is profiled over
them (Harville 1977, JASA 72, 320-338; the Gaussian profile likelihood of a regression with a
parametric covariance). Each evaluation is a banded Cholesky factorisation (LAPACK pbtrf), O(n b^2)
for n rows and bandwidth b.

The posterior (``study.identify.estimators.prior.gls_posterior``, beside the MAP estimator's
posterior it uses): GLS is least squares on the whitened rows ``C^-1 X, C^-1 y`` (``C C^T =
Sigma``); its covariance is the block cluster-robust sandwich of those rows
(``study.identify.estimators.prior.data_covariance``, the MAP estimator's: Mueller 2013's sandwich
posterior), so what the noise model misses (a regressor's gain changing along the record, coloured
noise, slow model error) still counts: weighted least squares with robust inference (Romano & Wolf
2017, J. Econometrics 197, 1-19). Whitened rows are nearly independent, so the blocks no longer
break a cancellation as they do on central-difference rows (where the same sandwich overstated the
spread 3-5 times on the KT Mariner). The result is Gaussian: emcee's per-walker cost is O(k^2).

Assumptions (labelled): white measurement noise on each channel; a constant noise mix ``Q`` along
the records (each regressor's gain to its noise treated as constant; the sandwich absorbs the rest);
rows linear in the noise to first order (small noise); the regressors' noise enters ``e`` but is not
modelled as noise in the regressors (errors in variables): measured, it leaves the KT Mariner's
intervals 1.2 times too wide at 0.1 s (1.06 at 0.02 s) and biases a few MMG coefficients by about
half a posterior sd, and where gaps in the rows keep the whitening from undoing a differencing
(diff_center's random split) it biases the estimate beyond any interval. Not modelled, because it is
no sampling noise: a structure's truncation error (euler's O(h)), which a noise-free record has too;
the posterior then covers the structure's noise-free limit, not the truth (``study.run.calibration``
measures both). Both the truncation and the errors in variables are estimated from the run's records
and removed before and after the whitening by ``study.identify.row_errors`` (emcee's default).
Numerical limit: the covariance of twice-differenced rows (diff_center) is ill-conditioned like n^4;
at 41,700 rows it is no longer positive definite in doubles.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import linalg, optimize
from scipy.linalg import lapack


@dataclass
class RowOperators:
    """What the rows' noise model needs from the structure: ``operators``, the sparse (training
    rows x nodes) maps ``(D_p, ..., D_1, V)`` (``Structure.noise_operators`` through the
    post-processing's row map), and ``centred``: the rows had their means removed (diff_center).
    Centring subtracts the mean of the noise too, a constant the whitening would blow up (a
    constant is the lowest frequency, where differenced noise has almost no power); it is
    modelled exactly as a free intercept with a flat prior (centring = least squares with an
    intercept), whose marginal is dropped."""

    operators: list
    centred: bool = False


def _banded(S: sp.spmatrix, b: int) -> np.ndarray:
    """Lower banded storage (``scipy.linalg.cholesky_banded(lower=True)``) of a symmetric sparse
    matrix."""
    n = S.shape[0]
    ab = np.zeros((b + 1, n))
    for d in range(b + 1):
        ab[d, :n - d] = S.diagonal(-d)
    return ab


def solve_lower_banded(c: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``C^-1 B`` for a lower triangular banded ``C`` in
    ``scipy.linalg.cholesky_banded(lower=True)`` storage: LAPACK's triangular banded solve
    (dtbtrs). ``scipy.linalg.solve_banded((b, 0), c, B)`` gives the same to rounding (measured:
    1e-15 relative, 9e-14 on the KT's three operators) but LU-factorises the triangle first
    (LAPACK gbsv): twice the time, and half of the noise model's maximum-likelihood fit was that
    solve."""
    B = np.asarray(B, float)
    x, info = lapack.dtbtrs(c, B.reshape(len(B), -1), uplo="L")
    if info != 0:
        raise linalg.LinAlgError(f"row noise: the row covariance's Cholesky factor is singular (dtbtrs info {info})")
    return x.reshape(B.shape)


def _bandwidth(S: sp.spmatrix) -> int:
    S = S.tocoo()
    return int(np.max(np.abs(S.row - S.col))) if S.nnz else 0


class RowNoise:
    """The covariance model ``Sigma(Q) = sum_ij Q_ij L_i L_j^T`` of the rows (see the module
    docstring).

    ``operators``: the (rows x nodes) sparse maps ``L`` with the target's derivative operator first.
    Each is scaled to unit RMS row norm, so that ``Q`` is of order one whatever the sampling
    interval.
    """

    def __init__(self, operators: list):
        L = [sp.csr_matrix(o, dtype=float) for o in operators]
        n = L[0].shape[0]
        if any(o.shape[0] != n for o in L):
            raise ValueError(f"row noise: operators with {[o.shape[0] for o in L]} rows; expected {n} each")
        self.scale = np.array([np.sqrt(o.multiply(o).sum() / max(n, 1)) or 1.0 for o in L])
        L = [o / s for o, s in zip(L, self.scale)]
        self.m, self.n = len(L), n
        G = {}
        for i in range(self.m):
            for j in range(i, self.m):
                g = L[i] @ L[j].T
                G[(i, j)] = (g if i == j else g + g.T).tocsr()
        self.b = max(_bandwidth(g) for g in G.values())
        self._G = {k: _banded(g, self.b) for k, g in G.items()}
        self.Q = None
        self._chol = None

    @property
    def n_params(self) -> int:
        return self.m * (self.m + 1) // 2 - 1

    def q_of(self, p: np.ndarray) -> np.ndarray:
        """``Q = F F^T`` from the free parameters: ``F`` lower triangular, ``F_00 = 1`` (the
        scale is profiled), the other diagonal entries as logarithms, so every ``p`` gives a
        positive definite ``Q``."""
        F = np.zeros((self.m, self.m))
        F[0, 0] = 1.0
        it = iter(np.asarray(p, float))
        for i in range(1, self.m):
            for j in range(i):
                F[i, j] = next(it)
            F[i, i] = np.exp(next(it))
        return F @ F.T

    def cholesky(self, Q: np.ndarray) -> np.ndarray:
        ab = sum(Q[i, j] * g for (i, j), g in self._G.items())
        return linalg.cholesky_banded(ab, lower=True)

    def _profile(self, p, X, y) -> float:
        """Negative profile log-likelihood (constants dropped) at ``Q(p)``, the coefficients and
        scale at their maximum (GLS)."""
        try:
            c = self.cholesky(self.q_of(p))
        except (linalg.LinAlgError, ValueError):
            return np.inf
        W = solve_lower_banded(c, np.column_stack([X, y]))
        Xw, yw = W[:, :-1], W[:, -1]
        th, *_ = np.linalg.lstsq(Xw, yw, rcond=None)
        r = yw - Xw @ th
        rss = float(r @ r)
        if not rss > 0:
            return np.inf
        return 0.5 * self.n * np.log(rss / self.n) + float(np.sum(np.log(c[0])))

    def fit(self, X: np.ndarray, y: np.ndarray) -> RowNoise:
        """``Q`` by maximum likelihood with the coefficients profiled out. Start: off-diagonal 0
        and the other noises a common fraction of the first, the best of a coarse grid; then
        Nelder-Mead."""
        X, y = np.asarray(X, float), np.asarray(y, float)
        if X.shape[0] != self.n:
            raise ValueError(f"row noise: {X.shape[0]} rows but operators for {self.n}")
        k = self.n_params

        def start(g):
            p, i = np.zeros(k), 0
            for r in range(1, self.m):
                i += r  # off-diagonal entries of row r stay 0
                p[i] = g
                i += 1
            return p

        grid = [start(g) for g in np.log(10.0) * np.arange(-6.0, 2.5, 1.0)]
        vals = [self._profile(p, X, y) for p in grid]
        p0 = grid[int(np.argmin(vals))]
        res = optimize.minimize(self._profile, p0, args=(X, y), method="Nelder-Mead",
                                options={"xatol": 1e-3, "fatol": 1e-3, "maxiter": 400 * k,
                                         "initial_simplex": p0 + 0.5 * np.vstack([np.zeros(k), np.eye(k)])})
        p = res.x if res.fun <= min(vals) else p0
        if not np.isfinite(min(res.fun, min(vals))):
            raise ValueError("row noise: no noise mix gives a positive definite row covariance (or the rows fit "
                             "exactly)")
        self.params_ = p
        self.Q = self.q_of(p)
        self._chol = self.cholesky(self.Q)
        self.nll_ = float(min(res.fun, min(vals)))
        self.evaluations_ = int(res.nfev + len(grid))
        return self

    @property
    def q_raw(self) -> np.ndarray:
        """``Q`` in the units of the operators as given (not scaled)."""
        return self.Q / np.outer(self.scale, self.scale)

    def use(self, q_raw: np.ndarray) -> RowNoise:
        """Take a noise mix fitted elsewhere (``q_raw`` of another :class:`RowNoise`) instead of
        fitting one: the same likelihood on other rows, e.g. the noise-free records' (the
        structure's noise-free limit)."""
        self.Q = np.asarray(q_raw, float) * np.outer(self.scale, self.scale)
        self._chol = self.cholesky(self.Q)
        self.params_, self.nll_, self.evaluations_ = None, float("nan"), 0
        return self

    def whiten(self, A: np.ndarray) -> np.ndarray:
        """``C^-1 A`` with ``C C^T = Sigma(Q)`` (the fitted ``Q``, up to its scale)."""
        return solve_lower_banded(self._chol, A)
