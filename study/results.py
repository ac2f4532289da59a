"""The results store: one atomic JSON record per run, resume, and the two parquet tables.

Every run, ok or failed, lands as exactly one record; the tables are always rebuilt from the records
(benchopt-style: the records are the truth, the tables a cache). Full description: ``results/README.md``.

Layout under the results folder ``root`` (default ``results/``, relative to the working directory)::

    records/<run_id>.json               one record per run (written to a temp file, then os.replace)
    records/failed/<run_id>.<ts>.json   earlier failed attempts, kept when a run is retried
    records/superseded/<run_id>.<ts>.json  finished records replaced by a re-run (changed code, force)
    records/.claims/<run_id>.lock       held by the process computing the run (overlapping sweeps wait or skip)
    artefacts/<run_id>/...              large files of one run (one folder per run, never shared)
    runs.parquet                        one row per run
    params.parquet                      one row per identified parameter (long form)

``run_id`` is the first 16 hex characters of the sha256 of the canonical JSON of the scientific
configuration (everything but ``hydra`` and the keys in :data:`NON_SCIENTIFIC_KEYS`; numbers normalised so
that ``0`` and ``0.0`` are one id: :func:`canonical`). Each record carries the fingerprint of the code that
made it (``code``, :mod:`study.fingerprint`); resume reuses a finished run only when it is unchanged.

runs.parquet columns: ``run_id``, ``status`` (ok / failed / skipped), ``error``, ``seed``, ``started``,
``finished``, ``wall_time`` [s], ``artefacts`` (JSON list), ``code_fingerprint``, ``code_current``,
``code_changed``, ``prov_*`` (git_rev, package versions, platform, hostname, threads, ...), ``cfg_*``
(configuration flattened with dotted keys, list/dict leaves as JSON), ``m_*`` (metrics), ``t_*`` (timings [s]).

params.parquet columns: ``run_id``, ``equation``, ``name``, ``estimate``, ``truth``, ``rel_error``,
``abs_error``, the optional numbers of :data:`PARAM_OPTIONAL` (``ci_low``, ``ci_high``, ``std``, ``vif``,
``selected``, ``prior_mean``, ``prior_sd``, ``identifiability``, ``term_scale``, ``scaled_error``; NaN where a run
has none), ``truth_kind`` and the copied config columns of :data:`PARAM_CONFIG_COLUMNS` that exist.

CLI: ``python -m study.results {rebuild,show,migrate} [--root results]``.
"""
from __future__ import annotations

import argparse
import contextlib
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
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd
from filelock import FileLock, Timeout

from . import fingerprint as code_fp

#: Top-level configuration keys that do not change the science of a run, so they are left out of the run id.
NON_SCIENTIFIC_KEYS = frozenset({"hydra", "results_dir", "out", "launcher", "progress", "n_jobs", "artefacts",
                                 "force", "resume"})
#: How resume decides that a finished run can be reused: ``code`` (its code fingerprint equals the current
#: code's) or ``config`` (any finished record of the configuration, whatever code made it).
RESUME_MODES = ("code", "config")

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
                  "term_scale", "scaled_error",
                  # emcee's regression runs: the structure's truncation bias in posterior sd (study.identify.truncation)
                  "truncation_bias_sd")
#: Optional text keys of a params entry: how the truth was obtained ('exact', 'approximate', 'derived', ...).
PARAM_TEXT = ("truth_kind",)

#: Config columns copied into the params table (when present) so it can be filtered without a join.
PARAM_CONFIG_COLUMNS = ("cfg_vessel.name", "cfg_model.name", "cfg_estimator.name", "cfg_structure.name",
                        "cfg_noise.level")

#: Distributions whose versions go into the provenance.
PROVENANCE_PACKAGES = ("numpy", "scipy", "scikit-learn", "pandas", "pysindy", "emcee", "numba", "hydra-core")

RUN_BASE_COLUMNS = ["run_id", "status", "error", "seed", "started", "finished", "wall_time", "artefacts",
                    "code_fingerprint", "code_current", "code_changed"]
PARAM_BASE_COLUMNS = ["run_id", "equation", "name", "estimate", "truth", "rel_error", "abs_error",
                      "ci_low", "ci_high", "std", "vif", "selected", "truth_kind"]

REPO_ROOT = Path(__file__).resolve().parents[1]
# a per-run lock is held only for the few ms of a write; the timeout guards against a wedged file system
_WRITE_LOCK_TIMEOUT = 300.0
_COLLECT_LOCK_TIMEOUT = 600.0
#: A temp file or folder of a writer on another host (whose process cannot be asked) is a crash leftover when
#: older than this [s]: a record or table is written in milliseconds, an artefact folder placed in seconds.
LEFTOVER_AGE = 3600.0
#: This machine's name as written into temp names ('~' separates the fields of a temp name).
HOST = socket.gethostname().replace("~", "-").replace("/", "-") or "unknown-host"


class ResultsFolderError(RuntimeError):
    """The results folder cannot be used (not writable, or a rebuild would empty a non-empty table)."""


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
    with a dot and ends in ``.tmp`` so that no glob for ``*.json`` / ``*.parquet`` ever picks it up; its name
    says which host and process wrote it (:func:`_tmp_path`), so a crash's leftover can be told from a live
    writer's file. It is created with mode 0666 minus the umask (not mkstemp's 0600) so a shared results folder
    stays readable.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_path(path.parent, path.name)
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


def _tmp_path(folder: Path, name: str) -> Path:
    """A temp name in ``folder`` for ``name``: ``.<name>~<host>~<pid>~<random>.tmp``."""
    return folder / f".{name}~{HOST}~{os.getpid()}~{uuid.uuid4().hex[:12]}.tmp"


def _tmp_owner(name: str) -> tuple[str, int] | None:
    """``(host, pid)`` of a temp name made by :func:`_tmp_path`; None for another name (an older format)."""
    if not (name.startswith(".") and name.endswith(".tmp")):
        return None
    parts = name[1:-4].rsplit("~", 3)
    if len(parts) != 4 or not parts[2].isdigit():
        return None
    return parts[1], int(parts[2])


def _pid_alive(pid: int) -> bool:
    """Whether a process of this machine is running (a zombie counts as running: it is not ours to judge)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists but belongs to someone else, or cannot be asked: assume alive
    return True


def _is_number(x: Any) -> bool:
    t = type(x)
    if t is float or t is int:  # the common case, without the slow ABC check
        return True
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _is_scalar(x: Any) -> bool:
    t = type(x)
    if t is float or t is int or t is str or t is bool or x is None:
        return True
    return isinstance(x, (str, bool, numbers.Number, np.generic))


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


def canonical(obj: Any) -> Any:
    """``obj`` with its numbers in one spelling, so that the same science hashes to one run id.

    Hydra keeps a number as typed: ``noise.level=0`` is the int 0, the YAML's ``level: 0.0`` a float, and
    ``sim.duration_scale=1`` an int against the config's 1.0 (the only differences between spellings of one
    configuration found by composing them: the resolved configuration already holds every default). Here every
    int that a float represents exactly becomes that float (``0`` -> ``0.0``; larger ints stay ints), ``-0.0``
    becomes ``0.0``, numpy scalars and arrays become Python numbers and lists, tuples lists. Bools and strings
    are left as they are (``true`` is not ``1``; ``'0.01'`` is not ``0.01``).
    """
    t = type(obj)  # exact types first: a records folder is thousands of configs, ABC checks are slow
    if t is dict:
        return {str(k): canonical(v) for k, v in obj.items()}
    if t is str or t is bool or obj is None:
        return obj
    if t is float:
        return 0.0 if obj == 0.0 else obj
    if isinstance(obj, dict):
        return {str(k): canonical(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [canonical(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return canonical(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, numbers.Integral):
        try:
            f = float(obj)
        except OverflowError:
            return int(obj)
        return f if f == obj else int(obj)
    if isinstance(obj, numbers.Real):
        f = float(obj)
        return 0.0 if f == 0.0 else f
    return obj


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
        The first 16 hex characters of the digest; independent of key order, of how a number is spelt
        (:func:`canonical`) and of the process.
    """
    if not isinstance(config, dict):
        raise TypeError(f"run_id needs the configuration as a dict, got {type(config).__name__}")
    canon = _dumps(canonical(scientific_config(config)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canon.encode("utf-8")).hexdigest()[:16]


def legacy_run_id(config: dict) -> str:
    """The run id records were named by before numbers were normalised (no :func:`canonical`): how records
    written by earlier versions are still found (:meth:`ResultStore.lookup`) and migrated."""
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

def record_problems(record: Any, legacy: bool = False) -> list[str]:
    """Everything wrong with ``record`` as a run record (empty when it is well-formed); never raises.

    ``legacy`` also accepts a ``run_id`` made by :func:`legacy_run_id` (records written before run ids were
    canonical); new records must carry :func:`run_id`.
    """
    return _check_record(record, legacy)[0]


def _check_record(record: Any, legacy: bool) -> tuple[list[str], str | None]:
    """``(problems, run_id(config))`` of a record (the id is None when the config cannot give one)."""
    cid = None
    if not isinstance(record, dict):
        return [f"a record must be a JSON object, got {type(record).__name__}"], cid
    errs = [f"missing field {k!r}" for k in REQUIRED_FIELDS if k not in record]
    if errs:
        return errs, cid
    if not isinstance(record["status"], str) or record["status"] not in STATUSES:
        errs.append(f"status {record['status']!r} not in {STATUSES}")
    if not isinstance(record["config"], dict):
        errs.append("config must be a dict")
    elif not isinstance(record["run_id"], str):
        errs.append(f"run_id {record['run_id']!r} is not a string")
    else:
        try:
            cid = run_id(record["config"])
            if record["run_id"] != cid and not (legacy and record["run_id"] == legacy_run_id(record["config"])):
                errs.append(f"run_id {record['run_id']!r} does not match run_id(config) = {cid!r}")
        except (TypeError, ValueError) as e:  # e.g. a config JSON cannot encode
            errs.append(f"config cannot be hashed: {e}")
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
    if record["seed"] is not None and (not isinstance(record["seed"], numbers.Integral)
                                       or isinstance(record["seed"], bool)):
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
    # fields the store adds: optional, but of the right shape when present
    if record.get("provenance") is not None and not isinstance(record["provenance"], dict):
        errs.append("provenance must be a dict")
    arts = record.get("artefacts")
    if arts is not None and not (isinstance(arts, list) and all(isinstance(a, str) for a in arts)):
        errs.append("artefacts must be a list of file names")
    code = record.get("code")
    if code is not None and not (isinstance(code, dict) and isinstance(code.get("fingerprint"), str)
                                 and isinstance(code.get("components"), dict)):
        errs.append("code must be a dict with 'fingerprint' and 'components'")
    return errs, cid


def _kind(v: Any) -> str | None:
    """A metric value's kind for its table column: number, text or flag (None and NaN say nothing)."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return None
    if isinstance(v, (bool, np.bool_)):
        return "a flag"
    if isinstance(v, (numbers.Number, np.number)):
        return "a number"
    return "text" if isinstance(v, str) else type(v).__name__


def mistyped_records(items: list) -> dict:
    """``{file: reason}`` of the records, among ``items`` (``(file, record)`` pairs, each record well-formed on
    its own), whose metric has the wrong type: text (or a flag) where the other records hold a number. One such
    value used to turn the metric's column into text for every row of ``runs.parquet``; the record is left out
    instead, by name, as a malformed one is. A metric only some records have, or of one kind in all, is kept."""
    kinds: dict = {}
    for _, rec in items:
        for k, v in (rec.get("metrics") or {}).items():
            kd = _kind(v)
            if kd is not None:
                kinds.setdefault(k, {}).setdefault(kd, 0)
                kinds[k][kd] += 1
    expected = {k: "a number" for k, c in kinds.items() if "a number" in c and len(c) > 1}
    out: dict = {}
    for path, rec in items:
        for k, v in (rec.get("metrics") or {}).items():
            kd = _kind(v)
            if k in expected and kd is not None and kd != expected[k]:
                out[path] = (f"metric {k!r} is {kd} ({v!r}) where the other records hold {expected[k]}; expected "
                             f"{expected[k]}")
                break
    return out


def validate_record(record: dict, legacy: bool = False) -> None:
    """Raise ``ValueError`` (with every problem listed) unless ``record`` is a well-formed run record
    (:func:`record_problems`)."""
    errs = record_problems(record, legacy=legacy)
    if errs:
        rid = record.get("run_id") if isinstance(record, dict) else None
        raise ValueError(f"invalid record {rid!r}: " + "; ".join(errs))


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


def _run_row(rec: dict, current_code: dict | None = None) -> dict:
    """One row of runs.parquet; ``current_code``: the fingerprint of the code as it is now, for the run's
    configuration (``code_current``, ``code_changed``)."""
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
    code = rec.get("code")
    row["code_fingerprint"] = code.get("fingerprint") if isinstance(code, dict) else None
    if current_code is not None:
        changed = code_fp.changed_components(code, current_code)
        row["code_current"] = not changed
        row["code_changed"] = ",".join(changed)
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

@dataclass
class StoreReport:
    """What the last reading of the records met (:attr:`ResultStore.report`): nothing is left out silently."""

    records: int = 0                                  #: valid records in the table (one per configuration)
    skipped: list = field(default_factory=list)       #: (file, reason) of records left out (malformed, misnamed)
    duplicates: list = field(default_factory=list)    #: (file left out, file kept): two records of one configuration
    legacy: list = field(default_factory=list)        #: files still named by a pre-canonical run id (``migrate``)
    stale: int = 0                                    #: rows whose code differs from the current code
    removed: list = field(default_factory=list)       #: (path, why) crash leftovers removed by ``collect``
    kept: list = field(default_factory=list)          #: (path, why) temp files of writers that may be alive

    def lines(self) -> list[str]:
        """The report as short lines for a terminal (empty when there is nothing to say)."""
        out = [f"skipped record {p}: {why}" for p, why in self.skipped]
        out += [f"duplicate record {p} left out: same configuration as {k}" for p, k in self.duplicates]
        if self.legacy:
            out.append(f"{len(self.legacy)} record(s) still named by the old run id; "
                       "`python -m study.results migrate` renames them")
        if self.stale:
            out.append(f"{self.stale} run(s) computed by code that has changed since (code_current false); "
                       "re-running them recomputes them")
        out += [f"removed crash leftover {p} ({why})" for p, why in self.removed]
        out += [f"kept temp file {p} ({why})" for p, why in self.kept]
        return out


class Claim:
    """The right to compute one run: an exclusive OS file lock ``records/.claims/<run_id>.lock``, held while the
    run is computed, beside ``<run_id>.json`` saying who holds it.

    The lock is a ``filelock.FileLock`` (``flock``; on NFS the kernel maps it to a POSIX lock): the operating
    system releases it when its process ends in any way, SIGKILL included, so a claim of a dead process is
    never in the way (its ``.json`` is removed by the next ``collect``). A process holds at most one claim.
    """

    def __init__(self, store: "ResultStore", rid: str):
        self.rid = rid
        self.store = store
        self.info_path = store.claims_dir / f"{rid}.json"
        self.lock = FileLock(str(store.claims_dir / f"{rid}.lock"))

    def holder(self) -> dict | None:
        """``{host, pid, since}`` of the process that holds (or, if dead, last held) the claim, when known."""
        try:
            info = json.loads(self.info_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return info if isinstance(info, dict) else None

    def acquire(self, wait: bool = True) -> bool:
        """Take the claim; False when another live process holds it and ``wait`` is False (else wait for it)."""
        self.store.claims_dir.mkdir(parents=True, exist_ok=True)
        try:
            # a second, not 0: a peer's `collect` may hold the lock for a moment to test it (clean_leftovers)
            self.lock.acquire(timeout=1.0)
        except Timeout:
            if not wait:
                return False
            h = self.holder() or {}
            print(f"[study] run {self.rid} is being computed by process {h.get('pid', '?')} on "
                  f"{h.get('host', '?')} (since {h.get('since', '?')}); waiting for it", file=sys.stderr, flush=True)
            self.lock.acquire(timeout=-1, poll_interval=0.5)
        _atomic_write_bytes(self.info_path, _dumps({"host": HOST, "pid": os.getpid(), "since": _now_iso()})
                            .encode("utf-8"))
        return True

    def release(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.info_path.unlink()
        self.lock.release()


class ResultStore:
    """The results folder: records (the truth), artefacts, and the two parquet tables (rebuilt from records).

    Parameters
    ----------
    root : str or Path, optional
        The results folder; default ``$STUDY_RESULTS_DIR`` if set, else ``results/`` in the working directory.

    Attributes
    ----------
    report : StoreReport
        What the last :meth:`tables` / :meth:`collect` met: records skipped and why, duplicates, records under
        old run ids, stale rows, crash leftovers removed.
    """

    def __init__(self, root: str | os.PathLike | None = None):
        self.root = Path(root if root is not None else os.environ.get("STUDY_RESULTS_DIR") or "results")
        self.records_dir = self.root / "records"
        self.failed_dir = self.records_dir / "failed"
        self.superseded_dir = self.records_dir / "superseded"
        self.claims_dir = self.records_dir / ".claims"
        self.artefacts_root = self.root / "artefacts"
        self.runs_path = self.root / "runs.parquet"
        self.params_path = self.root / "params.parquet"
        self.report = StoreReport()

    def __repr__(self) -> str:
        return f"ResultStore({str(self.root)!r})"

    # -- paths and reading
    def record_path(self, rid: str) -> Path:
        """Where the record of run ``rid`` lives."""
        return self.records_dir / f"{rid}.json"

    def artefact_dir(self, rid: str) -> Path:
        """The folder of run ``rid``'s large files (owned by that run only)."""
        return self.artefacts_root / rid

    def _read_path(self, path: Path) -> tuple[dict | None, str | None, str | None]:
        """``(record, canonical run id, None)`` of a well-formed record file, else ``(None, None, reason)``.

        Well-formed: valid JSON of the right shape (:func:`record_problems`; a run id made by the old, not yet
        canonical rule is accepted) whose file is named by its own ``run_id`` (a copy under another name would
        be a second row of one run).
        """
        try:
            rec = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None, None, "no such file"
        except (OSError, UnicodeDecodeError) as e:
            return None, None, f"unreadable ({e})"
        except ValueError as e:
            return None, None, f"not valid JSON ({e})"
        errs, cid = _check_record(rec, legacy=True)
        if errs:
            return None, None, "; ".join(errs)
        if rec["run_id"] != path.stem:
            return None, None, (f"the file name does not match its run_id {rec['run_id']!r} (a copy or a renamed "
                                f"record; the record of that run is records/{rec['run_id']}.json)")
        return rec, cid, None

    def read(self, rid: str) -> dict | None:
        """The record of ``rid``, or None when absent, torn or malformed (such a record counts as absent: the
        run is computed again and the bad file kept under ``records/failed/``)."""
        return self._read_path(self.record_path(rid))[0]

    def finished(self, rid: str) -> bool:
        """True when run ``rid`` need not run again: its record says 'ok' or 'skipped' ('failed' reruns)."""
        rec = self.read(rid)
        return rec is not None and rec.get("status") in FINISHED_STATUSES

    def lookup(self, config: dict) -> dict | None:
        """The record of ``config``: under its run id, or under the run id earlier versions gave it
        (:func:`legacy_run_id`), which is then migrated to the canonical name (:meth:`migrate_record`)."""
        rid = run_id(config)
        path = self.record_path(rid)
        if path.exists():
            return self.read(rid)
        old = legacy_run_id(config)
        if old != rid and self.record_path(old).exists():
            self.migrate_record(old)
            return self.read(rid)
        return None

    # -- writing
    def _lock(self, rid: str) -> FileLock:
        # one lock per run: writers of different runs never wait for each other
        lock_dir = self.records_dir / ".locks"
        lock_dir.mkdir(parents=True, exist_ok=True)
        return FileLock(str(lock_dir / f"{rid}.lock"), timeout=_WRITE_LOCK_TIMEOUT)

    def claim(self, rid: str) -> Claim:
        """The claim on computing run ``rid`` (:class:`Claim`; not yet taken)."""
        return Claim(self, rid)

    def check_writable(self) -> None:
        """Raise :class:`ResultsFolderError` unless files can be created in the results folder and its
        ``records/`` (tried with a real file: permission bits say nothing about ACLs, read-only mounts, a full
        disk or a file where the folder should be). The app calls it before the first job."""
        try:
            # nothing is created before the first job: a folder not there yet is probed at its nearest existing
            # ancestor (a refused setting must leave no results folder behind)
            dirs = [d for d in (self.root, self.records_dir) if d.is_dir()]
            if not dirs:
                anc = self.root.resolve()
                while not anc.exists() and anc != anc.parent:
                    anc = anc.parent
                if not anc.is_dir():
                    raise NotADirectoryError(20, "not a folder", str(anc))
                dirs = [anc]
            for d in dirs:
                probe = _tmp_path(d, "write-probe")
                os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
                os.unlink(probe)
        except OSError as e:
            raise ResultsFolderError(
                f"results folder {self.root.resolve()} is not writable ({e.strerror or e}"
                f"{': ' + str(e.filename) if getattr(e, 'filename', None) else ''}); expected a folder this user "
                "can create files in: set results_dir=<folder> or STUDY_RESULTS_DIR") from e

    def _archive(self, rid: str, dest: Path, stamp: str) -> None:
        """Move run ``rid``'s record into ``dest`` (``records/failed/`` or ``records/superseded/``) as
        ``<rid>.<stamp>.json`` and its artefact folder to ``artefacts/<dest name>/<rid>.<stamp>/``."""
        path = self.record_path(rid)
        if path.exists():
            dest.mkdir(parents=True, exist_ok=True)
            os.replace(path, _unique(dest / f"{rid}.{stamp}.json"))
        adir = self.artefact_dir(rid)
        if adir.exists():
            to = _unique(self.artefacts_root / dest.name / f"{rid}.{stamp}")
            to.parent.mkdir(parents=True, exist_ok=True)
            os.replace(adir, to)

    @staticmethod
    def _ordered(record: dict) -> dict:
        # a fixed, readable key order: the verdict first, the bulky parts last
        first = ("run_id", "status", "error", "seed", "started", "finished")
        return {**{k: record[k] for k in first if k in record}, **{k: v for k, v in record.items() if k not in first}}

    def write(self, record: dict, overwrite: bool = False, artefacts: dict | None = None) -> Path:
        """Validate ``record``, add the provenance, and write it atomically as ``records/<run_id>.json``.

        Parameters
        ----------
        record : dict
            See :data:`REQUIRED_FIELDS` and ``results/README.md``. ``provenance`` is added when absent.
        overwrite : bool
            Replace an existing 'ok' or 'skipped' record (otherwise ``FileExistsError``); the replaced record
            is moved to ``records/superseded/<run_id>.<timestamp>.json`` and its artefacts to
            ``artefacts/superseded/<run_id>.<timestamp>/`` (a re-run after a code change, or forced).
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
            The record or the artefacts are malformed (or its run id is not :func:`run_id` of its config).

        Notes
        -----
        An existing 'failed' (or unreadable, or malformed) record is not lost: it is moved to
        ``records/failed/<run_id>.<timestamp>.json`` and its artefact folder, if any, to
        ``artefacts/failed/<run_id>.<timestamp>/``. The check and the replace happen under a per-run file lock,
        so two processes finishing the same run produce exactly one record.
        """
        validate_record(record)
        artefacts = _check_artefacts(artefacts)
        rec = self._ordered(record)
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
            if path.exists() or self.artefact_dir(rid).exists():
                # keep what was there: a replaced finished run, a failed / unreadable attempt, or the files of a
                # crash between the artefacts and the record
                dest = self.superseded_dir if old_status in FINISHED_STATUSES else self.failed_dir
                self._archive(rid, dest, _stamp())
            if artefacts:
                self._place_artefacts(rid, artefacts)
            _atomic_write_bytes(path, data)
        return path

    def _place_artefacts(self, rid: str, artefacts: dict) -> None:
        # build the folder under a temp name and rename it: the run's folder appears complete or not at all
        self.artefacts_root.mkdir(parents=True, exist_ok=True)
        tmp = _tmp_path(self.artefacts_root, rid)
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

    # -- run ids of earlier versions
    def migrate_record(self, old: str) -> str:
        """Rename the record ``records/<old>.json`` (and its artefact folder) to the canonical run id of its
        configuration. Returns what happened: ``'migrated'``, ``'current'`` (already canonical),
        ``'duplicate'`` (a record under the canonical id stands: this one is moved to ``records/superseded/``)
        or ``'skipped: <reason>'`` (malformed)."""
        path = self.record_path(old)
        rec, new, why = self._read_path(path)
        if rec is None:
            return f"skipped: {why}"
        if new == old:
            return "current"
        first, second = sorted((old, new))  # one lock order: two migrators never deadlock
        with self._lock(first), self._lock(second):
            rec, new, why = self._read_path(path)  # again, under the locks
            if rec is None:
                return f"skipped: {why}"
            stamp = _stamp()
            cur = self.read(new)
            if cur is not None and (cur["status"] in FINISHED_STATUSES or rec["status"] not in FINISHED_STATUSES):
                self._archive(old, self.superseded_dir, stamp)
                return "duplicate"
            if self.record_path(new).exists():  # a failed or malformed canonical record: the older finished one wins
                self._archive(new, self.failed_dir, stamp)
            # artefacts first, then the record, then the old name: a crash in between leaves a state the next
            # migration completes (the record under either name, its artefacts where the canonical one looks)
            adir = self.artefact_dir(old)
            if adir.exists() and not self.artefact_dir(new).exists():
                os.replace(adir, self.artefact_dir(new))
            prior = rec.get("migrated_from") if isinstance(rec.get("migrated_from"), list) else []
            moved = self._ordered({**rec, "run_id": new, "migrated_from": [*prior, old]})
            _atomic_write_bytes(self.record_path(new), _dumps(moved, indent=1).encode("utf-8"))
            path.unlink()
        return "migrated"

    def migrate(self) -> dict:
        """Migrate every record still named by an old run id (:meth:`migrate_record`); counts by outcome."""
        counts: dict = {}
        for p in sorted(self.records_dir.glob("*.json")) if self.records_dir.is_dir() else []:
            try:  # the common case, cheaply: a record already named by its canonical id
                rec = json.loads(p.read_text(encoding="utf-8"))
                if isinstance(rec, dict) and isinstance(rec.get("config"), dict) and run_id(rec["config"]) == p.stem:
                    counts["current"] = counts.get("current", 0) + 1
                    continue
            except (OSError, ValueError, TypeError):
                pass
            what = self.migrate_record(p.stem)
            key = "skipped" if what.startswith("skipped") else what
            counts[key] = counts.get(key, 0) + 1
            if key == "skipped":
                warnings.warn(f"skipping record {p}: {what[len('skipped: '):]}", RuntimeWarning, stacklevel=2)
        return counts

    # -- crash leftovers
    def leftovers(self) -> list[tuple[Path, str, bool]]:
        """Temp files and folders of writes that never finished: ``(path, why, removable)``.

        Removable: written by a process of this host that is no longer running, or older than
        :data:`LEFTOVER_AGE` (a writer on another host cannot be asked). Also the ``.json`` of claims whose
        process has ended (their lock is free).
        """
        now, out = time.time(), []
        for d in (self.root, self.records_dir, self.artefacts_root, self.claims_dir):
            if not d.is_dir():
                continue
            for p in sorted(d.iterdir()):
                name = p.name
                if not (name.startswith(".") and (name.endswith(".tmp") or name.startswith(".tmp-"))):
                    continue
                try:
                    age = now - p.lstat().st_mtime
                except FileNotFoundError:
                    continue  # its write just finished
                owner = _tmp_owner(name)
                if owner is not None and owner[0] == HOST:
                    alive = _pid_alive(owner[1])
                    why = f"process {owner[1]} of this host {'is running' if alive else 'has ended'}"
                    gone = not alive
                else:
                    why = (f"process {owner[1]} on {owner[0]}" if owner else "an older temp name") + \
                          f", {age / 60:.0f} min old"
                    gone = False
                out.append((p, why, gone or age > LEFTOVER_AGE))
        if self.claims_dir.is_dir():
            for info in sorted(self.claims_dir.glob("*.json")):
                lock = FileLock(str(info.with_suffix(".lock")))
                try:
                    lock.acquire(timeout=0)
                except Timeout:
                    continue  # held: the run is being computed
                try:
                    h = Claim(self, info.stem).holder() or {}
                    out.append((info, f"claim of process {h.get('pid', '?')} on {h.get('host', '?')}, which has ended",
                                True))
                finally:
                    lock.release()
        return out

    def clean_leftovers(self) -> tuple[list, list]:
        """Remove the removable :meth:`leftovers`; ``(removed, kept)`` as ``(path, why)`` lists."""
        removed, kept = [], []
        for p, why, removable in self.leftovers():
            if not removable:
                kept.append((p, why))
                continue
            try:
                shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
            except FileNotFoundError:
                continue
            removed.append((p, why))
        return removed, kept

    # -- tables
    def _scan(self) -> list[dict]:
        """The well-formed records, one per configuration; what was left out goes into :attr:`report` and a
        ``RuntimeWarning`` naming its file."""
        rep = StoreReport()
        by_id: dict = {}
        for p in sorted(self.records_dir.glob("*.json")) if self.records_dir.is_dir() else []:
            rec, cid, why = self._read_path(p)
            if rec is None:
                rep.skipped.append((p, why))
                warnings.warn(f"skipping record {p}: {why}", RuntimeWarning, stacklevel=3)
                continue
            if cid != rec["run_id"]:
                rep.legacy.append(p)
            by_id.setdefault(cid, []).append((p, rec))
        out = []
        for cid, items in by_id.items():
            if len(items) > 1:
                # a record under an old id beside one under the canonical id (or two old spellings): keep a
                # finished one, the canonical name, the latest, in that order
                items.sort(key=lambda it: (it[1]["status"] in FINISHED_STATUSES, it[1]["run_id"] == cid,
                                           str(it[1]["finished"])), reverse=True)
                for p, _ in items[1:]:
                    rep.duplicates.append((p, items[0][0]))
                    warnings.warn(f"skipping record {p}: the same configuration as {items[0][0]} "
                                  "(`python -m study.results migrate` resolves it)", RuntimeWarning, stacklevel=3)
            out.append(items[0])
        bad = mistyped_records(out)  # a field of the wrong type would change its column for every row
        for p, why in bad.items():
            rep.skipped.append((p, why))
            warnings.warn(f"skipping record {p}: {why}", RuntimeWarning, stacklevel=3)
        out = [rec for p, rec in out if p not in bad]
        rep.records = len(out)
        self.report = rep
        return out

    def tables(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Build ``(runs, params)`` from the records without writing anything (see :attr:`report`)."""
        runs, params = [], []
        for rec in self._scan():
            try:
                current = code_fp.code_fingerprint(rec["config"])
            except Exception as e:  # never let one record stall the table: its row says nothing about its code
                warnings.warn(f"run {rec['run_id']}: no code fingerprint for its configuration ({e})", RuntimeWarning)
                current = None
            row = _run_row(rec, current)
            runs.append(row)
            params += _param_rows(rec, row)
        self.report.stale = sum(1 for r in runs if r.get("code_current") is False)
        runs_df = _frame(runs, RUN_BASE_COLUMNS)
        for c in ("started", "finished"):
            runs_df[c] = pd.to_datetime(runs_df[c], utc=True, format="ISO8601", errors="coerce")
        runs_df = runs_df.sort_values(["started", "run_id"], kind="stable").reset_index(drop=True)
        params_df = _frame(params, PARAM_BASE_COLUMNS)
        if len(params_df):
            order = {r: i for i, r in enumerate(runs_df["run_id"])}
            params_df = params_df.sort_values("run_id", key=lambda s: s.map(order), kind="stable")
        return runs_df, params_df.reset_index(drop=True)

    def collect(self, allow_empty: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Merge all records into ``runs.parquet`` and ``params.parquet`` and return them.

        Each file is written to a temp file and ``os.replace``d, under ``root/.collect.lock``, so a reader
        never sees a torn table and concurrent collectors never interleave. A malformed or misnamed record is
        left out with a ``RuntimeWarning`` naming its file, and counted in :attr:`report`; crash leftovers are
        removed first (:meth:`clean_leftovers`, also in :attr:`report`).

        Raises
        ------
        ResultsFolderError
            No well-formed record, and ``runs.parquet`` holds rows: a rebuild never replaces a non-empty table
            with an empty one (a wrong ``root``?) unless ``allow_empty``.
        """
        self.root.mkdir(parents=True, exist_ok=True)
        with FileLock(str(self.root / ".collect.lock"), timeout=_COLLECT_LOCK_TIMEOUT):
            removed, kept = self.clean_leftovers()
            runs, params = self.tables()
            self.report.removed, self.report.kept = removed, kept
            if not len(runs) and not allow_empty:
                before = _table_rows(self.runs_path)
                if before:
                    bad = f" ({len(self.report.skipped)} malformed record(s) skipped)" if self.report.skipped else ""
                    raise ResultsFolderError(
                        f"no well-formed record in {self.records_dir.resolve()}{bad}: refusing to replace "
                        f"{self.runs_path.resolve()} ({before} runs) with an empty table; expected the results "
                        "folder of those runs (a wrong --root / results_dir?), or allow_empty (--allow-empty)")
            for df, path in ((runs, self.runs_path), (params, self.params_path)):
                _atomic_write_bytes(path, df.to_parquet(index=False))
        return runs, params

    def load(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Read ``(runs, params)`` from the parquet files, collecting first when either is missing."""
        if not (self.runs_path.exists() and self.params_path.exists()):
            return self.collect()
        return read_table(self.runs_path), read_table(self.params_path)


def _table_rows(path: Path) -> int:
    """Rows of a parquet table (0 when absent or unreadable: nothing to protect)."""
    import pyarrow.parquet as pq

    try:
        with open(path, "rb") as fh:
            return int(pq.ParquetFile(io.BytesIO(fh.read())).metadata.num_rows)
    except Exception:  # OSError, or pyarrow's own ArrowInvalid on a torn file
        return 0


def read_table(path) -> pd.DataFrame:
    """Read a parquet table safely while a collector may be replacing it.

    The file is read into memory with one open() first: pyarrow's reader opens a path more than once (footer,
    then pages), and between two opens ``os.replace`` may swap in the new file, giving "Page was smaller than
    expected". One open pins one inode, so the snapshot is always whole.
    """
    with open(path, "rb") as fh:
        return pd.read_parquet(io.BytesIO(fh.read()))


# ---------------------------------------------------------------------------------------------- guarded run

def _reusable(rec: dict | None, code: dict, resume: str) -> bool:
    if rec is None or rec.get("status") not in FINISHED_STATUSES:
        return False
    return resume == "config" or not code_fp.changed_components(rec.get("code"), code)


def run_guarded(store: ResultStore, config: dict, fn: Callable[[], dict], seed: int | None, *,
                force: bool = False, resume: str = "code", wait: bool = True, code: dict | None = None) -> dict:
    """Run ``fn`` for ``config`` unless already finished by the same code, and always leave exactly one record.

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
    force : bool
        Compute the run even if a finished record exists (it is moved to ``records/superseded/``).
    resume : {'code', 'config'}
        Reuse a finished record only if the fingerprint of the code that made it equals the current one
        (``code``, the default: :mod:`study.fingerprint`), or whatever code made it (``config``). A record
        computed by other code is recomputed, and kept under ``records/superseded/``.
    wait : bool
        When another live process is computing the same run (it holds the run's :class:`Claim`): wait for it
        and reuse its record (True), or return at once with status ``'claimed'`` and ``claimed_by`` (False: a
        sweep moves on to its next run and leaves this one to its owner).
    code : dict, optional
        The code fingerprint to compare and store; default :func:`study.fingerprint.code_fingerprint`.

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
    here. A record written by an earlier version under another run id is found and renamed
    (:meth:`ResultStore.lookup`).
    """
    if resume not in RESUME_MODES:
        raise ValueError(f"resume={resume!r}: expected one of {RESUME_MODES}")
    rid = run_id(config)
    code = code if code is not None else code_fp.code_fingerprint(config)
    before = store.lookup(config)
    if not force and _reusable(before, code, resume):
        return {**before, "resumed": True}
    claim = store.claim(rid)
    if not claim.acquire(wait=wait):
        return {"run_id": rid, "status": "claimed", "config": config, "claimed_by": claim.holder()}
    try:
        existing = store.read(rid)  # again: the process we waited for may have finished it
        # under force, only a record made while this call waited counts (two forced sweeps compute a run once)
        fresh = existing is not None and (before is None or _when(existing) != _when(before))
        if _reusable(existing, code, resume) and (fresh or not force):
            return {**existing, "resumed": True}
        record, artefacts = _compute(rid, config, fn, seed, code)
        replace = existing is not None and existing.get("status") in FINISHED_STATUSES
        try:
            path = store.write(record, overwrite=replace, artefacts=artefacts)
        except FileExistsError:
            # a writer that takes no claim (an older version) finished the same run meanwhile: its record stands
            other = store.read(rid)
            if other is None:
                raise
            return {**other, "resumed": True}
    finally:
        claim.release()
    return json.loads(path.read_text(encoding="utf-8"))


def _when(rec: dict) -> tuple:
    return rec.get("started"), rec.get("finished")


def _compute(rid: str, config: dict, fn: Callable[[], dict], seed, code: dict) -> tuple[dict, dict | None]:
    """Call ``fn`` and make its record (a failure becomes a 'failed' record); ``(record, artefacts)``."""
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
    record["code"] = code
    return record, artefacts


# ------------------------------------------------------------------------------------------------------- CLI

def _counts(runs: pd.DataFrame) -> dict:
    return {s: int((runs["status"] == s).sum()) if len(runs) else 0 for s in STATUSES}


def _say(store: ResultStore, stream=None) -> None:
    for line in store.report.lines():
        print(f"study.results: {line}", file=stream or sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """``python -m study.results {rebuild,show,migrate} [--root results]``; exit status 1 on an error."""
    ap = argparse.ArgumentParser(prog="python -m study.results", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name, help_ in (("rebuild", "rebuild runs.parquet and params.parquet from the records"),
                        ("show", "counts by status and the last 10 runs"),
                        ("migrate", "rename records still named by the run id of an earlier version")):
        p = sub.add_parser(name, help=help_)
        p.add_argument("--root", default=None, help="results folder (default $STUDY_RESULTS_DIR or results/)")
        if name == "rebuild":
            p.add_argument("--allow-empty", action="store_true",
                           help="write empty tables even over non-empty ones (no well-formed record found)")
            p.add_argument("--strict", action="store_true", help="exit 1 when a record was skipped")
    args = ap.parse_args(argv)
    store = ResultStore(args.root)
    if not store.root.is_dir():  # nothing to show or rebuild: refused, and no folder is made
        print(f"study.results: error: --root {args.root or store.root}: no such folder {store.root.resolve()}; "
              "expected a results folder (one a study wrote)", file=sys.stderr)
        return 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the same problems are printed from the report below
        try:
            if args.cmd == "migrate":
                if not store.records_dir.is_dir():
                    raise ResultsFolderError(f"no records folder {store.records_dir.resolve()}; expected a results "
                                             "folder (--root)")
                c = store.migrate()
                print(f"{store.records_dir.resolve()}: {c.get('migrated', 0)} record(s) renamed to canonical run ids, "
                      f"{c.get('duplicate', 0)} duplicate(s) moved to records/superseded/, {c.get('current', 0)} "
                      f"already current, {c.get('skipped', 0)} malformed left alone")
                return 0
            if args.cmd == "rebuild":
                runs, params = store.collect(allow_empty=args.allow_empty)
                _say(store)
                c = _counts(runs)
                skipped = len(store.report.skipped) + len(store.report.duplicates)
                print(f"{len(runs)} runs ({c['ok']} ok, {c['failed']} failed, {c['skipped']} skipped), "
                      f"{len(params)} parameter rows" + (f"; {skipped} record(s) left out" if skipped else ""))
                print(f"runs:   {store.runs_path.resolve()}")
                print(f"params: {store.params_path.resolve()}")
                return 1 if args.strict and skipped else 0
            runs, _ = store.tables()  # fresh from the records, writes nothing
        except (ResultsFolderError, OSError, Timeout) as e:
            print(f"study.results: error: {e}", file=sys.stderr)
            return 1
    _say(store)
    for p, why, removable in store.leftovers():
        print(f"study.results: {'crash leftover' if removable else 'temp file'} {p} ({why})"
              + ("; the next rebuild removes it" if removable else ""), file=sys.stderr)
    c = _counts(runs)
    skipped = len(store.report.skipped) + len(store.report.duplicates)
    print(f"{store.root.resolve()}: {len(runs)} runs ({c['ok']} ok, {c['failed']} failed, {c['skipped']} skipped)"
          + (f"; {skipped} record(s) left out" if skipped else "")
          + (f"; {store.report.stale} computed by older code" if store.report.stale else ""))
    if len(runs):
        cols = [col for col in ("run_id", "status", "finished", "wall_time", "code_current", "cfg_vessel.name",
                                "cfg_model.name", "cfg_structure.name", "cfg_estimator.name", "cfg_noise.name")
                if col in runs]
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
