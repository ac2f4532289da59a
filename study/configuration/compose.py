"""The configuration folder ``conf/``: reading, listing and composing its groups (the bottom layer:
every component reads its YAML here, nothing here imports another module of the package).

``read_config(group, name)`` reads ``conf/<group>/<name>.yaml`` as a plain dict (outside Hydra: the
simulator's manoeuvres and vessels, models, structures, estimators, tests); ``list_configs(group)``
names a group's options; ``compose(config_name, overrides)`` composes a command's configuration as
Hydra does for it (the doctor's examples); ``simulated_studies()`` names the studies the experiments
define; ``check_target`` and ``check_targets`` are the trusted-code boundary: which classes a
configuration may name.
"""
from __future__ import annotations

from pathlib import Path

import yaml

#: the package's configuration folder (Hydra's ``config_path`` of every command)
CONF_DIR = Path(__file__).resolve().parents[2] / "conf"


def read_config(group: str, name: str) -> dict:
    """Read ``conf/<group>/<name>.yaml`` as a plain dict (outside Hydra: tests, the simulate
    CLI)."""
    path = CONF_DIR / group / f"{name}.yaml"
    if not path.exists():
        known = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))
        raise ValueError(f"no {group} config '{name}' ({path}); known: {known}")
    with open(path) as fh:
        return yaml.safe_load(fh)


def list_configs(group: str) -> list[str]:
    """The options of a config group: the names of ``conf/<group>/*.yaml``."""
    return sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


# ------------------------------------------------------------------------------------ trusted-code boundary

#: the packages whose classes a configuration may name (``_target_``): the project's own and Hydra's plugins
TRUSTED_PACKAGES = ("study", "hydra_plugins")
#: and Hydra's own launcher and sweeper
TRUSTED_PREFIXES = ("hydra._internal.core_plugins.",)
#: what a logging configuration (``hydra.job_logging``, ``hydra.hydra_logging``) may name besides
LOGGING_PREFIXES = ("logging.", "colorlog.")


class UntrustedCodeError(ValueError):
    """A configuration names code outside the trusted packages and plugin folders (refused before
    any import)."""


def check_target(target, where: str = "_target_", plugin_dirs=(), extra_prefixes=()) -> None:
    """Refuse ``target`` (a ``_target_``: a dotted class path) unless it lies in the project's
    packages (:data:`TRUSTED_PACKAGES`, :data:`TRUSTED_PREFIXES`) or in one of ``plugin_dirs`` (the
    effect folders the user names). Nothing is imported or run to decide: a module outside the
    packages is only located (``importlib.util.find_spec`` of its top-level name, which finds a file
    without executing it).

    A configuration that could name any importable callable would run any code
    (``shutil.copyfile``, ``builtins.open``): configuration folders and plugin folders are code
    and must be trusted, and everything else is refused here."""
    import importlib.util

    expect = ("expected a class of the project's packages (" + ", ".join(f"{p}." for p in TRUSTED_PACKAGES)
              + ") or of an effect folder named by effect_path or STUDY_EFFECT_PATH (configuration may run only "
              "trusted code)")
    parts = target.split(".") if isinstance(target, str) else []
    if len(parts) < 2 or not all(p.isidentifier() for p in parts):
        raise UntrustedCodeError(f"{where}={target!r}: not a dotted class path; {expect}")
    if parts[0] in TRUSTED_PACKAGES or target.startswith(TRUSTED_PREFIXES + tuple(extra_prefixes)):
        return
    dirs = [Path(d).expanduser().resolve() for d in plugin_dirs or ()]
    if dirs:
        try:
            spec = importlib.util.find_spec(parts[0])
        except (ImportError, ValueError):
            spec = None
        places = []
        if spec is not None:
            places = [spec.origin] if spec.origin and spec.origin not in ("built-in", "frozen") else []
            places += list(spec.submodule_search_locations or [])
        if places and all(any(Path(p).resolve().is_relative_to(d) for d in dirs) for p in places):
            return
    raise UntrustedCodeError(f"{where}={target}: {expect}")


def check_targets(node, where: str = "", plugin_dirs=()) -> None:
    """:func:`check_target` on every ``_target_`` in a configuration (dicts and lists, the
    ``hydra`` node too: callbacks, launcher, sweeper), and on the factories of its logging
    configurations (``()``, ``class``)."""
    if isinstance(node, dict):
        logging_ = where.split(".")[-1] in ("job_logging", "hydra_logging") or ".job_logging." in where + "." \
            or ".hydra_logging." in where + "."
        for k, v in node.items():
            key = f"{where}.{k}" if where else str(k)
            if k == "_target_" or (logging_ and k in ("()", "class") and isinstance(v, str)):
                check_target(v, key, plugin_dirs, LOGGING_PREFIXES if logging_ and k != "_target_" else ())
            else:
                check_targets(v, key, plugin_dirs)
    elif isinstance(node, (list, tuple)):
        for i, v in enumerate(node):
            check_targets(v, f"{where}[{i}]", plugin_dirs)


def compose(config_name: str, overrides=(), hydra: bool = False) -> dict:
    """The configuration ``conf/<config_name>.yaml`` composed with ``overrides`` as its command
    composes it, resolved to plain dicts and lists; with ``hydra``, Hydra's own node too
    (unresolved)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from omegaconf import OmegaConf

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = hydra_compose(config_name=config_name, overrides=list(overrides), return_hydra_config=hydra)
    if not hydra:
        return OmegaConf.to_container(cfg, resolve=True)
    # the job's keys resolved; Hydra's own node as written (its interpolations need a running Hydra)
    out = OmegaConf.to_container(OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"]), resolve=True)
    out["hydra"] = OmegaConf.to_container(cfg.hydra, resolve=False)
    return out


def simulated_studies() -> set[str]:
    """The named simulated studies: the ``study`` each experiment
    (``conf/experiment/<name>.yaml``) sets. Each has its figures and claim in
    ``study/figures/studies/<name>.py`` (``tests/figures/test_figures.py`` checks the two sets
    are the same)."""
    out = set()
    for name in list_configs("experiment"):
        study = (read_config("experiment", name) or {}).get("study")
        if study:
            out.add(str(study))
    return out
