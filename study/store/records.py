"""The run record: what every record holds, how a run is named (its run id), and the checks a record
passes before it is written or enters a table.

``run_id`` is the first 16 hex characters of the sha256 of the canonical JSON of the scientific
configuration (everything but ``hydra`` and the keys in :data:`NON_SCIENTIFIC_KEYS`; numbers
normalised so that ``0`` and ``0.0`` are one id: :func:`canonical`). Replicate ``k >= 1`` of a
configuration (one of its independent datasets, ``replicates=N``) hashes the pair ``{config,
replicate: k}``; replicate 0 keeps the configuration's own id, so a run made before replication
existed is replicate 0 of its configuration.
"""
from __future__ import annotations

import hashlib
import numbers
import os
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from .files import dumps

#: Top-level configuration keys that do not change the science of a run, so they are left out of the run id
#: (``replicates`` is how many datasets a job identifies: each dataset is its own run, named by its index).
NON_SCIENTIFIC_KEYS = frozenset({"hydra", "results_dir", "out", "launcher", "progress", "n_jobs", "artefacts",
                                 "force", "resume", "replicates"})

#: Record status values; 'ok' and 'skipped' count as finished (resume skips them), 'failed' is rerun.
STATUSES = ("ok", "failed", "skipped")
FINISHED_STATUSES = frozenset({"ok", "skipped"})

#: Fields every record must carry (``provenance`` and ``artefacts`` are added by the store).
REQUIRED_FIELDS = ("run_id", "status", "config", "metrics", "params", "timings", "seed", "error",
                   "started", "finished")
#: Fields of a replicated run (absent in records made before replication: replicate 0, dataset seed = seed).
REPLICATE_FIELDS = ("replicate", "dataset_seed")

#: Keys every entry of ``params`` must have; the optional ones default to None.
PARAM_REQUIRED = ("equation", "name", "estimate", "truth")
PARAM_OPTIONAL = ("ci_low", "ci_high", "std", "vif", "selected",
                  # prior-anchored fits (estimator map, emcee with a prior): the prior and posterior sd / prior sd
                  "prior_mean", "prior_sd", "identifiability",
                  # the term's share of its equation and the error scaled by it (study.identify.rows.term_scales)
                  "term_scale", "scaled_error",
                  # emcee's regression runs: the structure's truncation bias in posterior sd (study.identify.truncation)
                  "truncation_bias_sd")
#: Optional text keys of a params entry: how the truth was obtained ('exact', 'approximate', 'derived', ...).
PARAM_TEXT = ("truth_kind",)


def is_number(x: Any) -> bool:
    t = type(x)
    if t is float or t is int:  # the common case, without the slow ABC check
        return True
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def is_scalar(x: Any) -> bool:
    t = type(x)
    if t is float or t is int or t is str or t is bool or x is None:
        return True
    return isinstance(x, (str, bool, numbers.Number, np.generic))


def is_count(x: Any) -> bool:
    """A non-negative int (not a bool)."""
    return isinstance(x, numbers.Integral) and not isinstance(x, bool) and int(x) >= 0


def scientific_config(config: dict) -> dict:
    """The part of ``config`` that defines the science of a run (drops
    :data:`NON_SCIENTIFIC_KEYS`)."""
    return {k: v for k, v in config.items() if k not in NON_SCIENTIFIC_KEYS}


def canonical(obj: Any) -> Any:
    """``obj`` with its numbers in one spelling, so that the same science hashes to one run id.

    Hydra keeps a number as typed: ``noise.level=0`` is the int 0, the YAML's ``level: 0.0`` a
    float. Here every int that a float represents exactly becomes that float (``0`` -> ``0.0``;
    larger ints stay ints), ``-0.0`` becomes ``0.0``, numpy scalars and arrays become Python numbers
    and lists, tuples lists. Bools and strings are left as they are (``true`` is not ``1``;
    ``'0.01'`` is not ``0.01``).
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


def run_id(config: dict, replicate: int = 0) -> str:
    """Stable identifier of a run: sha256 of the canonical JSON of its scientific configuration.

    Parameters
    ----------
    config : dict
        The resolved configuration (e.g. ``OmegaConf.to_container(cfg, resolve=True)``). Anything
        under ``hydra`` and the top-level keys in :data:`NON_SCIENTIFIC_KEYS` are ignored.
    replicate : int
        Which independent dataset of the configuration (0, the default, is the configuration's own
        id).

    Returns
    -------
    str
        The first 16 hex characters of the digest; independent of key order, of how a number is
        spelt (:func:`canonical`), of the process, and of how many replicates the job asked for.
    """
    if not isinstance(config, dict):
        raise TypeError(f"run_id needs the configuration as a dict, got {type(config).__name__}")
    if not is_count(replicate):
        raise ValueError(f"replicate={replicate!r}: expected a non-negative int")
    body: Any = canonical(scientific_config(config))
    if replicate:
        body = {"config": body, "replicate": int(replicate)}
    canon = dumps(body, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canon.encode("utf-8")).hexdigest()[:16]


def record_problems(record: Any) -> list[str]:
    """Everything wrong with ``record`` as a run record (empty when it is well-formed); never
    raises."""
    return check_record(record)[0]


def check_record(record: Any) -> tuple[list[str], str | None]:
    """``(problems, run id of its config and replicate)`` of a record (the id is None when it
    cannot be made)."""
    cid = None
    if not isinstance(record, dict):
        return [f"a record must be a JSON object, got {type(record).__name__}"], cid
    errs = [f"missing field {k!r}" for k in REQUIRED_FIELDS if k not in record]
    if errs:
        return errs, cid
    if not isinstance(record["status"], str) or record["status"] not in STATUSES:
        errs.append(f"status {record['status']!r} not in {STATUSES}")
    rep = record.get("replicate", 0)
    for k in REPLICATE_FIELDS:
        if record.get(k) is not None and not is_count(record[k]):
            errs.append(f"{k} {record[k]!r} is not a non-negative int")
    if not isinstance(record["config"], dict):
        errs.append("config must be a dict")
    elif not isinstance(record["run_id"], str):
        errs.append(f"run_id {record['run_id']!r} is not a string")
    elif is_count(rep if rep is not None else 0):
        try:
            cid = run_id(record["config"], int(rep or 0))
            if record["run_id"] != cid:
                errs.append(f"run_id {record['run_id']!r} does not match run_id(config, replicate={rep or 0}) = "
                            f"{cid!r}")
        except (TypeError, ValueError) as e:  # e.g. a config JSON cannot encode
            errs.append(f"config cannot be hashed: {e}")
    if not isinstance(record["metrics"], dict):
        errs.append("metrics must be a dict")
    else:
        errs += [f"metric {k!r} is not a scalar ({type(v).__name__})"
                 for k, v in record["metrics"].items() if not is_scalar(v)]
    if not isinstance(record["timings"], dict):
        errs.append("timings must be a dict of seconds")
    else:
        errs += [f"timing {k!r} is not a number of seconds" for k, v in record["timings"].items()
                 if not (is_number(v) or v is None)]
    if not isinstance(record["params"], list):
        errs.append("params must be a list of dicts")
    else:
        for i, p in enumerate(record["params"]):
            if not isinstance(p, dict):
                errs.append(f"params[{i}] is not a dict")
                continue
            errs += [f"params[{i}] lacks {k!r}" for k in PARAM_REQUIRED if k not in p]
            errs += [f"params[{i}][{k!r}] is not a number or None" for k in ("estimate", "truth", *PARAM_OPTIONAL)
                     if k in p and not (p[k] is None or is_number(p[k]))]
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
    """A metric value's kind for its table column: number, text or flag (None and NaN say
    nothing)."""
    if v is None or (isinstance(v, float) and v != v):
        return None
    if isinstance(v, (bool, np.bool_)):
        return "a flag"
    if isinstance(v, (numbers.Number, np.number)):
        return "a number"
    return "text" if isinstance(v, str) else type(v).__name__


def mistyped_records(items: list) -> dict:
    """``{file: reason}`` of the records, among ``items`` (``(file, record)`` pairs, each record
    well-formed on its own), whose metric has the wrong type: a kind other than the one most
    records hold (a number on a tie), such as text where the others hold a number. One such value
    would retype the metric's column for every row of ``runs.parquet``; the record is left out
    instead, by name, as a malformed one is. A metric only some records have, or of one kind in
    all, is kept (some metrics are text: ``prior_source``, notes, estimator diagnostics)."""
    kinds: dict = {}
    for _, rec in items:
        for k, v in (rec.get("metrics") or {}).items():
            kd = _kind(v)
            if kd is not None:
                kinds.setdefault(k, {}).setdefault(kd, 0)
                kinds[k][kd] += 1
    # the kind most records hold (a number on a tie): one stray value, of any kind, cannot retype the column
    expected = {k: max(c, key=lambda kd: (c[kd], kd == "a number")) for k, c in kinds.items() if len(c) > 1}
    out: dict = {}
    for path, rec in items:
        for k, v in (rec.get("metrics") or {}).items():
            kd = _kind(v)
            if k in expected and kd is not None and kd != expected[k]:
                out[path] = (f"metric {k!r} is {kd} ({v!r}) where the other records hold {expected[k]}; expected "
                             f"{expected[k]}")
                break
    return out


def validate_record(record: dict) -> None:
    """Raise ``ValueError`` (with every problem listed) unless ``record`` is a well-formed run
    record
    (:func:`record_problems`)."""
    errs = record_problems(record)
    if errs:
        rid = record.get("run_id") if isinstance(record, dict) else None
        raise ValueError(f"invalid record {rid!r}: " + "; ".join(errs))


def check_artefacts(artefacts: dict | None) -> dict:
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


def ordered(record: dict) -> dict:
    """The record with a fixed, readable key order: the verdict first, the bulky parts last."""
    first = ("run_id", "status", "error", "seed", "replicate", "dataset_seed", "started", "finished")
    return {**{k: record[k] for k in first if k in record}, **{k: v for k, v in record.items() if k not in first}}
