"""The results store: run records, their checks and names, the results folder, the parquet tables.

It knows nothing of pipelines: ``study.run.executor`` decides what to compute and hands finished
records to :class:`ResultStore`. Full description of the folder and its columns:
``results/README.md``.
"""
from .files import dumps
from .provenance import PROVENANCE_PACKAGES, provenance
from .records import (FINISHED_STATUSES, NON_SCIENTIFIC_KEYS, PARAM_OPTIONAL, PARAM_REQUIRED, PARAM_TEXT,
                      REQUIRED_FIELDS, STATUSES, canonical, check_artefacts, record_problems, run_id,
                      scientific_config, validate_record)
from .store import Claim, ResultsFolderError, ResultStore, StoreReport
from .tables import PARAM_BASE_COLUMNS, PARAM_CONFIG_COLUMNS, RUN_BASE_COLUMNS, TableError, read_table

__all__ = ["Claim", "FINISHED_STATUSES", "NON_SCIENTIFIC_KEYS", "PARAM_BASE_COLUMNS", "PARAM_CONFIG_COLUMNS",
           "PARAM_OPTIONAL", "PARAM_REQUIRED", "PARAM_TEXT", "PROVENANCE_PACKAGES", "REQUIRED_FIELDS",
           "RUN_BASE_COLUMNS", "ResultStore", "ResultsFolderError", "STATUSES", "StoreReport", "TableError", "canonical",
           "check_artefacts", "dumps", "provenance", "read_table", "record_problems", "run_id",
           "scientific_config", "validate_record"]
