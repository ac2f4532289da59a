"""The worked examples in notebooks/ run from top to bottom (nbclient, the notebook's own kernel), each within its
time limit, from the repository root as a user opens them. The doctor's notebook reads HSVA's records and skips,
with the reason, where the shared real-data folder is not found."""
from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((REPO / "notebooks").glob("*.ipynb"))
#: seconds a notebook may take (each is meant to run in well under a minute)
TIMEOUT = 120
#: notebooks that read the measured records
NEEDS_REAL_DATA = {"02_doctor_real_records.ipynb"}
#: notebooks over about 20 s, kept out of the default test run (python -m pytest -m slow tests/test_notebooks.py)
SLOW = {"02_doctor_real_records.ipynb"}


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 3, NOTEBOOKS


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.name in SLOW else p for p in NOTEBOOKS],
                         ids=lambda p: p.name)
@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_notebook_runs(path, monkeypatch):
    nbformat = pytest.importorskip("nbformat", reason="nbformat is not installed (pip install -e '.[test]')")
    nbclient = pytest.importorskip("nbclient", reason="nbclient is not installed (pip install -e '.[test]')")
    pytest.importorskip("ipykernel", reason="ipykernel is not installed (pip install -e '.[test]')")
    if path.name in NEEDS_REAL_DATA:
        from study.records.loaders import real_data_dir

        if not (real_data_dir() / "kvlcc2_hsva" / "raw_data").is_dir():
            pytest.skip("HSVA's records are not here: no shared/data/real beside the checkout (STUDY_REAL_DATA)")
    monkeypatch.setenv("PYTHONPATH", str(REPO))
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    nb = nbformat.read(path, as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "commit notebooks without outputs"
    client = nbclient.NotebookClient(nb, timeout=TIMEOUT, kernel_name="python3", resources={"metadata": {"path": str(REPO)}})
    client.execute()  # raises CellExecutionError, with the cell and its traceback, on any error
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.get("output_type") == "error"]
    assert not errors
    figures = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if "image/png" in o.get("data", {})]
    assert figures, f"{path.name} drew no figure"
