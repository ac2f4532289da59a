"""The doctor's report written: the figures, ``report.json`` and ``report.html`` of a finished
diagnosis (:func:`write_report`: a :class:`.report_schema.Report`, serialised once), with what goes
into them beside the ranking and the ladder (:mod:`.diagnose`): each record's replays, the worst
windows, the manoeuvre metrics of each candidate, the conventions and definitions, the catalogue and
the provenance (package, git revision, command line, date, each record's sha256).

``doctor`` is a finished :class:`.diagnose.Doctor` (not imported here: the diagnosis is the layer
above)."""
from __future__ import annotations

import math

import numpy as np

from ..identify.with_effects import CHANNELS
from .report_schema import Report


def _running_error(meas, pred) -> np.ndarray | None:
    """Mean over u, v, r, psi of |predicted - measured| / spread of the measured channel, at each
    sample."""
    if pred is None:
        return None
    t = meas["time"].to_numpy()
    errs = []
    for c in CHANNELS:
        a = meas[c].to_numpy()
        b = np.interp(t, pred["time"].to_numpy(), pred[c].to_numpy())
        sd = float(np.std(a)) or 1.0
        errs.append(np.abs(b - a) / sd)
    return np.mean(errs, axis=0)


def worst_windows(curves: list, n: int = 3) -> list:
    """The ``n`` windows (10 % of a record, at least 10 samples) with the largest mean error, at
    most one per record first, then the next ones; from the baseline's running errors."""
    cands = []
    for name, t, err, _ in curves:
        if err is None or len(err) < 20:
            continue
        w = max(10, len(err) // 10)
        m = np.convolve(err, np.ones(w) / w, mode="valid")
        order = np.argsort(m)[::-1]
        taken = []
        for i in order:
            if all(abs(i - j) >= w for j in taken):
                taken.append(i)
                cands.append({"record": name, "t_start": float(t[i]), "t_end": float(t[i + w - 1]),
                              "nrmse": float(m[i])})
            if len(taken) >= n:
                break
    cands.sort(key=lambda d: -d["nrmse"])
    return cands[:n]


def predictions(doctor, ev) -> dict:
    """Each validation record's prediction by an evaluation's model (the fold's model when held
    out)."""
    out = {}
    if doctor.mode == "given":
        for name, df, info in zip(doctor.val_names, doctor.val_df, doctor.val_infos):
            out[name] = doctor.predict(doctor.problem, ev.fit, df, info)
    else:
        for i, (name, df) in enumerate(zip(doctor.train_names, doctor.train_df)):
            out[name] = (doctor.predict(doctor.folds[i], ev.fold_fits[i], df, doctor.problem.infos[i], i)
                         if ev.fold_fits else None)
    return out


def manoeuvre_predictions(doctor, ev, whole: dict) -> dict:
    """The replays the manoeuvre metrics compare: a record whose manoeuvre starts after an
    approach (``maneuver_metrics.manoeuvre_start``) replayed from the measured state at that
    start; any other record's whole-record replay (``whole``, from :func:`predictions`)."""
    from study.records.maneuver_metrics import manoeuvre_start

    out = dict(whole)
    if doctor.mode == "given":
        items = [(n, df, info, doctor.problem, ev.fit, None) for n, df, info in
                 zip(doctor.val_names, doctor.val_df, doctor.val_infos)]
    else:
        items = [(n, df, doctor.problem.infos[i], doctor.folds[i], ev.fold_fits[i] if ev.fold_fits else None, i)
                 for i, (n, df) in enumerate(zip(doctor.train_names, doctor.train_df))]
    for name, df, info, problem, fit, fold in items:
        t0 = manoeuvre_start(df)
        if t0 is not None and fit is not None:
            cut = df[df["time"] >= t0 - 1e-9].reset_index(drop=True)
            out[name] = doctor.predict(problem, fit, cut, info, fold) if len(cut) >= 10 else None
    return out


def _metrics_error(rows: list, col: str) -> tuple:
    """(mean over the finite metrics of |predicted - measured| / |measured|, their count)."""
    errs = [abs(r[col] - r["measured"]) / abs(r["measured"]) for r in rows
            if np.isfinite(r.get(col, np.nan)) and np.isfinite(r["measured"]) and r["measured"] != 0]
    return (float(np.mean(errs)) if errs else math.nan), len(errs)


def candidate_metrics(doctor, rep: dict, meas: dict, mb: dict) -> None:
    """Beside each ranked candidate's validation error, its effect on the validation manoeuvres'
    metrics (tactical diameter, advance, overshoots...: ``study.records.maneuver_metrics``): the
    mean relative error of the metrics the baseline and the candidate can both be measured on,
    and a note when the candidate lowers the NRMSE but worsens the metrics. Without turning
    circles or zigzags among the validation records a row gets none."""
    from study.records.maneuver_metrics import maneuver_metrics

    given = tuple(doctor.result["base"].effects)
    for row in rep["ranking"]:
        ev = doctor.evaluations.get((doctor.key(given + (row["effect"],)), False, False))
        if ev is None:
            continue
        mc = manoeuvre_predictions(doctor, ev, predictions(doctor, ev))
        rows = [m for name, df in meas.items() for m in maneuver_metrics(name, df, mb.get(name), mc.get(name),
                                                                         doctor.problem.L)
                if not m["metric"].endswith("_L")]  # the same metric in ship lengths: counted once
        both = [m for m in rows if np.isfinite(m["baseline"]) and np.isfinite(m["final"])]
        e0, n = _metrics_error(both, "baseline")
        e1, _ = _metrics_error(both, "final")
        if not n:
            continue
        worse = [f"{m['record']}: {m['metric']}" for m in both if np.isfinite(m["measured"])
                 and abs(m["final"] - m["measured"]) > abs(m["baseline"] - m["measured"])]
        row["metrics"] = {"n": n, "baseline_error": e0, "error": e1, "worse": worse}
        lowers = row.get("improvement") is not None and row["improvement"] > 0
        if lowers and e1 > e0:
            row["metrics_worse"] = True
            row["note"] = (row["note"] + "; " if row.get("note") else "") + (
                f"lowers the NRMSE but worsens the manoeuvre metrics (mean relative error {100 * e0:.1f} % -> "
                f"{100 * e1:.1f} % over {n}; worse: {', '.join(worse[:4])}{', ...' if len(worse) > 4 else ''})")


def write_report(doctor, out_dir, vessel: str, model: str, overwrite: bool = False) -> dict:
    """Write ``report.json``, ``report.html`` and the figures (``figures/*.png``) into
    ``out_dir``; returns the report as ``report.json`` holds it
    (:meth:`.report_schema.Report.to_dict`). Refuses to replace an existing report unless
    ``overwrite``."""
    from pathlib import Path

    from .html import render_html

    out = Path(out_dir)
    if (out / "report.json").exists() and not overwrite:
        raise FileExistsError(f"{out / 'report.json'} exists; refusing to overwrite it (pass overwrite=true)")
    rep = doctor.report()
    r = doctor.result
    base, final = r["base"], r["final"]
    pb, pf = predictions(doctor, base), predictions(doctor, final)
    meas = dict(zip(doctor.val_names, doctor.val_df)) if doctor.mode == "given" else \
        dict(zip(doctor.train_names, doctor.train_df))
    figs, listing, windows = _figures(doctor, rep, meas, pb, pf)
    mm, uncertainty = _manoeuvres(doctor, rep, meas, pb, pf)
    _interval_figure(mm, figs, listing)
    _put_figures(out, figs)
    report = Report(**_jsonable(rep), title=f"Model doctor: {model} on {vessel}",
                    created_by="python -m study diagnose", vessel=vessel, model=model,
                    structure=doctor.problem.structure.name, worst_windows=windows, catalogue=catalogue_rows(doctor),
                    figures=listing, maneuver_metrics=mm, prediction_uncertainty=uncertainty,
                    conventions=CONVENTIONS, definitions=DEFINITIONS, provenance=provenance(doctor))
    (out / "report.json").write_text(report.to_json(), encoding="utf-8")
    (out / "report.html").write_text(render_html(report, figs), encoding="utf-8")
    return report.to_dict()


def _figures(doctor, rep: dict, meas: dict, pb: dict, pf: dict) -> tuple:
    """(figure name -> PNG bytes, their listing for the page, the worst windows) of a report:
    measured against predicted per record, the residual forces, the error's growth along each
    record and the ladder."""
    from . import plots
    from ..identify.with_effects import residuals

    r = doctor.result
    base, final = r["base"], r["final"]
    figs, listing = {}, []

    def add(name, data, title, caption, section):
        figs[name] = data
        listing.append({"file": name, "title": title, "caption": caption, "section": section})

    fl = "+".join(final.effects) if final.effects != base.effects else None
    # a weak verdict: the two candidates it could not tell apart, replayed beside the baseline
    pair = {e: predictions(doctor, ev) for e, ev in (r.get("pair_evaluations") or {}).items()
            if doctor.mode == "given" or ev.fold_fits}  # held out in turn: only where each fold was fitted
    pair_text = (f" The two candidates the records cannot tell apart (or that the verdict rests on weakly), "
                 f"{' and '.join(pair)}, in orange and green." if pair else "")
    for name, df in meas.items():
        add(f"compare_{_slug(name)}.png",
            plots.compare(name, df, pb.get(name), pf.get(name) if fl else None,
                          "baseline" + (f" ({'+'.join(base.effects)})" if base.effects else ""),
                          f"with {fl}" if fl else "", [(p.get(name), f"+ {e}") for e, p in pair.items()]),
            f"{name}: measured against predicted",
            ("Measured (dots), the baseline model (red) and the model with the effects found (blue), replayed open "
             "loop with the record's rudder and propeller." if fl else
             "Measured (dots) and the baseline model (red), replayed open loop with the record's rudder and "
             "propeller (no effect was added).") + pair_text +
            (" The baseline replay DIVERGED on this record and is not drawn." if name in base.diverged else ""),
            "compare")
    res = residuals(doctor.problem, base.fit, doctor.train_names)
    add("residuals_time.png", plots.residuals_time(res), "Residual forces over time",
        "Measured inertial forces minus the baseline model's forces on the training records.", "residuals")
    states = tuple(s for s in ("u", "v", "r", "delta", "psi", "wind_angle_rel") if all(s in x for x in res))
    add("residuals_states.png", plots.residuals_states(res, states), "Residual forces against states and inputs",
        "A missing effect leaves a pattern here: against psi a current or wind, a constant offset a yaw bias, a "
        "curve against v or r a missing hull term.", "residuals")
    curves = []
    for name, df in meas.items():
        eb, ef = _running_error(df, pb.get(name)), _running_error(df, pf.get(name)) if fl else None
        curves.append((name, df["time"].to_numpy(), eb if eb is not None else np.full(len(df), np.nan), ef))
    windows = worst_windows(curves)
    add("growth.png", plots.growth(curves, windows), "How the error grows along each record",
        "Mean normalised error of u, v, r and psi at each instant; the worst windows are shaded.", "growth")
    rej = any(s.get("rejected") for s in rep["ladder"])
    div = any(s.get("diverged") for s in rep["ladder"])
    add("ladder.png", plots.ladder(rep["ladder"]), "The error ladder", "Validation error (mean NRMSE of u, v, r, "
        "psi, and x0, y0 where u, v, r were estimated, over the validation records) of the baseline and of each step with an effect added" +
        ("; a rejected step (its error not lower by 10 %) is hatched" if rej else "") +
        ("; a diverged replay is marked, with no bar" if div else "") + ".", "ladder")
    return figs, listing, windows


def _manoeuvres(doctor, rep: dict, meas: dict, pb: dict, pf: dict) -> tuple:
    """(the manoeuvre metrics rows of every record, baseline and final, with their intervals; the
    predicted turns and what carries them); each candidate's effect on the metrics is added to
    ``rep``'s ranking."""
    from study.records.maneuver_metrics import maneuver_metrics
    from .uncertainty import annotate

    base, final = doctor.result["base"], doctor.result["final"]
    mm = []
    mb = manoeuvre_predictions(doctor, base, pb)
    mf = mb if final is base else manoeuvre_predictions(doctor, final, pf)  # no effect added: the same replays
    for name, df in meas.items():
        mm += maneuver_metrics(name, df, mb.get(name), mf.get(name), doctor.problem.L)
    candidate_metrics(doctor, rep, meas, mb)
    uncertainty = annotate(doctor, mm, base, final, mb, mf, meas=meas,  # intervals, extrapolation, carriers, turns
                           frames_of=lambda ev: manoeuvre_predictions(doctor, ev, predictions(doctor, ev)))
    return mm, uncertainty


def _interval_figure(mm: list, figs: dict, listing: list) -> None:
    """Add the figure of the manoeuvre metrics measured against predicted with their 90 %
    intervals, when any validation record has such a metric."""
    from . import plots

    data = plots.metric_intervals(mm)
    if data is None:
        return
    figs["metric_intervals.png"] = data
    listing.append({"file": "metric_intervals.png", "title": "Manoeuvre metrics against their 90 % intervals",
                    "caption": "Each validation record's measured turning-circle and zigzag metrics (black) "
                               "against the final model's prediction (blue) and the baseline's (red, open), each "
                               "with its 90 % interval (identification spread, the models that fit as well, and the "
                               "extrapolation error; see the section on how far the predictions can be trusted).",
                    "section": "intervals"})


def _put_figures(out, figs: dict) -> None:
    """Write the figures into ``out/figures``: to a temporary folder first, moved in at once, so a
    doctor stopped meanwhile leaves no figures/ that would make a rerun refuse ("already holds
    figures") though no report
    exists."""
    import os
    import shutil

    partial, final_dir = out / ".figures.partial", out / "figures"
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    for name, data in figs.items():
        (partial / name).write_bytes(data)
    if final_dir.is_dir():  # overwrite=true: the new figures replace the old ones of the same name
        for f in partial.iterdir():
            os.replace(f, final_dir / f.name)
        partial.rmdir()
    else:
        os.replace(partial, final_dir)


#: shown on the report page beside the numbers they explain
CONVENTIONS = ("Body axes x forward, y starboard; positions x0 north, y0 east; heading psi clockwise from north; "
               "rudder delta > 0 turns the ship to starboard (r > 0); a current's direction is where it flows "
               "TOWARDS, a wind's where it comes FROM, both clockwise from north; SI units, angles in radians "
               "unless marked deg (docs/conventions.md)")
DEFINITIONS = {
    "NRMSE": "root-mean-square error of a replayed channel over the standard deviation of the measured channel "
             "(or a floor when it hardly varies: 2 % of U0 for u and v, 2 % of U0/L for r, 0.02 rad for psi); at "
             "most 10",
    "validation error": "the mean NRMSE of u, v, r and psi (and of the positions x0, y0 on a record whose u, v, r "
                        "were estimated from them), averaged over the validation records (held-out records when "
                        "none are given), the model replayed open loop from each record's initial state (fitted to "
                        "the positions and heading when u, v, r were estimated) with its measured rudder and "
                        "propeller; lower is better; a diverged replay has none",
    "training error": "the equation-error misfit on the training records: per equation (X, Y, N) the residual sum "
                      "of squares over that of the model-free rows, averaged over the equations",
    "improvement": "the relative fall of the validation error when a candidate effect is added (out of sample)",
    "diverged": "a replay that overflows or leaves the envelope (speed over 5 U0, yaw rate over 20 U0/L)",
    "track error": "RMS distance between replayed and measured positions [m]; its NRMSE is over the track's extent",
}


def record_sha256(record) -> tuple:
    """(sha256 hex digest, of what): of the record's file as read when it has one, else of its
    data as CSV."""
    import hashlib
    from pathlib import Path

    path = getattr(record, "path", None)
    if path and Path(path).is_file():
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest(), "file"
    df = record.data if hasattr(record, "data") else record
    return hashlib.sha256(df.to_csv(index=False).encode()).hexdigest(), "data (CSV, no file)"


def git_revision() -> dict:
    """The package's git revision and whether its tracked files differ from it; None when it is
    not a checkout."""
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=10)
        if rev.returncode != 0:
            return {"revision": None, "modified": None}
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=30)
        return {"revision": rev.stdout.strip(), "modified": bool(dirty.stdout.strip())}
    except (OSError, subprocess.SubprocessError):
        return {"revision": None, "modified": None}


def provenance(doctor, command: str | None = None) -> dict:
    """What made the report: package and version, git revision, command line, date (UTC), and
    each record's sha256 (its file's bytes when the report is written; a record without a file:
    its data as CSV)."""
    import shlex
    import sys
    from datetime import datetime, timezone
    from importlib import metadata

    try:
        version = metadata.version("study")
    except metadata.PackageNotFoundError:
        version = None
    if command is None:
        argv = list(getattr(sys, "orig_argv", None) or sys.argv)
        command = shlex.join(argv)
    records = []
    for role, recs, names in (("train", doctor.train, doctor.train_names),
                              ("validate", doctor.validate, doctor.val_names if doctor.validate else [])):
        for r, name in zip(recs, names):
            digest, of = record_sha256(r)
            records.append({"role": role, "name": name, "path": getattr(r, "path", None), "sha256": digest,
                            "sha256_of": of})
    return {"package": "study", "version": version, **git_revision(), "command": command,
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "records": records}


def catalogue_rows(doctor) -> list:
    """The catalogue of the doctor's candidate effects: physics, parameters with units, how each
    enters, source, and why it could not act here (if so)."""
    out = []
    for name, eff in doctor.effects.items():
        out.append({"name": name, "physics": eff.physics, "parameters": eff.param_text(doctor.problem),
                    "enters": eff.enters, "source": eff.source,
                    "applies": doctor.not_applicable.get(name, "yes")})
    return out


def _slug(s: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "_", str(s))[:80]


def _jsonable(x):
    """Floats stay floats (inf/NaN as JSON's Infinity/NaN, which Python reads), numpy scalars
    become numbers."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x
