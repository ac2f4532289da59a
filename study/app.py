"""The Hydra app: ``python -m study`` runs one run, ``python -m study -m a=1,2 b=x,y`` sweeps;
``python -m study train=<files> [validate=<files>] ...`` runs on the user's own records (``study.records_run``).

Each job resolves its configuration, hands it to the results store (which skips a run already finished,
records a failure without stopping the sweep, and writes the record atomically), and the table
``results/runs.parquet`` + ``results/params.parquet`` is rebuilt when the run or the sweep ends.
"""
from __future__ import annotations

import json
import logging
import os
import re
import sys
from pathlib import Path

import hydra
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

log = logging.getLogger("study")
CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")


def _register_covering_sweeper() -> None:
    """conf/config.yaml uses hydra_plugins/study_sweeper (Hydra's basic sweeper composing only a covering
    subset of the jobs up front). Hydra finds plugins by scanning the `hydra_plugins` namespace, which a
    setuptools editable install (`pip install -e .`) hides from the scan, so it is registered by hand here,
    before any config is composed."""
    from hydra.core.plugins import Plugins

    plugins = Plugins.instance()  # first: its scan re-executes Hydra's core plugin modules, BasicSweeper's too
    from hydra_plugins.study_sweeper.covering_sweeper import CoveringSweeper

    plugins.register(CoveringSweeper)


_register_covering_sweeper()


def _results_dir(cfg: DictConfig) -> Path:
    return Path(str(cfg.results_dir)).resolve()


class CollectResults(Callback):
    """Bring the results table up to date at the end of a run or of a whole sweep."""

    def _collect(self, config: DictConfig) -> None:
        from .results import ResultStore

        root = _results_dir(config)
        runs, _ = ResultStore(root).collect()
        print(f"Results: {root / 'runs.parquet'} ({len(runs)} runs), {root / 'params.parquet'}")

    def on_run_end(self, config: DictConfig, **kwargs) -> None:
        self._collect(config)

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        self._collect(config)


_STATUS = re.compile(rb'"status":\s*"(\w+)"')


def _record_status(path: Path) -> str | None:
    """A record's status from its first bytes (records are written run_id first, status second): parsing
    every record after every job made a 1188-job sweep quadratic, 1-2 s a job by its thousandth record."""
    try:
        with open(path, "rb") as fh:
            m = _STATUS.search(fh.read(256))
        if m:
            return m.group(1).decode()
        return json.loads(path.read_text(encoding="utf-8")).get("status", "?")
    except (OSError, ValueError):
        return None


_SEEN: dict = {}  # record file name -> (inode, status): what this worker process has read already


def _folder_counts(root: Path) -> dict:
    """Runs in the records folder by status. A worker reads only the records it has not seen (or that were
    replaced since: a failed run rerun; the store writes a record to a temporary file and renames it), from the
    folder's listing: reading every record after every job cost O(records)
    file opens per job (2.5 s at 30,000 records; ``benchmarks/bench_store.py``), a joblib worker now reads each
    record once per sweep."""
    counts, names = {}, set()
    if not root.is_dir():
        return counts
    for e in os.scandir(root):
        if not e.name.endswith(".json"):
            continue
        names.add(e.name)
        key = e.inode()  # from the listing itself (no stat); a rewritten record is a new file (atomic rename)
        seen = _SEEN.get(e.name)
        if seen is None or seen[0] != key:
            status = _record_status(Path(e.path))
            if status is None:
                continue
            seen = _SEEN[e.name] = (key, status)
        counts[seen[1]] = counts.get(seen[1], 0) + 1
    for gone in set(_SEEN) - names:
        del _SEEN[gone]
    return counts


class SweepProgress(Callback):
    """One line per finished job of a sweep: its number, status and time, and how many runs the results folder
    holds by status (Hydra itself lists the jobs when it launches them). Works with any launcher: the line is
    printed by the job's own process."""

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
        status = rec.get("status", "?") if isinstance(rec, dict) else "error"
        wall = (rec.get("timings") or {}).get("wall") if isinstance(rec, dict) else None
        counts = _folder_counts(_results_dir(config) / "records")
        took = f", {wall:.1f} s" if isinstance(wall, (int, float)) else ""
        resumed = " (resumed)" if isinstance(rec, dict) and rec.get("resumed") else ""
        print(f"[study] job #{num}: {status}{resumed}{took}; results folder: "
              + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())), flush=True)


@hydra.main(config_path=CONF_DIR, config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> dict:
    from .pipeline import run_study, study_config
    from .records_run import RecordsInputError
    from .results import ResultStore, run_guarded

    conf = OmegaConf.to_container(cfg, resolve=True)
    try:  # a run on the user's files (train=...): read, checksum and check them before anything is written
        run_conf, data = study_config(conf)
    except RecordsInputError as e:
        print(f"study: error: {e}", file=sys.stderr, flush=True)
        sys.exit(2)
    store = ResultStore(_results_dir(cfg))
    record = run_guarded(store, run_conf, lambda: run_study(conf, data=data), seed=int(conf.get("seed", 0)))
    status = record.get("status")
    msg = f"run {record['run_id']}: {status}" + (" (already finished, resumed)" if record.get("resumed") else "")
    if status == "failed":
        msg += "\n" + str(record.get("error", "")).strip().splitlines()[-1]
    log.info(msg)
    return record


if __name__ == "__main__":
    main()
