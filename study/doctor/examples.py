"""``python -m study doctor_examples``: the doctor's five worked examples, rebuilt into
``paper_figs/doctor/``.

1. ``simulated_current``: the README's example -- five records of the 7 m KVLCC2 made by ``python -m
   study simulate`` with a hidden current (10 % of the speed towards the north-east), 1 % noise; the
   model is the vessel's own (``known``).
2. ``esso_osaka``: the Esso Osaka 3 m model's free-running zigzags (training) and its 14 turning
   circles (validation), Osaka University's pond, with its measured wind; the model is
   ``esso_osaka`` as configured (its empirical hull from the main particulars, KVLCC2's interaction
   coefficients as a labelled stand-in).
3. ``esso_osaka_identified``: the hull identified from the zigzags and the random-rudder runs,
   anchored to that empirical hull, validated on the same 14 turns.
4. ``kvlcc2_hsva``: HSVA's free-running KVLCC2 zigzags, the 5 deg and 1 deg switch-heading ones for
   training, the 10/10 and 20/10 ones (both sides) for validation; the model is ``kvlcc2_l7``, the
   published MMG set.
5. ``kvlcc2_hsva_identified``: the same records, the MMG hull identified from them (anchored to the
   published set): the user's normal case.

Each writes ``<out>/<example>/`` (report.html, report.json, figures/) and the summary
``<out>/README.md``. The committed ones are ``paper_figs/doctor/``: ``python -m study
doctor_examples --out paper_figs/doctor --overwrite`` rebuilds them; by default the examples go to
``doctor_examples/`` in the current folder, and a folder that holds a report is never replaced
without ``--overwrite``. The real data are read in place (``../shared/data/real``); an example whose
data are missing is skipped and listed as such. The runs are not logged in the results table.
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

from .measurement_noise import agrees

REPO = Path(__file__).resolve().parents[2]
#: the committed examples (rebuilt only when asked: --out paper_figs/doctor)
COMMITTED = REPO / "paper_figs" / "doctor"
#: where the examples go by default: a folder of the current directory, never a committed one
DEFAULT_OUT = Path("doctor_examples")


def simulated_current(tmp: Path, out: Path = DEFAULT_OUT, overwrite: bool = False) -> dict:
    import subprocess
    import sys

    for m, stem in (("zigzag_10_10", "train_zz10"), ("zigzag_20_20", "train_zz20"), ("random_rudder", "train_rr"),
                    ("zigzag_20_10", "val_zz2010"), ("turning_35", "val_turn35")):
        subprocess.run([sys.executable, "-m", "study", "simulate", "vessel=kvlcc2_l7", f"maneuver={m}",
                        "environment=current", "noise=low_relative", "noise.sample_dt=0.1", "sim.duration=300",
                        f"seed={len(stem)}", f"out={tmp / stem}.csv"], check=True, capture_output=True)
    from .run import diagnose_conf, run

    return run(diagnose_conf(vessel="kvlcc2_l7", train=f"{tmp}/train_*.csv", validate=f"{tmp}/val_*.csv",
                     out=str(out / "simulated_current"), overwrite=overwrite))


def esso_osaka(out: Path = DEFAULT_OUT, overwrite: bool = False) -> dict:
    from .run import diagnose_conf, run
    from study.records.loaders import real_data_dir

    d = real_data_dir() / "esso_osaka_frt" / "data"
    return run(diagnose_conf(vessel="esso_osaka", train=f"{d}/zigzag/*.csv", validate=f"{d}/turning/*.csv",
                     out=str(out / "esso_osaka"), overwrite=overwrite))


def esso_osaka_identified(out: Path = DEFAULT_OUT, overwrite: bool = False) -> dict:
    """Esso Osaka's MMG hull identified from its zigzags and random-rudder runs (the data papers'
    training set), anchored to its empirical prior (the config's hull), validated on all 14
    measured turning circles: a turn from zigzags, on real records."""
    from .run import diagnose_conf, run
    from study.records.loaders import real_data_dir

    d = real_data_dir() / "esso_osaka_frt" / "data"
    return run(diagnose_conf(vessel="esso_osaka", model="mmg_hull", train=f"{d}/zigzag/*.csv,{d}/random/*.csv",
                     validate=f"{d}/turning/*.csv", out=str(out / "esso_osaka_identified"), overwrite=overwrite))


def kvlcc2_hsva(out: Path = DEFAULT_OUT, overwrite: bool = False) -> dict:
    from .run import diagnose_conf, run
    from study.records.loaders import real_data_dir

    d = real_data_dir() / "kvlcc2_hsva" / "raw_data"
    return run(diagnose_conf(vessel="kvlcc2_l7", train=f"{d}/HSVA_CPMC_KVLCC2_Z_*_0?.dat",
                     validate=f"{d}/HSVA_CPMC_KVLCC2_Z_*_10_?.dat", out=str(out / "kvlcc2_hsva"), overwrite=overwrite))


def kvlcc2_hsva_identified(out: Path = DEFAULT_OUT, overwrite: bool = False) -> dict:
    """The HSVA zigzags again, with the MMG hull identified from them (anchored to the published
    set): the user's normal case."""
    from .run import diagnose_conf, run
    from study.records.loaders import real_data_dir

    d = real_data_dir() / "kvlcc2_hsva" / "raw_data"
    return run(diagnose_conf(vessel="kvlcc2_l7", model="mmg_hull", train=f"{d}/HSVA_CPMC_KVLCC2_Z_*_0?.dat",
                             validate=f"{d}/HSVA_CPMC_KVLCC2_Z_*_10_?.dat", out=str(out / "kvlcc2_hsva_identified"),
                             overwrite=overwrite))


def _turns(rep: dict) -> list:
    """The validation turning circles' tactical diameters (report.json ``maneuver_metrics``):
    measured, the baseline model's and the final model's replays with the final's 90 % interval,
    the mean relative error of each over the turns both replays complete, how many intervals hold
    the measured value and their median half-width; then the final model's predicted 35 deg turns
    (``prediction_uncertainty``)."""
    rows = [m for m in rep.get("maneuver_metrics", []) if m["metric"] == "tactical_diameter_L"]
    ok = lambda x: x is not None and x == x and abs(x) != float("inf")  # noqa: E731
    out = []
    if rows:
        out = ["", "| turning circle | measured TD [L] | its noise, 90 % | baseline | final | final, 90 % |",
               "|---|---|---|---|---|---|"]
        errs = {"baseline": [], "final": []}
        held, agree, widths = 0, 0, []
        for m in rows:
            cells = [f"{m[k]:.2f}" if ok(m[k]) else "-" for k in ("measured", "baseline", "final")]
            lo, hi = m.get("final_low"), m.get("final_high")
            iv = f"{lo:.2f}-{hi:.2f}" if ok(lo) and ok(hi) else "-"
            mlo, mhi = m.get("measured_low"), m.get("measured_high")
            noise = f"{mlo:.2f}-{mhi:.2f}" if ok(mlo) and ok(mhi) else "-"
            out.append(f"| {m['record']} | {cells[0]} | {noise} | " + " | ".join(cells[1:]) + f" | {iv} |")
            if ok(m["measured"]) and ok(m["baseline"]) and ok(m["final"]):
                for k in errs:
                    errs[k].append(abs(m[k] / m["measured"] - 1))
            if ok(lo) and ok(hi) and ok(m["measured"]):
                held += lo <= m["measured"] <= hi
                agree += bool(agrees(m))
                widths.append(m["final_uncertainty"]["half_width"])
        if errs["baseline"]:
            n = len(errs["baseline"])
            out += ["", f"Mean |TD error| over the {n} turns both replays complete: baseline "
                        f"{100 * sum(errs['baseline']) / n:.0f} %, final {100 * sum(errs['final']) / n:.0f} %."]
        if widths:
            widths.sort()
            med = (widths[(len(widths) - 1) // 2] + widths[len(widths) // 2]) / 2
            out.append(f"The final model's 90 % intervals hold {held} of {len(widths)} measured tactical diameters; "
                       f"median half-width {100 * med:.0f} %. With the measured values' own noise (each record's, "
                       f"replayed) prediction and measurement agree on {agree} of {len(widths)}.")
    for t in (rep.get("prediction_uncertainty") or {}).get("predicted_turns", []):
        td = (t.get("metrics") or {}).get("tactical_diameter_L")
        if td:
            who = ", ".join(c["coefficient"] for c in td.get("carriers", []))
            out += ["", f"Predicted {t['maneuver']}: tactical diameter {td['value']:.2f} L (90 %: {td['low']:.2f}-"
                        f"{td['high']:.2f}); {t['extrapolation']['text']}" + (f"; carried by {who}" if who else "")
                    + "."]
    for t in ((rep.get("prediction_uncertainty") or {}).get("tie") or {}).get("turns", []):
        if "metrics" not in t:
            continue
        td = t["metrics"]["tactical_diameter_L"]
        each = "; ".join(f"{e} {x['value']:.2f} L ({x['low']:.2f}-{x['high']:.2f})" for e, x in td["readings"].items())
        out += ["", f"The verdict is a tie; {t['maneuver']} as each reading predicts it: {each}; weighted equally "
                    f"{td['value']:.2f} L (90 %: {td['low']:.2f}-{td['high']:.2f})."]
    return out


def _summary(name: str, rep: dict) -> list:
    lines = [f"### {name}", "", f"**{rep['verdict']}**", "", "| step | validation error |", "|---|---|"]
    def num(x, pct=False):
        if x is None or x != x:
            return "-"
        if x == float("inf"):
            return "diverged"
        return f"{100 * x:.0f} %" if pct else f"{x:.3g}"

    lines += [f"| {s['step']}{' (rejected: ' + s['reason'] + ')' if s.get('rejected') else ''} | "
              f"{num(s.get('scored_error', s['validation_error']))} |" for s in rep["ladder"]]
    lines += ["", "| candidate | validation error | improvement | significant | parameters |", "|---|---|---|---|---|"]
    for c in rep["ranking"]:
        pars = ", ".join(f"{k} {num(v) if isinstance(v, (int, float)) else v}"
                         for k, v in list(c["parameters"].items())[:4])
        lines.append(f"| {c['effect']} | {num(c['validation_error'])} | {num(c['improvement'], True)} | "
                     f"{'yes' if c['significant'] else 'no'} | {pars} |")
    if rep.get("notes"):
        lines += [""] + [f"- {n}" for n in rep["notes"]]
    lines += _turns(rep)
    lines += ["", f"Report: [`{name}/report.html`]({name}/report.html); figures in `{name}/figures/`.", ""]
    return lines


def main(argv=None) -> int:
    from study.configuration.cli import OutputExistsError, parser
    from study.run.settings import existing_report

    ap = parser("study doctor_examples", "The model doctor's five worked examples (see the module's docstring).")
    ap.add_argument("--out", default=str(DEFAULT_OUT),
                    help=f"output folder (default {DEFAULT_OUT}/ in the current folder; the committed examples: "
                         f"--out paper_figs/doctor --overwrite)")
    ap.add_argument("--overwrite", action="store_true", help="replace the reports already in the output folder")
    ap.add_argument("--only", nargs="+", choices=list(EXAMPLES), default=None, help="run only these examples")
    args = ap.parse_args(argv)
    out = Path(args.out)
    names = args.only or list(EXAMPLES)
    there = [f"{n}/{f}" for n in names for f in existing_report(out / n)]
    if there and not args.overwrite:  # before any work, and before the data are looked for (whatever is missing)
        raise OutputExistsError(f"--out {out}: already holds {', '.join(there[:3])}{' ...' if len(there) > 3 else ''}"
                                "; refusing to overwrite them (--overwrite to overwrite them, or another --out)")
    if any(n != "simulated_current" for n in names):  # the real-data examples: say where the data were looked for
        from study.records.loaders import require_real_records

        for ds in ("esso_osaka", "kvlcc2_hsva"):
            require_real_records(ds)  # RealDataMissing (a FileNotFoundError): one line, exit 2 (study.configuration.cli)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# The model doctor's worked examples", "", "Rebuilt by `python -m study doctor_examples` (see its "
             "docstring for the data and the models); never edited by hand.", "",
             "Data: Esso Osaka free-running tests, Osaka University (Wakita et al. 2022; Miyauchi et al. 2022), "
             "CC BY-NC-SA 4.0: the `esso_osaka/` figures are derived from them and carry that licence. KVLCC2: "
             "HSVA free-running tests, SIMMAN 2008 (Stern et al. 2011). The data are read in place from "
             "`../shared/data/real`, never copied here.", ""]
    summaries = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            fn = EXAMPLES[name]
            kw = {"out": out, "overwrite": args.overwrite}
            try:
                rep = fn(Path(tmp), **kw) if name == "simulated_current" else fn(**kw)
            except FileNotFoundError as e:  # an example whose data are missing is listed, not run
                summaries[name] = [f"### {name}", "", f"not run: {e}", ""]
                continue
            print(f"{name}: {rep['verdict']}")
            summaries[name] = _summary(name, rep)
            (out / name / "summary.json").write_text(json.dumps({"verdict": rep["verdict"], "ladder": rep["ladder"],
                                                                  "missing_effect": rep["missing_effect"]},
                                                                 indent=1, default=float))
    for name in EXAMPLES:  # with --only, the examples not rebuilt keep their summary (from their report)
        if name not in summaries and (out / name / "report.json").is_file():
            summaries[name] = _summary(name, json.loads((out / name / "report.json").read_text(encoding="utf-8")))
    lines += [line for name in EXAMPLES if name in summaries for line in summaries[name]]
    (out / "README.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"examples in {out.resolve()}")
    return 0


#: the examples in the order the summary lists them
EXAMPLES = {"simulated_current": simulated_current, "esso_osaka": esso_osaka,
            "esso_osaka_identified": esso_osaka_identified, "kvlcc2_hsva": kvlcc2_hsva,
            "kvlcc2_hsva_identified": kvlcc2_hsva_identified}
