"""Where and with what a run was computed: git revision, package versions, platform, threads."""
from __future__ import annotations

import functools
import os
import platform
import socket
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

#: Distributions whose versions go into the provenance.
PROVENANCE_PACKAGES = ("numpy", "scipy", "scikit-learn", "pandas", "pysindy", "emcee", "numba", "hydra-core")

REPO_ROOT = Path(__file__).resolve().parents[2]


def _git_rev(repo: Path) -> str:
    try:
        top = subprocess.run(["git", "-C", str(repo), "rev-parse", "--show-toplevel", "HEAD"],
                             capture_output=True, text=True, timeout=10)
        lines = top.stdout.split()
        # the package must be the checkout itself, not an installed copy that happens to sit inside some repo
        if top.returncode != 0 or len(lines) != 2 or Path(lines[0]).resolve() != repo.resolve():
            return "unknown"
        # --no-optional-locks: `git status` must never take index.lock and collide with a commit in progress
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
        ``git_rev`` (commit hash, ``-dirty`` appended with uncommitted changes, ``'unknown'``
        outside a git checkout), ``python`` and the versions of :data:`PROVENANCE_PACKAGES` (None
        when not installed), ``platform``, ``hostname``, ``threads`` (``os.cpu_count()``),
        ``omp_num_threads`` and ``numba_num_threads`` (the env variables, None when unset).
    """
    return dict(_provenance_cached())  # a fresh dict so callers cannot alter the cache
