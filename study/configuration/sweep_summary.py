"""How a sweep ends: one line counting its jobs by status, and the command's exit status.

Called by the project's sweeper (``hydra_plugins/study_sweeper``) with every job's return; here,
below the app that registers the sweeper, so that the sweeper never imports the app (no import
cycle), and outside every run's code fingerprint (a run's result does not depend on how its sweep
is summarised)."""
from __future__ import annotations

from study.configuration.cli import EXIT_FAILED, fail

__all__ = ["sweep_finished"]


def sweep_finished(returns: list) -> None:
    """After a sweep (called by the sweeper with every job's return): one line counting the jobs
    by status, and a non-zero exit status when a run failed or a job ended in an error (each was
    reported when it happened)."""
    counts: dict = {}
    for r in returns:
        st = r.get("status", "?") if isinstance(r, dict) else "error"
        counts[st] = counts.get(st, 0) + 1
    bad = counts.get("failed", 0) + counts.get("error", 0)
    print(f"[study] sweep finished: {len(returns)} jobs, " + ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
          + (f"; exit status {EXIT_FAILED}: {bad} run(s) failed or ended in an error" if bad else ""), flush=True)
    if bad:
        fail(EXIT_FAILED)
