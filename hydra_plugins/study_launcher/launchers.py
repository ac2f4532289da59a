"""The project's Hydra launchers: a sweep's jobs run in long-lived worker processes that each
receive the sweep once.

* ``study_local`` (``hydra/launcher=local``): one machine, ``n_jobs`` worker processes (loky, as
  Hydra's joblib launcher), jobs handed over in chunks (``runner.run_jobs``).
* ``study_slurm`` (``hydra/launcher=slurm_grouped``): a SLURM job array through submitit, as Hydra's
  submitit launcher, but each array task runs a group of jobs (``jobs_per_task``) with
  ``cpus_per_task`` worker processes, so that a node pays Python's start, the imports and the
  compiled code once per worker instead of once per run.

Why (``benchmarks/bench_sweep.py --part launcher``, README "Where the time goes"): Hydra's joblib
launcher sends the sweep's whole context with every job and re-installs it in the worker (its plugin
registry rebuilt by a scan of every plugin module each time), and composes every job's configuration
from scratch; the submitit launcher starts one Python process per run. Per job these launchers do
only what a job needs (``runner``, ``compose``), with the same results: each job's configuration
equal to Hydra's own composition, Hydra's ``run_job`` (output folder, logging, callbacks,
JobReturn), the JobReturns in the jobs' order. Hydra only loads launchers from the ``hydra_plugins``
namespace package, hence this package (registered by hand by ``study.commands.app``, as the
sweeper).
"""
# no `from __future__ import annotations`: Hydra execs plugin modules outside sys.modules (see covering_sweeper)

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from hydra.core.config_store import ConfigStore
from hydra.plugins.launcher import Launcher
from hydra_plugins.hydra_submitit_launcher.config import SlurmQueueConf

log = logging.getLogger(__name__)


@dataclass
class StudyLocalConf:
    _target_: str = "hydra_plugins.study_launcher.launchers.StudyLocalLauncher"
    # worker processes: -1 every CPU this process may use, -2 all but one, ... (as joblib's n_jobs); 1: the jobs
    # run in the launching process, one after the other
    n_jobs: int = -1
    # compose less (compose.JobComposer): loaded config files kept per worker, jobs that differ only in value
    # overrides composed from one composition; false: Hydra composes every job from scratch
    share_composition: bool = True


@dataclass
class StudySlurmConf(SlurmQueueConf):
    _target_: str = "hydra_plugins.study_launcher.launchers.StudySlurmLauncher"
    # jobs of the sweep per array task; null: spread the jobs over array_parallelism tasks (one wave)
    jobs_per_task: Optional[int] = None
    share_composition: bool = True


ConfigStore.instance().store(group="hydra/launcher", name="study_local", node=StudyLocalConf, provider="study")
ConfigStore.instance().store(group="hydra/launcher", name="study_slurm", node=StudySlurmConf, provider="study")


class _StudyLauncher(Launcher):
    def setup(self, *, hydra_context, task_function, config) -> None:
        self.config = config
        self.hydra_context = hydra_context
        self.task_function = task_function

    def _begin(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int, what: str) -> List[Any]:
        """The parent's part of every launcher: logging as configured, the sweep folder, the jobs
        listed."""
        from hydra.core.utils import configure_log, filter_overrides, setup_globals

        setup_globals()
        configure_log(self.config.hydra.hydra_logging, self.config.hydra.verbose)
        sweep_dir = Path(str(self.config.hydra.sweep.dir))
        sweep_dir.mkdir(parents=True, exist_ok=True)
        if "mode" in self.config.hydra.sweep:
            os.chmod(sweep_dir, mode=int(str(self.config.hydra.sweep.mode), 8))
        log.info(f"{what} is launching {len(job_overrides)} jobs, sweep output dir : {sweep_dir}")
        jobs = []
        for i, overrides in enumerate(job_overrides):
            log.info(f"\t#{initial_job_idx + i} : {' '.join(filter_overrides(overrides))}")
            jobs.append((initial_job_idx + i, list(overrides)))
        return jobs

    def _context(self, share: bool):
        from .runner import SweepContext

        return SweepContext(self.hydra_context, self.config, self.task_function, share_composition=share)


class StudyLocalLauncher(_StudyLauncher):
    def __init__(self, n_jobs: int = -1, share_composition: bool = True) -> None:
        self.n_jobs = n_jobs
        self.share_composition = share_composition

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int):
        from .runner import run_jobs, worker_count

        workers = worker_count(self.n_jobs)
        jobs = self._begin(job_overrides, initial_job_idx, f"study_local (n_jobs={self.n_jobs}: {workers} workers)")
        return run_jobs(self._context(self.share_composition), jobs, workers)


class TaskRunner:
    """One SLURM array task: its group of jobs, with ``workers`` worker processes on the task's
    CPUs."""

    def __init__(self, context: bytes, workers: int) -> None:
        self.context = context
        self.workers = workers

    def __call__(self, jobs: List[Any]) -> list:
        import pickle

        from .runner import install, run_jobs

        context = pickle.loads(self.context)
        install(context)  # a fresh process: Hydra's singleton state (config store, resolvers) from the sweep
        workers = max(1, min(self.workers, len(jobs)))
        print(f"study_slurm task: {len(jobs)} jobs " + (f"on {workers} worker processes" if workers > 1
                                                        else "in this process"), flush=True)
        return run_jobs(context, jobs, workers, installed=True)


def task_groups(jobs: List[Any], key, n_tasks: int) -> List[List[Any]]:
    """``jobs`` in ``n_tasks`` consecutive groups of near-equal size (sizes differ by one at
    most), after a stable sort by ``key`` so that jobs sharing a composition share a task."""
    order = {}
    for _, overrides in jobs:
        order.setdefault(key(overrides), len(order))
    ranked = sorted(jobs, key=lambda j: order[key(j[1])])
    n_tasks = max(1, min(n_tasks, len(jobs)))
    size, extra = divmod(len(jobs), n_tasks)
    out, i = [], 0
    for t in range(n_tasks):
        n = size + (1 if t < extra else 0)
        out.append(ranked[i:i + n])
        i += n
    return out


class StudySlurmLauncher(_StudyLauncher):
    def __init__(self, **params: Any) -> None:
        from omegaconf import OmegaConf

        self.params = {k: OmegaConf.to_container(v, resolve=True) if OmegaConf.is_config(v) else v
                       for k, v in params.items()}
        self.jobs_per_task = self.params.pop("jobs_per_task", None)
        self.share_composition = bool(self.params.pop("share_composition", True))
        if self.params.get("tasks_per_node", 1) != 1 or self.params.get("nodes", 1) != 1:
            raise ValueError("hydra.launcher: study_slurm runs one process per array task (its jobs on a pool of "
                             "cpus_per_task workers): expected nodes=1 and tasks_per_node=1, got "
                             f"nodes={self.params.get('nodes')}, tasks_per_node={self.params.get('tasks_per_node')}")
        if self.jobs_per_task is not None and int(self.jobs_per_task) < 1:
            raise ValueError(f"hydra.launcher.jobs_per_task={self.jobs_per_task}: expected a positive number of "
                             "jobs per array task, or null (spread the jobs over array_parallelism tasks)")

    def _executor(self):
        """submitit's executor, set up as Hydra's submitit launcher sets it up (its parameter
        names)."""
        import submitit
        from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf
        from omegaconf import OmegaConf

        init_keys = {"max_num_timeout", "submitit_folder"}
        executor = submitit.AutoExecutor(cluster="slurm", folder=self.params["submitit_folder"],
                                         slurm_max_num_timeout=self.params.get("max_num_timeout", 0))
        base = set(OmegaConf.structured(BaseQueueConf).keys())
        executor.update_parameters(**{k if k in base else f"slurm_{k}": v for k, v in self.params.items()
                                      if k not in init_keys})
        return executor

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int):
        from .compose import JobComposer

        workers = max(1, int(self.params.get("cpus_per_task") or 1))
        n = len(job_overrides)
        per_task = int(self.jobs_per_task) if self.jobs_per_task else math.ceil(
            n / max(1, int(self.params.get("array_parallelism") or 1)))
        n_tasks = math.ceil(n / per_task)
        jobs = self._begin(job_overrides, initial_job_idx,
                           f"study_slurm ({n_tasks} array tasks of {per_task} jobs or fewer, {workers} workers each)")
        context = self._context(self.share_composition)
        keyer = JobComposer(self.hydra_context.config_loader, self.config, share=self.share_composition,
                            cache_loaded=False)
        groups = task_groups(jobs, keyer.group_key, n_tasks)
        executor = self._executor()
        tasks = executor.map_array(TaskRunner(context.dumps(), workers), groups)
        log.info(f"Submitted array {tasks[0].job_id.split('_')[0] if tasks else '-'} ({len(tasks)} tasks); "
                 "waiting for them")
        by_num: Dict[int, Any] = {}
        for group, task in zip(groups, tasks):
            for (num, _), ret in zip(group, task.results()[0]):
                by_num[num] = ret
        return [by_num[num] for num, _ in jobs]
