"""Running a sweep's jobs: what each job needs and no more, in this process or in a pool of worker
processes.

Per job: its configuration (:class:`~hydra_plugins.study_launcher.compose.JobComposer`: Hydra's
composition, shared between jobs that differ only in value overrides), ``hydra.job.num`` and
``hydra.job.id`` set as Hydra's joblib launcher sets them, and Hydra's own ``run_job`` (the job's
output folder, its logging, ``hydra.output_subdir``, ``hydra.job.chdir`` and ``env_set``, the
callbacks' ``on_job_start``/``on_job_end``, the task function, and its ``JobReturn``: a task that
raises is a FAILED JobReturn carrying the exception, as with every Hydra launcher).

Per worker process, once: the sweep's context (Hydra's context with the callbacks, the sweep's
configuration, the task function, Hydra's singleton state), unpickled and installed. Hydra's joblib
launcher sends all of it with every job and re-installs it in the worker for every job, which
rebuilds Hydra's plugin registry (a scan of every plugin module: ``Singleton.set_state``) each time.

Jobs are handed to the workers in chunks of jobs with the same group overrides (so a worker composes
their configuration once), at most ``1/(4 x workers)`` of the jobs in a chunk so that the load stays
balanced; results come back in the jobs' order whatever order they ran in.
"""
# no `from __future__ import annotations`: Hydra execs plugin modules outside sys.modules (see covering_sweeper)

import logging
import math
from collections import Counter
from typing import Any, Callable, Dict, List, Sequence, Tuple

log = logging.getLogger(__name__)

Job = Tuple[int, List[str]]  # (job number in the sweep, its overrides)


class SweepContext:
    """What every job of one sweep shares: sent to each worker process once."""

    def __init__(self, hydra_context, config, task_function, share_composition: bool = True) -> None:
        from hydra.core.singleton import Singleton

        self.hydra_context = hydra_context
        self.config = config
        self.task_function = task_function
        self.singleton_state = Singleton.get_state()
        self.share_composition = share_composition

    def dumps(self) -> bytes:
        import cloudpickle  # the task function is the undecorated body of a @hydra.main: by value if need be

        return cloudpickle.dumps(self)


_WORKER: Dict[str, Any] = {}  # this process's installed context and composer


def install(context, in_process: bool = False) -> None:
    """Make ``context`` (a :class:`SweepContext` or its pickle) this process's sweep. A worker
    process also takes Hydra's singleton state (config store, resolvers) from it; the launching
    process has it already."""
    import pickle

    from hydra.core.utils import setup_globals

    from .compose import JobComposer

    if isinstance(context, (bytes, bytearray)):
        context = pickle.loads(context)
    setup_globals()
    if not in_process:
        from hydra.core.singleton import Singleton

        Singleton.set_state(context.singleton_state)
    _WORKER["context"] = context
    _WORKER["composer"] = JobComposer(context.hydra_context.config_loader, context.config,
                                      share=context.share_composition, cache_loaded=context.share_composition)


def composer():
    return _WORKER["composer"]


def run_one(num: int, overrides: Sequence[str], alone: bool = False):
    """One job in this process (its context installed): compose, number, run with Hydra's
    ``run_job``. ``alone``: no other job of its chunk shares its group overrides."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.core.utils import run_job
    from omegaconf import open_dict

    ctx = _WORKER["context"]
    sweep_config = _WORKER["composer"].compose(list(overrides), alone=alone)
    with open_dict(sweep_config):  # as Hydra's joblib launcher numbers its jobs
        sweep_config.hydra.job.id = f"{sweep_config.hydra.job.name}_{num}"
        sweep_config.hydra.job.num = num
    HydraConfig.instance().set_config(sweep_config)
    return run_job(hydra_context=ctx.hydra_context, config=sweep_config, task_function=ctx.task_function,
                   job_dir_key="hydra.sweep.dir", job_subdir_key="hydra.sweep.subdir")


def run_chunk(chunk: Sequence[Job]) -> list:
    """Every job of a chunk, in order, in this process."""
    keys = [composer().group_key(overrides) for _, overrides in chunk]
    n = Counter(keys)
    return [run_one(num, overrides, alone=n[k] == 1) for (num, overrides), k in zip(chunk, keys)]


def make_chunks(jobs: Sequence[Job], key: Callable[[Sequence[str]], Any], workers: int,
                per_worker: int = 4) -> List[List[Job]]:
    """The jobs grouped by ``key`` (jobs of one group stay together, groups in order of first
    appearance), each group cut into chunks of at most ``ceil(len(jobs) / (per_worker x workers))``
    jobs: every job in exactly one
    chunk."""
    cap = max(1, math.ceil(len(jobs) / (per_worker * max(1, workers))))
    groups: Dict[Any, List[Job]] = {}
    for job in jobs:
        groups.setdefault(key(job[1]), []).append(job)
    return [g[i:i + cap] for g in groups.values() for i in range(0, len(g), cap)]


def die_with_parent(parent: int) -> None:
    """Make this worker process end when ``parent`` (the launcher) ends, however it ends: a
    SIGKILLed launcher left its workers computing and then idle until they were killed by hand.
    On Linux the kernel sends SIGKILL at the parent's death (``prctl(PR_SET_PDEATHSIG)``);
    everywhere a daemon thread checks once a second whether the worker has been handed to another
    parent, and ends it then."""
    import os
    import threading
    import time

    try:
        import ctypes
        import signal
        import sys

        if sys.platform.startswith("linux"):
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # no prctl: the thread below does it
        pass
    if os.getppid() != parent:  # the parent died before the line above: nobody would send the signal
        os._exit(1)

    def watch():
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


def _worker_start(parent: int, context: bytes) -> None:
    """A worker's initializer: tied to its parent's life, then given the sweep."""
    die_with_parent(parent)
    install(context)


def worker_count(n_jobs: int) -> int:
    """Workers for ``n_jobs`` as joblib reads it: -1 every CPU this process may use (cgroup
    quotas and affinity counted, loky's cpu_count), -2 all but one, and so on."""
    from joblib.externals.loky import cpu_count

    if n_jobs is None or n_jobs == 0:
        return 1
    if n_jobs < 0:
        return max(1, cpu_count() + 1 + n_jobs)
    return int(n_jobs)


def run_jobs(context: SweepContext, jobs: Sequence[Job], workers: int, installed: bool = False) -> list:
    """Run ``jobs`` with ``workers`` processes (one: in this process, as Hydra's basic launcher
    does) and return their JobReturns in the jobs' order. ``installed``: this process has the
    context already (a SLURM task)."""
    if workers <= 1 or len(jobs) <= 1:
        if not installed:
            install(context, in_process=True)
        chunks = make_chunks(jobs, composer().group_key, 1)
        log.info(f"Running {len(jobs)} jobs in this process ({len(chunks)} chunks)")
        return _in_order(jobs, chunks, [run_chunk(c) for c in chunks])
    from joblib.externals.loky import ProcessPoolExecutor

    from .compose import JobComposer

    keyer = JobComposer(context.hydra_context.config_loader, context.config, share=context.share_composition,
                        cache_loaded=False)
    chunks = make_chunks(jobs, keyer.group_key, workers)
    workers = min(workers, len(chunks))
    log.info(f"Running {len(jobs)} jobs in {len(chunks)} chunks on {workers} worker processes")
    import os

    pool = ProcessPoolExecutor(max_workers=workers, initializer=_worker_start, initargs=(os.getpid(),
                                                                                        context.dumps()))
    ok = False
    try:
        futures = [pool.submit(run_chunk, c) for c in chunks]
        results = [f.result() for f in futures]
        ok = True
    finally:
        pool.shutdown(wait=ok, kill_workers=not ok)  # interrupted or a worker lost: stop the others now
    return _in_order(jobs, chunks, results)


def _in_order(jobs: Sequence[Job], chunks: List[List[Job]], results: List[list]) -> list:
    by_num = {}
    for chunk, rets in zip(chunks, results):
        for (num, _), r in zip(chunk, rets):
            by_num[num] = r
    return [by_num[num] for num, _ in jobs]
