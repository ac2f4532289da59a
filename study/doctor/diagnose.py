"""The diagnosis: baseline, candidate effects ranked by out-of-sample improvement, the error ladder,
the verdict.

1. **Baseline**: the model (with the effects the user already added) identified on the training
   records and replayed through the validation records (or, with no validation records, each record
   held out in turn).
2. **Candidates**: each effect of the catalogue (``conf/effect``, plus the user's) not in the model
   is added, the model re-identified on the training records, and replayed through the validation
   records. Its *improvement* is the relative fall of the validation error (the mean over records of
   the mean NRMSE of u, v, r, psi, and of x0, y0 on a record whose u, v, r were estimated; NRMSE: RMSE
   over the measured channel's standard deviation, or a floor of 2 % of U0, of U0/L and 0.02 rad when
   the channel hardly varies).
3. **Significance** (parsimony): a candidate is significant when the validation error falls by at
   least ``min_improvement`` (default 10 %) -- out-of-sample, so an effect that only fits noise
   earns nothing -- and, with three validation records or more, the per-record errors fall
   consistently (one-sided paired t-test on the log errors, p < ``alpha``). With fewer records the
   report says the test was not possible.
4. **Verdict**: the best significant candidate is the missing effect, unless the next significant
   one is within ``tie`` (default 10 %) of its validation error: then the data cannot tell them
   apart, and the report says so (``missing_effect`` null, ``ambiguous`` the pair). Each verdict is
   repeated with each validation record left out and reported as "named in k of n"; a named effect
   that removes less than half of the validation error (``decision.EXPLAINS_MOST``) is said to
   explain it in part: it may stand in for a cause no candidate models.
5. **Ladder**: the missing effect is added (its parameters refined on the training replays; the
   step keeps its ranking fit if refining raised the validation error by more than ``tie``), the
   remaining candidates ranked again on top of it, and so on while a significant one remains. A step
   whose validation error, refined, is not at least ``min_improvement`` lower than the step before
   is rejected: the ladder stops and says why. So is a step after the first that is named in half
   or fewer of the leave-one-out repetitions of step 4 (the first is reported with its count
   whatever it is: it explains the baseline's error; a further step explains what is left of it).
   A step takes a pair of candidates at once when no single one explains the records
   (:mod:`study.doctor.pairs`: two effects acting together, which a third can stand in for).
6. **The place** (``study.records.facility``): a candidate that needs what the training records'
   facility lacks (wind indoors, a current in still water) is not tried; a fitted candidate that is
   physically implausible there (a pond's current faster than the wind's drift) is rejected with the
   reason and never significant.
7. **Set-up effects** (an effect whose class says ``setup_effect``: a yaw bias, a rudder zero
   offset) belong to the set-up the training records were measured in: they are left out of the
   prediction of a record measured in another facility or at another scale
   (``study.records.facility.other_setup``) unless ``keep_setup_effects``; the report says which
   were left out, and of which records.
8. **Divergence**: a replay that leaves the physical envelope (``fit.ENVELOPE``) or overflows is
   *diverged*: it has no error to compare. A diverged baseline gets a headline of its own and no
   missing effect; a diverged candidate is never significant.
"""
from __future__ import annotations

import math
import time

import numpy as np

from study.records import facility as fac
from ..identify.effects import list_effects, registry
from ..identify.with_effects import (CHANNELS, UNITS, EffectsProblem, Fit, identify_effects, record_errors,
                                     scored_channels, states_estimated, validation_error)
from ..identify.with_effects.initial_state import WINDOW_L_U
from .decision import MIN_RECORDS_FOR_TEST, Evaluation, Options, decide, mean_on
from .model_error import without_effects
from .pairs import better_pair
from .verdict import verdict_line


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
        names = list(self.opt.candidates) if self.opt.candidates is not None else list_effects(self.opt.effect_path)
        self.effects = registry(list(dict.fromkeys(self.given + names)), self.opt.effect_path)
        self.order = list(self.effects)
        self.train = list(train)
        self.validate = list(validate) if validate else []
        self.mode = "given" if self.validate else "held_out"
        if self.mode == "held_out" and len(self.train) < 2:
            raise ValueError("with no validation records, at least two records are needed (each is held out in "
                             "turn); give validate=<file|folder|glob>")
        self.train_names = _names(self.train)
        self.val_names = _names(self.validate) if self.validate else self.train_names
        self.check_messages = []
        from study.records.vessel_checks import check_envelope

        check_envelope(vessel_cfg, self.train + self.validate)  # no measurement, whatever checks= says
        if self.opt.checks != "off":
            from study.records.vessel_checks import check_records

            self.check_messages = check_records(vessel_cfg, self.train + self.validate,
                                                strict=self.opt.checks == "error")
        self.problem = EffectsProblem(vessel_cfg, self.model_cfg, self.train, self.opt.structure, self.effects,
                                     self.train_names, self.opt.anchor)
        self.val_df = [r.data if hasattr(r, "data") else r for r in self.validate]
        self.val_infos = [self.problem.info_for(df, getattr(r, "meta", None), n)
                          for r, df, n in zip(self.validate, self.val_df, self.val_names)]
        self.train_df = self.problem.records
        if self.mode == "held_out":
            self.folds = [EffectsProblem(vessel_cfg, self.model_cfg, [r for j, r in enumerate(self.train) if j != i],
                                        self.opt.structure, self.effects,
                                        [n for j, n in enumerate(self.train_names) if j != i], self.opt.anchor)
                          for i in range(len(self.train))]
        metas = lambda recs: [getattr(r, "meta", None) or {} for r in recs]  # noqa: E731
        self.train_facilities = [fac.facility_of(m, vessel_cfg) for m in metas(self.train)]
        self.train_setups = [fac.setup_of(m, vessel_cfg) for m in metas(self.train)]
        self.val_setups = [fac.setup_of(m, vessel_cfg) for m in metas(self.validate)]
        self.left_out = {}  # record -> (set-up effects left out of its prediction, why)
        self.not_applicable = {}
        for e, eff in self.effects.items():
            why = eff.applies(self.problem) or fac.ruled_out(eff, self.train_facilities)
            if why:
                if e in self.given:
                    raise ValueError(f"model effect '{e}' cannot act here: {why}")
                self.not_applicable[e] = why
        self.candidates = [e for e in names if e not in self.not_applicable]
        self.evaluations: dict = {}

    def key(self, effects) -> tuple:
        return tuple(sorted(set(effects), key=self.order.index))

    # ------------------------------------------------------------------------------------------ evaluate
    def evaluate(self, effects, start=None, fixed=(), refine=False) -> Evaluation:
        """Identify with ``effects`` and measure the validation error. ``fixed``: outer parameters
        kept at their ``start`` values; ``refine``: polish the outer parameters on the training
        replay error (the ladder's
        steps)."""
        effects = self.key(effects)
        key = (effects, bool(fixed), refine)
        if key in self.evaluations:
            return self.evaluations[key]
        t0 = time.perf_counter()
        fit = identify_effects(self.problem, effects, start=start, fixed=fixed, refine=refine)
        errors, folds = {}, []
        if self.mode == "given":
            for name, df, info in zip(self.val_names, self.val_df, self.val_infos):
                errors[name] = record_errors(df, self.predict(self.problem, fit, df, info), self.problem.floors,
                                             scored_channels(info.meta))
        else:
            for i, (name, df) in enumerate(zip(self.train_names, self.train_df)):
                # warm start from the full fit
                f = identify_effects(self.folds[i], effects, start=fit.outer, grid=False)
                folds.append(f)
                info = self.problem.infos[i]
                errors[name] = record_errors(df, self.predict(self.folds[i], f, df, info, i), self.problem.floors,
                                             scored_channels(info.meta))
        ev = Evaluation(effects, fit, errors, validation_error(errors), fit.training_error,
                        time.perf_counter() - t0, folds)
        self.evaluations[key] = ev
        return ev

    def setup_left_out(self, fit: Fit, name: str, fold: int | None = None) -> tuple:
        """(set-up effects of ``fit`` left out of the prediction of record ``name``, why): those
        effects when the record was measured in another facility or at another scale than the
        records the fit was trained on (the fold's, held out), unless ``keep_setup_effects``;
        ((), None) otherwise."""
        setup_effects = tuple(e for e in fit.effects if getattr(self.effects[e], "setup_effect", False))
        if not setup_effects or self.opt.keep_setup_effects:
            return (), None
        if fold is None:
            setup, training = self.val_setups[self.val_names.index(name)], self.train_setups
        else:
            setup, training = self.train_setups[fold], [s for j, s in enumerate(self.train_setups) if j != fold]
        why = fac.other_setup(setup, training)
        return (setup_effects, why) if why else ((), None)

    def predict(self, problem, fit: Fit, df, info, fold: int | None = None):
        """A record's replay by ``fit`` (``problem``: the full training problem, or the fold's
        when held out), the set-up effects left out when the record is of another set-up
        (:meth:`setup_left_out`)."""
        drop, why = self.setup_left_out(fit, info.name, fold)
        if drop:
            for e in drop:
                self.left_out.setdefault(info.name, {})[e] = why
            fit = without_effects(problem, fit, drop)
        return problem.predict(fit, df, info)

    def left_out_of(self, ev: Evaluation) -> dict:
        """record -> why, for the records whose prediction by ``ev`` left set-up effects out."""
        names = self.val_names if self.mode == "given" else self.train_names
        out = {}
        for k, name in enumerate(names):
            fold = None if self.mode == "given" else k
            fit = ev.fit if self.mode == "given" else (ev.fold_fits[k] if ev.fold_fits else ev.fit)
            drop, why = self.setup_left_out(fit, name, fold)
            if drop:
                out[name] = why
        return out

    def setup_report(self, final: Evaluation) -> dict:
        """The set-up effects of the final model, the records whose prediction left them out (and
        why), and the sentences the report's notes carry."""
        effects = [e for e in final.effects if getattr(self.effects[e], "setup_effect", False)]
        left = {}
        names = self.val_names if self.mode == "given" else self.train_names
        for k, name in enumerate(names):
            fold = None if self.mode == "given" else k
            fit = final.fit if self.mode == "given" else (final.fold_fits[k] if final.fold_fits else final.fit)
            drop, why = self.setup_left_out(fit, name, fold)
            if drop:
                left[name] = {"effects": list(drop), "why": why}
        notes = []
        if effects:
            notes.append(f"{', '.join(effects)}: attributed to the test set-up (a rudder zero offset, an asymmetry "
                         "of the set-up), not to the ship: " + (
                             "kept in every prediction (keep_setup_effects=true)" if self.opt.keep_setup_effects
                             else "left out of the prediction of a record from another facility or scale "
                                  "(keep_setup_effects=true keeps it)"))
        for name, d in left.items():
            notes.append(f"{', '.join(d['effects'])} left out of the prediction of {name}: {d['why']}")
        return {"effects": effects, "kept": bool(self.opt.keep_setup_effects), "left_out": left, "notes": notes}

    def rank(self, base: Evaluation, scored=None) -> tuple:
        """Every candidate not in ``base`` added on top of it, compared on the ``scored`` records
        (those whose baseline replay did not diverge): (rows best first, evaluations by effect)."""
        evs = {}
        for c in self.candidates:
            if c in base.effects:
                continue
            # the candidate's parameters from its grid, the ones already found re-fitted with it (a first effect's
            # estimate absorbs part of a second one, and must be free to give it back)
            evs[c] = self.evaluate(base.effects + (c,), start=base.fit.outer)
        _, _, rows = decide(base, evs, self.opt, scored)
        plausible = dict(evs)
        for r in rows:
            ev = evs[r["effect"]]
            eff = self.effects[r["effect"]]
            r.update({"parameters": self.problem.describe(ev.fit, [r["effect"]], model=False),
                      "training_error": ev.training_error, "seconds": ev.seconds, "note": "",
                      "diverged_records": ev.diverged,
                      "stabilises": [x for x in base.diverged if x not in ev.diverged],
                      "setup_effect": bool(getattr(eff, "setup_effect", False))})
            if ev.diverged:
                r["note"] = f"diverges on {', '.join(ev.diverged)}"
            if r["stabilises"]:
                r["note"] = (r["note"] + "; " if r["note"] else "") + \
                    f"keeps {', '.join(r['stabilises'])} stable (the baseline diverges there)"
            if r["setup_effect"]:
                left = self.left_out_of(ev)
                r["left_out_of"] = left
                r["note"] = (r["note"] + "; " if r["note"] else "") + "a set-up effect (of the test set-up, not " \
                    "of the ship)" + (f"; left out of the prediction of {', '.join(left)} ({next(iter(left.values()))})"
                                      if left else "")
            why = fac.implausible(eff, r["parameters"], self.train_facilities, self.train_df)
            if why:  # physically implausible where the records were measured: never significant, never named
                r.update(implausible=why, significant=False)
                r["note"] = (r["note"] + "; " if r["note"] else "") + f"rejected: {why}"
                plausible.pop(r["effect"])
        return rows, plausible

    def stability(self, base: Evaluation, evs: dict, named, ambiguous, scored=None) -> dict:
        """The step's verdict repeated with each (scored) validation record left out: in how many it
        is the
        same."""
        recs = list(scored or base.errors)
        n = len(recs)
        if n < 2:
            return {"k": None, "n": n, "text": f"not assessable with {n} validation record (leave-one-out needs 2)"}
        same, outcomes = 0, []
        for r in recs:
            m, amb, _ = decide(base, evs, self.opt, [x for x in recs if x != r])
            outcomes.append({"left_out": r, "named": m, "ambiguous": amb})
            same += (m == named) if named else (m is None and (not ambiguous or sorted(amb) == sorted(ambiguous)))
        what = named or ("no missing effect" if not ambiguous else "the tie " + " / ".join(ambiguous))
        return {"k": int(same), "n": n, "text": f"{what}: named in {same} of {n} (each validation record left out "
                "in turn)", "outcomes": outcomes}

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

    def _ladder_row(self, step: str, ev: Evaluation, scored: list, **extra) -> dict:
        """A ladder step: the validation error over every record (inf when one diverged) and over
        the scored records (those where the baseline did not diverge: what steps are compared
        on)."""
        return {"step": step, "effects": list(ev.effects), "validation_error": ev.validation_error,
                "scored_error": mean_on(ev, scored), "scored_records": list(scored),
                "training_error": ev.training_error, "diverged": ev.diverged, **extra}

    def run(self) -> dict:
        """The ladder: rank the candidates against the step's fit, take the first when it passes the
        bar refined on the training replays, stop at a tie, a rejection or ``max_steps``; returns
        (and keeps as ``result``) the ranking, the ladder, its fits, notes and the separating
        manoeuvre."""
        t0 = time.perf_counter()
        base = self.evaluate(tuple(self.given), refine=bool(self.given))
        # the records a comparison can be made on: those whose baseline replay did not diverge (a diverged
        # replay has no error: it is reported, never scored)
        scored = [r for r in base.errors if r not in base.diverged]
        ladder = [self._ladder_row("baseline", base, scored)]
        ladder_fits = [base.fit]
        notes = self._opening_notes(base, scored)
        first_ranking, missing, ambiguous, stab, first_evs, named_first = None, None, [], [], {}, []
        diverged = {"baseline": base.diverged}
        current = base  # the ladder's step as reported (outer parameters refined on the replay error)
        ranking_base = base if not self.given else self.evaluate(tuple(self.given))  # its equation-error twin
        for step in range(self.opt.max_steps):
            # candidates are fitted by equation error: compared with the equation-error fit of the same step
            ranking, evs = self.rank(ranking_base, scored)
            m, amb, _ = decide(ranking_base, evs, self.opt, scored)
            if first_ranking is None:
                first_ranking, first_evs = ranking, evs
            if not scored:
                break
            pair = better_pair(self, ranking_base, ranking, evs, m, scored)
            taken = self._pair_step(pair, ranking_base, current, scored, step, notes) if pair else None
            if taken is None:
                st = self.stability(ranking_base, evs, m, amb, scored)
                st["step"] = step + 1
                if amb or m is None:  # a tie, or nothing significant: the ladder stops
                    ambiguous = amb if step == 0 else ambiguous
                    if amb or step == 0:
                        stab.append(st)
                    if amb:
                        notes.append(self._tie_note(ranking, amb))
                    break
                if step > 0 and st.get("k") is not None and 2 * st["k"] <= st["n"]:
                    # a further effect explains what is left after a named one, a small error: it must not hang on
                    # which validation record is scored. The row shows its ranking fit (not refined: it is not taken)
                    why = (f"is named in only {st['k']} of {st['n']} with one validation record left out in turn: "
                           "the records do not settle a further effect")
                    ladder.append(self._ladder_row(f"+ {m}", evs[m], scored, rejected=True, reason=why))
                    notes.append(f"ladder step + {m} rejected: it {why}; the ladder stops at the step before")
                    stab.append(st)
                    break
                cand = self.evaluate(ranking_base.effects + (m,), start=ranking_base.fit.outer, refine=True)
                e_prev, e_new = mean_on(current, scored), mean_on(cand, scored)
                # the step as refined must pass the ranking's own bar: lower, by at least min_improvement
                if not e_new <= e_prev * (1.0 - self.opt.min_improvement):
                    why = self._why_rejected(cand, scored, e_prev, e_new)
                    ladder.append(self._ladder_row(f"+ {m}", cand, scored, rejected=True, reason=why))
                    notes.append(f"ladder step + {m} rejected: with its parameters refined on the training replays "
                                 f"it {why}; the ladder stops at the step before")
                    diverged[f"+ {m}"] = cand.diverged
                    break
                cand = self.kept(evs[m], cand, scored, notes)
                if step == 0:  # the ranking shows the estimates of the effect it names as the step keeps them
                    next(r for r in ranking if r["effect"] == m)["parameters"] = self.problem.describe(
                        cand.fit, [m], model=False)
                taken = [m], cand, st
            names, current, st = taken
            stab.append(st)
            if step == 0:
                missing, named_first = names[0], names
            ranking_base = self.evaluations[(current.effects, False, False)]
            label = "+ " + " + ".join(names)
            diverged[label] = current.diverged
            ladder.append(self._ladder_row(label, current, scored))
            ladder_fits.append(current.fit)
        self._closing_notes(notes, missing, ambiguous, scored)
        separating = self.separating(first_ranking or [], first_evs, missing, ambiguous, stab)
        if separating is not None:
            notes.append(separating["text"])
        self.result = {"base": base, "final": current, "ranking": first_ranking or [], "missing": missing,
                       "named_first": named_first,
                       "ambiguous": ambiguous, "ladder": ladder, "notes": notes, "stability": stab,
                       "separating": separating,
                       "pair_evaluations": {e: first_evs[e] for e in (separating or {}).get("pair", [])},
                       "tie_evaluations": {e: first_evs[e] for e in ambiguous},
                       "diverged": diverged, "scored": scored, "ladder_fits": ladder_fits,
                       "seconds": time.perf_counter() - t0}
        return self.result

    def kept(self, ranked: Evaluation, refined: Evaluation, scored: list, notes: list) -> Evaluation:
        """The fit a taken step keeps: ``refined`` (its outer parameters polished on the training
        replays; the step passed the bar with it) -- unless its validation error is more than ``tie``
        above that of ``ranked``, the equation-error fit the ranking compared: then refining overfitted
        the training replays (small manoeuvres that say little about larger ones), the ranked fit is
        kept and a note says so."""
        e_ranked, e_refined = mean_on(ranked, scored), mean_on(refined, scored)
        if not e_refined > (1.0 + self.opt.tie) * e_ranked:
            return refined
        notes.append(f"the step {', '.join(refined.effects)}: refined on the training replays its validation error is "
                     f"{e_refined:.3g} against {e_ranked:.3g} as ranked, more than {100 * self.opt.tie:.0f} % higher: "
                     "the fit that ranked it is kept (refining overfitted the training records)")
        return ranked

    def _pair_step(self, pair: dict, base: Evaluation, current: Evaluation, scored: list, step: int,
                   notes: list):
        """The ladder step of a pair (:mod:`study.doctor.pairs`): refined on the training replays, taken
        when it passes the step's bar (at least ``min_improvement`` below the step before); returns
        (its two effects, its evaluation, its stability entry) and appends its note, or None."""
        a, b = pair["pair"]
        cand = self.evaluate(base.effects + (a, b), start=base.fit.outer, refine=True)
        e_prev, e_new = mean_on(current, scored), mean_on(cand, scored)
        alone = ", ".join(f"{e} alone {pair['singles'][e]:.3g}" for e in (a, b))
        if not e_new <= e_prev * (1.0 - self.opt.min_improvement):
            notes.append(f"the pair {a} + {b} ({alone}; together {mean_on(pair['evaluation'], scored):.3g}) was tried "
                         f"and rejected: with its parameters refined it {self._why_rejected(cand, scored, e_prev, e_new)}")
            return None
        text = (f"{a} + {b}: named together in {pair['k']} of {pair['n']} (each validation record left out in turn)"
                if pair["n"] >= 2 else f"{a} + {b}: not assessable with {pair['n']} validation record")
        notes.append(f"{a} and {b} named together: neither alone explains the records (validation errors as ranked: "
                     f"{alone}, the step's best single candidate {pair['best_single']} {pair['best_error']:.3g}, "
                     f"together {mean_on(pair['evaluation'], scored):.3g}; with the pair's parameters refined on the "
                     f"training replays, the ladder's step, {e_new:.3g})")
        return [a, b], self.kept(pair["evaluation"], cand, scored, notes), {
            "k": pair["k"] if pair["n"] >= 2 else None, "n": pair["n"], "text": text,
            "step": step + 1, "pair": [a, b]}

    def _tie_note(self, ranking: list, amb: list) -> str:
        """The note on two candidates the data cannot tell apart; each of their ranking rows says so."""
        a, b = (next(r for r in ranking if r["effect"] == e) for e in amb)
        for r in ranking:
            if r["effect"] in amb:
                r["note"] = "cannot be told apart from " + amb[1 - amb.index(r["effect"])]
        return (f"the data cannot tell {amb[0]} from {amb[1]} apart: validation errors "
                f"{a['validation_error']:.3g} and {b['validation_error']:.3g} are within "
                f"{100 * self.opt.tie:.0f} % (more varied manoeuvres would separate them)")

    @staticmethod
    def _closing_notes(notes: list, missing, ambiguous: list, scored: list) -> None:
        """The notes on the ladder's outcome: no significant effect, or a first rank on little excitation."""
        if missing is None and not ambiguous and scored:
            notes.insert(0, "no candidate effect lowers the out-of-sample error significantly: no significant "
                         "missing effect")
        if notes and any("too little excitation" in n for n in notes) and missing:
            notes.append(f"{missing} ranks first, but with little excitation the ranking is weak evidence")

    def _opening_notes(self, base, scored: list) -> list:
        """The report's notes known before any candidate is fitted: the input checks, the
        excitation, too few records for the consistency test, a diverged baseline."""
        notes = list(self.check_messages) + self.excitation_notes() + self._estimated_states_notes()
        n_val = len(scored)
        if n_val < MIN_RECORDS_FOR_TEST:
            notes.append(f"only {n_val} validation record(s) to compare on: the consistency test (a paired t-test "
                         f"of the per-record errors, which needs at least {MIN_RECORDS_FOR_TEST}) was not run, so a "
                         f"verdict rests on the mean error alone; give at least {MIN_RECORDS_FOR_TEST} validation "
                         f"records (or {MIN_RECORDS_FOR_TEST} training records, each held out in turn) to settle it")
        if base.diverged:
            notes.insert(0, f"the baseline model DIVERGES when replayed through {len(base.diverged)} of "
                         f"{len(base.errors)} validation record(s) ({', '.join(base.diverged)}): "
                         + (f"those records have no error and are not scored; candidates are compared on the other "
                            f"{n_val}" if scored else "no record is left to compare on, so no missing effect is "
                            "named") +
                         ". Check the model's stability (an identified hull extrapolating beyond its training "
                         "manoeuvres), validate within the range it was identified on, or add training records "
                         "that cover the validation manoeuvres")
        return notes

    def _estimated_states_notes(self) -> list:
        """What records whose u, v, r were estimated from positions and heading (the state
        estimator, ``states=auto``) do to the verdict: their replays start from a state fitted to
        the measured positions and heading (``with_effects.initial_state``) and are scored on the
        estimates and the measured positions (``replay_errors.scored_channels``); the estimates'
        own error is a floor no model removes."""
        records = list(self.train) + (list(self.validate) if self.validate else [])
        est = [n for n, r in zip(self.train_names + (self.val_names if self.validate else []), records)
               if states_estimated(getattr(r, "meta", None))]
        if not est:
            return []
        return [f"u, v, r of {len(est)} record(s) ({', '.join(est[:4])}{', ...' if len(est) > 4 else ''}) were "
                "estimated from positions and heading: each replay starts from the state that best fits the first "
                f"{WINDOW_L_U:g} ship lengths of the measured positions and heading (not the smoother's first "
                "estimates, its least accurate), and is scored on the estimated u, v, r, the heading and the measured "
                "positions; the estimates' own error is a floor under the validation error that no model removes"]

    def _why_rejected(self, cand, scored: list, e_prev: float, e_new: float) -> str:
        """Why a ladder step, refined, fails the ranking's bar (diverged, not lower, or not lower
        by enough)."""
        if not np.isfinite(e_new):
            return f"diverges on {', '.join(r for r in cand.diverged if r in scored)}"
        if e_new >= e_prev:
            return f"its validation error {e_new:.3g} is not below the previous step's {e_prev:.3g}"
        return (f"its validation error falls only {100 * (1 - e_new / e_prev):.0f} % ({e_prev:.3g} -> "
                f"{e_new:.3g}), less than the {100 * self.opt.min_improvement:.0f} % a candidate needs")

    def rudder_residual(self, base, final) -> dict:
        """The residual yaw moment and sway force per rudder-angle bin of the baseline's and the
        final model's fit (:func:`study.doctor.rudder_residual.residual_by_rudder`): a ramp says
        the rudder force is off, a kink at zero that it differs to port and to starboard."""
        from .rudder_residual import residual_by_rudder

        out = {"baseline": residual_by_rudder(self.problem, base.fit)}
        if final.effects != base.effects:
            out["final"] = residual_by_rudder(self.problem, final.fit)
        return out

    def depth_notes(self) -> list:
        """A warning when some records give their water depth and others do not: those without
        share one fitted h/T (or are deep), so a record run at a depth of its own is mispredicted
        (measured on simulated records trained deep and at h/T 2.0, validated at 1.5 without a
        depth: the shallow-water candidate is not named)."""
        infos = list(self.problem.infos) + list(self.val_infos)
        given = [i.name for i in infos if i.h_T is not None]
        missing = [i.name for i in infos if i.h_T is None]
        if not given or not missing or "shallow_water" not in self.effects:
            return []
        return [f"water depth given for {len(given)} record(s) but not for {', '.join(missing)}: those share one "
                "h/T (fitted by shallow_water, else deep water), so a record run at a depth of its own is "
                "mispredicted; give each record's depth (a depth column, or depth in its metadata)"]

    def separating(self, ranking: list, evs: dict, missing, ambiguous, stab: list) -> dict | None:
        """For a weak verdict, the manoeuvre that would best tell the two leading candidates
        apart (:mod:`study.doctor.separating`): the tie when the data cannot tell two apart, or
        the named effect and the runner-up when the name does not survive leaving each validation
        record out. None otherwise."""
        from .separating import separating_maneuvers

        if ambiguous:
            pair = list(ambiguous)
        elif missing and stab and stab[0].get("k") is not None and stab[0]["k"] < stab[0]["n"]:
            pair = [missing] + [r["effect"] for r in ranking if r["effect"] != missing][:1]
        else:
            return None
        if len(pair) < 2 or any(e not in evs for e in pair):
            return None
        return separating_maneuvers(self.problem, {e: evs[e].fit for e in pair},
                                    list(self.train_df) + list(self.val_df),
                                    list(self.train_names) + list(self.val_names))

    # ------------------------------------------------------------------------------------------ report
    def report(self) -> dict:
        """The diagnosis as the report's JSON holds it (the first fields of
        :class:`.report_schema.Report`): the verdict, baseline, ranking, ladder, stability, final
        model, identifiability, errors per record and channel, notes, set-up effects, facilities
        and depths."""
        r = self.result
        base, final = r["base"], r["final"]
        m = r["missing"]
        params_units = self.problem.units(tuple(self.effects))
        setup = self.setup_report(final)
        notes = list(r["notes"]) + setup["notes"] + self.depth_notes()
        implausible = [c for c in r["ranking"] if c.get("implausible")]
        for c in implausible:
            notes.append(f"candidate {c['effect']} rejected as physically implausible here: {c['implausible']}")
        return {
            "verdict": verdict_line(self),
            "baseline": {"validation_error": base.validation_error, "training_error": base.training_error,
                         "effects": list(base.effects), "parameters": self.problem.describe(base.fit),
                         "errors": base.errors, "diverged": base.diverged},
            "ranking": [{k: v for k, v in c.items() if k != "seconds"} for c in r["ranking"]],
            "not_applicable": self.not_applicable,
            "missing_effect": m,
            "missing_effects": list(r["named_first"]),
            "ambiguous": r["ambiguous"],
            "ladder": r["ladder"],
            "stability": r["stability"],
            "separating_maneuver": r.get("separating"),
            "rudder_residual": self.rudder_residual(base, final),
            "scored_records": r["scored"],
            "diverged": r["diverged"],
            "final": {"effects": list(final.effects), "validation_error": final.validation_error,
                      "parameters": self.problem.describe(final.fit), "errors": final.errors,
                      "diverged": final.diverged},
            "units": params_units,
            "identifiability": self.problem.identifiability(base.fit),
            "errors_table": _errors_rows(base, final),
            "notes": notes,
            "setup_effects": {k: v for k, v in setup.items() if k != "notes"},
            "facilities": {n: f for n, f in zip(self.train_names, self.train_facilities)} | (
                {n: s[0] for n, s in zip(self.val_names, self.val_setups)} if self.mode == "given" else {}),
            "mode": self.mode,
            "train": self.train_names,
            "validate": self.val_names if self.mode == "given" else [],
            "depths_h_T": {i.name: i.h_T for i in self.problem.infos + self.val_infos},
            "seconds": r["seconds"],
        }


def _errors_rows(base: Evaluation, final: Evaluation) -> list:
    """Per validation record and channel, the baseline's and the final model's RMSE and NRMSE."""
    rows = []
    for rec in base.errors:
        extra = tuple(c for c in base.errors[rec].get("scored", ()) if c not in CHANNELS)  # x0, y0 when scored
        for c in CHANNELS + extra + ("track",):
            b, f = base.errors[rec][c], final.errors[rec][c]
            rows.append({"record": rec, "channel": c, "unit": UNITS[c],
                         "baseline_rmse": b["rmse"], "final_rmse": f["rmse"],
                         "baseline_nrmse": b["nrmse"], "final_nrmse": f["nrmse"],
                         "baseline_diverged": bool(base.errors[rec].get("diverged")),
                         "final_diverged": bool(final.errors[rec].get("diverged"))})
    return rows
