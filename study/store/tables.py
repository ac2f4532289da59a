"""The two parquet tables made from the records: ``runs`` (one row per run: one dataset of one
configuration) and ``params`` (one row per identified coefficient of a run). Columns:
``results/README.md``."""
from __future__ import annotations

import io
import math
import numbers
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from study.store import fingerprint as code_fp
from .files import dumps
from .records import PARAM_OPTIONAL, PARAM_TEXT, is_number

#: Config columns copied into the params table (when present) so it can be filtered without a join.
PARAM_CONFIG_COLUMNS = ("cfg_vessel.name", "cfg_model.name", "cfg_estimator.name", "cfg_structure.name",
                        "cfg_noise.level")

RUN_BASE_COLUMNS = ["run_id", "status", "error", "seed", "replicate", "dataset_seed", "started", "finished",
                    "wall_time", "artefacts", "code_fingerprint", "code_current", "code_changed"]
PARAM_BASE_COLUMNS = ["run_id", "replicate", "equation", "name", "estimate", "truth", "rel_error", "abs_error",
                      "ci_low", "ci_high", "std", "vif", "selected", "truth_kind"]
_FLOAT_COLUMNS = ("wall_time", "estimate", "truth", "rel_error", "abs_error", *PARAM_OPTIONAL)


def flatten(d: dict, prefix: str = "") -> dict:
    """Dotted keys for nested dicts; list leaves and empty dicts become JSON so each column has
    one type."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(flatten(v, key + "."))
        elif isinstance(v, (dict, list, tuple)):
            out[key] = dumps(v, sort_keys=True)
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
                   else dumps(v))


def _finite_float(x: Any) -> float:
    return float(x) if is_number(x) else math.nan


def replicate_of(rec: dict) -> tuple[int, int | None]:
    """``(replicate, dataset seed)`` of a record; a record made before replication is replicate 0
    of its configuration, drawn from its own seed."""
    rep = rec.get("replicate")
    rep = int(rep) if rep is not None else 0
    ds = rec.get("dataset_seed")
    return rep, (int(ds) if ds is not None else (rec.get("seed") if rep == 0 else None))


def run_row(rec: dict, current_code: dict | None = None) -> dict:
    """One row of runs.parquet; ``current_code``: the fingerprint of the code as it is now, for
    the run's configuration (``code_current``, ``code_changed``)."""
    timings = rec.get("timings") or {}
    wall = timings.get("wall")
    if not is_number(wall):
        try:
            wall = (datetime.fromisoformat(rec["finished"]) - datetime.fromisoformat(rec["started"])).total_seconds()
        except (TypeError, ValueError, KeyError):
            wall = math.nan
    rep, ds = replicate_of(rec)
    row = {"run_id": rec["run_id"], "status": rec["status"], "error": rec.get("error"), "seed": rec.get("seed"),
           "replicate": rep, "dataset_seed": ds, "started": rec.get("started"), "finished": rec.get("finished"),
           "wall_time": float(wall), "artefacts": dumps(rec.get("artefacts") or [])}
    code = rec.get("code")
    row["code_fingerprint"] = code.get("fingerprint") if isinstance(code, dict) else None
    if current_code is not None:
        changed = code_fp.changed_components(code, current_code)
        row["code_current"] = not changed
        row["code_changed"] = ",".join(changed)
    row.update({f"prov_{k}": v for k, v in flatten(rec.get("provenance") or {}).items()})
    cfg = {k: v for k, v in (rec.get("config") or {}).items() if k != "hydra"}
    row.update({f"cfg_{k}": v for k, v in flatten(cfg).items()})
    row.update({f"m_{k}": v for k, v in (rec.get("metrics") or {}).items()})
    row.update({f"t_{k}": v for k, v in timings.items()})
    return row


def param_rows(rec: dict, row: dict) -> list[dict]:
    """The params.parquet rows of one record (``row``: its runs.parquet row, for the copied
    config columns)."""
    copied = {c: row[c] for c in PARAM_CONFIG_COLUMNS if c in row}
    rows = []
    for p in rec.get("params") or []:
        est, truth = _finite_float(p.get("estimate")), _finite_float(p.get("truth"))
        nonzero = not math.isnan(truth) and truth != 0.0
        rows.append({"run_id": rec["run_id"], "replicate": row["replicate"], "equation": str(p.get("equation")),
                     "name": str(p.get("name")), "estimate": est, "truth": truth,
                     "rel_error": (est - truth) / abs(truth) if nonzero else math.nan,
                     "abs_error": abs(est - truth),  # NaN when truth is unknown (NaN propagates)
                     **{k: _finite_float(p.get(k)) for k in PARAM_OPTIONAL},
                     **{k: p.get(k) for k in PARAM_TEXT}, **copied})
    return rows


def frame(rows: list[dict], base: list[str]) -> pd.DataFrame:
    """A table of ``rows`` with the ``base`` columns first and one parquet type per column."""
    df = pd.DataFrame(rows)
    for c in base:
        if c not in df:
            df[c] = pd.Series(dtype=float if c in _FLOAT_COLUMNS else object)
    df = df[base + [c for c in df.columns if c not in base]]
    for c in df.columns:
        if c != "error":  # error stays text (or null) whatever the other columns hold
            df[c] = _unify(df[c])
    return df


def build(records: list[dict]) -> tuple[pd.DataFrame, pd.DataFrame, int]:
    """``(runs, params, stale)`` of well-formed records; ``stale``: rows whose code differs from
    today's."""
    import warnings

    runs, params = [], []
    for rec in records:
        try:
            current = code_fp.code_fingerprint(rec["config"])
        except Exception as e:  # never let one record stall the table: its row says nothing about its code
            warnings.warn(f"run {rec['run_id']}: no code fingerprint for its configuration ({e})", RuntimeWarning)
            current = None
        row = run_row(rec, current)
        runs.append(row)
        params += param_rows(rec, row)
    stale = sum(1 for r in runs if r.get("code_current") is False)
    runs_df = frame(runs, RUN_BASE_COLUMNS)
    for c in ("started", "finished"):
        runs_df[c] = pd.to_datetime(runs_df[c], utc=True, format="ISO8601", errors="coerce")
    runs_df = runs_df.sort_values(["started", "run_id"], kind="stable").reset_index(drop=True)
    params_df = frame(params, PARAM_BASE_COLUMNS)
    if len(params_df):
        order = {r: i for i, r in enumerate(runs_df["run_id"])}
        params_df = params_df.sort_values("run_id", key=lambda s: s.map(order), kind="stable")
    return runs_df, params_df.reset_index(drop=True), stale


def table_rows(path: Path) -> int:
    """Rows of a parquet table (0 when absent or unreadable: nothing to protect)."""
    import pyarrow.parquet as pq

    try:
        with open(path, "rb") as fh:
            return int(pq.ParquetFile(io.BytesIO(fh.read())).metadata.num_rows)
    except Exception:  # OSError, or pyarrow's own ArrowInvalid on a torn file
        return 0


def read_table(path) -> pd.DataFrame:
    """Read a parquet table safely while a collector may be replacing it.

    The file is read into memory with one open() first: pyarrow's reader opens a path more than once
    (footer, then pages), and between two opens ``os.replace`` may swap in the new file, giving
    "Page was smaller than expected". One open pins one inode, so the snapshot is always whole.
    """
    with open(path, "rb") as fh:
        data = fh.read()
    try:
        return pd.read_parquet(io.BytesIO(data))
    except Exception as e:  # pyarrow's own error types name no file
        raise TableError(f"{path}: not a readable parquet table ({type(e).__name__}: {e}); expected a table the "
                         "store wrote: `python -m study results rebuild` remakes it from the records") from e


class TableError(ValueError):
    """A results table that cannot be read (a torn or foreign file), named by its path."""
