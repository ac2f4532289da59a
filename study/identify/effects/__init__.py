"""Candidate physical effects, discovered from ``conf/effect/*.yaml`` (nothing here lists them):
what identification with effects (``study.identify.with_effects``) adds to a model, and the model
doctor's candidates.

An effect config names its class (``_target_``), its nonlinear parameters and options; the contract
is in :mod:`.base`. Adding an effect is one class plus one YAML, like an estimator. A user adds
their own without touching the package: a YAML in a folder of their own, named by
``effect_path=<dir>`` (``python -m study diagnose``) or the environment variable
``STUDY_EFFECT_PATH`` (folders separated by ``:``), whose ``_target_`` is a class importable from
their ``PYTHONPATH`` and defined in a module of one of those folders (an effect folder is code, and
must be trusted: a ``_target_`` elsewhere is refused before anything is imported,
``study.configuration.compose.check_target``); or a config dict given directly as a candidate.
"""
from __future__ import annotations

import os
from pathlib import Path

import yaml

from .base import Effect, Param, RecordInfo

__all__ = ["Effect", "Param", "RecordInfo", "effect_dirs", "list_effects", "make_effect", "effect_config",
           "registry", "describe_values"]


def effect_dirs(extra=()) -> list:
    """The folders effect YAMLs are read from: the package's ``conf/effect``, then
    ``STUDY_EFFECT_PATH``, then ``extra`` (a later folder's YAML of the same name replaces an
    earlier one)."""
    from study.configuration.compose import CONF_DIR

    dirs = [CONF_DIR / "effect"]
    env = os.environ.get("STUDY_EFFECT_PATH", "")
    dirs += [Path(p) for p in env.split(os.pathsep) if p]
    dirs += [Path(p) for p in ([extra] if isinstance(extra, (str, Path)) else (extra or ()))]
    for d in dirs[1:]:
        if not d.is_dir():
            raise ValueError(f"effect folder {d} (STUDY_EFFECT_PATH or effect_path) does not exist")
    return dirs


def _configs(extra=()) -> dict:
    out = {}
    for d in effect_dirs(extra):
        for f in sorted(d.glob("*.yaml")):
            with open(f, encoding="utf-8") as fh:
                cfg = yaml.safe_load(fh) or {}
            if not isinstance(cfg, dict):
                raise ValueError(f"{f}: an effect config must be a mapping (name, _target_, params, ...)")
            cfg.setdefault("name", f.stem)
            cfg["_file"] = str(f)
            out[cfg["name"]] = cfg
    return out


def list_effects(extra=()) -> list:
    """Names of every discovered effect, the package's first (in file order), then the user's."""
    return list(_configs(extra))


def effect_config(name: str, extra=()) -> dict:
    cfgs = _configs(extra)
    if name not in cfgs:
        raise ValueError(f"unknown effect '{name}'; the catalogue has {sorted(cfgs)} (conf/effect/*.yaml, "
                         "STUDY_EFFECT_PATH or effect_path)")
    return cfgs[name]


def make_effect(cfg, extra=()) -> Effect:
    """An effect from its config (a dict, or a name looked up in the effect folders)."""
    from hydra.utils import get_class

    if isinstance(cfg, str):
        cfg = effect_config(cfg, extra)
    cfg = dict(cfg)
    where = cfg.get("_file", "effect config")
    target = cfg.get("_target_")
    if not target:
        raise ValueError(f"{where}: effect '{cfg.get('name')}' has no _target_ (the effect's class path)")
    from study.configuration.compose import check_target

    # the trusted-code boundary, before anything is imported: the package's effects, or a module that lies in
    # one of the effect folders the user named (a folder of effects is code and must be trusted)
    check_target(target, f"{where}: _target_", plugin_dirs=effect_dirs(extra)[1:])
    try:
        cls = get_class(target)
    except Exception as e:  # hydra wraps import errors in its own type
        raise ValueError(f"{where}: cannot import _target_ '{target}': {e}") from e
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        raise ValueError(f"{where}: {target} is not a subclass of study.identify.effects.Effect")
    try:
        eff = cls(cfg["name"], cfg.get("params"), **dict(cfg.get("options") or {}))
    except TypeError as e:
        raise ValueError(f"{where}: bad options for {target}: {e}") from e
    if "needs" in cfg:
        needs = cfg["needs"]
        if not isinstance(needs, (list, tuple)) or any(n not in ("wind", "current") for n in needs):
            raise ValueError(f"{where}: needs: {needs}: expected a list of wind, current")
        eff.needs = tuple(needs)
    if "setup_effect" in cfg:
        if not isinstance(cfg["setup_effect"], bool):
            raise ValueError(f"{where}: setup_effect: {cfg['setup_effect']}: expected true or false")
        eff.setup_effect = cfg["setup_effect"]
    eff.config = cfg
    return eff


def registry(names, extra=()) -> dict:
    """name -> Effect for the given names or config dicts."""
    out = {}
    for n in names:
        e = make_effect(n, extra)
        out[e.name] = e
    return out


def describe_values(effects: dict, by_effect: dict) -> dict:
    """Every effect's estimates in the user's terms, merged (``by_effect``: name -> its own
    values)."""
    out = {}
    for name, vals in by_effect.items():
        out.update(effects[name].describe(vals) if name in effects else vals)
    return out
