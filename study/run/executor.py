"""What to compute and when: claim a run, resume it when finished by the same code, compute it, hand
the record to the store. The store (``study.store``) only keeps records; the computation is handed
in from above (a function for one run, a :class:`ReplicatedJob` for the independent datasets of one
configuration), the way emcee's sampler is handed a backend it never looks inside.

Replicates
----------
``replicates=N`` identifies N independent datasets of one configuration in one job. Replicate ``k``
is a run of its own (its own run id, record and row), drawn from the dataset seed
:func:`dataset_seed` ``(seed, k)``: replicate 0 is the configuration's seed itself (the run a job
without replicates makes), replicate ``k >= 1`` the first 31 bits of
``numpy.random.SeedSequence([seed, k])``'s state. The seed of replicate ``k`` depends on ``seed``
and ``k`` only, so replicate 5 is the same dataset whether a job asks for 10 replicates or 50, and
raising N later computes only the new ones. Work shared by the replicates (composing the models,
simulating the noise-free truth) is done once per job; the replicates are computed in chunks, each
written as soon as its chunk is done, so a kill loses at most one chunk (as many replicates as about
:data:`CHUNK_SECONDS` of computing, at least one).
"""
from __future__ import annotations

import json
import os
import time
import traceback
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np

from study.store import fingerprint as code_fp
from study.store import FINISHED_STATUSES, ResultStore, check_artefacts, run_id, validate_record
from study.store.files import now_iso

#: How resume decides that a finished run can be reused: ``code`` (its code fingerprint equals the current
#: code's) or ``config`` (any finished record of the configuration, whatever code made it).
RESUME_MODES = ("code", "config")
#: A chunk of replicates takes about this long [s] to compute (at least one replicate): what a kill can lose
#: (``STUDY_CHUNK_SECONDS`` sets it; 0: every replicate written as soon as it is computed, no batched replay).
CHUNK_SECONDS = 2.0


def _chunk_seconds() -> float:
    v = os.environ.get("STUDY_CHUNK_SECONDS", "").strip()
    try:
        return max(0.0, float(v)) if v else CHUNK_SECONDS
    except ValueError:
        return CHUNK_SECONDS


def dataset_seed(seed: int, replicate: int) -> int:
    """The seed of replicate ``replicate``'s dataset (measurement noise, random rudder signal,
    estimator's own randomness): ``seed`` itself for replicate 0, else the first 31 bits of the
    state of ``numpy.random.SeedSequence([seed, replicate])`` (independent streams for every
    pair; the same number whatever the number of replicates asked for)."""
    if replicate == 0:
        return int(seed)
    state = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(replicate)]).generate_state(1, dtype=np.uint32)
    return int(state[0] & 0x7FFFFFFF)


@dataclass(frozen=True)
class Replicate:
    """One dataset of a configuration: its index, the seed it is drawn from, its run id."""

    index: int
    dataset_seed: int
    run_id: str


class ReplicatedJob(Protocol):
    """What the executor needs of a job that identifies many datasets of one configuration."""

    def prepare(self) -> dict | None:
        """The work every replicate shares; a result (``status: skipped`` with ``error``) that
        holds for every replicate, or None."""

    def identify(self, rep: Replicate) -> Any:
        """One dataset drawn and identified (an intermediate result handed to :meth:`finish`)."""

    def finish(self, partials: list) -> list[dict]:
        """The results of a chunk of identified datasets, in order: ``{'metrics', 'params',
        'timings', 'artefacts'}`` each (validation replays may be batched over the chunk)."""


def _reusable(rec: dict | None, code: dict, resume: str) -> bool:
    if rec is None or rec.get("status") not in FINISHED_STATUSES:
        return False
    return resume == "config" or not code_fp.changed_components(rec.get("code"), code)


def _when(rec: dict | None) -> tuple:
    return (rec.get("started"), rec.get("finished")) if rec else (None, None)


def _record(rep: Replicate, config: dict, seed, started: str, out: Any, wall: float, code: dict,
            replicated: bool) -> tuple[dict, dict | None]:
    """The record of one run from its result ``out`` (a dict, or the traceback text of a
    failure)."""
    record = {"run_id": rep.run_id, "config": config, "seed": seed, "started": started}
    if replicated:
        record.update(replicate=rep.index, dataset_seed=rep.dataset_seed)
    artefacts = None
    try:
        if isinstance(out, str):
            raise _Failed(out)
        if not isinstance(out, dict):
            raise TypeError(f"the run function must return a dict, got {type(out).__name__}")
        status = out.get("status", "ok")
        record.update(status=status, error=out.get("error") if status != "ok" else None,
                      metrics=dict(out.get("metrics") or {}), params=list(out.get("params") or []),
                      timings={**dict(out.get("timings") or {}), "wall": wall}, finished=now_iso())
        validate_record(record)  # a malformed result is a failure of the run, recorded like any other
        artefacts = check_artefacts(out.get("artefacts"))
    except _Failed as e:
        record.update(status="failed", error=str(e), metrics={}, params=[], timings={"wall": wall},
                      finished=now_iso())
    except Exception:
        record.update(status="failed", error=traceback.format_exc(), metrics={}, params=[], timings={"wall": wall},
                      finished=now_iso())
        artefacts = None
    record["code"] = code
    return record, artefacts


class _Failed(Exception):
    """A failure already turned into its traceback text."""


def _write(store: ResultStore, record: dict, artefacts, existing: dict | None) -> dict:
    replace = existing is not None and existing.get("status") in FINISHED_STATUSES
    try:
        path = store.write(record, overwrite=replace, artefacts=artefacts)
    except FileExistsError:
        # a writer that takes no claim finished the same run meanwhile: its record stands
        other = store.read(record["run_id"])
        if other is None:
            raise
        return {**other, "resumed": True}
    return json.loads(path.read_text(encoding="utf-8"))


def run_replicated(store: ResultStore, config: dict, job: ReplicatedJob, replicates: int, seed: int | None, *,
                   force: bool = False, resume: str = "code", wait: bool = True,
                   code: dict | None = None) -> list[dict]:
    """Identify ``replicates`` independent datasets of ``config``, each its own run, and leave
    exactly one record per replicate.

    Parameters
    ----------
    store : ResultStore
    config : dict
        The resolved configuration (without ``replicates``); the run id of replicate ``k`` is
        ``run_id(config, k)``.
    job : ReplicatedJob
        What to compute; :meth:`ReplicatedJob.prepare` is called only when a replicate needs
        computing.
    replicates : int
        How many datasets (N >= 1): replicates 0 .. N-1.
    seed : int or None
        The configuration's seed (stored in every record; each dataset's own seed is
        :func:`dataset_seed`).
    force, resume, wait, code
        As for :func:`run_guarded`, per replicate.

    Returns
    -------
    list of dict
        The record of each replicate, in order (``resumed=True`` when it was already finished;
        ``status: claimed`` when another live process computes it and ``wait`` is False).

    Notes
    -----
    A replicate whose identification or validation raises is a 'failed' record with its traceback;
    the others land. A failure of the shared work fails every replicate still to compute, each with
    that traceback. ``KeyboardInterrupt`` / ``SystemExit`` propagate and leave no record of the
    chunk in progress.
    """
    _check_arguments(resume, replicates)
    replicated = replicates > 1
    code = code if code is not None else code_fp.code_fingerprint(config)
    out, pending, before = _finished_replicates(store, config, replicates, seed, code, force, resume)
    shared: Any = None  # None: not prepared yet; a dict: every replicate's result; a str: its failure
    prepared, shared_time = False, 0.0
    chunk, i = 1, 0
    while i < len(pending):
        batch, i = pending[i:i + chunk], i + chunk
        claims = []
        try:
            _claim_batch(store, config, batch, code, force, resume, wait, out, before, claims)
            todo = [rep for rep in batch if out[rep.index] is None]
            if not todo:
                continue
            if not prepared:
                shared, shared_time = _prepare_shared(job)
                prepared = True
            # a replicate's wall time: its own share of the chunk and of the work shared by the job
            took = _compute_and_write(store, config, job, todo, shared, shared_time / max(1, len(pending)), seed,
                                      code, replicated, out, before)
            chunk = max(1, int(_chunk_seconds() / max(took / len(todo), 1e-3)))
        finally:
            for claim in claims:
                claim.release()
    return out


def _check_arguments(resume: str, replicates) -> None:
    """Refuse a ``resume`` mode or a number of ``replicates`` that :func:`run_replicated` does
    not know."""
    if resume not in RESUME_MODES:
        raise ValueError(f"resume={resume!r}: expected one of {RESUME_MODES}")
    if not (isinstance(replicates, int) and not isinstance(replicates, bool) and replicates >= 1):
        raise ValueError(f"replicates={replicates!r}: expected a whole number >= 1")


def _finished_replicates(store: ResultStore, config: dict, replicates: int, seed, code: dict, force: bool,
                         resume: str) -> tuple[list, list, dict]:
    """The records of the replicates already finished (``out``, None where not), the replicates
    still to compute (``pending``) and the record each of those had (``before``, None if none)."""
    out: list = [None] * replicates
    pending, before = [], {}
    for k in range(replicates):
        rep = Replicate(k, dataset_seed(seed or 0, k), run_id(config, k))
        rec = store.read(rep.run_id)
        if not force and _reusable(rec, code, resume):
            out[k] = {**rec, "resumed": True}
        else:
            pending.append(rep)
            before[k] = rec
    return out, pending, before


def _claim_batch(store: ResultStore, config: dict, batch: list, code: dict, force: bool, resume: str, wait: bool,
                 out: list, before: dict, claims: list) -> None:
    """Claim each replicate of ``batch`` (appended to ``claims``, for the caller to release);
    fill ``out`` for those claimed by another live process (when not waiting) or finished
    meanwhile by one we waited for."""
    for rep in batch:
        claim = store.claim(rep.run_id)
        if not claim.acquire(wait=wait):
            out[rep.index] = {"run_id": rep.run_id, "status": "claimed", "config": config,
                              "claimed_by": claim.holder(), "replicate": rep.index}
            continue
        claims.append(claim)
        existing = store.read(rep.run_id)  # again: the process we waited for may have finished it
        fresh = existing is not None and _when(existing) != _when(before[rep.index])
        if _reusable(existing, code, resume) and (fresh or not force):
            out[rep.index] = {**existing, "resumed": True}
            continue
        before[rep.index] = existing


def _prepare_shared(job: ReplicatedJob) -> tuple[Any, float]:
    """The job's shared work (its result, or its traceback text when it failed) and the seconds
    it took."""
    t0 = time.perf_counter()
    try:
        shared = job.prepare()
    except Exception:
        shared = traceback.format_exc()
    return shared, time.perf_counter() - t0


def _compute_and_write(store: ResultStore, config: dict, job: ReplicatedJob, todo: list, shared: Any,
                       shared_wall: float, seed, code: dict, replicated: bool, out: list, before: dict) -> float:
    """Compute the replicates ``todo`` and write their records (into ``out`` too); the seconds
    the computing took. ``shared_wall``: each replicate's share of the shared work's time."""
    t0, started = time.perf_counter(), now_iso()
    results = _compute_chunk(job, todo, shared)
    took = time.perf_counter() - t0
    for rep, (res, own) in zip(todo, results):
        record, artefacts = _record(rep, config, seed, started, res, own + shared_wall, code, replicated)
        out[rep.index] = _write(store, record, artefacts, before[rep.index])
    return took


def _compute_chunk(job: ReplicatedJob, todo: list, shared: Any) -> list[tuple[Any, float]]:
    """``(result or traceback text, seconds)`` of each replicate of a chunk."""
    if shared is not None:
        return [(shared, 0.0) for _ in todo]
    partials, times = [], []
    for rep in todo:
        t0 = time.perf_counter()
        try:
            partials.append(job.identify(rep))
        except Exception:
            partials.append(_Failed(traceback.format_exc()))
        times.append(time.perf_counter() - t0)
    ok = [j for j, p in enumerate(partials) if not isinstance(p, _Failed)]
    results: list = [str(p) if isinstance(p, _Failed) else None for p in partials]
    if ok:
        t0 = time.perf_counter()
        try:
            finished = job.finish([partials[j] for j in ok])
            for j, res in zip(ok, finished):
                results[j] = res
            share = (time.perf_counter() - t0) / len(ok)
            for j in ok:
                times[j] += share
        except Exception:  # the batch failed: finish each alone, so a failure is its own replicate's
            for j in ok:
                t1 = time.perf_counter()
                try:
                    results[j] = job.finish([partials[j]])[0]
                except Exception:
                    results[j] = traceback.format_exc()
                times[j] += time.perf_counter() - t1
    return list(zip(results, times))


class _OneRun:
    """A single run computed by a function (a run on the user's records, the doctor's runs)."""

    def __init__(self, fn: Callable[[], dict]):
        self.fn = fn

    def prepare(self) -> None:
        return None

    def identify(self, rep: Replicate) -> Any:
        return self.fn()

    def finish(self, partials: list) -> list[dict]:
        return partials


def run_guarded(store: ResultStore, config: dict, fn: Callable[[], dict], seed: int | None, *,
                force: bool = False, resume: str = "code", wait: bool = True, code: dict | None = None) -> dict:
    """Run ``fn`` for ``config`` unless already finished by the same code, and always leave exactly
    one record.

    Parameters
    ----------
    store : ResultStore
    config : dict
        The resolved configuration; its run id names the record.
    fn : callable
        ``fn() -> {'metrics', 'params', 'timings'}`` plus optionally ``status`` ('skipped' with
        ``error`` = the reason) and ``artefacts`` (``{name: bytes or path}``, moved into
        ``artefacts/<run_id>/``).
    seed : int or None
        Stored in the record.
    force : bool
        Compute the run even if a finished record exists (it is moved to ``records/superseded/``).
    resume : {'code', 'config'}
        Reuse a finished record only if the fingerprint of the code that made it equals the current
        one (``code``, the default: :mod:`study.store.fingerprint`), or whatever code made it
        (``config``). A record computed by other code is recomputed, and kept under
        ``records/superseded/``.
    wait : bool
        When another live process is computing the same run (it holds the run's claim): wait for it
        and reuse its record (True), or return at once with status ``'claimed'`` and ``claimed_by``
        (False: a sweep moves on to its next run and leaves this one to its owner).
    code : dict, optional
        The code fingerprint to compare and store; default
        :func:`study.store.fingerprint.code_fingerprint`.

    Returns
    -------
    dict
        The record written, or the existing one with ``resumed=True`` (``fn`` is then not called).

    Notes
    -----
    An exception in ``fn`` (or a malformed result) is recorded as 'failed' with the full traceback
    in ``error`` and is not re-raised, so a sweep goes on. ``KeyboardInterrupt``/``SystemExit``
    propagate and leave no record: an interrupted run is simply run again on resume.
    ``timings['wall']`` is measured here.
    """
    return run_replicated(store, config, _OneRun(fn), 1, seed, force=force, resume=resume, wait=wait,
                          code=code)[0]
