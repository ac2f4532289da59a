"""Posterior sampling with emcee (Foreman-Mackey et al. 2013, PASP 125, 306), the affine-invariant
ensemble sampler (Goodman & Weare 2010), every step's whole ensemble evaluated in one vectorised
call.

Likelihoods (``likelihood``; output error whenever the structure simulates): **regression**
(default), the sandwich posterior (Mueller 2013) of the rows whitened for the noise the sample
structure makes (``study.identify.row_noise``), the structure's truncation and the regressors' noise
removed first (``correct_rows``, ``study.identify.row_errors``); **regression_iid**, independent
rows (right for white residuals only); **output error**, a noise scale per output channel. Priors,
run length, moves and defaults, with their sources:
``docs/concepts/emcee.md``.
"""
from __future__ import annotations

import io
import math

import emcee
import numpy as np
from scipy import linalg

from ..row_errors import N_PROBES
from ..trust import heterogeneity, omitted_terms, range_key
from .base import Estimator, as_arrays


class EmceeSampler(Estimator):
    """emcee ensemble sampler on the regression or output-error likelihood (see the module
    docstring).

    Parameters
    ----------
    n_walkers : int or None
        None: max(32, 2 x dimension), even.
    target_ess : int
        Effective samples wanted (of the slowest-mixing parameter).
    max_steps, check_every, min_steps : int
        Step budget, the chunk after which the stopping rule is checked, and a floor (emcee's
        estimate of tau is biased low on short chains). ``check_every``, ``min_steps`` None (the
        default): :attr:`RUN_LENGTH`.
    prior_scale : float
        Width of the regression coefficients' default prior N(0, (prior_scale sd(y) / rms(X_j))^2).
    interval : float
        Central credible interval reported (0.9: 5 % and 95 % quantiles).
    seed : int
    max_saved : int
        Draws kept in ``samples_`` and in the saved chain at most (thinned evenly).
    min_tau_multiple : float
        The chain must be longer than this many autocorrelation times (emcee's guidance: 50).
    moves : str
        'de' (DEMove 0.8, :class:`SnookerMove` 0.2; ter Braak & Vrugt 2008), 'stretch' (Goodman &
        Weare 2010, emcee's default), 'laplace' (an independence proposal most of the steps, the DE
        moves the rest) or 'auto' ('laplace' where a Gaussian approximation of the posterior exists,
        else 'de').
    init : str
        Output error: 'local' (a Gauss-Newton fit from the problem's initial estimate), 'de'
        (differential evolution over the box first: a KT model's likelihood has distant local
        optima) or 'auto' (DE for up to 10 parameters, else local).
    prior : dict or None
        ``{source, sd, offset}``: an informative prior (``study.identify.priors``), resolved for
        :meth:`fit`.
    likelihood : str
        Regression structures: 'regression' (the rows' noise modelled with the structure's
        operators; default) or 'regression_iid' (independent rows). Output error ignores it.
    correct_rows : bool
        'regression' likelihood: remove the structure's truncation and the regressors' noise from
        the rows first, estimated from the run's own records (``study.identify.row_errors``, passed
        by ``study.identify.fit``).
    n_probes : int
        Noisy copies of the records the regressors' noise is measured with
        (``row_errors.N_PROBES``).
    """

    problem_types = frozenset({"regression", "output_error"})
    accepts_prior = True
    models_row_noise = True
    checks_omitted_terms = True
    reports_progress = True

    def __init__(self, n_walkers: int | None = None, target_ess: int = 1000, max_steps: int = 20000,
                 check_every: int | None = None, min_steps: int | None = None, prior_scale: float = 10.0,
                 interval: float = 0.9, seed: int = 0, max_saved: int = 20000, min_tau_multiple: float = 50.0,
                 moves: str = "auto", init: str = "auto", prior: dict | None = None, likelihood: str = "regression",
                 correct_rows: bool = True, n_probes: int = N_PROBES):
        self.likelihood = likelihood
        self.correct_rows = correct_rows
        self.n_probes = n_probes
        self.prior = prior  # {source, sd, offset}: an informative prior (study.identify.priors), see fit
        self.n_walkers = n_walkers
        self.target_ess = target_ess
        self.max_steps = max_steps
        self.check_every = check_every
        self.min_steps = min_steps
        self.prior_scale = prior_scale
        self.interval = interval
        self.seed = seed
        self.max_saved = max_saved
        self.min_tau_multiple = min_tau_multiple
        self.moves = moves
        self.init = init

    # ----------------------------------------------------------------------------------------- sampling
    def _walkers(self, ndim: int) -> int:
        w = self.n_walkers or max(32, 2 * ndim)
        return int(w + w % 2)

    #: (min_steps, check_every) when None: chains that mix over tens of steps, chains drawing from a closed form
    RUN_LENGTH = {"mixing": (500, 250), "closed_form": (200, 50)}
    #: the share of DE moves next to an independence proposal: the output error's adapted one, the closed form
    DE_SHARE = {"adapted": 0.2, "closed_form": 0.1}

    def _run_length(self, closed_form: bool) -> tuple[int, int]:
        """(min_steps, check_every): the parameters as given, or the defaults of
        :attr:`RUN_LENGTH` when None."""
        dflt = self.RUN_LENGTH["closed_form" if closed_form else "mixing"]
        return (int(dflt[0] if self.min_steps is None else self.min_steps),
                int(dflt[1] if self.check_every is None else self.check_every))

    def _sample(self, log_prob, p0: np.ndarray, names: list, progress: bool, laplace=None, adapt: bool = True):
        """Run the chain to the stopping rule or the step budget; keep its draws, diagnostics and
        saved chain. ``laplace``: the independence proposal of ``moves`` 'laplace'/'auto', a
        :class:`LaplaceProposal` refitted to the draws (output error, ``adapt``) or the posterior
        in closed form (regression, fixed). One function: the moves, the chunked run with its
        refits and stopping rule, and the summary share the run's state."""
        nw, ndim = p0.shape
        rng = np.random.default_rng(self.seed)
        kind = self.moves
        if kind == "auto":
            kind = "laplace" if laplace is not None else "de"
        closed_form = kind == "laplace" and not adapt
        min_steps, check_every = self._run_length(closed_form)
        if kind == "de":
            moves = [(emcee.moves.DEMove(), 0.8), (SnookerMove(), 0.2)]
        elif kind == "stretch":
            moves = None
        elif kind == "laplace":
            if laplace is None:
                raise ValueError("emcee: moves 'laplace' needs a Gaussian approximation of the posterior (output "
                                 "error: a nonsingular Gauss-Newton information at the fit); use moves 'de'")
            de = self.DE_SHARE["closed_form" if closed_form else "adapted"]
            moves = [(emcee.moves.MHMove(laplace), 1.0 - de), (emcee.moves.DEMove(), 0.8 * de),
                     (SnookerMove(), 0.2 * de)]
        else:
            raise ValueError(f"emcee: moves must be 'auto', 'de', 'stretch' or 'laplace', got {self.moves!r}")
        sampler = emcee.EnsembleSampler(nw, ndim, log_prob, vectorize=True, moves=moves)
        sampler.random_state = np.random.RandomState(int(rng.integers(2 ** 31))).get_state()  # reproducible
        state = p0
        steps, tau, ess, converged = 0, np.full(ndim, np.nan), 0.0, False
        last_adapt = 0  # 'laplace': the step of the proposal's last refit (the burn-in is at least this long)
        # refits after a and 2a steps, a = check_every, within half the budget (else a short run is all burn-in)
        a = max(1, min(check_every, self.max_steps // 4))
        adapt_at = [a, 2 * a] if kind == "laplace" and adapt else []
        bar = None
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=self.max_steps, desc="emcee steps", leave=False)
        try:
            while steps < self.max_steps:
                pending = [t - steps for t in adapt_at if t > steps]
                n = min([check_every, self.max_steps - steps] + pending[:1])
                state = sampler.run_mcmc(state, n, progress=False)
                steps += n
                if steps in adapt_at:
                    # refit to the draws past half the chain and the last refit (they see the prior box and skew);
                    # the chain up to the last refit is burn-in: the kept chain has a fixed proposal
                    laplace.refit(sampler.get_chain(discard=max(steps // 2, last_adapt)).reshape(-1, ndim))
                    last_adapt = steps
                if bar is not None:
                    bar.update(n)
                if steps < min_steps or steps <= last_adapt:
                    continue
                chain = sampler.get_chain(discard=max(steps // 2, last_adapt))
                tau = emcee.autocorr.integrated_time(chain, quiet=True, tol=0)
                kept = chain.shape[0]
                ess = nw * kept / float(np.max(tau))
                if bar is not None:
                    bar.set_postfix(ess=f"{ess:.0f}", tau=f"{np.max(tau):.0f}")
                if ess >= self.target_ess and steps > self.min_tau_multiple * float(np.max(tau)):
                    converged = True
                    break
            if bar is not None:  # the bar ends full, saying why the chain stopped where it did
                bar.total = steps
                bar.set_postfix_str(f"{'converged' if converged else 'step budget spent'} at {steps} steps "
                                    f"(ess {ess:.0f} of {self.target_ess:g}, tau {np.max(tau):.0f})"
                                    if np.isfinite(ess) else f"stopped at {steps} steps")
                bar.refresh()
        finally:
            if bar is not None:
                bar.close()
        burn = max(steps // 2, last_adapt)
        chain = sampler.get_chain(discard=burn)  # (kept, nw, ndim)
        logp = sampler.get_log_prob(discard=burn)
        flat = chain.reshape(-1, ndim)
        thin = max(1, int(math.ceil(len(flat) / self.max_saved)))
        self.samples_all_ = flat[::thin]
        q = (0.5 - self.interval / 2, 0.5 + self.interval / 2)
        self.moves_ = kind
        self.proposal_ = laplace if kind == "laplace" else None  # the frozen proposal (an importance sampler too)
        self.diagnostics_ = {"acceptance": float(np.mean(sampler.acceptance_fraction)),
                             "tau_max": float(np.max(tau)), "ess": float(ess), "steps": int(steps),
                             "walkers": int(nw), "converged": float(converged)}
        tsave = max(1, int(math.ceil(chain.shape[0] * nw / self.max_saved)))
        buf = io.BytesIO()
        np.savez_compressed(buf, chain=chain[::tsave], log_prob=logp[::tsave], names=np.array(names),
                            tau=np.asarray(tau), burn=burn, thin=tsave, interval=self.interval)
        self.artefacts_ = {"chain.npz": buf.getvalue()}
        return flat, q

    def _summarise(self, flat: np.ndarray, q, k: int):
        th = flat[:, :k]
        self.coef_ = np.median(th, axis=0)
        self.coef_std_ = th.std(axis=0)
        self.coef_interval_ = np.quantile(th, q, axis=0).T
        self.interval_level_ = float(self.interval)
        self.samples_ = self.samples_all_[:, :k]

    # ------------------------------------------------------------------------------------ regression
    LIKELIHOODS = ("regression", "regression_iid")

    def skip(self, model, structure) -> tuple[bool, str]:
        """The iid regression likelihood asked of a structure that simulates is a sweep's cross
        product, not a run: output error has its own likelihood, so the run would repeat the
        default one under another id."""
        if structure.simulates and self.likelihood == "regression_iid":
            return True, (f"likelihood 'regression_iid' is a regression likelihood; structure '{structure.name}' "
                          "simulates the model (its likelihood is the output error's, run with the default)")
        if not self.correct_rows and (structure.simulates or self.likelihood != "regression"):
            return True, ("correct_rows false changes the 'regression' likelihood alone; with "
                          f"{'output error' if structure.simulates else repr(self.likelihood)} the run would repeat "
                          "the default's under another id")
        return super().skip(model, structure)

    @property
    def uses_noise_operators(self) -> bool:
        """Whether :meth:`fit` wants the structure's noise operators (``study.identify.fit``
        passes them)."""
        return self.likelihood == "regression"

    def trust_verdict(self, structure_name: str, bias_sd: dict, dropped_differences: int, corrected: bool,
                      metrics: dict) -> tuple[bool, str]:
        """(trusted, note) of a regression run's intervals
        (:func:`study.identify.trust.run_verdict`), from the run's own records: ``bias_sd`` the
        structure's truncation bias per reported parameter in posterior sd,
        ``dropped_differences`` differenced rows cut afterwards, ``corrected`` whether the rows'
        errors were removed, ``metrics`` the diagnostics every equation reported. An informative
        prior's posterior (the MAP estimator's) is judged as the regression likelihood's."""
        from ..trust import run_verdict

        likelihood = self.likelihood if getattr(self, "prior_sd_", None) is None else "regression"
        return run_verdict(likelihood, structure_name, bias_sd, dropped_differences, corrected, metrics)

    def _default_prior_sd(self, X, y) -> np.ndarray:
        sd_y = float(np.std(y)) or 1.0
        rms = np.sqrt(np.mean(X ** 2, axis=0))
        return self.prior_scale * sd_y / np.where(rms > 0, rms, 1.0)

    @property
    def uses_row_errors(self) -> bool:
        """The rows' truncation and regressors' noise are corrected
        (``study.identify.row_errors``)."""
        return self.likelihood == "regression" and bool(self.correct_rows)

    @property
    def row_error_probes(self) -> int | None:
        """``n_probes``: the noisy copies of the records the regressors' noise is measured with."""
        return self.n_probes

    def gaussian_regression(self, X, y, noise_operators=None, q_raw=None, prior_sd=None, errors=None):
        """(mean, covariance, diagnostics, noise model or None) of the coefficients' posterior
        under the 'regression' likelihood and the default prior: what :meth:`fit` samples, in
        closed form. ``q_raw``, ``prior_sd``: a noise mix and prior widths taken as given (the
        same likelihood on other rows, e.g. noise-free ones); ``errors``: the rows' errors to
        remove (``study.identify.row_errors.RowErrors``; with the operators only)."""
        from .prior import gaussian_posterior, gls_posterior

        X, y, _ = as_arrays(X, y)
        k = X.shape[1]
        if X.shape[0] < 2:
            raise ValueError(f"n_samples = {X.shape[0]}: emcee needs at least 2 samples")
        rank = np.linalg.matrix_rank(X)
        if rank < k:
            raise ValueError(f"emcee: the regressors are rank-deficient (rank {rank} of {k}); the posterior is "
                             "improper along the null space")
        sd0 = self._default_prior_sd(X, y) if prior_sd is None else np.asarray(prior_sd, float)
        failed = 0.0
        if noise_operators is not None:
            try:
                return gls_posterior(X, y, noise_operators, np.zeros(k), sd0, q_raw=q_raw, errors=errors)
            except (ValueError, linalg.LinAlgError):  # no usable noise mix: the rows as they are (recorded)
                failed = 1.0
        mean, cov, diag = gaussian_posterior(X, y, np.zeros(k), sd0, widen=False)
        return mean, cov, {"whitened": 0.0, "whitening_failed": failed, "sigma": diag["sigma"],
                           "data_blocks": diag["data_blocks"]}, None

    def fit(self, X, y, progress: bool = False, prior: dict | None = None, noise_operators=None, row_errors=None,
            neighbours=None):
        """Sample the posterior of ``y = X theta + e``. ``noise_operators``: the structure's, a
        ``study.identify.row_noise.RowOperators`` (``study.identify.fit`` passes it), used by the
        'regression' likelihood, with ``row_errors`` (``study.identify.row_errors.RowErrors``)
        removed when ``correct_rows``; ``prior``: an informative prior (then the MAP estimator's
        posterior is sampled, whatever the likelihood); ``neighbours``: terms the model lacks on
        the same rows, tested for the trust verdict (regression only)."""
        if self.likelihood not in self.LIKELIHOODS:
            raise ValueError(f"emcee: likelihood must be one of {self.LIKELIHOODS}, got {self.likelihood!r}")
        X, y, names = as_arrays(X, y)
        n, k = X.shape
        if n < 2:
            raise ValueError(f"n_samples = {n}: emcee needs at least 2 samples")
        self._init_outputs(k)
        # the fitted row-noise model (None: least squares on the rows as they are), kept for the trust verdict
        self.row_noise_ = None
        if prior is not None:
            return self._fit_informative(X, y, names, prior, progress)
        if self.likelihood == "regression":
            errors = row_errors if self.uses_row_errors else None
            mean, cov, diag, self.row_noise_ = self.gaussian_regression(X, y, noise_operators, errors=errors)
            self._sample_gaussian(mean, cov, names, progress)
            self.diagnostics_.update(diag)
            if self.row_noise_ is not None:  # for the trust verdict: do the coefficients hold over the records?
                Xc, yc = errors.corrected(X, y) if errors is not None else (X, y)
                fitted = Xc @ mean
                if noise_operators.centred:  # the centring's intercept, as gls_posterior fits it
                    Xc = np.column_stack([Xc, np.ones(len(yc))])
                w = self.row_noise_.whiten
                per_dof, tail = heterogeneity(w(Xc), w(yc), range_key(fitted, self.row_noise_.b + 1))
                self.diagnostics_.update(heterogeneity=per_dof, heterogeneity_p=tail)
                if neighbours is not None and len(neighbours) == len(yc):  # ... and does it lack a term?
                    names_z = list(getattr(neighbours, "columns", range(np.shape(neighbours)[1])))
                    per_dof, tail, top = omitted_terms(w(Xc), w(np.asarray(neighbours, float)), w(yc), names_z)
                    self.diagnostics_.update(omitted_terms=per_dof, omitted_terms_p=tail, omitted_terms_top=top)
            return self
        ls, _, rank, _ = linalg.lstsq(X, y, lapack_driver="gelsd")
        if rank < k:
            raise ValueError(f"emcee: the regressors are rank-deficient (rank {rank} of {k}); the posterior is "
                             "improper along the null space")
        A = X.T @ X
        ss_min = float(np.sum((y - X @ ls) ** 2))
        sd_y = float(np.std(y)) or 1.0
        prior_sd = self._default_prior_sd(X, y)
        lo_s, hi_s = math.log(1e-8 * sd_y), math.log(10.0 * sd_y)

        def log_prob(p):
            th, ls_ = p[:, :k], p[:, k]
            d = th - ls
            ss = ss_min + np.einsum("bi,ij,bj->b", d, A, d)
            sig2 = np.exp(2.0 * ls_)
            lp = -n * ls_ - 0.5 * ss / sig2 - 0.5 * np.sum((th / prior_sd) ** 2, axis=1)
            return np.where((ls_ > lo_s) & (ls_ < hi_s), lp, -np.inf)

        s_hat = math.sqrt(max(ss_min, 1e-300 * n) / max(n - k, 1))
        nw = self._walkers(k + 1)
        rng = np.random.default_rng(self.seed)
        proposal = None
        if self.moves in ("auto", "laplace") and n > k:
            proposal = IidRegressionProposal(ls, A, ss_min, n, lo_s, hi_s)
        if proposal is not None:  # start at equilibrium: draws from the flat-prior posterior
            p0 = proposal.draw(nw, np.random.RandomState(int(rng.integers(2 ** 31))))
        else:
            cov = s_hat ** 2 * np.linalg.pinv(A)
            # walkers drawn from the Laplace approximation (the exact posterior under a flat prior): no burn-in
            L = np.linalg.cholesky(cov + 1e-30 * np.eye(k) * np.max(np.abs(np.diag(cov))))
            p0 = np.column_stack([ls + rng.standard_normal((nw, k)) @ L.T,
                                  math.log(max(s_hat, math.exp(lo_s + 1))) + 0.01 * rng.standard_normal(nw)])
        flat, q = self._sample(log_prob, p0, names + ["log_sigma"], progress, laplace=proposal, adapt=False)
        self._summarise(flat, q, k)
        self.diagnostics_["sigma"] = float(np.exp(np.median(flat[:, k])))
        return self

    def _sample_gaussian(self, mean, cov, names, progress: bool):
        """emcee on N(mean, cov) in standardised coordinates, walkers drawn from it (no burn-in);
        under 'auto' or 'laplace' the main move proposes from N(mean, cov) itself (every such
        proposal accepted, up to rounding)."""
        k = len(mean)
        sd = np.sqrt(np.diag(cov))
        Pz = np.linalg.inv(cov / np.outer(sd, sd))  # precision of the standardised coefficients

        def log_prob(p):
            z = (p - mean) / sd
            return -0.5 * np.einsum("bi,ij,bj->b", z, Pz, z)

        nw = self._walkers(k)
        rng = np.random.default_rng(self.seed)
        p0 = mean + rng.standard_normal((nw, k)) @ np.linalg.cholesky(cov).T
        proposal = None
        if self.moves in ("auto", "laplace"):
            proposal = LaplaceProposal(mean, cov, df=math.inf, inflate=1.0)
        flat, q = self._sample(log_prob, p0, list(names), progress, laplace=proposal, adapt=False)
        self._summarise(flat, q, k)

    def _fit_informative(self, X, y, names, prior: dict, progress: bool):
        """The posterior under the informative prior N(mean0, sd0^2) per coefficient and the
        records' sandwich likelihood (the MAP estimator's model, module ``prior``): Gaussian, but
        sampled (:meth:`_sample_gaussian`) so that the draws feed the predictive bands and the
        chain diagnostics like any other run's."""
        from .prior import gaussian_posterior

        mean0 = np.array([prior[c][0] for c in names], float)
        sd0 = np.array([prior[c][1] for c in names], float)
        m_map, cov, diag = gaussian_posterior(X, y, mean0, sd0)
        self._sample_gaussian(m_map, cov, names, progress)
        self.diagnostics_.update({"rho": diag["rho"], "data_blocks": diag["data_blocks"],
                                  "prior_widening": diag["prior_widening"]})
        self.prior_mean_, self.prior_sd_ = mean0, sd0
        self.identifiability_ = np.std(self.samples_, axis=0) / (diag["prior_widening"] * sd0)
        return self

    # ---------------------------------------------------------------------------------- output error
    def fit_output_error(self, problem, progress: bool = False):
        """Sample the output-error posterior of ``problem`` (``study.identify.output_error``),
        the walkers started at the Laplace approximation at the fit (differential evolution first
        per ``init``)."""
        from ..output_error import DIVERGED, local_fit

        k, nc = problem.k, len(problem.outputs)
        self._init_outputs(k)
        lo, hi = problem.bounds[:, 0], problem.bounds[:, 1]
        start = problem.x0 if problem.x0 is not None else 0.5 * (lo + hi)
        if self.init not in ("auto", "de", "local"):
            raise ValueError(f"emcee: init must be 'auto', 'de' or 'local', got {self.init!r}")
        # DE over the box first for few parameters, or when the start diverges (no local fit can start there)
        if self.init == "de" or (self.init == "auto" and k <= 10) or problem.cost(start) >= DIVERGED:
            from scipy.optimize import differential_evolution

            de = differential_evolution(problem.cost, problem.bounds, popsize=15, maxiter=200, tol=1e-6,
                                        seed=self.seed, polish=False, vectorized=True, updating="deferred",
                                        init="sobol")
            start = de.x
        opt = local_fit(problem, start)
        S = problem.sse(opt.x[:, None])[:, 0]
        nobs = problem.n_obs.astype(float)
        sig0 = np.sqrt(np.maximum(S / nobs, 1e-300))
        slo, shi = np.log(1e-8 * problem.scale), np.log(10.0 * problem.scale)

        def log_prob(p):
            th, lsig = p[:, :k], p[:, k:]
            inside = np.all((th > lo) & (th < hi), axis=1) & np.all((lsig > slo) & (lsig < shi), axis=1)
            out = np.full(len(p), -np.inf)
            if inside.any():
                sse = problem.sse(th[inside].T)  # (nc, B)
                ll = -(nobs[:, None] * lsig[inside].T) - 0.5 * sse / np.exp(2.0 * lsig[inside].T)
                out[inside] = np.sum(ll, axis=0)
            return np.where(np.isfinite(out), out, -np.inf)

        nw = self._walkers(k + nc)
        rng = np.random.default_rng(self.seed)
        # start: draws from the Laplace approximation at the optimum (Gauss-Newton covariance times the noise
        # variance of the normalised residuals), clipped into the box; a small ball if it is singular
        n_res = problem.n_total * len(problem.outputs)  # residual entries: samples x channels
        var_n = opt.fun * problem.n_total / max(n_res - k, 1)  # their variance (cost = sum r^2 / n_total)
        span = hi - lo
        th0 = None
        if opt.cov is not None and np.all(np.isfinite(opt.cov)):
            try:
                L = np.linalg.cholesky(0.5 * (opt.cov + opt.cov.T) * var_n + 1e-300 * np.eye(k))
                th0 = opt.x + rng.standard_normal((nw, k)) @ L.T
            except np.linalg.LinAlgError:
                th0 = None
        if th0 is None:
            th0 = opt.x + 1e-4 * span * rng.standard_normal((nw, k))
        th0 = np.clip(th0, lo + 1e-9 * span, hi - 1e-9 * span)
        p0 = np.column_stack([th0, np.log(sig0) + 0.01 * rng.standard_normal((nw, nc))])
        laplace = None
        if self.moves in ("auto", "laplace"):
            laplace = _oe_laplace(problem, opt.x, nobs)
            if laplace is not None:  # start at equilibrium: draws from the approximation, inside the prior box
                laplace = LaplaceProposal(*laplace, lo=np.concatenate([lo, slo]), hi=np.concatenate([hi, shi]))
                p0 = laplace.draw(nw, np.random.RandomState(int(rng.integers(2 ** 31))))
        flat, q = self._sample(log_prob, p0, list(problem.names) + [f"log_sigma_{c}" for c in problem.outputs],
                               progress, laplace=laplace)
        self._summarise(flat, q, k)
        for i, c in enumerate(problem.outputs):
            self.diagnostics_[f"sigma_{c}"] = float(np.exp(np.median(flat[:, k + i])))
        self.diagnostics_["optimum_cost"] = float(opt.fun)
        return self


def _oe_laplace(problem, x0, nobs, max_iter: int = 10):
    """Laplace approximation (mean, covariance) of the output-error posterior at its mode, or
    None: the mode by reweighted Gauss-Newton (channel weights 1 / sigma_c^2, sigma_c^2 = SSE_c /
    n_c, until they settle), the parameters' covariance (J^T J)^-1 of the residuals normalised by
    sigma_c, log sigma_c N(log sigma_c, 1 / (2 n_c)) independent of them. Derivation:
    ``docs/concepts/emcee.md``."""
    from ..output_error import local_fit

    x = np.asarray(x0, float)
    sig = np.sqrt(np.maximum(problem.sse(x[:, None])[:, 0] / nobs, 1e-300))
    opt = None
    for _ in range(max_iter):
        opt = local_fit(problem, x, scale=sig)
        x = opt.x
        new = np.sqrt(np.maximum(problem.sse(x[:, None])[:, 0] / nobs, 1e-300))
        settled = np.max(np.abs(new / sig - 1.0)) < 1e-6
        sig = new
        if settled:
            break
    J = getattr(opt, "jac", None)
    if J is None or not np.all(np.isfinite(J)):
        return None
    try:
        cov_th = np.linalg.inv(J.T @ J)
        np.linalg.cholesky(cov_th)
    except np.linalg.LinAlgError:
        return None
    centre = x  # the mode in the box, not the unconstrained Gauss-Newton centre (a worse proposal where it binds)
    k, nc = problem.k, len(nobs)
    cov = np.zeros((k + nc, k + nc))
    cov[:k, :k] = 0.5 * (cov_th + cov_th.T)
    cov[k:, k:] = np.diag(1.0 / (2.0 * nobs))
    return np.concatenate([centre, np.log(sig)]), cov


class SnookerMove(emcee.moves.DESnookerMove):
    """The differential-evolution snooker move of ter Braak & Vrugt (2008, Stat. Comput. 18,
    435-446, Sec. 3.2): from a walker x and a random walker z of the other half of the ensemble, a
    step along the line through x and z by gamma times the difference of the projections of two more
    walkers z1, z2 on it, accepted with the extra factor (|x' - z| / |x - z|)^(d - 1). Written here
    because emcee's ``DESnookerMove`` (3.1.6) normalises by
    |x - z| where the formulas need |x - z|^2, so it does not leave the target invariant."""

    def get_proposal(self, s, c, random):
        randint = getattr(random, "integers", None) or random.randint
        ns, ndim = s.shape
        nc = list(map(len, c))
        q = np.empty((ns, ndim), dtype=np.float64)
        metropolis = np.empty(ns, dtype=np.float64)
        for i in range(ns):
            w = np.array([c[j][randint(nc[j])] for j in range(3)])
            random.shuffle(w)
            z, z1, z2 = w
            delta = s[i] - z
            norm2 = float(np.dot(delta, delta))  # emcee: np.linalg.norm(delta), i.e. |delta| (the bug)
            u = delta / np.sqrt(norm2)  # the unit vector along the line
            q[i] = s[i] + u * self.gammas * (np.dot(u, z1) - np.dot(u, z2))
            d = q[i] - z
            metropolis[i] = np.log(float(np.dot(d, d))) - np.log(norm2)
        return q, 0.5 * (ndim - 1.0) * metropolis  # (d - 1) log(|x' - z| / |x - z|)


class LaplaceProposal:
    """Independence proposal for emcee's ``MHMove``: a multivariate t with ``df`` degrees of
    freedom, location ``mean`` and scale matrix ``inflate^2 cov`` (the Laplace approximation),
    cut by the box [lo, hi]. Heavy tails and the inflation keep the ratio target / proposal
    bounded; the Metropolis-Hastings correction (emcee's ``factors``) keeps the chain exact.
    ``df=inf``: a normal (the regression posteriors in closed form). Written here because emcee
    ships no independence move."""

    def __init__(self, mean, cov, lo=None, hi=None, df: float = 5.0, inflate: float = 1.1):
        self.mean = np.asarray(mean, float)
        self.L = inflate * np.linalg.cholesky(np.asarray(cov, float))
        self.df = float(df)
        self.inflate = float(inflate)
        d = len(self.mean)
        self.lo = np.full(d, -np.inf) if lo is None else np.asarray(lo, float)
        self.hi = np.full(d, np.inf) if hi is None else np.asarray(hi, float)

    def log_density(self, x):
        """Log density up to a constant (it cancels in the Metropolis-Hastings ratio)."""
        y = linalg.solve_triangular(self.L, (np.atleast_2d(x) - self.mean).T, lower=True)
        r2 = np.sum(y * y, axis=0)
        if math.isinf(self.df):
            return -0.5 * r2
        return -0.5 * (self.df + len(self.mean)) * np.log1p(r2 / self.df)

    def refit(self, draws):
        """Location and scale from draws of the target (their mean and covariance), keeping df
        and the box."""
        cov = np.cov(np.asarray(draws, float).T)
        try:
            L = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            return
        self.mean = np.mean(draws, axis=0)
        self.L = self.inflate * L

    def _draw(self, n, random):
        z = random.randn(n, len(self.mean))
        if math.isinf(self.df):
            return self.mean + z @ self.L.T
        w = random.chisquare(self.df, n)
        return self.mean + (z @ self.L.T) / np.sqrt(w / self.df)[:, None]

    def __call__(self, coords, random):
        # cut by the prior box (redrawn outside it): the density q(x) / Z has one Z for every draw, so the ratio
        # q(x) / q(x') is unchanged; a draw still outside after 100 rounds is kept and rejected by the prior
        q = self.draw(len(coords), random)
        return q, self.log_density(coords) - self.log_density(q)

    def draw(self, n, random):
        """``n`` draws of the proposal cut by the box (``random``: a numpy RandomState)."""
        q = self._draw(n, random)
        for _ in range(100):
            out = ~np.all((q > self.lo) & (q < self.hi), axis=1)
            if not out.any():
                break
            q[out] = self._draw(int(out.sum()), random)
        return q


class IidRegressionProposal:
    """Independence proposal for the 'regression_iid' likelihood: its posterior under a flat
    prior on the coefficients and the Jeffreys prior on log sigma, drawn exactly
    (normal-inverse-gamma; Gelman et al. 2013, Bayesian Data Analysis, 3rd ed., Sec. 14.2): theta
    a multivariate t with n - k degrees of freedom, location the least-squares estimate and scale
    s^2 (X^T X)^-1, s^2 = SS_min / (n - k); then sigma^2 = SS(theta) / chi^2_n. Its log density
    is the target's likelihood, so nearly every proposal is accepted
    (``docs/concepts/emcee.md``); draws outside the box of log sigma are redrawn, as in
    :class:`LaplaceProposal`."""

    def __init__(self, ls, A, ss_min: float, n: int, lo_s: float, hi_s: float):
        self.ls, self.A = np.asarray(ls, float), np.asarray(A, float)
        self.ss_min, self.n = float(ss_min), int(n)
        k = len(self.ls)
        self.nu = self.n - k
        s2 = max(self.ss_min, 1e-300 * self.n) / self.nu
        self.L = np.linalg.cholesky(s2 * np.linalg.inv(self.A))
        self.lo_s, self.hi_s = float(lo_s), float(hi_s)

    def _ss(self, th):
        d = th - self.ls
        return self.ss_min + np.einsum("bi,ij,bj->b", d, self.A, d)  # as the target computes it

    def log_density(self, x):
        x = np.atleast_2d(x)
        k = len(self.ls)
        ls_ = x[:, k]
        return -self.n * ls_ - 0.5 * self._ss(x[:, :k]) / np.exp(2.0 * ls_)

    def _draw(self, n, random):
        k = len(self.ls)
        th = self.ls + (random.randn(n, k) @ self.L.T) / np.sqrt(random.chisquare(self.nu, n) / self.nu)[:, None]
        ls_ = 0.5 * np.log(self._ss(th) / random.chisquare(self.n, n))
        return np.column_stack([th, ls_])

    def draw(self, n, random):
        """``n`` draws inside the box of log sigma (``random``: a numpy RandomState)."""
        q = self._draw(n, random)
        for _ in range(100):
            out = ~((q[:, -1] > self.lo_s) & (q[:, -1] < self.hi_s))
            if not out.any():
                break
            q[out] = self._draw(int(out.sum()), random)
        return q

    def __call__(self, coords, random):
        q = self.draw(len(coords), random)
        return q, self.log_density(coords) - self.log_density(q)
