"""Can a run's own residual tell that its model lacks a term? emcee's regression likelihood on central rows of
KVLCC2's MMG hull and the waterjet USV's full model (the ``emcee_calibration_stress`` set-up: 1 % white noise,
0.005 L/U0), exact and with N'vvr left out, over datasets 1-10. Per equation it prints the largest error of a
coefficient in posterior sd (``z``, against the vessel's values), the whitened residual's lag-1 autocorrelation
(what ``study.identify.trust`` checks), the coefficients' heterogeneity over four groups of rows by where they lie in the records'
range (``H``, chi-square per degree of freedom, and its upper tail: ``study.identify.trust.heterogeneity`` on
``range_key``, also checked)
and the omitted-terms test (``W``, the Wald statistic per degree of freedom of the states' monomials up to degree 3
the model leaves out, its upper tail and the term that alone explains most: ``study.identify.trust.omitted_terms``,
also checked).

Run from the repository's root: ``python scripts/probe_missing_term.py [case] [structure]`` (defaults kvlcc2_mmg,
central); about 2 min per model and omission on one core.
"""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the repository's hydra_plugins (the covering sweeper the experiments name)

import numpy as np  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402
from omegaconf import OmegaConf  # noqa: E402

from study.identify.estimators import make_estimator  # noqa: E402
from study.identify.estimators.prior import gls_posterior  # noqa: E402
from study.identify.fit import _neighbours  # noqa: E402
from study.identify.rows import prepare, regression_rows, row_errors, truncation_rows  # noqa: E402
from study.identify.trust import heterogeneity, omitted_terms, range_key  # noqa: E402
from study.run.pipeline import SimulatedJob  # noqa: E402


def compose_run(case: str, omit: str, structure: str) -> dict:
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=emcee_calibration_stress", f"case={case}",
                      "noise=low_relative", "noise.sample_dt_LU=0.005", f"model.omit={omit}",
                      f"structure={structure}"])
    return OmegaConf.to_container(cfg, resolve=True)


def probe(case: str, omit: str, structure: str, datasets) -> None:
    job = SimulatedJob(compose_run(case, omit, structure))
    job.prepare()
    est = make_estimator(job.est_cfg)
    truth = job.model.truth()[0]
    for s in datasets:
        records, _ = job.dataset(s)
        prep = prepare(job.model, job.structure, records, seed=s, operators=True,
                       rows=regression_rows(job.model, job.structure, records))
        errs = row_errors(job.model, job.structure, records, prep,
                          truncation_rows(job.model, job.structure, records), seed=s, n_probes=est.n_probes)
        near = _neighbours(job.model, job.structure, records, prep, seed=s)
        out = []
        for eq, pr in prep.items():
            X, y = pr.X.to_numpy(float), np.asarray(pr.y, float)
            k = X.shape[1]
            mean, cov, diag, noise = gls_posterior(X, y, pr.noise_operators, np.zeros(k),
                                                   est._default_prior_sd(X, y), errors=errs.get(eq))
            t = np.array([truth.get(n, np.nan) for n in pr.X.columns])
            z = np.nanmax(np.abs(mean - t) / np.sqrt(np.diag(cov)))
            Xc, yc = errs[eq].corrected(X, y) if errs.get(eq) is not None else (X, y)
            if pr.noise_operators.centred:
                Xc = np.column_stack([Xc, np.ones(len(yc))])
            yh = Xc[:, :k] @ mean
            H, tail = heterogeneity(noise.whiten(Xc), noise.whiten(yc), range_key(yh, noise.b + 1))
            W, w_tail, top = omitted_terms(noise.whiten(Xc), noise.whiten(near[eq].to_numpy(float)), noise.whiten(yc),
                                           list(near[eq].columns))
            out.append(f"{eq}: z={z:5.1f} acf1={diag['whitened_acf1']:+.2f} H={H:5.2f} (p {tail:.0e}) "
                       f"W={W:5.2f} (p {w_tail:.0e}, {top})")
        print(f"{case} {structure} omit={omit} dataset {s}: " + " | ".join(out), flush=True)


if __name__ == "__main__":
    case = sys.argv[1] if len(sys.argv) > 1 else "kvlcc2_mmg"
    structure = sys.argv[2] if len(sys.argv) > 2 else "central"
    for omit in ("[]", "[Nvvr]"):
        probe(case, omit, structure, range(1, 11))
