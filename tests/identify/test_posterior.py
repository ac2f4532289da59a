"""emcee's posteriors as ArviZ InferenceData: every equation's chain joined into one posterior, ArviZ's r-hat and
ESS, a netCDF file that reads back, and the command that prints and writes them."""
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from study.identify.estimators.bayes import EmceeSampler
from study.identify.posterior import diagnostics, inference_data

REPO = Path(__file__).resolve().parents[2]


def _chain(seed, coef):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(300, len(coef)))
    y = X @ np.asarray(coef) + 0.1 * rng.normal(size=300)
    est = EmceeSampler(max_steps=4000, target_ess=300, seed=seed)
    est.fit(X, y)
    return est.artefacts_["chain.npz"], est


def test_two_equations_join_into_one_posterior_with_arviz_diagnostics(tmp_path):
    import arviz as az

    (cx, ex), (cy, ey) = _chain(0, [1.0, -0.5]), _chain(1, [2.0, 0.3, -1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        idata = inference_data({"X": cx, "Y": cy}, {"run_id": "r1"})
        table = diagnostics(idata)
    post = idata.posterior
    assert set(post.data_vars) == {"X.x0", "X.x1", "Y.x0", "Y.x1", "Y.x2"}
    assert post.sizes["chain"] == min(ex.diagnostics_["walkers"], ey.diagnostics_["walkers"])
    assert {"lp_X", "lp_Y"} <= set(idata.sample_stats.data_vars) and idata.attrs["run_id"] == "r1"
    # the joint posterior's medians are each equation's own estimates, and the ensemble has mixed
    assert float(post["Y.x2"].median()) == pytest.approx(ey.coef_[2], abs=3 * ey.coef_std_[2])
    assert (table["r_hat"] < 1.05).all() and (table["ess_bulk"] > 100).all()
    path = tmp_path / "post.nc"
    idata.to_netcdf(str(path))
    back = az.from_netcdf(str(path))
    assert np.array_equal(back.posterior["X.x1"].values, post["X.x1"].values)


@pytest.mark.slow
def test_the_command_prints_the_diagnostics_and_writes_the_file(tmp_path):
    table = REPO / "paper_figs" / "emcee_kt" / "table"
    run = sorted(p.name for p in (table / "artefacts").iterdir() if (p / "chain.npz").exists())[0]
    out = tmp_path / "post.nc"
    p = subprocess.run([sys.executable, "-m", "study", "results", "posterior", run, "--root", str(table), "--out",
                        str(out)], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "r_hat" in p.stdout and "ess_bulk" in p.stdout and out.is_file()
    bad = subprocess.run([sys.executable, "-m", "study", "results", "posterior", "0000000000000000", "--root",
                          str(table)], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert bad.returncode == 2 and bad.stderr.startswith("study results: error: 0000000000000000: no chain.npz")
