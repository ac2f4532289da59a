"""The configuration folder ``conf/``: reading, listing and composing its groups (the bottom layer: every
component reads its YAML here, nothing here imports another module of the package).

``read_config(group, name)`` reads ``conf/<group>/<name>.yaml`` as a plain dict (outside Hydra: the simulator's
manoeuvres and vessels, models, structures, estimators, tests); ``list_configs(group)`` names a group's options;
``compose(config_name, overrides)`` composes a command's configuration as Hydra does for it (the doctor's
examples); ``simulated_studies()`` names the studies the experiments define.
"""
from __future__ import annotations

from pathlib import Path

import yaml

#: the package's configuration folder (Hydra's ``config_path`` of every command)
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def read_config(group: str, name: str) -> dict:
    """Read ``conf/<group>/<name>.yaml`` as a plain dict (outside Hydra: tests, the simulate CLI)."""
    path = CONF_DIR / group / f"{name}.yaml"
    if not path.exists():
        known = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))
        raise ValueError(f"no {group} config '{name}' ({path}); known: {known}")
    with open(path) as fh:
        return yaml.safe_load(fh)


def list_configs(group: str) -> list[str]:
    """The options of a config group: the names of ``conf/<group>/*.yaml``."""
    return sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


def compose(config_name: str, overrides=()) -> dict:
    """The configuration ``conf/<config_name>.yaml`` composed with ``overrides`` as its command composes it,
    resolved to plain dicts and lists."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from omegaconf import OmegaConf

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = hydra_compose(config_name=config_name, overrides=list(overrides))
    return OmegaConf.to_container(cfg, resolve=True)


def simulated_studies() -> set[str]:
    """The named simulated studies: the ``study`` each experiment (``conf/experiment/<name>.yaml``) sets. Each has
    its figures and claim in ``study/figures/studies/<name>.py`` (``tests/test_figures.py`` checks the two sets
    are the same)."""
    out = set()
    for name in list_configs("experiment"):
        study = (read_config("experiment", name) or {}).get("study")
        if study:
            out.add(str(study))
    return out
