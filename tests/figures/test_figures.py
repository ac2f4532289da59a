"""CI runs the ``smoke`` study and rebuilds the figures from its table: every estimator on a regression
structure and on output error lands in the table (regression estimators skipped on output error, with the
reason); ``python -m study figures`` rebuilds the outputs twice, byte for byte the same, with CLAIMS.md and a
README listing each output. A rebuild from a table holding one study leaves every other study's outputs and rows
as they were. (A killed sweep resuming without recomputing: tests/commands/test_app.py.)"""
import filecmp
import json
import re
import shutil
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]


def _env(results):
    return dict(os.environ, STUDY_RESULTS_DIR=str(results), OPENBLAS_NUM_THREADS="1")


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    root = tmp_path_factory.mktemp("smoke")
    results = root / "results"
    p = subprocess.run([sys.executable, "-m", "study", "-m", "experiment=smoke", "hydra/launcher=local",
                        "progress=false"], cwd=root, env=_env(results), capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    return root, results, p


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_smoke_study_runs_everything(smoke):
    root, results, p = smoke
    runs = pd.read_parquet(results / "runs.parquet")
    assert (runs["cfg_study"] == "smoke").all()
    assert set(runs["status"]) <= {"ok", "skipped"}, runs.loc[runs.status == "failed", "error"].tolist()
    ok = runs[runs.status == "ok"]
    assert set(ok["cfg_estimator.name"]) == {"ls", "ridge", "lasso", "lssvm", "tlssvm", "lssvm_online", "svr_eps",
                                             "svr_nu", "sindy", "de", "emcee"}
    skipped = runs[runs.status == "skipped"]
    assert len(skipped) and skipped["error"].str.contains("output error").all()
    assert set(ok.loc[ok["cfg_structure.name"] == "output_error", "cfg_estimator.name"]) == {"de", "emcee"}
    assert "[study] job 66/66: " in p.stdout or p.stdout.count("/66: ") == 66  # the sweep shows its progress


@pytest.fixture(scope="module")
def figs(smoke, tmp_path_factory):
    """paper_figs/ built once from the smoke study's table (with its study table)."""
    root, results, _ = smoke
    out = tmp_path_factory.mktemp("figs") / "figs0"
    p = subprocess.run([sys.executable, "-m", "study", "figures", "--results", str(results), "--out", str(out)],
                       cwd=root, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "not fit for print" not in p.stderr, p.stderr[-3000:]  # study/figures/style.py's rules
    return out


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_figures_rebuild_byte_stable(smoke, figs, tmp_path):
    root, results, _ = smoke
    outs = [figs]
    out = tmp_path / "figs1"
    p = subprocess.run([sys.executable, "-m", "study", "figures", "--results", str(results), "--out", str(out)],
                       cwd=root, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    outs.append(out)
    files = sorted(str(f.relative_to(outs[0])) for f in outs[0].rglob("*") if f.is_file())
    files2 = sorted(str(f.relative_to(outs[1])) for f in outs[1].rglob("*") if f.is_file())
    assert files == files2
    _, mismatch, errors = filecmp.cmpfiles(outs[0], outs[1], files, shallow=False)
    assert not mismatch and not errors, mismatch + errors
    names = {Path(f).stem for f in files}
    for expected in ("fit_time", "lcurve", "online_convergence", "corner", "correlation_matrices", "condition_numbers",
                     "rmse_cc", "vif"):
        assert expected in names, (expected, sorted(names))
    assert any(n.startswith("drift_heatmap") for n in names) and any(n.startswith("validation_") for n in names)
    assert any(n.startswith("posterior_band") for n in names)
    for ext in (".png", ".pdf", ".csv", ".md"):
        assert any(f.endswith(ext) for f in files)
    readme = (outs[0] / "README.md").read_text()
    assert "smoke/fit_time.{png,pdf}" in readme
    assert "seed000_svr_mmg" in readme  # studies not run are listed as such
    assert (outs[0] / "CLAIMS.md").read_text().count("not run") >= 4


def test_figures_without_a_table_is_a_clear_error(tmp_path):
    p = subprocess.run([sys.executable, "-m", "study", "figures", "--results", str(tmp_path / "nothing"), "--out",
                        str(tmp_path / "figs")], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "no results table" in p.stderr


def _snapshot(root: Path) -> dict:
    return {str(f.relative_to(root)): f.read_bytes() for f in root.rglob("*") if f.is_file()}


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_rebuilding_one_study_leaves_every_other_study_untouched(smoke, tmp_path):
    """The committed paper_figs/ rebuilt from a table that holds only the smoke study: every file of every other
    study is byte-identical, their CLAIMS.md and README.md rows stay, the smoke study's stale files go."""
    _, results, _ = smoke
    out = tmp_path / "paper_figs"
    shutil.copytree(REPO / "paper_figs", out)
    (out / "smoke" / "stale_figure.png").write_bytes(b"not written by this rebuild")
    before = _snapshot(out)
    others = {k: v for k, v in before.items() if "/" in k and not k.startswith("smoke/")}
    assert len({k.split("/")[0] for k in others}) >= 6  # the seed studies, emcee_kt, grand, the doctor
    p = subprocess.run([sys.executable, "-m", "study", "figures", "--results", str(results), "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    after = _snapshot(out)
    assert {k: after.get(k) for k in others} == others
    assert "smoke/stale_figure.png" not in after and "smoke/fit_time.png" in after
    idx = json.loads(after["smoke/index.json"])
    assert idx["study"] == "smoke" and idx["runs"] > 0 and idx["claims"] == []
    assert after["CLAIMS.md"] == before["CLAIMS.md"]  # smoke makes no claim: every row stays as it was
    readme_before = [ln for ln in before["README.md"].decode().splitlines() if ln.startswith("| `")
                     and "| smoke" not in ln]
    readme_after = after["README.md"].decode().splitlines()
    assert all(ln in readme_after for ln in readme_before)
    claims = after["CLAIMS.md"].decode()
    # every study with a committed table keeps its claim rows (a study not yet run says "not run")
    assert not [d.parent.name for d in out.glob("*/table") if f"`{d.parent.name}` | not run" in claims]


def test_a_study_module_without_name_and_build_is_refused(tmp_path, monkeypatch):
    import importlib

    from study.figures.studies import discover

    pkg = tmp_path / "fake_studies"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "half_written.py").write_text("x = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ImportError, match="half_written.py: a study module needs NAME = 'half_written'"):
        discover(importlib.import_module("fake_studies"))


def test_every_study_module_has_its_experiment_and_every_experiment_with_a_study_its_module():
    from study.configuration.compose import simulated_studies
    from study.figures.studies import discover

    found = discover()
    conf = REPO / "conf" / "experiment"
    # each experiment's study (a study may be swept in parts: emcee_calibration and emcee_calibration_stress)
    named = {m.group(1) for f in conf.glob("*.yaml")
             if (m := re.search(r"^study: (\w+)", f.read_text(), re.M))}
    assert set(found) == named, (sorted(found), sorted(named))
    assert simulated_studies() == named  # the names a run on files may not join (study.run.records_run)


def _discovered_studies() -> list:
    from study.figures.studies import discover

    return sorted(discover())


@pytest.mark.parametrize("name", _discovered_studies())
def test_every_study_follows_the_contract(name):
    """Each discovered study (study/figures/studies/<name>.py) as tests/identify/test_estimators.py checks each estimator:
    its module names itself, says which seed paper's claim it tests (or None), builds through the builder with the
    table's runs and parameters and appends its claims; its experiment (conf/experiment/<name>.yaml) runs it as a
    sweep under its name. (Its figures rebuilt from a table: the tests above, on smoke and the committed tables.)"""
    import inspect

    from study.configuration.compose import read_config
    from study.figures.studies import discover

    mod = discover()[name]
    assert mod.NAME == name == mod.__name__.rpartition(".")[2]
    assert mod.SEED is None or (isinstance(mod.SEED, str) and mod.SEED.isdigit() and len(mod.SEED) == 3)
    assert (mod.__doc__ or "").strip(), "a study says what it shows and which claim it tests"
    params = list(inspect.signature(mod.build).parameters)
    assert len(params) >= 4 and params[1:4] == ["runs", "params", "claims"], params
    exp = read_config("experiment", name)
    assert exp.get("study") == name
    assert ((exp.get("hydra") or {}).get("sweeper") or {}).get("params"), "a study is a sweep of its axes"


def _from_committed_tables(out: Path, tmp_path: Path) -> str:
    """`python -m study figures --out OUT` as on a fresh clone: no results folder, no STUDY_RESULTS_DIR."""
    empty = tmp_path / "cwd"
    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "STUDY_RESULTS_DIR"}
    p = subprocess.run([sys.executable, "-m", "study", "figures", "--out", str(out)], cwd=empty, env=env,
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "not fit for print" not in p.stderr, p.stderr[-3000:]  # study/figures/style.py's rules
    return p.stdout


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_a_study_rebuilds_byte_identically_from_its_own_committed_table(smoke, figs, tmp_path):
    """Each rebuilt study keeps its table (finished runs, parameters, the artefacts its figures read) in
    <out>/<study>/table/; with no results folder, `python -m study figures` rebuilds from those tables alone, to
    the same bytes (a fresh clone can rebuild paper_figs/ without re-running any study)."""
    _, results, _ = smoke
    a = figs
    table = a / "smoke" / "table"
    assert (table / "runs.parquet").is_file() and (table / "params.parquet").is_file()
    arts = [f for f in (table / "artefacts").rglob("*") if f.is_file()]
    assert arts and len(arts) < len([f for f in (results / "artefacts").rglob("*") if f.is_file()])
    b = tmp_path / "b"
    shutil.copytree(a, b)
    for f in b.rglob("*.png"):
        f.unlink()  # the rebuild must make them again
    assert "rebuilding from the study tables committed" in _from_committed_tables(b, tmp_path)
    assert _snapshot(a) == _snapshot(b)


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_the_committed_paper_figs_rebuild_from_their_tables_to_the_same_bytes(tmp_path):
    """What a fresh clone does: `python -m study figures` with no results folder rebuilds every study whose table
    is committed, and every file of paper_figs/ comes out as committed (git status stays clean)."""
    out = tmp_path / "paper_figs"
    shutil.copytree(REPO / "paper_figs", out)
    tables = sorted(p.parent.parent.name for p in out.glob("*/table/runs.parquet"))
    assert tables, "no study table is committed"
    before = _snapshot(out)
    _from_committed_tables(out, tmp_path)
    after = _snapshot(out)
    assert sorted(after) == sorted(before)
    changed = sorted(k for k in before if before[k] != after[k])
    assert not changed, changed


def test_an_unknown_study_is_refused_before_anything_is_written(tmp_path):
    out = tmp_path / "figs"
    r = subprocess.run([sys.executable, "-m", "study", "figures", "--study", "nope", "--out", str(out)],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 2 and "--study nope: no such study" in r.stderr and not out.exists()


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_figures_say_which_artefacts_they_lack_when_runs_arrive_without_their_files(smoke, tmp_path):
    """Records moved without their artefacts (``results export --no-artefacts``) still build; the figures that
    read one of those files say so, naming the run and the file."""
    _, results, _ = smoke
    cli = [sys.executable, "-m", "study"]
    for args in (["results", "export", "--root", str(results), "--no-artefacts", str(tmp_path / "r.tar.xz")],
                 ["results", "import", "--root", str(tmp_path / "bare"), str(tmp_path / "r.tar.xz")]):
        p = subprocess.run(cli + args, cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, p.stderr[-2000:]
    p = subprocess.run(cli + ["figures", "--results", str(tmp_path / "bare"), "--out", str(tmp_path / "figs")],
                       cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    warned = [ln for ln in p.stderr.splitlines() if "artefact(s) its figures read are listed by their runs" in ln]
    assert len(warned) == 1 and warned[0].startswith("study figures: warning: smoke: "), p.stderr[-2000:]
    assert re.search(r"[0-9a-f]{16}/validation/\S+\.csv", warned[0])
