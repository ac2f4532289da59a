"""The Gaussian side of identification with effects: the anchor's prior on the model's
coefficients, the posterior of a fit's linear unknowns, and how far the records determine each
coefficient (the identifiability table of the doctor's report). Functions of an
:class:`~study.identify.with_effects.problem.EffectsProblem` (``pb``), which calls them from
``solve``, ``posterior`` and ``identifiability``."""
from __future__ import annotations

import math

import numpy as np

from .search import Fit


def noise_per_row(pb) -> float:
    """The training error's share of one independent row, from the unanchored baseline fit: its
    error over the EFFECTIVE number of rows per equation, m (1 - rho) / (1 + rho) with rho the
    lag-one autocorrelation of its residuals (smoothed rows of a manoeuvre are far from
    independent: rho is near 1, and counting every row would let any misfit overrule the prior)."""
    y, Phi, names = pb.rows((), {})
    coefs, J, _ = pb.solve((), {}, model=True, _unanchored=True)
    c = np.array([coefs.get(n, 0.0) for n in names])
    r = y - (np.einsum("mek,k->me", Phi, c) if len(names) else 0.0)
    rho = []
    for k in range(3):
        a = r[:, k] - r[:, k].mean()
        den = float(np.dot(a, a))
        if den > 0:
            rho.append(float(np.dot(a[1:], a[:-1])) / den)
    rho = float(np.clip(np.mean(rho), 0.0, 0.999)) if rho else 0.0
    pb.m_base = len(y)
    m_eff = max(1.0, len(y) * (1.0 - rho) / (1.0 + rho))
    return J / m_eff

def anchor_prior(pb, names: list, m: int):
    """(prior values, weights) of the unknowns ``names`` in the normal equations: the model's own
    free coefficients anchored to the vessel config's values (the coefficients the user has:
    published, captive tests, CFD) with a standard deviation of ``anchor`` (relative) times their
    size, at least ``anchor`` times the median size of the model's nonzero coefficients (a
    coefficient published as 0 is not known to be 0). The data term is the training error (1/3)
    sum_e rss_e/ref_e; for a Gaussian likelihood whose noise is the same fraction of each
    equation's scale, that fraction is the unanchored baseline's error over the effective number
    of independent rows (``noise_per_row``), so the prior enters as that fraction times sum_j
    ((theta_j - theta0_j)/s_j)^2 (scaled to the rows of the fit at hand). Coefficients an effect
    frees are anchored the same way when the config has a value for them (an effect says they may
    differ from it, within the prior); terms the model omits, and the effects' own unknowns, are
    not. Assumption labelled: independent priors, no correlation between coefficients."""
    anchored = [j for j, n in enumerate(names) if n in pb.model_eq or
                (n in pb.base.param_names and n not in pb.omit and pb.base_param(n) != 0.0)]
    if not anchored:
        return None
    if pb.tau is None:
        pb.tau = noise_per_row(pb)
    theta0 = np.zeros(len(names))
    lam = np.zeros(len(names))
    prior = np.array([pb.base_param(names[j]) for j in anchored])
    nz = np.abs(prior[prior != 0])
    floor = pb.anchor * (float(np.median(nz)) if len(nz) else 1.0)
    sd = np.maximum(pb.anchor * np.abs(prior), floor)
    theta0[anchored] = prior
    lam[anchored] = (pb.tau * pb.m_base / m) / sd ** 2
    return theta0, lam

def posterior(pb, fit: Fit) -> dict | None:
    """The Gaussian posterior of a fit's linear unknowns (free model coefficients and the
    effects' linear parameters) with the effects' nonlinear parameters held at their estimates:
    ``{'names', 'mean', 'cov', 'tau', 'prior'}``. The covariance is that of the normal equations
    ``solve`` uses (anchored when the problem is), with the data weight of ``noise_per_row`` (the
    effective number of independent rows); an unanchored fit gets the same data weight and no
    prior. None when nothing is free."""
    y, Phi, names = pb.rows(fit.effects, fit.outer, model=True)
    if not names:
        return None
    prior = anchor_prior(pb, names, len(y)) if pb.anchor else None
    if pb.tau is None:
        pb.tau = noise_per_row(pb)
    w2 = 1.0 / pb.reference()
    G = sum(w2[k] * (Phi[:, k, :].T @ Phi[:, k, :]) for k in range(3))
    tau = pb.tau * pb.m_base / len(y)  # the objective's scale of one unit of -2 log posterior
    A = (G + (np.diag(prior[1]) if prior is not None else 0.0)) / tau
    s = np.sqrt(np.diag(A))
    s[~(s > 0)] = 1.0
    cov = np.linalg.pinv(A / np.outer(s, s), hermitian=True) / np.outer(s, s)
    mean = np.array([float(fit.coefs.get(n, 0.0)) for n in names])
    return {"names": list(names), "mean": mean, "cov": cov, "tau": tau, "prior": prior}

#: a nonlinear parameter within this share of its box from a bound is on it (not identified: no curvature there)
ON_BOUND = 1e-3
#: the first difference that finds a nonlinear parameter's scale, as a share of its box; the curvature is then measured
#: over +-1 of its posterior sd (assumption: the profile error is close to quadratic over that range)
FIRST_STEP = 1e-3


def _profile(pb, fit: Fit, outer: dict) -> tuple:
    """(training error, linear unknowns) with the nonlinear parameters at ``outer`` and the linear
    unknowns solved there (variable projection's profile)."""
    coefs, J, _ = pb.solve(fit.effects, {**fit.outer, **outer})
    return J, coefs


def _outer_free(pb, fit: Fit) -> list:
    """(name, estimate, lo, hi) of the fit's continuous nonlinear parameters strictly inside their
    box."""
    out = []
    for name, lo, hi, *_ in pb.outer_params(fit.effects):
        x = fit.outer.get(name)
        if not isinstance(x, (int, float)) or not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            continue
        tol = ON_BOUND * (hi - lo)
        if lo + tol < x < hi - tol:
            out.append((name, float(x), float(lo), float(hi)))
    return out


def joint_posterior(pb, fit: Fit) -> dict | None:
    """The Gaussian (Laplace) posterior of a fit's linear unknowns together with its effects'
    continuous nonlinear parameters (a current's components, a wind's, a depth, a rudder's lag):
    ``posterior``'s keys plus ``outer`` (the nonlinear parameters' names, last in ``names``).

    The nonlinear parameters' covariance is that of the profile training error (the linear
    unknowns solved at each point, as the search does): its Hessian H by central differences
    over +-1 sd of each parameter, Sigma = (2 tau / 3) H^-1 on the same data weight as the linear
    posterior (-2 log p = 3 J / tau); a direction the error does not curve in gets the variance
    of a uniform draw over the box (it is not determined). The linear unknowns follow the
    nonlinear parameters along their conditional mean c*(o) (slope B by the same differences) and
    keep their conditional covariance: cov(c) = Sigma_c + B Sigma_o B^T. Parameters on a bound of
    their box and discrete variants are held at their estimates. None when nothing is free."""
    lin = posterior(pb, fit)
    free = _outer_free(pb, fit)
    if not free:
        return None if lin is None else {**lin, "outer": []}
    if pb.tau is None:
        pb.tau = noise_per_row(pb)
    y, _, _ = pb.rows(fit.effects, fit.outer, model=True)
    tau = pb.tau * pb.m_base / len(y)
    names_o = [f[0] for f in free]
    x0 = np.array([f[1] for f in free])
    box = np.array([f[3] - f[2] for f in free])
    room = np.array([min(f[1] - f[2], f[3] - f[1]) for f in free])
    lin_names = lin["names"] if lin is not None else []

    def at(dx):
        J, c = _profile(pb, fit, dict(zip(names_o, x0 + dx)))
        return J, np.array([c.get(n, 0.0) for n in lin_names])

    J0, _ = at(np.zeros(len(free)))
    d = len(free)

    def diag(h):
        Hd, B = np.zeros(d), np.zeros((len(lin_names), d))
        for i in range(d):
            e = np.zeros(d)
            e[i] = h[i]
            (jp, cp), (jm, cm) = at(e), at(-e)
            Hd[i] = (jp + jm - 2.0 * J0) / h[i] ** 2
            B[:, i] = (cp - cm) / (2.0 * h[i])
        return Hd, B

    h = np.minimum(FIRST_STEP * box, 0.9 * room)
    Hd, _ = diag(h)
    sd = np.where(Hd > 0, np.sqrt(2.0 * tau / (3.0 * np.where(Hd > 0, Hd, 1.0))), box / math.sqrt(12.0))
    h = np.clip(sd, 1e-6 * box, np.minimum(0.25 * box, 0.9 * room))
    Hd, B = diag(h)
    H = np.diag(Hd)
    for i in range(d):
        for j in range(i + 1, d):
            ei, ej = np.zeros(d), np.zeros(d)
            ei[i], ej[j] = h[i], h[j]
            f = [at(ei + ej)[0], at(ei - ej)[0], at(-ei + ej)[0], at(-ei - ej)[0]]
            H[i, j] = H[j, i] = (f[0] - f[1] - f[2] + f[3]) / (4.0 * h[i] * h[j])
    # in box units, each direction's precision floored at a uniform draw's over the box (variance 1/12)
    Hs = (3.0 / (2.0 * tau)) * H * np.outer(box, box)
    w, V = np.linalg.eigh(0.5 * (Hs + Hs.T))
    cov_o = (V / np.maximum(w, 12.0)) @ V.T * np.outer(box, box)
    mean = np.concatenate([lin["mean"], x0]) if lin is not None else x0
    if lin is not None:
        k = len(lin_names)
        cov = np.zeros((k + d, k + d))
        cov[:k, :k] = lin["cov"] + B @ cov_o @ B.T
        cov[:k, k:] = B @ cov_o
        cov[k:, :k] = cov[:k, k:].T
        cov[k:, k:] = cov_o
        prior = None if lin["prior"] is None else tuple(np.concatenate([a, np.zeros(d)]) for a in lin["prior"])
    else:
        cov, prior = cov_o, None
    return {"names": list(lin_names) + names_o, "mean": mean, "cov": cov, "tau": tau, "prior": prior,
            "outer": names_o}


def identifiability(pb, fit: Fit) -> list[dict]:
    """Per anchored model coefficient of a fit: prior, estimate, posterior and prior standard
    deviation and their ratio (near 0: the records determine it; near 1: the prior does), with a
    plain sentence. The posterior covariance is that of the anchored normal equations
    (``solve``): data weight as there, the effects' nonlinear parameters held at their estimates.
    Empty when the model is not anchored."""
    if not pb.anchor or not pb.model_free:
        return []
    post = posterior(pb, fit)
    if post is None or post["prior"] is None:
        return []
    names, cov, tau = post["names"], post["cov"], post["tau"]
    theta0, lam = post["prior"]
    out = []
    for j, n in enumerate(names):
        if not lam[j] > 0:
            continue
        sd0 = float(np.sqrt(tau / lam[j]))
        sd = float(np.sqrt(max(cov[j, j], 0.0)))
        ratio = sd / sd0
        est = float(fit.coefs.get(n, theta0[j]))
        moved = (est - theta0[j]) / sd0
        if ratio < 0.5:
            say = f"{n}: determined by the records (posterior sd {ratio:.2f} of the prior's)"
        elif ratio < 0.9:
            say = f"{n}: partly determined (posterior sd {ratio:.2f} of the prior's)"
        else:
            say = (f"{n}: NOT determined by these records (posterior sd {ratio:.2f} of the prior's): its value "
                   f"is the prior's, and a prediction that depends on it extrapolates")
        if abs(moved) > 2.0:
            say += (f"; moved {moved:+.1f} prior sd from the prior: the records and the prior disagree (a model "
                    f"error elsewhere can cause this)")
        out.append({"coefficient": n, "prior": float(theta0[j]), "estimate": est, "prior_sd": sd0,
                    "posterior_sd": sd, "ratio": ratio, "moved_prior_sd": float(moved), "sentence": say})
    return out
