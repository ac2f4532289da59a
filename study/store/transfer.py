"""Finished runs moved between results folders as one tar archive: a sweep started on one machine
(a laptop, a cluster's scratch disk) goes on in another folder, where the resume finds the runs
already done and computes only the rest.

``export_runs`` packs the finished records (status ok or skipped) of a folder, or of one study, as
``records/<run_id>.json`` and, unless left out, their artefacts as ``artefacts/<run_id>/...``.
``import_runs`` checks every member of such an archive before it writes anything, then adds each
run the receiving folder has not finished; a run finished there already is kept as it is (the
store replaces a finished record only by computing it again).

The tar format and its compression come from the standard library's :mod:`tarfile`; the checks
are our own because an archive is outside input: only regular files under those two names, every
record well-formed and named by its own run id, every artefact owned by a record in the archive.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import tarfile
import tempfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from .files import tmp_path
from .records import FINISHED_STATUSES, check_record

#: archive name endings and the compression :mod:`tarfile` writes for each
SUFFIXES = {".tar": "", ".tar.gz": "gz", ".tgz": "gz", ".tar.bz2": "bz2", ".tar.xz": "xz"}
_RUN_ID = re.compile(r"[0-9a-f]{16}")


class ArchiveError(ValueError):
    """An archive that cannot be written or read as runs of a results folder; the message names the
    file or member and what was expected."""


@dataclass
class ImportReport:
    """What :func:`import_runs` did: run ids added, and those kept because the folder had finished
    them already."""

    added: list = field(default_factory=list)
    kept: list = field(default_factory=list)
    artefact_files: int = 0


def _compression(path: Path) -> str:
    name = path.name.lower()
    for suffix in sorted(SUFFIXES, key=len, reverse=True):
        if name.endswith(suffix):
            return SUFFIXES[suffix]
    raise ArchiveError(f"{path}: expected a name ending in one of {', '.join(SUFFIXES)}")


def export_runs(store, dest: str | os.PathLike, study: str | None = None, artefacts: bool = True) -> int:
    """Write the finished runs of ``store`` (those of ``study`` alone when given: the record's
    ``config['study']``) to the tar archive ``dest``; returns how many.

    The archive is written under a temporary name and renamed, so ``dest`` is complete or
    untouched. With ``artefacts=False`` only the records travel; they keep their list of
    artefacts, and a figure that reads one of those files finds it missing in the receiving
    folder.

    Raises
    ------
    ArchiveError
        ``dest`` has no tar name ending, or no finished run matches.
    """
    dest = Path(dest)
    mode = "w:" + _compression(dest)
    records = [r for r in store.records() if r.get("status") in FINISHED_STATUSES
               and (study is None or (r.get("config") or {}).get("study") == study)]
    if not records:
        where = f" of study {study!r}" if study is not None else ""
        raise ArchiveError(f"{store.root}: no finished run{where} to export; expected a results folder a sweep "
                           "wrote" + (" with that study" if study is not None else ""))
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = tmp_path(dest.parent, dest.name)
    try:
        with tarfile.open(tmp, mode) as tar:
            for rec in sorted(records, key=lambda r: r["run_id"]):
                rid = rec["run_id"]
                tar.add(store.record_path(rid), arcname=f"records/{rid}.json")
                adir = store.artefact_dir(rid)
                if artefacts and adir.is_dir():
                    tar.add(adir, arcname=f"artefacts/{rid}")
        os.replace(tmp, dest)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return len(records)


def _open(src: Path) -> tarfile.TarFile:
    try:
        return tarfile.open(src, "r:*")
    except FileNotFoundError:
        raise ArchiveError(f"{src}: no such file; expected a tar archive of runs (python -m study results "
                           "export)") from None
    except (tarfile.TarError, OSError):
        raise ArchiveError(f"{src}: not a readable tar archive (plain, gzip, bzip2 or xz); expected one written by "
                           "python -m study results export") from None


def _artefact_member(m: tarfile.TarInfo) -> tuple[str, str] | None:
    """``(run id, relative name)`` of an artefact member, or None."""
    parts = PurePosixPath(m.name).parts
    if m.isfile() and len(parts) >= 3 and parts[0] == "artefacts" and _RUN_ID.fullmatch(parts[1]):
        return parts[1], PurePosixPath(*parts[2:]).as_posix()
    return None


def _read_members(src: Path, staging: Path) -> tuple[dict, dict]:
    """``({run_id: record}, {run_id: [relative artefact names]})`` of the archive ``src``, every
    member checked first (:class:`ArchiveError` on the first one that is not as expected). Each
    artefact is copied to ``staging/<run_id>/<name>`` on the way (streamed: an archive of large
    traces is not held in memory)."""
    records, files = {}, {}
    with _open(src) as tar:
        for m in tar:
            parts = PurePosixPath(m.name).parts
            if m.isdir() and parts and parts[0] in ("records", "artefacts"):
                continue
            if not m.isfile() or m.name.startswith("/") or ".." in parts:
                raise ArchiveError(f"{src}: member {m.name!r}: expected only regular files under records/ and "
                                   "artefacts/ (no links, absolute paths or '..')")
            if len(parts) == 2 and parts[0] == "records" and parts[1].endswith(".json"):
                stem = parts[1][:-5]
                try:
                    rec = json.loads(tar.extractfile(m).read().decode("utf-8"))
                except (ValueError, UnicodeDecodeError) as e:
                    raise ArchiveError(f"{src}: member {m.name}: not valid JSON ({e})") from None
                errs, _ = check_record(rec)
                if not errs and rec["run_id"] != stem:
                    errs = [f"its run_id {rec['run_id']!r} is not its file name"]
                if not errs and rec["status"] not in FINISHED_STATUSES:
                    errs = [f"status {rec['status']!r}; expected a finished run ({', '.join(FINISHED_STATUSES)})"]
                if errs:
                    raise ArchiveError(f"{src}: member {m.name}: not a run record: {'; '.join(errs)}")
                records[stem] = rec
            elif (art := _artefact_member(m)) is not None:
                files.setdefault(art[0], []).append(art[1])
                dest = staging.joinpath(*art)
                dest.parent.mkdir(parents=True, exist_ok=True)
                with tar.extractfile(m) as fin, open(dest, "wb") as fout:
                    shutil.copyfileobj(fin, fout)
            else:
                raise ArchiveError(f"{src}: member {m.name!r}: expected records/<run_id>.json or "
                                   "artefacts/<run_id>/<file>")
    orphans = sorted(set(files) - set(records))
    if orphans:
        raise ArchiveError(f"{src}: artefacts/{orphans[0]}/ has no record in the archive; expected "
                           f"records/{orphans[0]}.json beside it")
    if not records:
        raise ArchiveError(f"{src}: no record in the archive; expected records/<run_id>.json members")
    return records, files


def import_runs(store, src: str | os.PathLike) -> ImportReport:
    """Add the runs of the archive ``src`` to ``store``: each run it has not finished (absent, or
    failed, which is kept under ``records/failed/`` as any retried run's) is written with its
    artefacts; each it has finished is kept. The whole archive is checked before the first write.

    The artefacts are streamed to a temporary folder while the archive is checked, then moved into
    the store run by run: the import needs the memory of one member, not of the archive (and, for
    the while, the disk of its artefacts).

    Raises
    ------
    ArchiveError
        ``src`` is missing, not a tar archive, or holds a member that is not a run's record or
        artefact (named in the message); nothing has been written.
    """
    src = Path(src)
    report = ImportReport()
    with tempfile.TemporaryDirectory(prefix="study-import-") as staging:
        records, files = _read_members(src, Path(staging))
        store.check_writable()
        for rid in sorted(records):
            if store.finished(rid):
                report.kept.append(rid)
            else:
                _add(store, records[rid], {n: Path(staging, rid, n) for n in files.get(rid, ())}, report)
    return report


def _add(store, record: dict, artefacts: dict, report: ImportReport) -> None:
    """Write one run (its artefacts: files moved into the store), or count it kept when a sweep
    writing to the same folder finished it meanwhile."""
    try:
        store.write(record, artefacts=artefacts or None)
    except FileExistsError:
        report.kept.append(record["run_id"])
        return
    report.added.append(record["run_id"])
    report.artefact_files += len(artefacts)
