"""Estimators, discovered from ``conf/estimator/*.yaml`` (one YAML each; nothing here lists them).

An estimator config names its class and hyper-parameters::

    name: ridge
    _target_: study.identify.estimators.linear.Ridge   # any importable class following base.Estimator
    params: {alphas: [1.0e-6, 1.0e+6, 61]}

Adding an estimator is one class (anywhere importable, normally one module here) plus one YAML; the
test suite and the app pick it up from the config folder. The contract is in :mod:`.base`.
"""
from __future__ import annotations

from hydra.utils import get_class

from .base import Estimator, as_arrays
from .linear import LeastSquares

__all__ = ["Estimator", "LeastSquares", "as_arrays", "estimator_class", "list_estimators", "make_estimator"]


def list_estimators() -> list[str]:
    """Names of the estimator configs (``conf/estimator/*.yaml``)."""
    from study.configuration.compose import list_configs

    return list_configs("estimator")


def estimator_class(cfg: dict):
    """The class an estimator config names (``_target_``), checked against the contract."""
    target = cfg.get("_target_")
    if not target:
        raise ValueError(f"estimator config '{cfg.get('name')}' has no _target_ (the estimator's class path)")
    from study.configuration.compose import check_target

    check_target(target, "estimator._target_")  # the trusted-code boundary: checked before anything is imported
    try:
        cls = get_class(target)
    except Exception as e:  # hydra wraps import errors in its own type
        raise ValueError(f"estimator config '{cfg.get('name')}': cannot import _target_ '{target}': {e}") from e
    if not (isinstance(cls, type) and issubclass(cls, Estimator)):
        raise ValueError(f"estimator config '{cfg.get('name')}': {target} is not a study Estimator subclass")
    return cls


def make_estimator(cfg, **overrides) -> Estimator:
    """An estimator from its config (dict or config name), hyper-parameters from ``params`` +
    overrides."""
    if isinstance(cfg, str):
        from study.configuration.compose import read_config

        cfg = read_config("estimator", cfg)
    params = dict(cfg.get("params") or {})
    params.update(overrides)
    cls = estimator_class(cfg)
    try:
        return cls(**params)
    except TypeError as e:
        raise ValueError(f"estimator '{cfg.get('name')}': bad hyper-parameters {sorted(params)}: {e}") from e
