"""Where the truncated LS-SVM's truncation acted: shared by the studies of Xu & Guedes Soares's
claim.

The truncated LS-SVM drops the columns beyond its L-curve's corner (``est_<equation>_rank`` below
``est_<equation>_k``); where it keeps every column it is least squares with LS-SVM's regularisation,
and a claim about truncation compares nothing. So the claim is decided on the datasets where the
truncation acted, and how often it acted is said beside it.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["acted", "on_datasets"]


def acted(runs: pd.DataFrame, estimator: str = "tlssvm") -> pd.Series:
    """For each run of ``estimator`` (indexed like ``runs``), whether any equation kept fewer
    columns than it has; NaN for a run that reports no rank (failed)."""
    r = runs[runs["cfg_estimator.name"] == estimator]
    eqs = sorted({c[len("m_est_"):-len("_rank")] for c in r.columns if c.startswith("m_est_") and c.endswith("_rank")})
    if not eqs:
        return pd.Series(np.nan, index=r.index)
    cut = pd.DataFrame({e: r[f"m_est_{e}_rank"] < r[f"m_est_{e}_k"] for e in eqs if f"m_est_{e}_k" in r})
    known = pd.DataFrame({e: r[f"m_est_{e}_rank"].notna() for e in eqs})
    return cut.any(axis=1).where(known.any(axis=1))


def on_datasets(df: pd.DataFrame, runs: pd.DataFrame, keys: list, estimator: str = "tlssvm") -> pd.DataFrame:
    """The rows of ``df`` (params or runs of any estimator) on the datasets (``keys`` +
    replicate) where ``estimator``'s truncation acted."""
    k = list(keys) + [c for c in ("replicate",) if c in runs and c in df]
    a = acted(runs, estimator)
    sel = runs.loc[a[a.fillna(False).astype(bool)].index, k].drop_duplicates()
    return df.merge(sel, on=k, how="inner")
