"""The results folder: one atomic JSON record per run (the truth), each run's artefacts, claims that
let one process compute a run while others wait or move on, and the two parquet tables rebuilt from
the records (benchopt-style: the records are the truth, the tables a cache). It knows nothing of
what a run computes: the executor (``study.run.executor``) hands it finished records.

Layout under the results folder ``root`` (default ``results/``, relative to the working directory)::

    records/<run_id>.json               one record per run (written to a temp file, then os.replace)
    records/failed/<run_id>.<ts>.json   earlier failed attempts, kept when a run is retried
    records/superseded/<run_id>.<ts>.json  finished records replaced by a re-run (changed code, force)
    records/.claims/<run_id>.lock       held by the process computing the run (overlapping sweeps wait or skip)
    artefacts/<run_id>/...              large files of one run (one folder per run, never shared)
    runs.parquet                        one row per run
    params.parquet                      one row per identified parameter (long form)
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
from filelock import FileLock, Timeout

from . import tables
from .files import HOST, atomic_write_bytes, dumps, now_iso, pid_alive, stamp, tmp_owner, tmp_path, unique
from .provenance import provenance
from .records import FINISHED_STATUSES, check_artefacts, check_record, mistyped_records, ordered, validate_record

# a per-run lock is held only for the few ms of a write; the timeout guards against a wedged file system
_WRITE_LOCK_TIMEOUT = 300.0
_COLLECT_LOCK_TIMEOUT = 600.0
#: A temp file or folder of a writer on another host (whose process cannot be asked) is a crash leftover when
#: older than this [s]: a record or table is written in milliseconds, an artefact folder placed in seconds.
LEFTOVER_AGE = 3600.0


class ResultsFolderError(RuntimeError):
    """The results folder cannot be used (not writable, or a rebuild would empty a non-empty
    table)."""


@dataclass
class StoreReport:
    """What the last reading of the records met (:attr:`ResultStore.report`): nothing is left out
    silently."""

    records: int = 0                                  #: valid records in the table (one per run)
    skipped: list = field(default_factory=list)       #: (file, reason) of records left out (malformed, misnamed)
    stale: int = 0                                    #: rows whose code differs from the current code
    removed: list = field(default_factory=list)       #: (path, why) crash leftovers removed by ``collect``
    kept: list = field(default_factory=list)          #: (path, why) temp files of writers that may be alive

    def lines(self) -> list[str]:
        """The report as short lines for a terminal (empty when there is nothing to say)."""
        out = [f"skipped record {p}: {why}" for p, why in self.skipped]
        if self.stale:
            out.append(f"{self.stale} run(s) computed by code that has changed since (code_current false); "
                       "re-running them recomputes them")
        out += [f"removed crash leftover {p} ({why})" for p, why in self.removed]
        out += [f"kept temp file {p} ({why})" for p, why in self.kept]
        return out


class Claim:
    """The right to compute one run: an exclusive OS file lock ``records/.claims/<run_id>.lock``,
    held while the run is computed, beside ``<run_id>.json`` saying who holds it.

    The lock is a ``filelock.FileLock`` (``flock``; on NFS the kernel maps it to a POSIX lock): the
    operating system releases it when its process ends in any way, SIGKILL included, so a claim of a
    dead process is never in the way (its ``.json`` is removed by the next ``collect``).
    """

    def __init__(self, store: "ResultStore", rid: str):
        self.rid = rid
        self.store = store
        self.info_path = store.claims_dir / f"{rid}.json"
        self.lock = FileLock(str(store.claims_dir / f"{rid}.lock"))

    def holder(self) -> dict | None:
        """``{host, pid, since}`` of the process that holds (or, if dead, last held) the claim,
        when known."""
        try:
            info = json.loads(self.info_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return info if isinstance(info, dict) else None

    def acquire(self, wait: bool = True) -> bool:
        """Take the claim; False when another live process holds it and ``wait`` is False (else
        wait for it)."""
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
        atomic_write_bytes(self.info_path, dumps({"host": HOST, "pid": os.getpid(), "since": now_iso()})
                           .encode("utf-8"))
        return True

    def release(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.info_path.unlink()
        self.lock.release()


_STATUS = re.compile(rb'"status":\s*"(\w+)"')


class ResultStore:
    """The results folder: records (the truth), artefacts, and the two parquet tables (rebuilt from
    records).

    Parameters
    ----------
    root : str or Path, optional
        The results folder; default ``$STUDY_RESULTS_DIR`` if set, else ``results/`` in the working
        directory.

    Attributes
    ----------
    report : StoreReport
        What the last :meth:`tables` / :meth:`collect` met: records skipped and why, stale rows,
        crash leftovers removed.
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
        self._seen: dict = {}  # record file name -> (inode, status): what status_counts has read already

    def __repr__(self) -> str:
        return f"ResultStore({str(self.root)!r})"

    # -- paths and reading
    def record_path(self, rid: str) -> Path:
        """Where the record of run ``rid`` lives."""
        return self.records_dir / f"{rid}.json"

    def artefact_dir(self, rid: str) -> Path:
        """The folder of run ``rid``'s large files (owned by that run only)."""
        return self.artefacts_root / rid

    def _read_path(self, path: Path) -> tuple[dict | None, str | None]:
        """``(record, None)`` of a well-formed record file, else ``(None, reason)``.

        Well-formed: valid JSON of the right shape (:func:`study.store.records.record_problems`)
        whose file is named by its own ``run_id`` (a copy under another name would be a second row
        of one run).
        """
        try:
            rec = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None, "no such file"
        except (OSError, UnicodeDecodeError) as e:
            return None, f"unreadable ({e})"
        except ValueError as e:
            return None, f"not valid JSON ({e})"
        errs, _ = check_record(rec)
        if errs:
            return None, "; ".join(errs)
        if rec["run_id"] != path.stem:
            return None, (f"the file name does not match its run_id {rec['run_id']!r} (a copy or a renamed "
                          f"record; the record of that run is records/{rec['run_id']}.json)")
        return rec, None

    def read(self, rid: str) -> dict | None:
        """The record of ``rid``, or None when absent, torn or malformed (such a record counts as
        absent: the run is computed again and the bad file kept under ``records/failed/``)."""
        return self._read_path(self.record_path(rid))[0]

    def finished(self, rid: str) -> bool:
        """True when run ``rid`` need not run again: its record says 'ok' or 'skipped' ('failed'
        reruns)."""
        rec = self.read(rid)
        return rec is not None and rec.get("status") in FINISHED_STATUSES

    def status_counts(self) -> dict:
        """Runs in the records folder by status, for progress lines. A record is read once per
        store object (and again only when replaced: every write is a new file), from its first
        bytes (records are written run_id first, status second), so counting after every job of a
        long sweep stays cheap. A record whose status is not a word is counted as ``malformed``."""
        counts, names = {}, set()
        if not self.records_dir.is_dir():
            return counts
        for e in os.scandir(self.records_dir):
            if not e.name.endswith(".json"):
                continue
            names.add(e.name)
            key = e.inode()  # from the listing itself (no stat); a rewritten record is a new file (atomic rename)
            seen = self._seen.get(e.name)
            if seen is None or seen[0] != key:
                status = self._peek_status(Path(e.path))
                if status is None:
                    continue
                seen = self._seen[e.name] = (key, status)
            counts[seen[1]] = counts.get(seen[1], 0) + 1
        for gone in set(self._seen) - names:
            del self._seen[gone]
        return counts

    @staticmethod
    def _peek_status(path: Path) -> str | None:
        try:
            with open(path, "rb") as fh:
                m = _STATUS.search(fh.read(256))
            if m:
                return m.group(1).decode()
            st = json.loads(path.read_text(encoding="utf-8")).get("status")
            return st if isinstance(st, str) else "malformed"
        except FileNotFoundError:
            return None
        except (OSError, ValueError, AttributeError):
            return "malformed"

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
        """Raise :class:`ResultsFolderError` unless files can be created in the results folder
        and its ``records/`` (tried with a real file: permission bits say nothing about ACLs,
        read-only mounts, a full disk or a file where the folder should be). Nothing is created:
        a folder not there yet is probed at its nearest existing ancestor (a refused setting must
        leave no results folder behind)."""
        try:
            dirs = [d for d in (self.root, self.records_dir) if d.is_dir()]
            if not dirs:
                anc = self.root.resolve()
                while not anc.exists() and anc != anc.parent:
                    anc = anc.parent
                if not anc.is_dir():
                    raise NotADirectoryError(20, "not a folder", str(anc))
                dirs = [anc]
            for d in dirs:
                probe = tmp_path(d, "write-probe")
                os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
                os.unlink(probe)
        except OSError as e:
            raise ResultsFolderError(
                f"results folder {self.root.resolve()} is not writable ({e.strerror or e}"
                f"{': ' + str(e.filename) if getattr(e, 'filename', None) else ''}); expected a folder this user "
                "can create files in: set results_dir=<folder> or STUDY_RESULTS_DIR") from e

    def _archive(self, rid: str, dest: Path, when: str) -> None:
        """Move run ``rid``'s record into ``dest`` (``records/failed/`` or
        ``records/superseded/``) as ``<rid>.<when>.json`` and its artefact folder to
        ``artefacts/<dest name>/<rid>.<when>/``."""
        path = self.record_path(rid)
        if path.exists():
            dest.mkdir(parents=True, exist_ok=True)
            os.replace(path, unique(dest / f"{rid}.{when}.json"))
        adir = self.artefact_dir(rid)
        if adir.exists():
            to = unique(self.artefacts_root / dest.name / f"{rid}.{when}")
            to.parent.mkdir(parents=True, exist_ok=True)
            os.replace(adir, to)

    def write(self, record: dict, overwrite: bool = False, artefacts: dict | None = None) -> Path:
        """Validate ``record``, add the provenance, and write it atomically as
        ``records/<run_id>.json``.

        Parameters
        ----------
        record : dict
            See :data:`study.store.records.REQUIRED_FIELDS` and ``results/README.md``.
            ``provenance`` is added when absent.
        overwrite : bool
            Replace an existing 'ok' or 'skipped' record (otherwise ``FileExistsError``); the
            replaced record is moved to ``records/superseded/<run_id>.<timestamp>.json`` and its
            artefacts to ``artefacts/superseded/<run_id>.<timestamp>/`` (a re-run after a code
            change, or forced).
        artefacts : dict, optional
            ``{relative name: bytes or path}``; bytes are written, paths moved into
            ``artefacts/<run_id>/``. Their names are stored in the record's ``artefacts`` list.

        Returns
        -------
        Path
            The record's file.

        Raises
        ------
        FileExistsError
            A finished ('ok'/'skipped') record of this run exists and ``overwrite`` is False; it is
            unchanged.
        ValueError
            The record or the artefacts are malformed (or its run id is not the run id of its
            config).

        Notes
        -----
        An existing 'failed' (or unreadable, or malformed) record is not lost: it is moved to
        ``records/failed/<run_id>.<timestamp>.json`` and its artefact folder, if any, to
        ``artefacts/failed/<run_id>.<timestamp>/``. The check and the replace happen under a per-run
        file lock, so two processes finishing the same run produce exactly one record.
        """
        validate_record(record)
        artefacts = check_artefacts(artefacts)
        rec = ordered(record)
        rec.setdefault("provenance", provenance())
        rec["artefacts"] = sorted(Path(str(n)).as_posix() for n in artefacts) if artefacts else \
            list(rec.get("artefacts") or [])
        data = dumps(rec, indent=1).encode("utf-8")  # fails here, before anything on disk changes
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
                self._archive(rid, dest, stamp())
            if artefacts:
                self._place_artefacts(rid, artefacts)
            atomic_write_bytes(path, data)
        return path

    def restamp(self, current, unchanged) -> tuple[int, int]:
        """Re-label the code of finished records written under an older hashing of the same code:
        for each record whose ``code`` has no ``scheme``, ``current(config)`` gives the code dict
        today and ``unchanged(old, new)`` whether the record's code is that code
        (``study.store.fingerprint``: the files' bytes are the same); if so the record's ``code``
        becomes today's, with the old fingerprint kept as ``code['restamped_from']``. Written
        atomically under the run's lock; nothing else in the record changes. Returns (restamped,
        left as they were: computed by other code, to be re-run)."""
        done = left = 0
        for path in sorted(self.records_dir.glob("*.json")) if self.records_dir.is_dir() else []:
            rec, _ = self._read_path(path)
            code = rec.get("code") if rec is not None else None
            if rec is None or rec.get("status") not in FINISHED_STATUSES or not isinstance(code, dict) \
                    or code.get("scheme"):
                continue
            new = current(rec["config"])
            if not unchanged(code, new):
                left += 1
                continue
            with self._lock(rec["run_id"]):
                fresh, _ = self._read_path(path)
                if fresh is None or fresh.get("code") != code:  # rewritten meanwhile: leave it to its writer
                    continue
                fresh["code"] = {**new, "restamped_from": code.get("fingerprint")}
                atomic_write_bytes(path, dumps(ordered(fresh), indent=1).encode("utf-8"))
            done += 1
        return done, left

    def _place_artefacts(self, rid: str, artefacts: dict) -> None:
        # build the folder under a temp name and rename it: the run's folder appears complete or not at all
        self.artefacts_root.mkdir(parents=True, exist_ok=True)
        tmp = tmp_path(self.artefacts_root, rid)
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

    # -- crash leftovers
    def leftovers(self) -> list[tuple[Path, str, bool]]:
        """Temp files and folders of writes that never finished: ``(path, why, removable)``.

        Removable: written by a process of this host that is no longer running, or older than
        :data:`LEFTOVER_AGE` (a writer on another host cannot be asked). Also the ``.json`` of
        claims whose process has ended (their lock is free).
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
                owner = tmp_owner(name)
                if owner is not None and owner[0] == HOST:
                    alive = pid_alive(owner[1])
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
    def records(self) -> list[dict]:
        """The well-formed records; what was left out goes into :attr:`report` and a
        ``RuntimeWarning`` naming its file."""
        rep = StoreReport()
        out = []
        for p in sorted(self.records_dir.glob("*.json")) if self.records_dir.is_dir() else []:
            rec, why = self._read_path(p)
            if rec is None:
                rep.skipped.append((p, why))
                warnings.warn(f"skipping record {p}: {why}", RuntimeWarning, stacklevel=3)
                continue
            out.append((p, rec))
        bad = mistyped_records(out)  # a field of the wrong type would change its column for every row
        for p, why in bad.items():
            rep.skipped.append((p, why))
            warnings.warn(f"skipping record {p}: {why}", RuntimeWarning, stacklevel=3)
        out = [rec for p, rec in out if p not in bad]
        rep.records = len(out)
        self.report = rep
        return out

    def tables(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Build ``(runs, params)`` from the records without writing anything (see
        :attr:`report`)."""
        runs, params, stale = tables.build(self.records())
        self.report.stale = stale
        return runs, params

    def collect(self, allow_empty: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Merge all records into ``runs.parquet`` and ``params.parquet`` and return them.

        Each file is written to a temp file and ``os.replace``d, under ``root/.collect.lock``, so a
        reader never sees a torn table and concurrent collectors never interleave. A malformed or
        misnamed record is left out with a ``RuntimeWarning`` naming its file, and counted in
        :attr:`report`; crash leftovers are removed first (:meth:`clean_leftovers`, also in
        :attr:`report`).

        Raises
        ------
        ResultsFolderError
            No well-formed record, and ``runs.parquet`` holds rows: a rebuild never replaces a
            non-empty table with an empty one (a wrong ``root``?) unless ``allow_empty``.
        """
        self.root.mkdir(parents=True, exist_ok=True)
        with FileLock(str(self.root / ".collect.lock"), timeout=_COLLECT_LOCK_TIMEOUT):
            removed, kept = self.clean_leftovers()
            runs, params = self.tables()
            self.report.removed, self.report.kept = removed, kept
            if not len(runs) and not allow_empty:
                before = tables.table_rows(self.runs_path)
                if before:
                    bad = f" ({len(self.report.skipped)} malformed record(s) skipped)" if self.report.skipped else ""
                    raise ResultsFolderError(
                        f"no well-formed record in {self.records_dir.resolve()}{bad}: refusing to replace "
                        f"{self.runs_path.resolve()} ({before} runs) with an empty table; expected the results "
                        "folder of those runs (a wrong --root / results_dir?), or allow_empty (--allow-empty)")
            for df, path in ((runs, self.runs_path), (params, self.params_path)):
                atomic_write_bytes(path, df.to_parquet(index=False))
        return runs, params

    def load(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Read ``(runs, params)`` from the parquet files, collecting first when either is
        missing."""
        if not (self.runs_path.exists() and self.params_path.exists()):
            return self.collect()
        return tables.read_table(self.runs_path), tables.read_table(self.params_path)
