"""Figures for a sweep of one's own: runs that no named study claims get a generic comparison of what the sweep
varied, and the command says what it built."""
import pytest

from study.configuration.compose import compose
from study.run.executor import run_replicated
from study.run.pipeline import SimulatedJob
from study.store import ResultStore


@pytest.mark.slow
def test_a_sweep_of_ones_own_gets_figures_and_is_told_what_they_are(tmp_path, capsys):
    from study.figures import main

    store = ResultStore(tmp_path / "mine")
    for est in ("ls", "ridge"):
        conf = compose("config", ["experiment=tiny", "+artefacts.traces=false", f"estimator={est}"])
        conf.pop("replicates")
        run_replicated(store, conf, SimulatedJob(conf), 3, seed=0)
    store.collect()
    assert main(["--results", str(tmp_path / "mine"), "--out", str(tmp_path / "figs")]) == 0
    said = capsys.readouterr().out
    d = tmp_path / "figs" / "sweep_mine"
    for name in ("drift", "validation_zigzag_35_35", "fit_time"):
        assert (d / f"{name}.png").is_file() and (d / f"{name}.csv").is_file(), name
        assert f"sweep_mine/{name}:" in said
    drift = (d / "drift.csv").read_text()
    assert "ls" in drift and "ridge" in drift and ",3," in drift  # three datasets per cell
    assert "estimator.name" in (d / "varied.csv").read_text()
