"""The Hydra app: ``python -m study`` runs one run, ``python -m study -m a=1,2 b=x,y`` sweeps;
``python -m study train=<files> [validate=<files>] ...`` runs on the user's own records
(``study.run.records_run``).

Each job resolves its configuration, hands it to the results store (which skips a run already
finished by the current code, leaves a run that another live process is computing to it in a sweep
and waits for it in a single run, records a failure without stopping the sweep, and writes the
record atomically), and the table ``results/runs.parquet`` + ``results/params.parquet`` is rebuilt
when the run or the sweep ends. A results folder that cannot be written is refused before the first
job (exit status 2), and a failed rebuild exits with status 1.
"""
from __future__ import annotations

import logging
import os
import sys
import warnings
from pathlib import Path

import hydra
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from study.configuration import compose as config
from study.configuration.cli import EXIT_FAILED, EXIT_USAGE, fail, report, reported, run_hydra, status

log = logging.getLogger("study")
CONF_DIR = str(config.CONF_DIR)  # Hydra's config_path


def _register_plugins() -> None:
    """conf/config.yaml uses hydra_plugins/study_sweeper (Hydra's basic sweeper composing only a
    covering subset of the jobs up front), conf/hydra/launcher/ hydra_plugins/study_launcher (the
    launchers running a sweep's jobs in long-lived workers). Hydra finds plugins by scanning the
    `hydra_plugins` namespace, which a setuptools editable install (`pip install -e .`) hides
    from the scan, so they are registered by hand here, before any config is composed."""
    from hydra.core.plugins import Plugins

    plugins = Plugins.instance()  # first: its scan re-executes Hydra's core plugin modules, BasicSweeper's too
    from hydra_plugins.study_launcher.launchers import StudyLocalLauncher, StudySlurmLauncher
    from hydra_plugins.study_sweeper.covering_sweeper import CoveringSweeper

    for plugin in (CoveringSweeper, StudyLocalLauncher, StudySlurmLauncher):
        plugins.register(plugin)


_register_plugins()


def _results_dir(cfg: DictConfig) -> Path:
    return Path(str(cfg.results_dir)).resolve()


def precheck(overrides: list, multirun: bool) -> None:
    """Every check of ``python -m study``, on the configuration composed from the command line,
    before Hydra makes its output folder (``<results_dir>/logs/...``) or anything else: the
    classes the configuration names, in Hydra's own node too (callbacks, launcher, sweeper: the
    trusted-code boundary), the settings (``study.run.settings.check_run``: values, enumerated
    settings, settings that must fit together), the results folder writable, and a run's records
    read and checked against the vessel. A sweep's jobs are checked by the sweeper, before it
    writes anything."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from study.configuration.cli import ConfigError
    from study.configuration.compose import check_target, check_targets, compose
    from study.store import ResultsFolderError, ResultStore
    from study.run.settings import check_run

    parsed = OverridesParser.create().parse_overrides(overrides)
    sweeps = [o for o in parsed if o.is_sweep_override()]
    for o in sweeps:
        if o.get_key_element().split("@")[0].endswith("_target_"):
            for v in o.sweep_string_iterator():
                check_target(v, o.get_key_element())
    conf = compose("config", [o.input_line for o in parsed if not o.is_sweep_override()] if multirun
                   else overrides, hydra=True)
    check_targets(conf)
    if multirun or str(conf["hydra"].get("mode")) in ("MULTIRUN", "RunMode.MULTIRUN"):
        return
    task = {k: v for k, v in conf.items() if k != "hydra"}
    check_run(task)
    try:
        ResultStore(Path(str(task["results_dir"])).resolve()).check_writable()
    except ResultsFolderError as e:
        raise ConfigError(f"results_dir={task['results_dir']}: {e}") from None
    from study.run.pipeline import study_config

    study_config(task)  # a run on the user's records: read and checked against the vessel


class CollectResults(Callback):
    """Refuse a results folder that cannot be written before the first job; bring the results
    table up to date at the end of a run or of a whole sweep (a failure to do so exits with
    status 1, the records intact)."""

    def _check(self, config: DictConfig) -> None:
        from study.store import ResultsFolderError, ResultStore

        try:
            ResultStore(_results_dir(config)).check_writable()
        except ResultsFolderError as e:
            print(f"study: error: {e}", file=sys.stderr, flush=True)
            sys.exit(2)

    def on_run_start(self, config: DictConfig, **kwargs) -> None:
        from study.configuration.cli import UsageError
        from study.run.settings import check_run

        try:  # a setting that makes no sense is refused before the results folder is even created
            # (a sweep's jobs are checked by the sweeper); the hydra node cannot be resolved in a callback
            check_run({k: OmegaConf.to_container(config[k], resolve=True) if OmegaConf.is_config(config[k])
                       else config[k] for k in config if k != "hydra"})
        except UsageError as e:
            sys.exit(report(e, "study"))  # one line (the traceback with --verbose), exit status 2
        self._check(config)

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        self._check(config)

    def _collect(self, config: DictConfig) -> None:
        from study.store import ResultStore

        root = _results_dir(config)
        store = ResultStore(root)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # printed from the report below
                runs, _ = store.collect()
        except Exception as e:  # Hydra turns a callback's exception into a warning and exit status 0
            print(f"study: error: the results table was not rebuilt: {type(e).__name__}: {e} (the records in "
                  f"{root / 'records'} are kept; `python -m study results rebuild --root {root}` retries)",
                  file=sys.stderr, flush=True)
            sys.exit(1)
        for line in store.report.lines():
            print(f"study: {line}", file=sys.stderr, flush=True)
        print(f"Results: {root / 'runs.parquet'} ({len(runs)} runs), {root / 'params.parquet'}")

    def on_run_end(self, config: DictConfig, **kwargs) -> None:
        if status() >= EXIT_USAGE:  # the run was refused before any work: nothing is written, not even a table
            return
        self._collect(config)

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        self._collect(config)


#: the number of jobs of the running sweep, set by the sweeper before it launches them (an environment variable:
#: jobs may run in other processes, which inherit it)
SWEEP_JOBS_ENV = "STUDY_SWEEP_JOBS"

_STORES: dict = {}  # results folder -> its store in this worker process (it remembers the records it has read)


def _folder_counts(root: Path) -> dict:
    """Runs in the results folder by status (``ResultStore.status_counts``: each record read once
    per worker)."""
    from study.store import ResultStore

    store = _STORES.get(root)
    if store is None:
        store = _STORES[root] = ResultStore(root)
    return store.status_counts()


class SweepProgress(Callback):
    """One line per finished job of a sweep: its number out of the sweep's total, status (a
    skipped run's reason) and time, and how many runs the results folder holds by status (Hydra
    itself lists the jobs when it launches them). Works with any launcher: the line is printed by
    the job's own process."""

    def on_job_end(self, config: DictConfig, job_return, **kwargs) -> None:
        from hydra.core.hydra_config import HydraConfig

        try:
            hc = HydraConfig.get()
            if hc.mode is None or str(hc.mode) != "RunMode.MULTIRUN":
                return
            num = hc.job.num
        except ValueError:
            return
        rec = job_return.return_value if job_return is not None and job_return.status.name == "COMPLETED" else None
        status_ = rec.get("status", "?") if isinstance(rec, dict) else "error"
        wall = (rec.get("timings") or {}).get("wall") if isinstance(rec, dict) else None
        counts = _folder_counts(_results_dir(config))
        took = f", {wall:.1f} s" if isinstance(wall, (int, float)) else ""
        resumed = " (resumed)" if isinstance(rec, dict) and rec.get("resumed") else ""
        why = f" ({_reason(rec)})" if status_ == "skipped" and not resumed else ""
        reps = rec.get("replicates") if isinstance(rec, dict) else None
        if isinstance(reps, dict):  # a job of many datasets: its replicates by status
            why += f" ({sum(reps.values())} replicates: " + ", ".join(f"{v} {k}" for k, v in sorted(reps.items())) + ")"
        total = os.environ.get(SWEEP_JOBS_ENV, "").strip()
        # one write of the whole line: workers share the stdout, and print() writes the text and its newline
        # apart (two workers' lines were seen joined on one line)
        sys.stdout.write(f"[study] job {num + 1}/{total or '?'}: {status_}{resumed}{why}{took}; results folder: "
                         + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())) + "\n")
        sys.stdout.flush()


def _in_sweep() -> bool:
    from hydra.core.hydra_config import HydraConfig

    try:
        return str(HydraConfig.get().mode) == "RunMode.MULTIRUN"
    except ValueError:  # not under Hydra (a test calling main's pieces)
        return False


@hydra.main(config_path=CONF_DIR, config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> dict | None:
    with reported("study"):  # a problem: one line on stderr and the exit status (study.configuration.cli)
        return _run(cfg)
    return None


def distinct_datasets(conf: dict, n: int) -> int:
    """How many of ``n`` replicates are distinct datasets: one when nothing in the configuration
    draws at random (no measurement noise, no coloured noise, outliers or dropouts, no
    random-rudder manoeuvre), since every replicate would then be the same records and counting
    them as independent evidence would be false; else ``n``. An estimator's own randomness
    (differential evolution's population) is no new dataset."""
    if n <= 1 or conf.get("train"):
        return n
    from study.sim.maneuvers import get_maneuver

    noise = conf.get("noise") or {}
    level = noise.get("level")
    levels = list(level.values()) if isinstance(level, dict) else [level]
    drawn = (noise.get("kind") == "absolute" or any(float(v or 0.0) > 0 for v in levels)
             or any(noise.get(k) for k in ("colored", "outliers", "dropouts")))
    random = any(get_maneuver(m).type == "random" for m in (conf.get("maneuvers") or {}).get("train") or [])
    return n if drawn or random else 1


def _run(cfg: DictConfig) -> dict:
    from study.configuration.cli import ConfigError
    from study.run.executor import RESUME_MODES, run_guarded, run_replicated
    from study.run.pipeline import SimulatedJob, run_study, study_config
    from study.run.settings import check_run
    from study.store import ResultStore

    conf = OmegaConf.to_container(cfg, resolve=True)
    check_run(conf)  # a setting that makes no sense is refused before anything is simulated or written
    resume = conf.get("resume") or "code"
    if resume not in RESUME_MODES:
        raise ConfigError(f"resume={resume}: expected one of {', '.join(RESUME_MODES)}")
    asked = int(conf.get("replicates", 1))
    n = distinct_datasets(conf, asked)
    if n < asked and not _in_sweep():
        print(f"replicates={asked}: nothing in this configuration is drawn at random (no measurement noise, no "
              "random-rudder manoeuvre), so its datasets are identical: one is computed", flush=True)
    # a run on the user's files (train=...): read, checksum and check them before anything is written
    run_conf, data = study_config(conf)
    run_conf.pop("replicates", None)  # how many datasets a job draws is no part of any one dataset's run
    store = ResultStore(_results_dir(cfg))
    seed, force = int(conf.get("seed", 0)), bool(conf.get("force", False))
    # in a sweep, a run another live process is computing (an overlapping sweep) is left to it; a single run waits
    if data is not None:
        records = [run_guarded(store, run_conf, lambda: run_study(conf, data=data), seed=seed, force=force,
                               resume=resume, wait=not _in_sweep())]
    else:
        records = run_replicated(store, run_conf, SimulatedJob(conf), n, seed, force=force, resume=resume,
                                 wait=not _in_sweep())
    for record in records:
        _say_run(record, store)
    if not _in_sweep():
        print(_key_numbers(records, store.root, on_records=data is not None,
                          drawn=distinct_datasets(conf, 2) > 1), flush=True)
    failed = [r for r in records if r.get("status") == "failed"]
    if failed and not _in_sweep():  # a sweep goes on; it ends with its count of failed runs (sweep_summary.sweep_finished)
        fail(EXIT_FAILED)
    return records[0] if n == 1 else _job_summary(records)


def _say_run(record: dict, store) -> None:
    status = record.get("status")
    rep = record.get("replicate")
    msg = f"run {record['run_id']}" + (f" (replicate {rep})" if rep else "") + f": {status}" + \
        (" (already finished, resumed)" if record.get("resumed") else "")
    if status == "claimed":
        by = record.get("claimed_by") or {}
        msg += f" (being computed by process {by.get('pid', '?')} on {by.get('host', '?')}; left to it)"
    if status == "skipped":
        msg += f": {_reason(record)}"
    log.info(msg)
    if status == "failed":
        print(f"study: error: run {record['run_id']} failed: {_reason(record)} (the traceback: "
              f"{store.root / 'records'}/{record['run_id']}.json, or python -m study results show)",
              file=sys.stderr, flush=True)


def _key_numbers(records: list, root: Path, on_records: bool = False, drawn: bool = True) -> str:
    """What a run found, in two lines: its median coefficient error, the held-out prediction
    error of each validation manoeuvre's heading and the time (medians and the range over
    datasets for replicates), and the next command to try (more datasets only where they would
    differ: ``drawn``)."""
    import numpy as np

    ok = [r for r in records if r.get("status") == "ok"]
    if not ok:
        return f"Nothing identified ({', '.join(sorted({str(r.get('status')) for r in records}))})."

    def figure(key: str, scale: float = 1.0, unit: str = "") -> str | None:
        vals = np.array([float(m[key]) for m in (r.get("metrics") or {} for r in ok)
                         if isinstance(m.get(key), (int, float))], float) * scale
        vals = vals[np.isfinite(vals)]
        if not len(vals):
            return None
        if len(vals) == 1:
            return f"{vals[0]:.3g}{unit}"
        return f"{np.median(vals):.3g}{unit} (median of {len(vals)} datasets, {vals.min():.3g}-{vals.max():.3g})"

    parts = []
    drift = figure("drift_median", 100.0, " %")
    if drift:
        parts.append(f"median coefficient error {drift}")
    names = sorted({k[len("val_"):-len("_nrmse_psi")] for r in ok for k in (r.get("metrics") or {})
                    if k.startswith("val_") and k.endswith("_nrmse_psi")})
    for n in names:
        v = figure(f"val_{n}_nrmse_psi")
        if v:
            parts.append(f"{n} heading NRMSE {v}")
    wall = sum(float((r.get("timings") or {}).get("wall") or 0.0) for r in ok if not r.get("resumed"))
    if wall:
        parts.append(f"{wall:.1f} s computing")
    many = len(records) > 1
    nxt = (f"python -m study results show --root {root}" if many or on_records or not drawn else
           "python -m study replicates=20 (the same configuration on 20 independent datasets)")
    found = "; ".join(parts) if parts else ("no truth and no held-out records to score the identified model "
                                            "against (validate=<files> replays held-out records)")
    return f"Found: {found}.\nNext: {nxt}; every column: {root / 'runs.parquet'}"


def _job_summary(records: list) -> dict:
    """What a job of many replicates returns to the sweep: its worst status, counts by status,
    total time."""
    counts: dict = {}
    for r in records:
        counts[r.get("status", "?")] = counts.get(r.get("status", "?"), 0) + 1
    status = next((s for s in ("failed", "claimed", "ok", "skipped") if s in counts), "?")
    first_bad = next((r for r in records if r.get("status") == status), records[0])
    wall = sum(float((r.get("timings") or {}).get("wall") or 0.0) for r in records if not r.get("resumed"))
    return {"run_id": records[0]["run_id"], "status": status, "error": first_bad.get("error"),
            "replicates": counts, "timings": {"wall": wall}, "resumed": all(r.get("resumed") for r in records)}


def _reason(record: dict) -> str:
    """A skipped run's reason, or a failed run's error (the last line of its traceback)."""
    lines = str(record.get("error") or "").strip().splitlines()
    return lines[-1].strip() if lines else "(no reason recorded)"


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    run_hydra(main, "study", precheck)
