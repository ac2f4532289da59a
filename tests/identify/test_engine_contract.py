"""The engine's contract with the estimators, generated over every estimator config (discovered from conf/).

Each estimator declares what it can do as class attributes (``study.identify.estimators.base``); the engine hands
``fit`` only what they declare, through ``Estimator.fit_problem``. Here each declaration is checked against the
signatures of ``fit`` and ``fit_output_error``, so that a declaration cannot drift from the code, and
``fit_problem`` is checked to pass exactly the declared arguments and to refuse the undeclared ones.
"""
import inspect

import numpy as np
import pandas as pd
import pytest

from study.identify.estimators import Estimator, estimator_class, list_estimators, make_estimator
from study.identify.estimators.problem import RegressionProblem
from study.configuration.compose import read_config

ROW_NOISE_ARGS = ("noise_operators", "row_errors")


def _classes():
    return sorted({estimator_class(read_config("estimator", e)) for e in list_estimators()}, key=lambda c: c.__name__)


def _args(fn) -> set:
    return set(inspect.signature(fn).parameters)


@pytest.mark.parametrize("cls", _classes(), ids=lambda c: c.__name__)
def test_declared_capabilities_match_the_signatures(cls):
    fit = _args(cls.fit)
    if "regression" in cls.problem_types:
        assert cls.accepts_prior == ("prior" in fit), "accepts_prior must say whether fit takes prior"
        assert cls.reports_progress == ("progress" in fit), "reports_progress must say whether fit takes progress"
        for a in ROW_NOISE_ARGS:
            assert cls.models_row_noise == (a in fit), f"models_row_noise must say whether fit takes {a}"
        assert cls.checks_omitted_terms == ("neighbours" in fit), \
            "checks_omitted_terms must say whether fit takes neighbours"
    simulates = "output_error" in cls.problem_types
    assert simulates == (cls.fit_output_error is not Estimator.fit_output_error), \
        "problem_types must name output_error exactly when fit_output_error is implemented"
    if simulates:
        assert cls.reports_progress == ("progress" in _args(cls.fit_output_error))


@pytest.mark.parametrize("name", list_estimators())
def test_an_instance_wants_row_noise_only_when_its_class_models_it(name):
    est = make_estimator(name)
    if not est.models_row_noise:
        assert not est.uses_noise_operators and not est.uses_row_errors and est.row_error_probes is None


class _Recorded(Exception):
    pass


@pytest.mark.parametrize("name", list_estimators())
def test_fit_problem_passes_exactly_what_the_estimator_declares(name, monkeypatch):
    est = make_estimator(name)
    if "regression" not in est.problem_types:
        with pytest.raises(NotImplementedError, match="regression"):
            est.fit_problem(RegressionProblem(pd.DataFrame({"a": [1.0, 2.0]}), np.ones(2)))
        return
    seen = {}

    def fit(X, y, **kwargs):
        seen.update(kwargs)
        raise _Recorded

    monkeypatch.setattr(est, "fit", fit)
    X = pd.DataFrame({"a": [1.0, 2.0, 3.0], "b": [0.0, 1.0, 0.5]})
    prior = {"a": (1.0, 0.5), "b": (0.0, 1.0)} if est.accepts_prior else None
    ops = (object(), object()) if est.models_row_noise else (None, None)
    neighbours = pd.DataFrame({"c": [1.0, 4.0, 9.0]}) if est.checks_omitted_terms else None
    with pytest.raises(_Recorded):
        est.fit_problem(RegressionProblem(X, np.ones(3), prior, *ops, equation="X", neighbours=neighbours),
                        progress=True)
    expected = ({"progress"} if est.reports_progress else set()) | ({"prior"} if est.accepts_prior else set()) | \
        (set(ROW_NOISE_ARGS) if est.models_row_noise else set()) | \
        ({"neighbours"} if est.checks_omitted_terms else set())
    assert set(seen) == expected
    if est.accepts_prior:
        assert seen["prior"] is prior


@pytest.mark.parametrize("name", list_estimators())
def test_fit_problem_refuses_what_the_estimator_does_not_declare(name):
    est = make_estimator(name)
    if "regression" not in est.problem_types:
        return
    X = pd.DataFrame({"a": [1.0, 2.0, 3.0]})
    if not est.accepts_prior:
        with pytest.raises(ValueError, match="takes no prior"):
            est.fit_problem(RegressionProblem(X, np.ones(3), prior={"a": (0.0, 1.0)}))
    else:
        with pytest.raises(ValueError, match=r"equation N: the prior has no value for \['a'\]"):
            est.fit_problem(RegressionProblem(X, np.ones(3), prior={"b": (0.0, 1.0)}, equation="N"))
    if not est.models_row_noise:
        with pytest.raises(ValueError, match="does not model the rows' noise"):
            est.fit_problem(RegressionProblem(X, np.ones(3), noise_operators=object()))
    if not est.checks_omitted_terms:
        with pytest.raises(ValueError, match="does not check for omitted terms"):
            est.fit_problem(RegressionProblem(X, np.ones(3), neighbours=pd.DataFrame({"c": [1.0, 4.0, 9.0]})))


@pytest.mark.parametrize("name", list_estimators())
def test_only_an_estimator_that_models_row_noise_gives_a_trust_verdict(name):
    est = make_estimator(name)
    verdict = est.trust_verdict("central", {}, 0, False, {})
    if type(est).trust_verdict is Estimator.trust_verdict:
        assert verdict is None
    else:
        assert est.models_row_noise
        trusted, note = verdict
        assert trusted in (True, False) and isinstance(note, str)


def test_a_model_with_effects_is_identified_by_variable_projection():
    """Whatever estimator a run names, a model with effects is identified by variable projection (the YAML
    config), which skips every model without effects, and fit_problem hands it only a model with effects."""
    from study.identify.fit import EFFECTS_ESTIMATOR, estimator_for, problem_type
    from study.identify.models import make_model
    from study.identify.structures import make_structure
    from study.sim import load_vessel

    assert EFFECTS_ESTIMATOR == read_config("estimator", "variable_projection")
    vessel = load_vessel(read_config("vessel", "kvlcc2"))
    plain = make_model(read_config("model", "mmg_hull"), vessel)
    with_fx = make_model({**read_config("model", "mmg_hull"), "effects": ["current"]}, vessel)
    central, oe = make_structure("central"), make_structure("output_error")
    ls = read_config("estimator", "ls")
    assert estimator_for(plain, ls) is ls and estimator_for(with_fx, ls) == EFFECTS_ESTIMATOR
    assert problem_type(with_fx, central) == "effects" and problem_type(plain, central) == "regression"
    vp = make_estimator("variable_projection")
    assert vp.skip(with_fx, central) == (False, "")
    assert vp.skip(plain, central)[0] and vp.skip(with_fx, oe)[0]
    with pytest.raises(NotImplementedError, match="regression"):
        vp.fit_problem(RegressionProblem(pd.DataFrame({"a": [1.0, 2.0]}), np.ones(2)))


def test_a_run_without_effects_does_not_use_identification_with_effects():
    from study.store.fingerprint import closure, entries

    def modules(model):  # every component of a simulated run
        conf = {"model": model, "estimator": read_config("estimator", "ls")}
        return {m for mods, _ in entries(conf).values() for m in closure(tuple(mods))}

    assert not any(m.startswith("study.identify.with_effects") for m in modules({"name": "mmg_hull"}))
    assert "study.identify.with_effects.estimator" in modules({"name": "mmg_hull", "effects": ["current"]})
