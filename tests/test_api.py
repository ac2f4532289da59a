"""The public Python API (``import study``): the documented verbs are there, ``import study`` loads none of the
heavy dependencies, and every example in the verbs' docstrings runs as a doctest (``study/api.py``)."""
from __future__ import annotations

import doctest
import subprocess
import sys
from pathlib import Path

import pytest

import study
from study import api

REPO = Path(__file__).resolve().parents[1]


def test_the_package_offers_every_verb():
    for name in study.__all__:
        assert getattr(study, name) is getattr(api, name), name
    assert sorted(study.__all__) == sorted(api.__all__)
    from study import diagnose_records, identify_model, load_records, read_results, simulate_maneuver  # noqa: F401

    with pytest.raises(AttributeError):
        study.no_such_verb  # noqa: B018


def test_import_study_is_light():
    """The verbs import their modules when called: ``import study`` brings no numpy, pandas, numba or Hydra."""
    code = ("import sys, study; heavy = [m for m in ('numpy', 'pandas', 'numba', 'hydra', 'scipy') "
            "if m in sys.modules]; print(','.join(heavy))")
    p = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "", f"import study loaded {p.stdout.strip()}"


def _examples():
    finder = doctest.DocTestFinder()
    tests = [t for t in finder.find(api, "study.api") if t.examples]
    assert len(tests) >= 10, [t.name for t in tests]
    return tests


def _real_data() -> bool:
    from study.records.loaders import real_data_dir

    return (real_data_dir() / "kvlcc2_hsva" / "raw_data").is_dir()


#: the examples that run a whole diagnosis: the slow tier
SLOW_EXAMPLES = ("study.api.diagnose_records",)


@pytest.mark.parametrize("name", [pytest.param(t.name, marks=pytest.mark.slow) if t.name in SLOW_EXAMPLES else t.name
                                  for t in _examples()])
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    """Each verb's examples, run as doctests from an empty folder (the results store, if any, lands there)."""
    if name == "study.api.load_records" and not _real_data():
        pytest.skip("the example reads HSVA's records: no shared/data/real here (STUDY_REAL_DATA)")
    monkeypatch.chdir(tmp_path)
    test = next(t for t in _examples() if t.name == name)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test, out=lambda s: print(s, end=""))
    res = runner.summarize(verbose=False)
    assert res.failed == 0, f"{res.failed} of {res.attempted} examples of {name} failed (output above)"
    assert res.attempted > 0


def test_a_failing_example_fails():
    """The runner above reports a wrong expected output (the check can fail)."""
    parser = doctest.DocTestParser()
    test = parser.get_doctest(">>> 1 + 1\n3\n", {}, "wrong", "wrong.py", 0)
    runner = doctest.DocTestRunner()
    runner.run(test, out=lambda s: None)
    assert runner.summarize(verbose=False).failed == 1


def test_identify_model_refuses_a_combination_that_cannot_run():
    rec = study.simulate_maneuver("kt1_mariner", "zigzag_10_10", duration=100.0)
    with pytest.raises(ValueError, match="output_error"):
        study.identify_model([rec], "kt1_mariner", model="nomoto1_nl", structure="output_error", estimator="ls")


def test_read_results_names_a_missing_table(tmp_path):
    with pytest.raises(FileNotFoundError, match="no runs table"):
        study.read_results(tmp_path)
