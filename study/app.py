"""The Hydra app: ``python -m study`` runs one run, ``python -m study -m a=1,2 b=x,y`` sweeps.

Each job resolves its configuration, hands it to the results store (which skips a run already finished,
records a failure without stopping the sweep, and writes the record atomically), and the table
``results/runs.parquet`` + ``results/params.parquet`` is rebuilt when the run or the sweep ends.
"""
from __future__ import annotations

import logging
from pathlib import Path

import hydra
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

log = logging.getLogger("study")
CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")


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


@hydra.main(config_path=CONF_DIR, config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> dict:
    from .pipeline import run_study
    from .results import ResultStore, run_guarded

    conf = OmegaConf.to_container(cfg, resolve=True)
    store = ResultStore(_results_dir(cfg))
    record = run_guarded(store, conf, lambda: run_study(conf), seed=int(conf.get("seed", 0)))
    status = record.get("status")
    msg = f"run {record['run_id']}: {status}" + (" (already finished, resumed)" if record.get("resumed") else "")
    if status == "failed":
        msg += "\n" + str(record.get("error", "")).strip().splitlines()[-1]
    log.info(msg)
    return record


if __name__ == "__main__":
    main()
