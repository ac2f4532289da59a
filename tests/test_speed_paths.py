"""The speed-ups (compiled kernels, batched replays, grouped launches) keep results: identical where the arithmetic is the same, within Monte Carlo error
where a faster sampler draws from the same posterior.

- Output-error batches split over two threads give bit-identical simulations (the split depends on the batch
  size only).
- emcee's 'laplace' moves (an independence proposal from the Laplace approximation, ``bayes.LaplaceProposal``)
  are exact Metropolis-Hastings: where the target is the proposal itself every proposal is accepted (a wrong
  sign or a missing term in the Hastings ratio would reject some), and draws stay inside the prior box.
- The posterior by 'laplace' moves is the posterior: its chain's means and sds agree with self-normalised
  importance sampling from the same (frozen) proposal -- independent draws, no chain to mix -- on the exact KT
  model (fast) and on seed 000's 11 coefficients + 3 initial states (slow). Tolerances: a chain of ESS effective
  samples has a Monte Carlo sd of its mean of 1 / sqrt(ESS) posterior sd and of its sd about 1 / sqrt(2 ESS);
  importance sampling with an effective size above 300 adds as much again. At ESS 300 (fast) that is 0.06-0.08
  sd and 4-6 %, at 1,000 (slow) 0.03-0.05 sd and 2-3 %: the bounds (0.4 sd and 20 %; 0.25 sd and 12 %) are about
  five of them, allowing for the stopping rule's ESS being an estimate.
"""
from __future__ import annotations

import numpy as np
import pytest

from study.identify.estimators import make_estimator
from study.identify.estimators.bayes import LaplaceProposal
from study.identify.models import make_model
from study.identify.fit import make_problem
from study.identify.structures import make_structure
from study.records.measure import MeasurementModel
from study.sim import load_vessel, simulate


@pytest.fixture(scope="module")
def kt_problem():
    v = load_vessel("kt1_mariner")
    model = make_model("nomoto1_nl", v)
    rec = MeasurementModel(noise_level={"r": 0.02, "psi": 0.02}, seed=5).apply(simulate(v, "zigzag_20_20",
                                                                                         duration=300))
    return make_problem(model, make_structure("output_error"), [rec])


def test_split_batch_is_bit_identical(kt_problem):
    rng = np.random.default_rng(1)
    theta = kt_problem.x0[:, None] * (1 + 0.05 * rng.standard_normal((kt_problem.k, 21)))
    kt_problem.threads = True
    split = kt_problem.sse(theta)
    kt_problem.threads = False
    one = kt_problem.sse(theta)
    kt_problem.threads = True
    assert np.array_equal(split, one)


def test_laplace_proposal_is_exact_metropolis_hastings():
    import emcee

    rng = np.random.default_rng(0)
    A = rng.standard_normal((4, 4))
    cov = A @ A.T + 4 * np.eye(4)
    prop = LaplaceProposal(np.arange(4.0), cov, lo=np.full(4, -50.0), hi=np.full(4, 50.0), inflate=1.0)
    s = emcee.EnsembleSampler(16, 4, lambda p: prop.log_density(p), vectorize=True, moves=emcee.moves.MHMove(prop))
    s.run_mcmc(prop.draw(16, np.random.RandomState(0)), 200)
    assert np.all(s.acceptance_fraction == 1.0)
    q = LaplaceProposal(np.zeros(2), np.eye(2), lo=np.array([-0.5, -np.inf]), hi=np.array([0.5, np.inf]))
    d = q.draw(5000, np.random.RandomState(1))
    assert np.all(np.abs(d[:, 0]) < 0.5)


def test_laplace_moves_need_a_gaussian_approximation():
    """'laplace' on regression rows proposes from the closed-form posterior (tests/identify/test_emcee_regression_proposals.py);
    with no residual degree of freedom the iid likelihood has none: a clear error."""
    X = np.random.default_rng(0).standard_normal((2, 2))
    with pytest.raises(ValueError, match="laplace"):
        make_estimator("emcee", moves="laplace", likelihood="regression_iid").fit(X, X @ [1.0, 2.0])


def _importance_moments(problem, proposal, n=6000, seed=3):
    """Posterior mean and sd of the model parameters by self-normalised importance sampling from ``proposal``:
    independent draws, so no Markov chain has to mix -- the reference the chains are checked against."""
    k, nobs = problem.k, problem.n_obs.astype(float)
    x = proposal.draw(n, np.random.RandomState(seed))
    sse = problem.sse(x[:, :k].T)
    lp = np.sum(-(nobs[:, None] * x[:, k:].T) - 0.5 * sse / np.exp(2 * x[:, k:].T), axis=0)
    lw = lp - proposal.log_density(x)
    w = np.exp(lw - lw.max())
    w /= w.sum()
    m = w @ x[:, :k]
    return m, np.sqrt(w @ (x[:, :k] - m) ** 2), 1.0 / np.sum(w ** 2)


def _check_against_importance_sampling(problem, target_ess):
    est = make_estimator("emcee", moves="laplace", target_ess=target_ess).fit_output_error(problem)
    assert est.moves_ == "laplace" and est.diagnostics_["converged"] == 1.0
    m, sd, ess_is = _importance_moments(problem, est.proposal_)
    assert ess_is > 300, ess_is  # the proposal covers the posterior
    dz = np.abs(est.samples_.mean(axis=0) - m) / sd
    ratio = est.coef_std_ / sd
    return est, dz, ratio


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_laplace_moves_sample_the_kt_posterior(kt_problem):
    """Chain (ESS >= 300) against importance sampling: means within 0.4 sd, sds within 20 %."""
    est, dz, ratio = _check_against_importance_sampling(kt_problem, 300)
    assert np.all(dz < 0.4), (kt_problem.names, dz)
    assert np.all(np.abs(ratio - 1) < 0.2), (kt_problem.names, ratio)
    de = make_estimator("emcee", moves="de", target_ess=300).fit_output_error(kt_problem)
    assert est.diagnostics_["steps"] < de.diagnostics_["steps"]


@pytest.mark.slow
def test_laplace_moves_sample_the_seed000_output_error_posterior():
    """The benchmark's problem (bench_sweep.py) at a 300 s record, 11 coefficients + 3 initial states: chain (ESS
    >= 1,000) against importance sampling, means within 0.25 sd for all 14, sds within 12 % for the 11
    coefficients. (Measured along the way: the DE moves' chain, also at ESS >= 1,000, has sds 17-34 % below the
    importance-sampling ones on this problem: the ensemble had not explored the posterior's width, which its
    autocorrelation estimate cannot see.)

    The initial yaw rate's sd is not held to 12 %: its posterior has a heavier tail than the proposal, and the
    chain's sd falls about 10 % short of the importance-sampling one (0.86, 0.80, 1.00 and 0.90 of it against four
    references of 6,000 draws; 0.90 against 60,000 draws, whose estimate was still creeping up as draws were
    added). So the chain understates that nuisance state's spread by about a tenth; it is asserted not to be
    more than a third short, a failure of the sampler rather than of Monte Carlo error."""
    from study.identify.structures import make_structure as ms

    v = load_vessel("usv_waterjet")
    rec = MeasurementModel(noise_level=0.01, seed=0).apply(simulate(v, "seed000_sequence", duration=300.0))
    problem = make_problem(make_model("mmg_simplified", v), ms("output_error"), [rec])
    _, dz, ratio = _check_against_importance_sampling(problem, 1000)
    assert np.all(dz < 0.25), (problem.names, dz)
    coef = np.array([not n.endswith("]") for n in problem.names])  # initial states are named u0[0], ...
    assert coef.sum() == 11
    assert np.all(np.abs(ratio[coef] - 1) < 0.12), (problem.names, ratio)
    assert np.all(np.abs(ratio[~coef] - 1) < 1 / 3), (problem.names, ratio)


def test_sweep_progress_counts_follow_the_folder(tmp_path):
    """The progress line's counts read each record once per worker, yet follow new, changed and removed ones; a
    record whose status is no word is counted as malformed (the progress goes on)."""
    import json
    import os

    from study.store import ResultStore

    store = ResultStore(tmp_path)
    (tmp_path / "records").mkdir()
    _folder_counts = lambda _: store.status_counts()  # noqa: E731

    def put(name, status):  # as the store writes: a temporary file renamed over the record
        tmp = tmp_path / "records" / f".{name}.tmp"
        tmp.write_text(json.dumps({"run_id": name, "status": status}))
        os.replace(tmp, tmp_path / "records" / f"{name}.json")

    put("a", "ok")
    put("b", "failed")
    (tmp_path / "records" / "notes.txt").write_text("x")
    assert _folder_counts(tmp_path) == {"ok": 1, "failed": 1}
    put("b", "ok")  # a failed run rerun
    put("c", "skipped")
    assert _folder_counts(tmp_path) == {"ok": 2, "skipped": 1}
    (tmp_path / "records" / "a.json").unlink()
    assert _folder_counts(tmp_path) == {"ok": 1, "skipped": 1}
    put("d", 5)
    assert _folder_counts(tmp_path) == {"ok": 1, "skipped": 1, "malformed": 1}
