"""Hydra's basic sweeper, checking a covering subset of the sweep's configs before launching.

Why a plugin: Hydra's BasicSweeper composes *every* job's config before launching anything, to catch
composition errors early ("This can be a bit slow for large jobs", its own comment), and the
launcher composes each one again. At about 0.2 s a config, the 1188-job `grand` study spent 4
minutes composing before its first job on two cores. This sweeper composes only enough jobs that
every swept value (every `key=value` of the sweep) appears in at least one composed config: a
misspelt group option, a bad value or an unknown key still fails before any job runs, in about 25
compositions instead of 1188. An error that only a particular combination of values would raise
surfaces when the launcher composes that job; the runs that finished before it stay in the results
table and the next start resumes them. `validate_all: true` restores Hydra's behaviour. Hydra only
loads sweepers from the `hydra_plugins` namespace package, hence this module.

Each composed config is also checked by the study's own rules (`study.run.settings.check_run`: zero,
negative or non-finite values, unknown estimator hyper-parameters), so such a sweep is refused
before any job runs. The sweep's number of jobs is exported (`STUDY_SWEEP_JOBS`) for the progress
lines (`job 12/66`), and when the sweep ends `study.configuration.sweep_summary.sweep_finished`
counts its jobs by status (a failed run makes the command's exit status
non-zero).
"""
# no `from __future__ import annotations`: Hydra execs plugin modules outside sys.modules, and dataclasses
# then cannot resolve string annotations

import logging
import os
import time
from dataclasses import dataclass
from typing import Dict, Optional, Sequence

from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.core.config_store import ConfigStore

log = logging.getLogger(__name__)


@dataclass
class CoveringSweeperConf:
    _target_: str = "hydra_plugins.study_sweeper.covering_sweeper.CoveringSweeper"
    max_batch_size: Optional[int] = None
    params: Optional[Dict[str, str]] = None
    validate_all: bool = False


ConfigStore.instance().store(group="hydra/sweeper", name="covering", node=CoveringSweeperConf, provider="study")


def covering_jobs(batch: Sequence[Sequence[str]]) -> list[Sequence[str]]:
    """A subset of the jobs in which every override string of the batch appears at least once
    (one greedy pass: a job is kept when it brings an override not seen yet; for a cartesian
    sweep that is about the sum of the numbers of values, not their product)."""
    seen: set[str] = set()
    keep = []
    for job in batch:
        new = set(job) - seen
        if new:
            keep.append(job)
            seen |= new
    return keep


class CoveringSweeper(BasicSweeper):
    def __init__(self, max_batch_size: Optional[int], params: Optional[Dict[str, str]] = None,
                 validate_all: bool = False) -> None:
        super().__init__(max_batch_size=max_batch_size, params=params)
        self.validate_all = validate_all

    def validate_batch_is_legal(self, batch: Sequence[Sequence[str]]) -> None:
        if getattr(self, "_checked", False):  # every batch was checked before the sweep folder was made (sweep)
            os.environ["STUDY_SWEEP_JOBS"] = str(sum(len(b) for b in self.overrides or [batch]))
            return
        self._validate(batch)

    def _validate(self, batch: Sequence[Sequence[str]]) -> None:
        jobs = list(batch) if self.validate_all else covering_jobs(batch)
        tic = time.perf_counter()
        check = _study_check()
        for overrides in jobs:  # BasicSweeper.validate_batch_is_legal, with the study's own check added
            cfg = self.hydra_context.config_loader.load_sweep_config(master_config=self.config,
                                                                     sweep_overrides=list(overrides))
            if check is not None:
                from omegaconf import OmegaConf

                task = OmegaConf.to_container(cfg, resolve=False)
                task.pop("hydra", None)  # the job's own config, as its task function gets it
                check(OmegaConf.to_container(OmegaConf.create(task), resolve=True))
        os.environ["STUDY_SWEEP_JOBS"] = str(sum(len(b) for b in self.overrides or [batch]))
        log.info(f"Composed {len(jobs)} of {len(batch)} job configs to validate the sweep "
                 f"({time.perf_counter() - tic:.1f} s)")

    def sweep(self, arguments):
        # every batch's jobs checked before BasicSweeper makes the sweep folder and writes its multirun.yaml: a
        # refused sweep writes nothing
        from hydra.core.override_parser.overrides_parser import OverridesParser

        params_conf = self._parse_config()
        params_conf.extend(arguments)
        parser = OverridesParser.create(config_loader=self.hydra_context.config_loader)
        batches = self.split_arguments(parser.parse_overrides(params_conf), self.max_batch_size)
        self._checked = False
        self._validate([job for b in batches for job in b])
        self._checked = True
        returns = super().sweep(arguments)
        try:
            from study.configuration.sweep_summary import sweep_finished
        except ImportError:
            return returns
        sweep_finished([r.return_value for batch in returns for r in batch])
        return returns


def _study_check():
    """The study's configuration check (None outside the study package)."""
    try:
        from study.run.settings import check_run
    except ImportError:
        return None
    return check_run
