"""The results store: one atomic JSON record per run, resume, and the two parquet tables.

Every run, ok or failed, lands as exactly one record; the tables are always rebuilt from the records
(benchopt-style: the records are the truth, the tables a cache). Full description: ``results/README.md``.

Layout under the results folder ``root`` (default ``results/``)::

    records/<run_id>.json               one record per run (written to a temp file, then os.replace)
    records/failed/<run_id>.<ts>.json   earlier failed attempts, kept when a run is retried
    artefacts/<run_id>/...              large files of one run (one folder per run, never shared)
    runs.parquet                        one row per run
    params.parquet                      one row per identified parameter (long form)

``run_id`` is the first 16 hex characters of the sha256 of the canonical JSON of the scientific
configuration (everything but ``hydra`` and the keys in :data:`NON_SCIENTIFIC_KEYS`).

runs.parquet columns: ``run_id``, ``status`` (ok / failed / skipped), ``error``, ``seed``, ``started``,
``finished``, ``wall_time`` [s], ``artefacts`` (JSON list), ``prov_*`` (git_rev, package versions, platform,
hostname, threads, ...), ``cfg_*`` (configuration flattened with dotted keys, list/dict leaves as JSON),
``m_*`` (metrics), ``t_*`` (timings [s]).

params.parquet columns: ``run_id``, ``equation``, ``name``, ``estimate``, ``truth``, ``rel_error``,
``abs_error``, the optional numbers of :data:`PARAM_OPTIONAL` (``ci_low``, ``ci_high``, ``std``, ``vif``,
``selected``, ``prior_mean``, ``prior_sd``, ``identifiability``, ``term_scale``, ``scaled_error``; NaN where a run
has none), ``truth_kind`` and the copied config columns of :data:`PARAM_CONFIG_COLUMNS` that exist.

CLI: ``python -m study.results rebuild [--root results]`` and ``python -m study.results show [--root results]``.
"""
from __future__ import annotations

import argparse
import functools
import hashlib
import io
import json
import math
import numbers
import os
import platform
import shutil
import socket
import subprocess
import sys
import time
import traceback
import uuid
import warnings
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd
from filelock import FileLock

#: Top-level configuration keys that do not change the science of a run, so they are left out of the run id.
NON_SCIENTIFIC_KEYS = frozenset({"hydra", "results_dir", "out", "launcher", "progress", "n_jobs", "artefacts"})

#: Record status values; 'ok' and 'skipped' count as finished (resume skips them), 'failed' is rerun.
STATUSES = ("ok", "failed", "skipped")
FINISHED_STATUSES = frozenset({"ok", "skipped"})

#: Fields every record must carry (``provenance`` and ``artefacts`` are added by the store).
REQUIRED_FIELDS = ("run_id", "status", "config", "metrics", "params", "timings", "seed", "error",
                   "started", "finished")

#: Keys every entry of ``params`` must have; the optional ones default to None.
PARAM_REQUIRED = ("equation", "name", "estimate", "truth")
PARAM_OPTIONAL = ("ci_low", "ci_high", "std", "vif", "selected",
                  # prior-anchored fits (estimator map, emcee with a prior): the prior and posterior sd / prior sd
                  "prior_mean", "prior_sd", "identifiability",
                  # the term's share of its equation and the error scaled by it (study.identify.fit.term_scales)
                  "term_scale", "scaled_error")
#: Optional text keys of a params entry: how the truth was obtained ('exact', 'approximate', 'derived', ...).
PARAM_TEXT = ("truth_kind",)

#: Config columns copied into the params table (when present) so it can be filtered without a join.
PARAM_CONFIG_COLUMNS = ("cfg_vessel.name", "cfg_model.name", "cfg_estimator.name", "cfg_structure.name",
                        "cfg_noise.level")

#: Distributions whose versions go into the provenance.
PROVENANCE_PACKAGES = ("numpy", "scipy", "scikit-learn", "pandas", "pysindy", "emcee", "numba", "hydra-core")

RUN_BASE_COLUMNS = ["run_id", "status", "error", "seed", "started", "finished", "wall_time", "artefacts"]
PARAM_BASE_COLUMNS = ["run_id", "equation", "name", "estimate", "truth", "rel_error", "abs_error",
                      "ci_low", "ci_high", "std", "vif", "selected", "truth_kind"]

REPO_ROOT = Path(__file__).resolve().parents[1]
# a per-run lock is held only for the few ms of a write; the timeout guards against a wedged file system
_WRITE_LOCK_TIMEOUT = 300.0
_COLLECT_LOCK_TIMEOUT = 600.0


# --------------------------------------------------------------------------------------------------- helpers

def _now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="microseconds")


def _json_default(obj: Any) -> Any:
    """Make numpy scalars/arrays and paths JSON-serialisable (configs and metrics often carry them)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (Path, os.PathLike)):
        return os.fspath(obj)
    if isinstance(obj, (set, frozenset)):
        return sorted(obj, key=str)
    return str(obj)


def _dumps(obj: Any, **kw) -> str:
    return json.dumps(obj, default=_json_default, ensure_ascii=False, **kw)


def _atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see either the old file or the complete new one.

    The temp file lives in the same folder (``os.replace`` is only atomic within one file system) and starts
    with a dot and ends in ``.tmp`` so that no glob for ``*.json`` / ``*.parquet`` ever picks it up. It is
    created with mode 0666 minus the umask (not mkstemp's 0600) so a shared results folder stays readable.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())  # the rename must not land before the data on a crash
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _is_number(x: Any) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _is_scalar(x: Any) -> bool:
    return x is None or isinstance(x, (str, bool, numbers.Number, np.generic))


def _stamp() -> str:
    """A file-name-safe UTC timestamp for archived attempts."""
    return datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S.%fZ")


def _unique(path: Path) -> Path:
    """``path`` or, if taken, ``path`` with ``-1``, ``-2``... before the suffix (archives never overwrite)."""
    if not path.exists():
        return path
    stem, suffix = (path.name[: -len(".json")], ".json") if path.name.endswith(".json") else (path.name, "")
    i = 1
    while (cand := path.with_name(f"{stem}-{i}{suffix}")).exists():
        i += 1
    return cand


# ------------------------------------------------------------------------------------------------- run ids

def scientific_config(config: dict) -> dict:
    """The part of ``config`` that defines the science of a run (drops :data:`NON_SCIENTIFIC_KEYS`)."""
    return {k: v for k, v in config.items() if k not in NON_SCIENTIFIC_KEYS}


def run_id(config: dict) -> str:
    """Stable identifier of a run: sha256 of the canonical JSON of its scientific configuration.

    Parameters
    ----------
    config : dict
        The resolved configuration (e.g. ``OmegaConf.to_container(cfg, resolve=True)``). Anything under
        ``hydra`` and the top-level keys in :data:`NON_SCIENTIFIC_KEYS` are ignored.

    Returns
    -------
    str
        The first 16 hex characters of the digest; independent of key order and of the process.
    """
    if not isinstance(config, dict):
        raise TypeError(f"run_id needs the configuration as a dict, got {type(config).__name__}")
    canon = _dumps(scientific_config(config), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canon.encode("utf-8")).hexdigest()[:16]


# ---------------------------------------------------------------------------------------------- provenance

def _git_rev(repo: Path) -> str:
    try:
        # --no-optional-locks: `git status` must never take index.lock and collide with a commit in progress
        top = subprocess.run(["git", "-C", str(repo), "rev-parse", "--show-toplevel", "HEAD"],
                             capture_output=True, text=True, timeout=10)
        lines = top.stdout.split()
        # the package must be the checkout itself, not an installed copy that happens to sit inside some repo
        if top.returncode != 0 or len(lines) != 2 or Path(lines[0]).resolve() != repo.resolve():
            return "unknown"
        dirty = subprocess.run(["git", "--no-optional-locks", "-C", str(repo), "status", "--porcelain"],
                               capture_output=True, text=True, timeout=30)
        suffix = "-dirty" if dirty.returncode != 0 or dirty.stdout.strip() else ""
        return lines[1] + suffix
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def _env_int(name: str) -> int | None:
    v = os.environ.get(name)
    try:
        return int(v) if v not in (None, "") else None
    except ValueError:
        return None


@functools.lru_cache(maxsize=1)
def _provenance_cached() -> tuple:
    prov: dict[str, Any] = {"git_rev": _git_rev(REPO_ROOT), "python": platform.python_version()}
    for dist in PROVENANCE_PACKAGES:
        prov[dist] = _version(dist)
    prov.update(platform=platform.platform(), hostname=socket.gethostname(), threads=os.cpu_count(),
                omp_num_threads=_env_int("OMP_NUM_THREADS"), numba_num_threads=_env_int("NUMBA_NUM_THREADS"))
    return tuple(prov.items())


def provenance() -> dict:
    """Where and with what a run was computed (cached per process: git is asked once).

    Returns
    -------
    dict
        ``git_rev`` (commit hash, ``-dirty`` appended with uncommitted changes, ``'unknown'`` outside a git
        checkout), ``python`` and the versions of :data:`PROVENANCE_PACKAGES` (None when not installed),
        ``platform``, ``hostname``, ``threads`` (``os.cpu_count()``), ``omp_num_threads`` and
        ``numba_num_threads`` (the env variables, None when unset).
    """
    return dict(_provenance_cached())  # a fresh dict so callers cannot alter the cache


# -------------------------------------------------------------------------------------------------- records

def validate_record(record: dict) -> None:
    """Raise ``ValueError`` (with every problem listed) unless ``record`` is a well-formed run record."""
    if not isinstance(record, dict):
        raise ValueError(f"a record must be a dict, got {type(record).__name__}")
    errs = [f"missing field {k!r}" for k in REQUIRED_FIELDS if k not in record]
    if errs:
        raise ValueError("invalid record: " + "; ".join(errs))
    if record["status"] not in STATUSES:
        errs.append(f"status {record['status']!r} not in {STATUSES}")
    if not isinstance(record["config"], dict):
        errs.append("config must be a dict")
    elif not isinstance(record["run_id"], str) or record["run_id"] != run_id(record["config"]):
        errs.append(f"run_id {record['run_id']!r} does not match run_id(config) = {run_id(record['config'])!r}")
    if not isinstance(record["metrics"], dict):
        errs.append("metrics must be a dict")
    else:
        errs += [f"metric {k!r} is not a scalar ({type(v).__name__})"
                 for k, v in record["metrics"].items() if not _is_scalar(v)]
    if not isinstance(record["timings"], dict):
        errs.append("timings must be a dict of seconds")
    else:
        errs += [f"timing {k!r} is not a number of seconds" for k, v in record["timings"].items()
                 if not (_is_number(v) or v is None)]
    if not isinstance(record["params"], list):
        errs.append("params must be a list of dicts")
    else:
        for i, p in enumerate(record["params"]):
            if not isinstance(p, dict):
                errs.append(f"params[{i}] is not a dict")
                continue
            errs += [f"params[{i}] lacks {k!r}" for k in PARAM_REQUIRED if k not in p]
            errs += [f"params[{i}][{k!r}] is not a number or None" for k in ("estimate", "truth", *PARAM_OPTIONAL)
                     if k in p and not (p[k] is None or _is_number(p[k]))]
            errs += [f"params[{i}][{k!r}] is not a string or None" for k in PARAM_TEXT
                     if k in p and not (p[k] is None or isinstance(p[k], str))]
    if record["seed"] is not None and not isinstance(record["seed"], numbers.Integral):
        errs.append("seed must be an int or None")
    err = record["error"]
    if err is not None and not isinstance(err, str):
        errs.append("error must be a str or None")
    if record["status"] in ("failed", "skipped") and not (isinstance(err, str) and err.strip()):
        errs.append(f"a {record['status']} record needs the reason in 'error'")
    for k in ("started", "finished"):
        try:
            datetime.fromisoformat(str(record[k]))
        except ValueError:
            errs.append(f"{k} {record[k]!r} is not an ISO time")
    if errs:
        raise ValueError(f"invalid record {record.get('run_id')!r}: " + "; ".join(errs))


def _check_artefacts(artefacts: dict | None) -> dict:
    """Validate ``{name: bytes | path}``: names stay inside the run folder, paths exist."""
    if not artefacts:
        return {}
    if not isinstance(artefacts, dict):
        raise ValueError("artefacts must be a dict name -> bytes or path")
    for name, value in artefacts.items():
        parts = Path(str(name)).parts
        if not parts or Path(str(name)).is_absolute() or ".." in parts:
            raise ValueError(f"artefact name {name!r} must be a relative path inside the run's folder")
        if isinstance(value, (bytes, bytearray, memoryview)):
            continue
        if isinstance(value, (str, os.PathLike)):
            if not Path(value).exists():
                raise ValueError(f"artefact {name!r}: {value} does not exist")
            continue
        raise ValueError(f"artefact {name!r} must be bytes or a path, got {type(value).__name__}")
    return artefacts


# -------------------------------------------------------------------------------------------------- tables

def _flatten(d: dict, prefix: str = "") -> dict:
    """Dotted keys for nested dicts; list leaves and empty dicts become JSON so each column has one type."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(_flatten(v, key + "."))
        elif isinstance(v, (dict, list, tuple)):
            out[key] = _dumps(v, sort_keys=True)
        else:
            out[key] = v
    return out


def _unify(col: pd.Series) -> pd.Series:
    """Give an object column one parquet type: numbers -> float, mixed kinds -> JSON text."""
    if col.dtype != object:
        return col
    vals = col.dropna()
    kinds = {"bool" if isinstance(v, (bool, np.bool_)) else "num" if isinstance(v, numbers.Number)
             else "str" if isinstance(v, str) else "other" for v in vals}
    if not kinds:
        return col.astype(float) if len(col) else col  # all None: float NaN is the cheapest parquet type
    if kinds == {"num"}:
        return pd.to_numeric(col, errors="coerce")
    if kinds in ({"str"}, {"bool"}):
        return col
    return col.map(lambda v: v if v is None or isinstance(v, str) or (isinstance(v, float) and math.isnan(v))
                   else _dumps(v))


def _finite_float(x: Any) -> float:
    return float(x) if _is_number(x) else math.nan


def _run_row(rec: dict) -> dict:
    timings = rec.get("timings") or {}
    wall = timings.get("wall")
    if not _is_number(wall):
        try:
            wall = (datetime.fromisoformat(rec["finished"]) - datetime.fromisoformat(rec["started"])).total_seconds()
        except (TypeError, ValueError, KeyError):
            wall = math.nan
    row = {"run_id": rec["run_id"], "status": rec["status"], "error": rec.get("error"), "seed": rec.get("seed"),
           "started": rec.get("started"), "finished": rec.get("finished"), "wall_time": float(wall),
           "artefacts": _dumps(rec.get("artefacts") or [])}
    row.update({f"prov_{k}": v for k, v in _flatten(rec.get("provenance") or {}).items()})
    cfg = {k: v for k, v in (rec.get("config") or {}).items() if k != "hydra"}
    row.update({f"cfg_{k}": v for k, v in _flatten(cfg).items()})
    row.update({f"m_{k}": v for k, v in (rec.get("metrics") or {}).items()})
    row.update({f"t_{k}": v for k, v in timings.items()})
    return row


def _param_rows(rec: dict, run_row: dict) -> list[dict]:
    copied = {c: run_row[c] for c in PARAM_CONFIG_COLUMNS if c in run_row}
    rows = []
    for p in rec.get("params") or []:
        est, truth = _finite_float(p.get("estimate")), _finite_float(p.get("truth"))
        nonzero = not math.isnan(truth) and truth != 0.0
        rows.append({"run_id": rec["run_id"], "equation": str(p.get("equation")), "name": str(p.get("name")),
                     "estimate": est, "truth": truth,
                     "rel_error": (est - truth) / abs(truth) if nonzero else math.nan,
                     "abs_error": abs(est - truth),  # NaN when truth is unknown (NaN propagates)
                     **{k: _finite_float(p.get(k)) for k in PARAM_OPTIONAL},
                     **{k: p.get(k) for k in PARAM_TEXT}, **copied})
    return rows


def _frame(rows: list[dict], base: list[str]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    for c in base:
        if c not in df:
            df[c] = pd.Series(dtype=object if c not in ("wall_time", "estimate", "truth", "rel_error", "abs_error",
                                                        *PARAM_OPTIONAL) else float)
    df = df[base + [c for c in df.columns if c not in base]]
    for c in df.columns:
        if c != "error":  # error stays text (or null) whatever the other columns hold
            df[c] = _unify(df[c])
    return df


# ----------------------------------------------------------------------------------------------------- store

class ResultStore:
    """The results folder: records (the truth), artefacts, and the two parquet tables (rebuilt from records).

    Parameters
    ----------
    root : str or Path, optional
        The results folder; default ``$STUDY_RESULTS_DIR`` if set, else ``results/``.
    """

    def __init__(self, root: str | os.PathLike | None = None):
        self.root = Path(root if root is not None else os.environ.get("STUDY_RESULTS_DIR") or "results")
        self.records_dir = self.root / "records"
        self.failed_dir = self.records_dir / "failed"
        self.artefacts_root = self.root / "artefacts"
        self.runs_path = self.root / "runs.parquet"
        self.params_path = self.root / "params.parquet"

    def __repr__(self) -> str:
        return f"ResultStore({str(self.root)!r})"

    # -- paths and reading
    def record_path(self, rid: str) -> Path:
        """Where the record of run ``rid`` lives."""
        return self.records_dir / f"{rid}.json"

    def artefact_dir(self, rid: str) -> Path:
        """The folder of run ``rid``'s large files (owned by that run only)."""
        return self.artefacts_root / rid

    def read(self, rid: str) -> dict | None:
        """The record of ``rid``, or None when absent or unreadable (a torn record counts as absent)."""
        try:
            rec = json.loads(self.record_path(rid).read_text(encoding="utf-8"))
        except (FileNotFoundError, ValueError, UnicodeDecodeError):
            return None
        return rec if isinstance(rec, dict) else None

    def finished(self, rid: str) -> bool:
        """True when run ``rid`` need not run again: its record says 'ok' or 'skipped' ('failed' reruns)."""
        rec = self.read(rid)
        return rec is not None and rec.get("status") in FINISHED_STATUSES

    # -- writing
    def _lock(self, rid: str) -> FileLock:
        # one lock per run: writers of different runs never wait for each other
        lock_dir = self.records_dir / ".locks"
        lock_dir.mkdir(parents=True, exist_ok=True)
        return FileLock(str(lock_dir / f"{rid}.lock"), timeout=_WRITE_LOCK_TIMEOUT)

    def write(self, record: dict, overwrite: bool = False, artefacts: dict | None = None) -> Path:
        """Validate ``record``, add the provenance, and write it atomically as ``records/<run_id>.json``.

        Parameters
        ----------
        record : dict
            See :data:`REQUIRED_FIELDS` and ``results/README.md``. ``provenance`` is added when absent.
        overwrite : bool
            Replace an existing 'ok' or 'skipped' record (otherwise ``FileExistsError``).
        artefacts : dict, optional
            ``{relative name: bytes or path}``; bytes are written, paths moved into ``artefacts/<run_id>/``.
            Their names are stored in the record's ``artefacts`` list.

        Returns
        -------
        Path
            The record's file.

        Raises
        ------
        FileExistsError
            A finished ('ok'/'skipped') record of this run exists and ``overwrite`` is False; it is unchanged.
        ValueError
            The record or the artefacts are malformed.

        Notes
        -----
        An existing 'failed' (or unreadable) record is not lost: it is moved to
        ``records/failed/<run_id>.<timestamp>.json`` and its artefact folder, if any, to
        ``artefacts/failed/<run_id>.<timestamp>/``. The check and the replace happen under a per-run file lock,
        so two processes finishing the same run produce exactly one record.
        """
        validate_record(record)
        artefacts = _check_artefacts(artefacts)
        # a fixed, readable key order: the verdict first, the bulky parts last
        first = ("run_id", "status", "error", "seed", "started", "finished")
        rec = {**{k: record[k] for k in first}, **{k: v for k, v in record.items() if k not in first}}
        rec.setdefault("provenance", provenance())
        rec["artefacts"] = sorted(Path(str(n)).as_posix() for n in artefacts) if artefacts else \
            list(rec.get("artefacts") or [])
        data = _dumps(rec, indent=1).encode("utf-8")  # fails here, before anything on disk changes
        rid = rec["run_id"]
        path = self.record_path(rid)
        with self._lock(rid):
            old_status = None
            if path.exists():
                old = self.read(rid)
                old_status = old.get("status") if old is not None else "corrupt"
                if old_status in FINISHED_STATUSES and not overwrite:
                    raise FileExistsError(f"{path} already holds a finished ({old_status!r}) record of run {rid}; "
                                          "pass overwrite=True to replace it")
            stamp = _stamp()
            if old_status not in FINISHED_STATUSES and path.exists():
                # keep the earlier failed / unreadable attempt
                self.failed_dir.mkdir(parents=True, exist_ok=True)
                os.replace(path, _unique(self.failed_dir / f"{rid}.{stamp}.json"))
            adir = self.artefact_dir(rid)
            if adir.exists():
                if old_status in FINISHED_STATUSES:
                    if artefacts:  # explicit overwrite with new files: the old run's files go
                        shutil.rmtree(adir)
                else:  # files of a failed attempt, or of a crash between artefacts and record: keep them
                    dest = _unique(self.artefacts_root / "failed" / f"{rid}.{stamp}")
                    dest.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(adir, dest)
            if artefacts:
                self._place_artefacts(rid, artefacts)
            _atomic_write_bytes(path, data)
        return path

    def _place_artefacts(self, rid: str, artefacts: dict) -> None:
        # build the folder under a temp name and rename it: the run's folder appears complete or not at all
        self.artefacts_root.mkdir(parents=True, exist_ok=True)
        tmp = self.artefacts_root / f".tmp-{rid}-{uuid.uuid4().hex}"
        tmp.mkdir()
        try:
            for name, value in artefacts.items():
                dest = tmp / Path(str(name))
                dest.parent.mkdir(parents=True, exist_ok=True)
                if isinstance(value, (bytes, bytearray, memoryview)):
                    dest.write_bytes(bytes(value))
                else:
                    shutil.move(os.fspath(value), dest)
            os.replace(tmp, self.artefact_dir(rid))
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise

    # -- tables
    def _records(self) -> list[dict]:
        recs = []
        if not self.records_dir.is_dir():
            return recs
        for p in sorted(self.records_dir.glob("*.json")):
            try:
                rec = json.loads(p.read_text(encoding="utf-8"))
                if not isinstance(rec, dict) or not all(k in rec for k in ("run_id", "status")):
                    raise ValueError("not a run record (no run_id/status)")
            except (ValueError, UnicodeDecodeError, OSError) as e:
                warnings.warn(f"skipping corrupt record {p}: {e}", RuntimeWarning, stacklevel=3)
                continue
            recs.append(rec)
        return recs

    def tables(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Build ``(runs, params)`` from the records without writing anything."""
        runs, params = [], []
        for rec in self._records():
            row = _run_row(rec)
            runs.append(row)
            params += _param_rows(rec, row)
        runs_df = _frame(runs, RUN_BASE_COLUMNS)
        for c in ("started", "finished"):
            runs_df[c] = pd.to_datetime(runs_df[c], utc=True, format="ISO8601", errors="coerce")
        runs_df = runs_df.sort_values(["started", "run_id"], kind="stable").reset_index(drop=True)
        params_df = _frame(params, PARAM_BASE_COLUMNS)
        if len(params_df):
            order = {r: i for i, r in enumerate(runs_df["run_id"])}
            params_df = params_df.sort_values("run_id", key=lambda s: s.map(order), kind="stable")
        return runs_df, params_df.reset_index(drop=True)

    def collect(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Merge all records into ``runs.parquet`` and ``params.parquet`` and return them.

        Each file is written to a temp file and ``os.replace``d, under ``root/.collect.lock``, so a reader
        never sees a torn table and concurrent collectors never interleave. A corrupt record is skipped with a
        ``RuntimeWarning`` naming its file.
        """
        self.root.mkdir(parents=True, exist_ok=True)
        with FileLock(str(self.root / ".collect.lock"), timeout=_COLLECT_LOCK_TIMEOUT):
            runs, params = self.tables()
            for df, path in ((runs, self.runs_path), (params, self.params_path)):
                _atomic_write_bytes(path, df.to_parquet(index=False))
        return runs, params

    def load(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Read ``(runs, params)`` from the parquet files, collecting first when either is missing."""
        if not (self.runs_path.exists() and self.params_path.exists()):
            return self.collect()
        return read_table(self.runs_path), read_table(self.params_path)


def read_table(path) -> pd.DataFrame:
    """Read a parquet table safely while a collector may be replacing it.

    The file is read into memory with one open() first: pyarrow's reader opens a path more than once (footer,
    then pages), and between two opens ``os.replace`` may swap in the new file, giving "Page was smaller than
    expected". One open pins one inode, so the snapshot is always whole.
    """
    with open(path, "rb") as fh:
        return pd.read_parquet(io.BytesIO(fh.read()))


# ---------------------------------------------------------------------------------------------- guarded run

def run_guarded(store: ResultStore, config: dict, fn: Callable[[], dict], seed: int | None) -> dict:
    """Run ``fn`` for ``config`` unless already finished, and always leave exactly one record.

    Parameters
    ----------
    store : ResultStore
    config : dict
        The resolved configuration; its :func:`run_id` names the record.
    fn : callable
        ``fn() -> {'metrics', 'params', 'timings'}`` plus optionally ``status`` ('skipped' with ``error`` = the
        reason) and ``artefacts`` (``{name: bytes or path}``, moved into ``artefacts/<run_id>/``).
    seed : int or None
        Stored in the record.

    Returns
    -------
    dict
        The record written. If the run was already finished (here or, in a race, by another process), the
        existing record with ``resumed=True``; ``fn`` is then not called (or its result discarded).

    Notes
    -----
    An exception in ``fn`` (or a malformed result) is recorded as 'failed' with the full traceback in
    ``error`` and is not re-raised, so a sweep goes on. ``KeyboardInterrupt``/``SystemExit`` do propagate
    and leave no record: an interrupted run is simply run again on resume. ``timings['wall']`` is measured
    here.
    """
    rid = run_id(config)
    existing = store.read(rid)
    if existing is not None and existing.get("status") in FINISHED_STATUSES:
        return {**existing, "resumed": True}
    started, t0 = _now_iso(), time.perf_counter()
    record = {"run_id": rid, "config": config, "seed": seed, "started": started}
    artefacts = None
    try:
        out = fn()
        if not isinstance(out, dict):
            raise TypeError(f"the run function must return a dict, got {type(out).__name__}")
        status = out.get("status", "ok")
        record.update(status=status, error=out.get("error") if status != "ok" else None,
                      metrics=dict(out.get("metrics") or {}), params=list(out.get("params") or []),
                      timings=dict(out.get("timings") or {}))
        record["timings"]["wall"] = time.perf_counter() - t0
        record["finished"] = _now_iso()
        validate_record(record)  # a malformed result is a failure of the run, recorded like any other
        artefacts = _check_artefacts(out.get("artefacts"))
    except Exception:
        record.update(status="failed", error=traceback.format_exc(), metrics={}, params=[],
                      timings={"wall": time.perf_counter() - t0}, finished=_now_iso())
        artefacts = None
    try:
        path = store.write(record, artefacts=artefacts)
    except FileExistsError:
        # another process finished the same run meanwhile: its record stands
        other = store.read(rid)
        if other is None:
            raise
        return {**other, "resumed": True}
    return json.loads(path.read_text(encoding="utf-8"))


# ------------------------------------------------------------------------------------------------------- CLI

def _counts(runs: pd.DataFrame) -> dict:
    return {s: int((runs["status"] == s).sum()) if len(runs) else 0 for s in STATUSES}


def main(argv: list[str] | None = None) -> int:
    """``python -m study.results {rebuild,show} [--root results]``."""
    ap = argparse.ArgumentParser(prog="python -m study.results", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name, help_ in (("rebuild", "rebuild runs.parquet and params.parquet from the records"),
                        ("show", "counts by status and the last 10 runs")):
        p = sub.add_parser(name, help=help_)
        p.add_argument("--root", default=None, help="results folder (default $STUDY_RESULTS_DIR or results/)")
    args = ap.parse_args(argv)
    store = ResultStore(args.root)
    if args.cmd == "rebuild":
        runs, params = store.collect()
        c = _counts(runs)
        print(f"{len(runs)} runs ({c['ok']} ok, {c['failed']} failed, {c['skipped']} skipped), "
              f"{len(params)} parameter rows")
        print(f"runs:   {store.runs_path.resolve()}")
        print(f"params: {store.params_path.resolve()}")
        return 0
    runs, _ = store.tables()  # fresh from the records, writes nothing
    c = _counts(runs)
    print(f"{store.root.resolve()}: {len(runs)} runs ({c['ok']} ok, {c['failed']} failed, {c['skipped']} skipped)")
    if len(runs):
        cols = [col for col in ("run_id", "status", "finished", "wall_time", "cfg_vessel.name", "cfg_model.name",
                                "cfg_structure.name", "cfg_estimator.name", "cfg_noise.name") if col in runs]
        last = runs.sort_values("finished", kind="stable").tail(10)[cols].copy()
        last["finished"] = last["finished"].dt.strftime("%Y-%m-%d %H:%M:%S")
        last["wall_time"] = last["wall_time"].round(2)
        errs = runs.loc[last.index, "error"].map(
            lambda e: str(e).strip().splitlines()[-1][:60] if isinstance(e, str) and e.strip() else "")
        if errs.any():
            last["error"] = errs
        print("last runs:")
        print(last.to_string(index=False))
    return 0


if __name__ == "__main__":
    from .cli import run

    run(main, "study.results")
