"""Support vector regression with a linear kernel: epsilon-SVR and nu-SVR (libsvm, or the primal QP
by Clarabel).

Song et al. (2025) identifies the MMG coefficients by a linear-kernel epsilon-SVR and reads them
from the weights ``w = sum (alpha_i - alpha_i^*) x_i`` (its eq. 26), when the bias b is near 0.
scikit-learn's ``SVR`` / ``NuSVR`` (libsvm; Chang & Lin 2011) give exactly that as ``coef_``, but
libsvm's dual solver is slow at the benchmark size: on 16,800 samples with a small epsilon nearly
every sample is a support vector (9 s at C = 1, 200 s at C = 100 for 5 columns). The linear SVR is
also a small *primal* quadratic programme (k + 1 + n variables, 3n inequalities, sparse), which the
interior-point solver Clarabel (Goulart & Chen
2024) solves in well under a second at n = 16,800, with the same optimum (tested against libsvm).
"""
from __future__ import annotations

import numpy as np
from scipy import sparse

from .base import Estimator
from .linear import check_regression, column_scale

# solver='auto' takes libsvm only where it is fast: its time grows with n and steeply with C (measured on
# 2000 noisy samples x 5: 1 s at C = 1, 45-80 s at C = 100; the QP 0.05-0.1 s at any C)
LIBSVM_MAX_N = 1000
LIBSVM_MAX_C = 10.0


def _scale(X, y):
    s = column_scale(X)
    sy = float(np.std(y))
    if not sy > 0:
        sy = 1.0
    return X / s, y / sy, s, sy


def _qp_svr(Z, y, C, epsilon=None, nu=None, intercept=True):
    """Primal linear SVR by Clarabel. ``epsilon`` given: eps-SVR; ``nu`` given: nu-SVR (eps a
    variable).

    eps-SVR (Vapnik 1995; Smola & Schoelkopf 2004):  min 1/2 |w|^2 + C sum t_i
        s.t.  |y_i - z_i.w - b| <= eps + t_i,  t_i >= 0        (t_i = xi_i + xi_i^*; one of them is 0)
    nu-SVR (Schoelkopf et al. 2000), scaled as libsvm solves it (Chang & Lin 2011, sec. 2.4):
        min 1/2 |w|^2 + C (n nu eps + sum t_i)   s.t. |y_i - z_i.w - b| <= eps + t_i,  t_i >= 0, eps >= 0
    Variables [w (k), b (if ``intercept``), t (n)] (+ eps). Returns w, b (0 without intercept), eps
    (nu-SVR) and Clarabel's status. Written by hand (the formulation; the solving is Clarabel's): no
    library poses the linear SVR as its primal QP.
    """
    import clarabel

    n, k = Z.shape
    has_eps = nu is not None
    nb = 1 if intercept else 0
    nv = k + nb + n + (1 if has_eps else 0)
    P = sparse.csc_matrix((np.ones(k), (np.arange(k), np.arange(k))), shape=(nv, nv))
    q = np.zeros(nv)
    q[k + nb:k + nb + n] = C
    if has_eps:
        q[-1] = C * n * nu
    Zs = sparse.csr_matrix(Z)
    one = [sparse.csr_matrix(np.ones((n, 1)))] if intercept else []
    eye = sparse.identity(n, format="csr")
    blocks_1 = [-Zs] + [-o for o in one] + [-eye]  # -(z.w + b) - t (- eps) <= -y (+ eps)
    blocks_2 = [Zs] + one + [-eye]  # (z.w + b) - t (- eps) <= y (+ eps)
    blocks_3 = [sparse.csr_matrix((n, k + nb)), -eye]  # -t <= 0
    if has_eps:
        m1 = sparse.csr_matrix(-np.ones((n, 1)))
        blocks_1.append(m1)
        blocks_2.append(m1)
        blocks_3.append(sparse.csr_matrix((n, 1)))
    rows = [sparse.hstack(blocks_1), sparse.hstack(blocks_2), sparse.hstack(blocks_3)]
    rhs = [-y, y, np.zeros(n)]
    if has_eps:
        rows.append(sparse.csr_matrix(([-1.0], ([0], [nv - 1])), shape=(1, nv)))
        rhs.append(np.zeros(1))
    else:
        rhs[0] = rhs[0] + epsilon
        rhs[1] = rhs[1] + epsilon
    A = sparse.vstack(rows, format="csc")
    b = np.concatenate(rhs)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    solver = clarabel.DefaultSolver(sparse.triu(P, format="csc"), q, A, b, [clarabel.NonnegativeConeT(b.size)],
                                    settings)
    sol = solver.solve()
    x = np.asarray(sol.x)
    status = str(sol.status)
    if "Solved" not in status:
        raise RuntimeError(f"Clarabel did not solve the SVR QP: {status}")
    return x[:k], (float(x[k]) if intercept else 0.0), (float(x[-1]) if has_eps else None), status


class _LinearSVR(Estimator):
    _kind = ""

    def _solver(self, n):
        if self.solver not in ("auto", "libsvm", "qp"):
            raise ValueError(f"solver must be 'auto', 'libsvm' or 'qp', got {self.solver!r}")
        if not self.fit_intercept:
            if self.solver == "libsvm":
                raise ValueError("libsvm always fits an intercept: fit_intercept=False needs solver 'qp' or 'auto'")
            return "qp"
        if self.solver == "auto":
            return "libsvm" if (n <= LIBSVM_MAX_N and float(self.C) <= LIBSVM_MAX_C) else "qp"
        return self.solver

    def _check_C(self):
        if not float(self.C) > 0:
            raise ValueError(f"C must be > 0, got {self.C}")

    def _finish(self, w, b, s, sy, solver, extra):
        self.coef_ = w * sy / s
        self.intercept_ = float(b * sy)
        self.diagnostics_ = {"C": float(self.C), "solver": solver, "intercept_rel": float(b), **extra}
        return self


class EpsilonSVR(_LinearSVR):
    """epsilon-SVR with a linear kernel (Vapnik 1995; Smola & Schoelkopf 2004), as Song et al.
    (2025).

    Columns are standardised inside ``fit`` (divided by their root mean square) and y divided by its
    standard deviation; the coefficients are the weights ``w`` (Song et al. (2025) eq. 26; sklearn's
    ``coef_``) mapped back to the units of X and y. The model has an intercept b (SVR always does):
    it is reported as ``intercept_`` and, divided by std(y), as ``diagnostics_['intercept_rel']``;
    Song et al. (2025) reads the coefficients "when b is near 0" -- b is not forced to 0 here, so a
    large ``intercept_rel`` flags a fit whose coefficients are not the model's. That happens when a
    regressor is nearly constant (u^2 in a surge equation at steady speed): b is unpenalised while
    |w|^2 is, so the SVR moves that term into b (measured on the USV surge equation, noise-free: b =
    -10 std(y), coefficients off by 260 %). ``fit_intercept=False`` (QP only; libsvm always has b)
    fits the model as it is, without b.

    The tube biases noise-free fits: the minimum-norm weights inside the tube leave weak (collinear)
    directions free, by an amount proportional to epsilon (measured on the noise-free ship
    regressions, largest error relative to the largest coefficient: epsilon = 0.01 -> 7-63 %, 1e-3
    -> 0.8-6 %, 1e-4 -> 0.03-0.6 %). With realistic noise (above 1e-3 std(y)) almost every sample is
    outside the tube whatever epsilon, and it hardly matters. Default 1e-4: unbiased on clean data,
    an eps-SVR (LAD-like) on noisy data.

    Parameters
    ----------
    C : float
        Penalty on the slacks, on standardised data (libsvm's C: multiplies the *sum* of slacks).
    epsilon : float
        Half-width of the insensitive tube relative to the spread of y: ``0.01`` means ``0.01 *
        std(y)``.
    solver : 'auto' | 'libsvm' | 'qp'
        libsvm (sklearn ``SVR``, the reference dual solver), or the primal QP by Clarabel
        (``_qp_svr``); 'auto': libsvm up to 1000 samples and C <= 10, the QP otherwise.
    tol : float
        libsvm's stopping tolerance (sklearn's default is 1e-3; smaller agrees better with the QP).
    fit_intercept : bool
        Fit the bias b (True: the SVR of the seed). False needs the QP.
    """

    _kind = "eps"

    def __init__(self, C: float = 1.0, epsilon: float = 1.0e-4, solver: str = "auto", tol: float = 1.0e-4,
                 fit_intercept: bool = True):
        self.C = C
        self.epsilon = epsilon
        self.solver = solver
        self.tol = tol
        self.fit_intercept = fit_intercept

    def fit(self, X, y):
        X, y, _ = check_regression(X, y)
        n, k = X.shape
        self._init_outputs(k)
        self._check_C()
        if not float(self.epsilon) >= 0:
            raise ValueError(f"epsilon must be >= 0, got {self.epsilon}")
        solver = self._solver(n)
        Z, ys, s, sy = _scale(X, y)
        if solver == "libsvm":
            from sklearn.svm import SVR

            m = SVR(kernel="linear", C=float(self.C), epsilon=float(self.epsilon), tol=float(self.tol)).fit(Z, ys)
            w, b = np.asarray(m.coef_, dtype=float).ravel(), float(np.ravel(m.intercept_)[0])
            n_sv = int(m.support_.size)
        else:
            w, b, _, _ = _qp_svr(Z, ys, float(self.C), epsilon=float(self.epsilon), intercept=self.fit_intercept)
            r = np.abs(ys - Z @ w - b)
            n_sv = int(np.sum(r >= float(self.epsilon) * (1 - 1e-6)))  # on or outside the tube
        return self._finish(w, b, s, sy, solver, {"epsilon": float(self.epsilon), "n_support": n_sv})


class NuSVR(_LinearSVR):
    """nu-SVR with a linear kernel (Schoelkopf et al. 2000; Smola & Schoelkopf 2004): the tube width
    is learned.

    ``nu`` in (0, 1] bounds the fraction of samples outside the tube from above and the fraction of
    support vectors from below. Scaling, coefficients (the weights w) and intercept (and its trade
    with nearly constant regressors) as :class:`EpsilonSVR`; the learned tube half-width (relative
    to std(y)) is ``diagnostics_['epsilon']`` (QP). On noise-free data the tube shrinks to 0 and the
    fit is exact. The QP is libsvm's scaled primal ``min 1/2 |w|^2 + C (n nu eps + sum(xi + xi*))``
    so that C means the same in both
    solvers.

    Parameters
    ----------
    C : float
        Penalty on standardised data (libsvm's C).
    nu : float
        In (0, 1].
    solver, tol, fit_intercept : as :class:`EpsilonSVR`.
    """

    _kind = "nu"

    def __init__(self, C: float = 1.0, nu: float = 0.5, solver: str = "auto", tol: float = 1.0e-4,
                 fit_intercept: bool = True):
        self.C = C
        self.nu = nu
        self.solver = solver
        self.tol = tol
        self.fit_intercept = fit_intercept

    def fit(self, X, y):
        X, y, _ = check_regression(X, y)
        n, k = X.shape
        self._init_outputs(k)
        self._check_C()
        if not 0 < float(self.nu) <= 1:
            raise ValueError(f"nu must be in (0, 1], got {self.nu}")
        solver = self._solver(n)
        Z, ys, s, sy = _scale(X, y)
        extra = {"nu": float(self.nu)}
        if solver == "libsvm":
            from sklearn.svm import NuSVR as _NuSVR

            m = _NuSVR(kernel="linear", C=float(self.C), nu=float(self.nu), tol=float(self.tol)).fit(Z, ys)
            w, b = np.asarray(m.coef_, dtype=float).ravel(), float(np.ravel(m.intercept_)[0])
            extra["n_support"] = int(m.support_.size)
        else:
            w, b, eps, _ = _qp_svr(Z, ys, float(self.C), nu=float(self.nu), intercept=self.fit_intercept)
            extra["epsilon"] = float(eps)
            extra["n_support"] = int(np.sum(np.abs(ys - Z @ w - b) >= eps * (1 - 1e-6)))
        return self._finish(w, b, s, sy, solver, extra)
