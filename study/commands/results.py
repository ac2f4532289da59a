"""``python -m study results {rebuild,show,posterior,restamp,export,import}``: the results folder from
the command line (the store itself is ``study.store``; its folder and columns are described in
``results/README.md``).

``rebuild`` remakes ``runs.parquet`` and ``params.parquet`` from the records; ``show`` counts the
runs by status and lists the last ten, without writing anything; ``export`` packs finished runs
into a tar archive and ``import`` adds an archive's runs to a folder, so a sweep goes on elsewhere
(``study.store.transfer``).
"""
from __future__ import annotations

import argparse
import os
import sys
import warnings

import pandas as pd
from filelock import Timeout

from study.store import STATUSES, ResultsFolderError, ResultStore


# ------------------------------------------------------------------------------------------------------- CLI

def _counts(runs: pd.DataFrame) -> dict:
    return {s: int((runs["status"] == s).sum()) if len(runs) else 0 for s in STATUSES}


def _say(store: ResultStore, stream=None) -> None:
    for line in store.report.lines():
        print(f"study results: {line}", file=stream or sys.stderr)


def _posterior(store: ResultStore, run_id: str, out: str | None) -> int:
    """An emcee run's chains as one ArviZ InferenceData: r-hat and ESS printed, the netCDF file
    written."""
    from pathlib import Path

    from study.identify.posterior import diagnostics, inference_data, run_chains

    chains = run_chains(store.artefact_dir(run_id))
    if not chains:
        print(f"study results: error: {run_id}: no chain.npz in {store.artefact_dir(run_id)}; expected the run id of "
              "an emcee run of this results folder", file=sys.stderr)
        return 2
    if out is not None and Path(out).suffix != ".nc":
        print(f"study results: error: --out {out}: expected a netCDF file name ending in .nc", file=sys.stderr)
        return 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # ArviZ announces its coming refactor on import
        idata = inference_data(chains, {"run_id": run_id, "results": str(store.root.resolve())})
        table = diagnostics(idata)
    print(f"{run_id}: {idata.posterior.sizes['chain']} walkers x {idata.posterior.sizes['draw']} saved draws, "
          f"{len(table)} coefficients (ArviZ; walkers as chains: r-hat says whether the ensemble mixed)")
    print(table.to_string(float_format=lambda x: f"{x:.4g}"))
    if out is not None:
        idata.to_netcdf(out)
        print(f"written {Path(out).resolve()}")
    return 0


def _transfer(store: ResultStore, args) -> int:
    """``export`` / ``import``: exit status 2 on an archive or folder refused (nothing written)."""
    from study.store.transfer import ArchiveError, export_runs, import_runs

    try:
        if args.cmd == "export":
            n = export_runs(store, args.archive, study=args.study, artefacts=not args.no_artefacts)
            print(f"{n} finished run(s){' of ' + args.study if args.study else ''} written to "
                  f"{os.path.abspath(args.archive)}" + (" (records only)" if args.no_artefacts else ""))
            return 0
        rep = import_runs(store, args.archive)
    except (ArchiveError, ResultsFolderError) as e:
        print(f"study results: error: {e}", file=sys.stderr)
        return 2
    print(f"{len(rep.added)} run(s) added ({rep.artefact_files} artefact files), {len(rep.kept)} kept as they were "
          f"(finished here already) in {store.root.resolve()}")
    runs, _ = store.collect(allow_empty=True)
    _say(store)
    print(f"runs: {store.runs_path.resolve()} ({len(runs)} runs)")
    return 0


def _parser() -> argparse.ArgumentParser:
    """The command's parser: one sub-command per job on the results folder."""
    ap = argparse.ArgumentParser(prog="python -m study results", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name, help_ in (("rebuild", "rebuild runs.parquet and params.parquet from the records"),
                        ("show", "counts by status and the last 10 runs"),
                        ("posterior", "an emcee run's posterior: ArviZ's r-hat and ESS, and a netCDF file"),
                        ("restamp", "give records fingerprinted on their files' bytes the executed-source "
                                    "fingerprint, where the code is unchanged (then rebuild)"),
                        ("export", "write the finished runs (of one study) to a tar archive (.tar, .tar.gz, "
                                   ".tar.xz)"),
                        ("import", "add the runs of such an archive that this folder has not finished; a sweep "
                                   "then computes only the rest")):
        p = sub.add_parser(name, help=help_)
        p.add_argument("--root", "--results", dest="root", default=None,
                       help="results folder (default $STUDY_RESULTS_DIR or results/)")
        if name == "rebuild":
            p.add_argument("--allow-empty", action="store_true",
                           help="write empty tables even over non-empty ones (no well-formed record found)")
            p.add_argument("--strict", action="store_true", help="exit 1 when a record was skipped")
        if name in ("export", "import"):
            p.add_argument("archive", help="the tar archive to write or read")
        if name == "export":
            p.add_argument("--study", default=None, help="only the runs of this study (its config's study)")
            p.add_argument("--no-artefacts", action="store_true",
                           help="records only (small enough to commit); figures that read an artefact of these "
                                "runs find it missing")
        if name == "posterior":
            p.add_argument("run_id", help="the run (runs.parquet's run_id)")
            p.add_argument("--out", default=None, help="write the InferenceData to this netCDF file (.nc)")
    return ap


def main(argv: list[str] | None = None) -> int:
    """``python -m study results {rebuild,show,posterior,restamp,export,import} [--root results]``;
    exit status 1 on an error, 2 on input refused."""
    args = _parser().parse_args(argv)
    store = ResultStore(args.root)
    if args.cmd == "import":  # the one command that may make the folder
        return _transfer(store, args)
    if not store.root.is_dir():  # nothing to show or rebuild: refused, and no folder is made
        print(f"study results: error: --root {args.root or store.root}: no such folder {store.root.resolve()}; "
              "expected a results folder (one a study wrote)", file=sys.stderr)
        return 2
    if args.cmd == "export":
        return _transfer(store, args)
    if args.cmd == "posterior":
        return _posterior(store, args.run_id, args.out)
    if args.cmd == "restamp":
        return _restamp(store)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the same problems are printed from the report below
        try:
            if args.cmd == "rebuild":
                return _rebuild(store, args.allow_empty, args.strict)
            runs, _ = store.tables()  # fresh from the records, writes nothing
        except (ResultsFolderError, OSError, Timeout) as e:
            print(f"study results: error: {e}", file=sys.stderr)
            return 1
    _show(store, runs)
    return 0


def _restamp(store: ResultStore) -> int:
    """``restamp``: the executed-source fingerprint for records whose code is unchanged, then the tables."""
    from study.store import fingerprint

    done, left = store.restamp(fingerprint.code_fingerprint,
                               lambda old, new: not fingerprint.changed_components(old, new))
    print(f"{done} record(s) restamped; {left} computed by code that has changed since (re-run them)")
    runs, _ = store.collect(allow_empty=True)
    print(f"runs: {store.runs_path.resolve()} ({len(runs)} runs)")
    return 0


def _rebuild(store: ResultStore, allow_empty: bool, strict: bool) -> int:
    """``rebuild``: both tables from the records; 1 under ``strict`` when a record was left out."""
    runs, params = store.collect(allow_empty=allow_empty)
    _say(store)
    c = _counts(runs)
    skipped = len(store.report.skipped)
    print(f"{len(runs)} runs ({c['ok']} ok, {c['failed']} failed, {c['skipped']} skipped), "
          f"{len(params)} parameter rows" + (f"; {skipped} record(s) left out" if skipped else ""))
    print(f"runs:   {store.runs_path.resolve()}")
    print(f"params: {store.params_path.resolve()}")
    return 1 if strict and skipped else 0


def _show(store: ResultStore, runs) -> None:
    """``show``: the folder's leftovers, its counts by status and its last ten runs."""
    _say(store)
    for p, why, removable in store.leftovers():
        print(f"study results: {'crash leftover' if removable else 'temp file'} {p} ({why})"
              + ("; the next rebuild removes it" if removable else ""), file=sys.stderr)
    c = _counts(runs)
    skipped = len(store.report.skipped)
    print(f"{store.root.resolve()}: {len(runs)} runs ({c['ok']} ok, {c['failed']} failed, {c['skipped']} skipped)"
          + (f"; {skipped} record(s) left out" if skipped else "")
          + (f"; {store.report.stale} computed by older code" if store.report.stale else ""))
    if not len(runs):
        return
    cols = [col for col in ("run_id", "replicate", "status", "finished", "wall_time", "code_current",
                            "cfg_vessel.name", "cfg_model.name", "cfg_structure.name", "cfg_estimator.name",
                            "cfg_noise.name", "m_drift_median") if col in runs]
    last = runs.sort_values("finished", kind="stable").tail(10)[cols].copy()
    last["finished"] = last["finished"].dt.strftime("%Y-%m-%d %H:%M:%S")
    last["wall_time"] = last["wall_time"].round(2)
    if "m_drift_median" in last:  # the median relative error of the run's coefficients, in per cent
        last["m_drift_median"] = (100 * last["m_drift_median"].astype(float)).round(1)
        last = last.rename(columns={"m_drift_median": "drift_%"})
    errs = runs.loc[last.index, "error"].map(
        lambda e: str(e).strip().splitlines()[-1][:60] if isinstance(e, str) and e.strip() else "")
    if errs.any():
        last["error"] = errs
    print("last runs:")
    print(last.to_string(index=False))


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    from study.configuration.cli import run

    run(main, "study results")
