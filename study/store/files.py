"""Files of the results folder written so that a reader never sees half of one: atomic writes,
temp names that say who wrote them (so a crash's leftover can be told from a live writer's file),
archive names."""
from __future__ import annotations

import json
import os
import socket
import uuid
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

#: This machine's name as written into temp names ('~' separates the fields of a temp name).
HOST = socket.gethostname().replace("~", "-").replace("/", "-") or "unknown-host"


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="microseconds")


def stamp() -> str:
    """A file-name-safe UTC timestamp for archived attempts."""
    return datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S.%fZ")


def _json_default(obj: Any) -> Any:
    """Make numpy scalars/arrays and paths JSON-serialisable (configs and metrics often carry
    them)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (Path, os.PathLike)):
        return os.fspath(obj)
    if isinstance(obj, (set, frozenset)):
        return sorted(obj, key=str)
    return str(obj)


def dumps(obj: Any, **kw) -> str:
    """JSON text of ``obj`` (numpy values and paths included)."""
    return json.dumps(obj, default=_json_default, ensure_ascii=False, **kw)


def tmp_path(folder: Path, name: str) -> Path:
    """A temp name in ``folder`` for ``name``: ``.<name>~<host>~<pid>~<random>.tmp``."""
    return folder / f".{name}~{HOST}~{os.getpid()}~{uuid.uuid4().hex[:12]}.tmp"


def tmp_owner(name: str) -> tuple[str, int] | None:
    """``(host, pid)`` of a temp name made by :func:`tmp_path`; None for another name (an older
    format)."""
    if not (name.startswith(".") and name.endswith(".tmp")):
        return None
    parts = name[1:-4].rsplit("~", 3)
    if len(parts) != 4 or not parts[2].isdigit():
        return None
    return parts[1], int(parts[2])


def pid_alive(pid: int) -> bool:
    """Whether a process of the local host is running (a zombie counts as running: it is not ours
    to judge)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists but belongs to someone else, or cannot be asked: assume alive
    return True


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see either the old file or the complete new one.

    The temp file lives in the same folder (``os.replace`` is only atomic within one file system),
    starts with a dot and ends in ``.tmp`` so that no glob for ``*.json`` / ``*.parquet`` picks it
    up, and its name says which host and process wrote it (:func:`tmp_path`). It is created with
    mode 0666 minus the umask (not mkstemp's
    0600) so a shared results folder stays readable.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = tmp_path(path.parent, path.name)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as e:
        raise OSError(e.errno, e.strerror, str(path)) from e  # the file meant, not its temporary name
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())  # the rename must not land before the data on a crash
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(e, OSError) and not isinstance(e, FileNotFoundError):  # a full disk, a quota: name the file
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise


def unique(path: Path) -> Path:
    """``path`` or, if taken, ``path`` with ``-1``, ``-2``... before the suffix (archives never
    overwrite)."""
    if not path.exists():
        return path
    stem, suffix = (path.name[: -len(".json")], ".json") if path.name.endswith(".json") else (path.name, "")
    i = 1
    while (cand := path.with_name(f"{stem}-{i}{suffix}")).exists():
        i += 1
    return cand
