"""The diagnosis: baseline, candidate effects ranked by out-of-sample improvement, the error ladder, the verdict.

1. **Baseline**: the model (with the effects the user already added) identified on the training records and
   replayed through the validation records (or, with no validation records, each record held out in turn).
2. **Candidates**: each effect of the catalogue not in the model is added, the model re-identified on the
   training records, and replayed through the validation records. Its *improvement* is the relative fall of the
   validation error (mean NRMSE of u, v, r, psi).
3. **Significance** (parsimony): a candidate is significant when the validation error falls by at least
   ``min_improvement`` (default 10 %) -- out-of-sample, so an effect that only fits noise earns nothing -- and,
   with three validation records or more, the per-record errors fall consistently (one-sided paired t-test
   on the log errors, p < ``alpha``).
4. **Verdict**: the best significant candidate is the missing effect, unless the next significant one is within
   ``tie`` (default 10 %) of its validation error: then the data cannot tell them apart, and the report says so
   (``missing_effect`` null, ``ambiguous`` the pair). Too little excitation (rudder spread under 2 deg) or too
   short records (under 5 ship lengths of travel) are reported as such.
5. **Ladder**: the missing effect is added, the remaining candidates ranked again on top of it, and so on while a
   significant one remains (two hidden effects are found one after the other).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .effects import CATALOGUE, describe
from .fit import CHANNELS, DoctorProblem, record_errors, validation_error


@dataclass
class Options:
    min_improvement: float = 0.10
    alpha: float = 0.05
    tie: float = 0.10
    max_steps: int = 3
    candidates: tuple = tuple(CATALOGUE)
    structure: str | dict | None = None  # None: Savitzky-Golay over 0.2 L/U0 (see DoctorProblem)


@dataclass
class Evaluation:
    effects: tuple
    fit: object
    errors: dict  # record -> channel -> {rmse, nrmse}
    validation_error: float
    training_error: float
    seconds: float
    fold_fits: list = field(default_factory=list)


def _names(records) -> list:
    out = []
    for i, r in enumerate(records):
        n = (getattr(r, "meta", None) or {}).get("name") or (getattr(r, "path", None) or f"record_{i}")
        out.append(str(n).split("/")[-1])
    seen = {}
    for i, n in enumerate(out):  # unique names
        if n in seen:
            out[i] = f"{n}#{i}"
        seen[n] = i
    return out


class Doctor:
    """Run the diagnosis of a model on records (see the module docstring)."""

    def __init__(self, vessel_cfg: dict, model_cfg: dict, train, validate=None, options: Options | None = None):
        self.opt = options or Options()
        self.vessel_cfg, self.model_cfg = vessel_cfg, dict(model_cfg)
        self.given = list(self.model_cfg.get("effects") or [])
        unknown = [e for e in self.given + list(self.opt.candidates) if e not in CATALOGUE]
        if unknown:
            raise ValueError(f"unknown effect(s) {unknown}; the catalogue has {sorted(CATALOGUE)}")
        self.train = list(train)
        self.validate = list(validate) if validate else []
        self.mode = "given" if self.validate else "held_out"
        if self.mode == "held_out" and len(self.train) < 2:
            raise ValueError("with no validation records, at least two records are needed (each is held out in "
                             "turn); give validate=<file|folder|glob>")
        self.train_names = _names(self.train)
        self.val_names = _names(self.validate) if self.validate else self.train_names
        self.train_df = [r.data if hasattr(r, "data") else r for r in self.train]
        self.val_df = [r.data if hasattr(r, "data") else r for r in self.validate]
        self.problem = DoctorProblem(vessel_cfg, self.model_cfg, self.train_df, self.opt.structure)
        if self.mode == "held_out":
            self.folds = [DoctorProblem(vessel_cfg, self.model_cfg, [d for j, d in enumerate(self.train_df) if j != i],
                                        self.opt.structure) for i in range(len(self.train_df))]
        self.evaluations: dict = {}

    # ------------------------------------------------------------------------------------------ evaluate
    def evaluate(self, effects, start=None, fixed=(), refine=False) -> Evaluation:
        """Identify with ``effects`` and measure the validation error. ``fixed``: outer parameters kept at their
        ``start`` values (a candidate on top of a ladder step is fitted alone); ``refine``: polish the outer
        parameters on the training replay error (the ladder's steps)."""
        effects = tuple(sorted(set(effects), key=list(CATALOGUE).index))
        key = (effects, bool(fixed), refine)
        if key in self.evaluations:
            return self.evaluations[key]
        t0 = time.perf_counter()
        fit = self.problem.fit(effects, start=start, fixed=fixed, refine=refine)
        errors, folds = {}, []
        if self.mode == "given":
            for name, df in zip(self.val_names, self.val_df):
                errors[name] = record_errors(df, self.problem.predict(fit, df), self.problem.floors)
        else:
            for i, (name, df) in enumerate(zip(self.train_names, self.train_df)):
                f = self.folds[i].fit(effects, start=fit.outer, grid=False)  # warm start from the full fit
                folds.append(f)
                errors[name] = record_errors(df, self.folds[i].predict(f, df), self.problem.floors)
        ev = Evaluation(effects, fit, errors, validation_error(errors), fit.training_error,
                        time.perf_counter() - t0, folds)
        self.evaluations[key] = ev
        return ev

    def _significance(self, base: Evaluation, cand: Evaluation) -> tuple[bool, float | None, float]:
        e0, e1 = base.validation_error, cand.validation_error
        if not np.isfinite(e1):
            return False, None, -math.inf
        imp = (e0 - e1) / e0 if np.isfinite(e0) and e0 > 0 else (1.0 if np.isfinite(e1) else 0.0)
        per0 = np.array([np.mean([base.errors[r][c]["nrmse"] for c in CHANNELS]) for r in base.errors])
        per1 = np.array([np.mean([cand.errors[r][c]["nrmse"] for c in CHANNELS]) for r in cand.errors])
        p = None
        ok = imp >= self.opt.min_improvement
        if len(per0) >= 3 and np.all(np.isfinite(per0)) and np.all(np.isfinite(per1)):
            d = np.log(per0) - np.log(per1)
            if np.allclose(d, d[0]):
                p = 0.0 if d[0] > 0 else 1.0
            else:
                p = float(stats.ttest_1samp(d, 0.0, alternative="greater").pvalue)
            ok = ok and p < self.opt.alpha
        return bool(ok), p, float(imp)

    def rank(self, base: Evaluation) -> list:
        """Every candidate not in ``base`` added on top of it, best (lowest validation error) first."""
        out = []
        for c in self.opt.candidates:
            if c in base.effects:
                continue
            # the candidate's parameters from its grid, the ones already found re-fitted with it (a first effect's
            # estimate absorbs part of a second one, and must be free to give it back)
            ev = self.evaluate(base.effects + (c,), start=base.fit.outer)
            sig, p, imp = self._significance(base, ev)
            extra = {k: v for k, v in ev.fit.outer.items() if k not in base.fit.outer}
            lin = {k: v for k, v in ev.fit.coefs.items() if k not in base.fit.coefs}
            out.append({"effect": c, "validation_error": ev.validation_error, "improvement": imp,
                        "significant": sig, "p_value": p, "parameters": {**describe(extra), **lin},
                        "training_error": ev.training_error, "seconds": ev.seconds, "note": ""})
        out.sort(key=lambda d: (not np.isfinite(d["validation_error"]), d["validation_error"]))
        return out

    # ------------------------------------------------------------------------------------------- run
    def excitation_notes(self) -> list:
        notes = []
        for name, df in zip(self.train_names, self.train_df):
            d_sd = math.degrees(float(np.std(df["delta"])))
            dist = float(np.sum(np.hypot(np.diff(df["x0"]), np.diff(df["y0"]))))
            L = float(self.vessel_cfg["particulars"]["Lpp"])
            if d_sd < 2.0:
                notes.append(f"training record {name}: the rudder hardly moves (spread {d_sd:.2g} deg): too little "
                             "excitation to identify anything that depends on it")
            if dist < 5 * L:
                notes.append(f"training record {name}: only {dist / L:.2g} ship lengths of travel (short)")
        return notes

    def run(self) -> dict:
        t0 = time.perf_counter()
        base = self.evaluate(tuple(self.given), refine=bool(self.given))
        ladder = [{"step": "baseline", "effects": list(base.effects), "validation_error": base.validation_error,
                   "training_error": base.training_error}]
        notes = self.excitation_notes()
        div = [rec for rec, e in base.errors.items() if e.get("diverged")]
        if div:
            notes.append(f"the baseline model diverges when replayed through {len(div)} of {len(base.errors)} "
                         f"validation record(s) ({', '.join(div[:5])}{'...' if len(div) > 5 else ''}); a diverged "
                         "replay counts as the largest error, so a candidate that keeps it stable scores well, but "
                         "if every candidate diverges too the doctor cannot say what is missing: check the "
                         "model's stability, or validate within the range it was identified on")
        first_ranking, missing, ambiguous = None, None, []
        current = base  # the ladder's step as reported (outer parameters refined on the replay error)
        ranking_base = base if not self.given else self.evaluate(tuple(self.given))  # its equation-error twin
        for step in range(self.opt.max_steps):
            # candidates are fitted by equation error: compared with the equation-error fit of the same step
            ranking = self.rank(ranking_base)
            if first_ranking is None:
                first_ranking = ranking
            sig = [r for r in ranking if r["significant"]]
            if not sig:
                break
            best = sig[0]
            if len(sig) > 1 and sig[1]["validation_error"] <= best["validation_error"] * (1 + self.opt.tie):
                pair = [best["effect"], sig[1]["effect"]]
                if step == 0:
                    ambiguous = pair
                notes.append(f"the data cannot tell {pair[0]} from {pair[1]} apart: validation errors "
                             f"{best['validation_error']:.3g} and {sig[1]['validation_error']:.3g} are within "
                             f"{100 * self.opt.tie:.0f} % (more varied manoeuvres would separate them)")
                for r in ranking:
                    if r["effect"] in pair:
                        r["note"] = "cannot be told apart from " + pair[1 - pair.index(r["effect"])]
                break
            if step == 0:
                missing = best["effect"]
            key = tuple(sorted(set(ranking_base.effects + (best["effect"],)), key=list(CATALOGUE).index))
            ranking_base = self.evaluations[(key, False, False)]
            current = self.evaluate(key, start=ranking_base.fit.outer, refine=True)
            if step == 0:  # the reported parameters of the missing effect: the refined ones
                best["parameters"] = {**describe({k: v for k, v in current.fit.outer.items()
                                                  if k not in base.fit.outer}),
                                      **{k: v for k, v in current.fit.coefs.items() if k not in base.fit.coefs}}
            ladder.append({"step": f"+ {best['effect']}", "effects": list(current.effects),
                           "validation_error": current.validation_error, "training_error": current.training_error})
        if missing is None and not ambiguous:
            notes.insert(0, "no candidate effect lowers the out-of-sample error significantly: no significant "
                         "missing effect")
        if notes and any("too little excitation" in n for n in notes) and missing:
            notes.append(f"{missing} ranks first, but with little excitation the ranking is weak evidence")
        self.result = {"base": base, "final": current, "ranking": first_ranking or [], "missing": missing,
                       "ambiguous": ambiguous, "ladder": ladder, "notes": notes,
                       "seconds": time.perf_counter() - t0}
        return self.result

    # ------------------------------------------------------------------------------------------ report
    def report(self) -> dict:
        r = self.result
        base, final = r["base"], r["final"]

        def errs_rows():
            rows = []
            for rec in base.errors:  # (the per-record 'diverged' flag is in the errors of baseline and final)
                for c in CHANNELS + ("track",):
                    b, f = base.errors[rec][c], final.errors[rec][c]
                    rows.append({"record": rec, "channel": c, "unit": {"u": "m/s", "v": "m/s", "r": "rad/s",
                                                                         "psi": "rad", "track": "m"}[c],
                                 "baseline_rmse": b["rmse"], "final_rmse": f["rmse"],
                                 "baseline_nrmse": b["nrmse"], "final_nrmse": f["nrmse"]})
            return rows

        m = r["missing"]
        if m:
            top = r["ranking"][0] if r["ranking"] else {}
            e1 = r["ladder"][1]["validation_error"]  # the step as refined (the ranking's is by equation error)
            pars = list(top.get("parameters", {}).items())
            verdict = (f"Missing effect: {m} (validation error {base.validation_error:.3g} -> {e1:.3g}, "
                       f"{100 * (1 - e1 / base.validation_error):.0f} % lower; " +
                       ", ".join(f"{k} = {v:.4g}" for k, v in pars[:6]) + (", ..." if len(pars) > 6 else "") + ")")
            if len(r["ladder"]) > 2:
                verdict += "; then " + ", ".join(s["step"][2:] for s in r["ladder"][2:])
        elif r["ambiguous"]:
            verdict = (f"The data cannot tell {r['ambiguous'][0]} from {r['ambiguous'][1]} apart; both lower the "
                       "validation error about equally")
        else:
            verdict = "No significant missing effect"
        return {
            "verdict": verdict,
            "baseline": {"validation_error": base.validation_error, "training_error": base.training_error,
                         "effects": list(base.effects), "parameters": {**describe(base.fit.outer), **base.fit.coefs},
                         "errors": base.errors},
            "ranking": [{k: v for k, v in c.items() if k != "seconds"} for c in r["ranking"]],
            "missing_effect": m,
            "ambiguous": r["ambiguous"],
            "ladder": r["ladder"],
            "final": {"effects": list(final.effects), "validation_error": final.validation_error,
                      "parameters": {**describe(final.fit.outer), **final.fit.coefs}, "errors": final.errors},
            "errors_table": errs_rows(),
            "notes": r["notes"],
            "mode": self.mode,
            "train": self.train_names,
            "validate": self.val_names if self.mode == "given" else [],
            "seconds": r["seconds"],
        }


# ---------------------------------------------------------------------------------------------- writing

def _running_error(meas, pred) -> np.ndarray | None:
    """Mean over u, v, r, psi of |predicted - measured| / spread of the measured channel, at each sample."""
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
    """The ``n`` windows (10 % of a record, at least 10 samples) with the largest mean error, at most one per
    record first, then the next ones; from the baseline's running errors."""
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


def predictions(doctor: "Doctor", ev: Evaluation) -> dict:
    """Each validation record's prediction by an evaluation's model (the fold's model when held out)."""
    out = {}
    if doctor.mode == "given":
        for name, df in zip(doctor.val_names, doctor.val_df):
            out[name] = doctor.problem.predict(ev.fit, df)
    else:
        for i, (name, df) in enumerate(zip(doctor.train_names, doctor.train_df)):
            out[name] = doctor.folds[i].predict(ev.fold_fits[i], df) if ev.fold_fits else None
    return out


def write_report(doctor: "Doctor", out_dir, vessel: str, model: str, overwrite: bool = False) -> dict:
    """Write ``report.json``, ``report.html`` and the figures (``figures/*.png``) into ``out_dir``; returns the
    report. Refuses to replace an existing report unless ``overwrite``."""
    import json
    from pathlib import Path

    from . import plots
    from .effects import catalogue_rows
    from .fit import residuals
    from .html import render_html

    out = Path(out_dir)
    if (out / "report.json").exists() and not overwrite:
        raise FileExistsError(f"{out / 'report.json'} exists; refusing to overwrite it (pass overwrite=true)")
    (out / "figures").mkdir(parents=True, exist_ok=True)
    rep = doctor.report()
    r = doctor.result
    base, final = r["base"], r["final"]
    pb, pf = predictions(doctor, base), predictions(doctor, final)
    meas = dict(zip(doctor.val_names, doctor.val_df)) if doctor.mode == "given" else \
        dict(zip(doctor.train_names, doctor.train_df))
    figs, listing = {}, []

    def add(name, data, title, caption, section):
        figs[name] = data
        listing.append({"file": name, "title": title, "caption": caption, "section": section})

    fl = "+".join(final.effects) if final.effects != base.effects else None
    for name, df in meas.items():
        add(f"compare_{_slug(name)}.png",
            plots.compare(name, df, pb.get(name), pf.get(name) if fl else None,
                          "baseline" + (f" ({'+'.join(base.effects)})" if base.effects else ""),
                          f"with {fl}" if fl else ""),
            f"{name}: measured against predicted", "Measured (dots), the baseline model (red) and the model with "
            "the effects found (blue), replayed open loop with the record's rudder and propeller.", "compare")
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
    add("ladder.png", plots.ladder(rep["ladder"]), "The error ladder", "Validation error of the model and of each "
        "step with an effect added.", "ladder")
    for name, data in figs.items():
        (out / "figures" / name).write_bytes(data)
    html_report = {**_jsonable(rep), "title": f"Model doctor: {model} on {vessel}", "created_by":
                   "python -m study.diagnose", "vessel": vessel, "model": model,
                   "structure": doctor.problem.structure.name, "worst_windows": windows,
                   "catalogue": catalogue_rows(), "figures": listing}
    (out / "report.json").write_text(json.dumps(html_report, indent=1, allow_nan=True, default=float),
                                     encoding="utf-8")
    (out / "report.html").write_text(render_html(html_report, figs), encoding="utf-8")
    return html_report


def _slug(s: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "_", str(s))[:80]


def _jsonable(x):
    """Floats stay floats (inf/NaN as JSON's Infinity/NaN, which Python reads), numpy scalars become numbers."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x
