"""``python -m study diagnose train=<file|folder|glob> [validate=...] vessel=<v> model=<m>
out=<dir>``.

The model doctor (``study.doctor``): compares a model with measured records, shows where it fails,
ranks the candidate missing effects by out-of-sample improvement, adds them one after the other, and
writes ``<out>/report.html`` (self-contained), ``<out>/report.json`` and ``<out>/figures/``; prints
a short verdict. Options in ``conf/diagnose.yaml``. Records: the schema's CSV/Parquet files
(``python -m study simulate`` makes them), HSVA's KVLCC2 ``.dat`` files and the Esso Osaka CSVs of
``../shared/data/real`` (read in place). This module is the command line only: the doctor run from a
resolved configuration is ``study.doctor.run.run``.
"""
from __future__ import annotations

from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from study.configuration.cli import reported, run_hydra
from study.configuration.compose import CONF_DIR


@hydra.main(config_path=str(CONF_DIR), config_name="diagnose", version_base="1.3")
def main(cfg: DictConfig) -> None:
    with reported("study diagnose"):  # a problem: one line on stderr and the exit status (study.configuration.cli)
        _main(OmegaConf.to_container(cfg, resolve=True))


def _main(conf: dict) -> None:
    from study.doctor.run import run

    rep = run(conf)
    out = Path(conf["out"]).resolve()
    print(rep["verdict"])

    def step(s):
        e = s.get("scored_error", s["validation_error"])
        txt = f"{s['step']} " + (f"{e:.3g}" if e == e and e != float("inf") else "diverged")
        if s.get("diverged"):
            txt += f" (diverges on {', '.join(s['diverged'])})"
        return txt + (" [rejected]" if s.get("rejected") else "")

    lad = " -> ".join(step(s) for s in rep["ladder"])
    print(f"validation error: {lad}")
    for n in rep.get("notes") or []:
        print(f"note: {n}")
    print(f"report: {out / 'report.html'} (and report.json, figures/)")


def precheck(overrides: list, multirun: bool) -> None:
    """The doctor's settings checks on its composed configuration, before Hydra starts: the
    settings, the classes the configuration and the effect folders name (before anything is
    imported), ``out=`` and the results folder writable. The records are read and checked against
    the vessel by the run, before it makes the report folder."""
    from study.configuration.compose import check_targets, compose
    from study.run.settings import check_diagnose

    conf = compose("diagnose", overrides, hydra=True)
    check_targets(conf)
    check_diagnose({k: v for k, v in conf.items() if k != "hydra"})


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    run_hydra(main, "study diagnose", precheck)
