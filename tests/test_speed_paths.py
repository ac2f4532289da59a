"""The speed-ups of issue 13 keep results: identical where the arithmetic is the same, within Monte Carlo error
where a faster sampler draws from the same posterior.

- Output-error batches split over two threads give bit-identical simulations (the split depends on the batch
  size only).
- emcee's 'laplace' moves (an independence proposal from the Laplace approximation, ``bayes.LaplaceProposal``)
  are exact Metropolis-Hastings: where the target is the proposal itself every proposal is accepted (a wrong
  sign or a missing term in the Hastings ratio would reject some), and draws stay inside the prior box.
- The posterior by 'laplace' moves agrees with the one by today's DE moves on an output-error problem: medians
  within 0.5 posterior sd and sds within 25 % on the exact KT model (fast), and on seed 000's 11 coefficients +
  3 initial states (slow). Tolerances: each chain has >= 1,000 effective samples (300 for the fast test), so the
  Monte Carlo sd of a median is about 1.25 / sqrt(ESS) posterior sd (0.04; 0.07) and of an sd 1 / sqrt(2 ESS)
  (2 %; 4 %); the difference of two chains is sqrt(2) larger: the bounds are about 5 such sds at ESS 300 and
  more at 1,000, allowing for the stopping rule's ESS being an estimate (short chains underestimate tau).
"""
from __future__ import annotations

import numpy as np
import pytest

from study.identify.estimators import make_estimator
from study.identify.estimators.bayes import LaplaceProposal
from study.identify.models import make_model
from study.identify.output_error import make_problem
from study.identify.structures import make_structure
from study.measure import MeasurementModel
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


def test_laplace_moves_need_the_output_error_likelihood():
    X = np.random.default_rng(0).standard_normal((100, 2))
    with pytest.raises(ValueError, match="laplace"):
        make_estimator("emcee", moves="laplace").fit(X, X @ [1.0, 2.0])


def _compare(problem, target_ess):
    fits = {m: make_estimator("emcee", moves=m, target_ess=target_ess).fit_output_error(problem)
            for m in ("de", "laplace")}
    de, lp = fits["de"], fits["laplace"]
    assert lp.moves_ == "laplace" and de.moves_ == "de"
    assert lp.diagnostics_["ess"] >= target_ess and lp.diagnostics_["converged"] == 1.0
    dz = np.abs(lp.coef_ - de.coef_) / de.coef_std_
    ratio = lp.coef_std_ / de.coef_std_
    return dz, ratio, fits


def test_laplace_and_de_moves_agree_on_a_kt_posterior(kt_problem):
    dz, ratio, fits = _compare(kt_problem, 300)
    assert np.all(dz < 0.5), (kt_problem.names, dz)
    assert np.all(np.abs(ratio - 1) < 0.25), (kt_problem.names, ratio)
    assert fits["laplace"].diagnostics_["steps"] < fits["de"].diagnostics_["steps"]


@pytest.mark.slow
def test_laplace_and_de_moves_agree_on_seed000_output_error():
    """The benchmark's problem (bench_sweep.py) at a 300 s record: 11 coefficients + 3 initial states."""
    from study.identify.structures import make_structure as ms

    v = load_vessel("usv_waterjet")
    rec = MeasurementModel(noise_level=0.01, seed=0).apply(simulate(v, "seed000_sequence", duration=300.0))
    problem = make_problem(make_model("mmg_simplified", v), ms("output_error"), [rec])
    dz, ratio, _ = _compare(problem, 1000)
    assert np.all(dz < 0.5), (problem.names, dz)
    assert np.all(np.abs(ratio - 1) < 0.25), (problem.names, ratio)


def test_sweep_progress_counts_follow_the_folder(tmp_path):
    """The progress line's counts read each record once per worker, yet follow new, changed and removed ones."""
    import json
    import os

    from study.app import _folder_counts

    def put(name, status):  # as the store writes: a temporary file renamed over the record
        tmp = tmp_path / f".{name}.tmp"
        tmp.write_text(json.dumps({"run_id": name, "status": status}))
        os.replace(tmp, tmp_path / f"{name}.json")

    put("a", "ok")
    put("b", "failed")
    (tmp_path / "notes.txt").write_text("x")
    assert _folder_counts(tmp_path) == {"ok": 1, "failed": 1}
    put("b", "ok")  # a failed run rerun
    put("c", "skipped")
    assert _folder_counts(tmp_path) == {"ok": 2, "skipped": 1}
    (tmp_path / "a.json").unlink()
    assert _folder_counts(tmp_path) == {"ok": 1, "skipped": 1}
