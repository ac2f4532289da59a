"""What an identified model predicts for a manoeuvre nobody measured, and how sure it can be.

:func:`predict_turn` simulates a fitted model (:class:`study.identify.with_effects.EffectsProblem` and one of its
fits) through a 35 deg turning circle (IMO MSC.137(76)) from a steady approach, and gives the tactical diameter and
advance of the point estimate and of draws from the fit's Gaussian posterior (``EffectsProblem.posterior``: the
prior-anchored normal equations with the doctor's data weight), so a prediction extrapolated from zigzags comes
with the spread its coefficients allow. The draws run in one compiled batch (``study.sim.simulate_batch``).

Choices, labelled:

- *Propeller*: by default the model's **own self-propulsion point** at the approach speed (the rpm at which it
  runs straight at that speed, SIMMAN 2008's rule for the free-running turns: "the RPM such that the ship is in
  longitudinal equilibrium"); an identified model whose resistance differs from the published set's then turns
  at another rpm than the published set does. ``n`` gives a fixed rpm instead (e.g. the tank's). The draws turn at
  the point estimate's rpm (their own resistance differs little: R'0 is among the best-determined coefficients).
- *Set-up effects*: an effect of the training records' test set-up (``setup_effect``: a yaw bias, a rudder zero
  offset; ``study.facility``) is left out of a turn predicted for another facility or scale: ``facility`` names
  the facility the turn is predicted for (None: not stated, taken as another set-up than the training records',
  since a manoeuvre nobody measured was not run in their set-up), ``keep_setup_effects`` keeps them. The result
  says which were left out (``setup_left_out``).
- *Interval*: the central ``level`` share of the draws' tactical diameters. It holds only the identification's
  statistical spread, not the model error that the doctor's prior-data conflicts point to; a narrow interval
  far from another source's figure says the records and that source disagree, not that either is right.

``python -m study.doctor.turn_prediction`` writes the KVLCC2 case (HSVA's zigzags, ``../shared/data/real``) to
``<out>/kvlcc2_turn_from_zigzags.{md,csv}`` (default ``turn_prediction/`` in the current folder; the committed
table: ``--out paper_figs/doctor --overwrite``): the published set against the hull identified from the zigzags
under the doctor's settings and under other reasonable ones.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd


from .predictions import default_alternatives, predict_turn, setup_effects_left_out, turn_vessel  # noqa: F401

__all__ = ["predict_turn", "kvlcc2_hsva_table"]

#: the committed table's folder (rebuilt only when asked: --out paper_figs/doctor --overwrite)
COMMITTED = Path(__file__).resolve().parents[2] / "paper_figs" / "doctor"
#: the default output: a folder of the current directory, never a committed one
DEFAULT_OUT = Path("turn_prediction")
FILES = ("kvlcc2_turn_from_zigzags.csv", "kvlcc2_turn_from_zigzags.md")


#: the KVLCC2 cases: (label, anchor, effects); the first identified one is the doctor's default
CASES = (
    ("hull identified, anchored 30 % (the doctor's default)", 0.3, ()),
    ("+ yaw bias (the doctor's verdict; a set-up effect, left out of the turn)", 0.3, ("yaw_bias",)),
    ("+ yaw bias, kept in the turn (keep_setup_effects)", 0.3, ("yaw_bias",)),
    ("+ yaw bias + rudder interaction (t_R, a_H, x_R free)", 0.3, ("yaw_bias", "rudder_interaction")),
    ("+ propeller wake (w_P0, t_P free)", 0.3, ("propeller_wake",)),
    ("hull identified, unanchored least squares", 0.0, ()),
)


def kvlcc2_hsva_table(data_dir=None, draws: int = 64) -> pd.DataFrame:
    """The published KVLCC2 set against hulls identified from HSVA's nine 1-5 deg switch zigzags (the doctor's
    training records in ``study.doctor.examples``), each turned at 35 deg from HSVA's approach speed at its own
    self-propulsion rpm and at HSVA's measured rpm."""
    from ..identify.effects import list_effects, registry
    from ..identify.with_effects import EffectsProblem, Fit
    from ..loaders import load_records, real_data_dir
    from .run import diagnose_conf

    d = Path(data_dir) if data_dir else real_data_dir() / "kvlcc2_hsva" / "raw_data"
    train = load_records(str(d / "HSVA_CPMC_KVLCC2_Z_*_0?.dat"), states="auto")
    u0 = float(np.median([r.data["u"].iloc[:50].mean() for r in train]))
    n_tank = float(np.median([r.data["n"].mean() for r in train]))
    conf = diagnose_conf(vessel="kvlcc2_l7", model="mmg_hull")
    effects = registry(list_effects())
    rows = []
    known = EffectsProblem(conf["vessel"], {"name": "known", "type": "kind", "equations": {}}, train, None, effects)
    published = Fit((), {}, {}, float("nan"))
    problems = {}
    for label, anchor, effs in (("published set (Yasukawa & Yoshimura 2015)", None, ()),) + CASES:
        if anchor is None:
            pb, fit = known, published
        else:
            pb = problems.setdefault(anchor, EffectsProblem(conf["vessel"], conf["model"], train, None, effects,
                                                           None, anchor))
            fit = pb.fit(effs)
        keep = "keep_setup_effects" in label
        own = predict_turn(pb, fit, u0=u0, draws=draws, keep_setup_effects=keep)
        tank = predict_turn(pb, fit, u0=u0, n=n_tank, draws=0, keep_setup_effects=keep)
        rows.append({"model": label, "training_error": fit.training_error, "n_own_rps": own["n"],
                     "TD_L": own["tactical_diameter_L"], "TD_L_low": own["td_low"], "TD_L_high": own["td_high"],
                     "advance_L": own["advance_L"], "TD_L_at_tank_rpm": tank["tactical_diameter_L"],
                     "draws_turned": own["finite_draws"] if own["draws"] and anchor is not None else None,
                     "setup_left_out": ", ".join(own["setup_left_out"])})
    df = pd.DataFrame(rows)
    ref = df.loc[0, "TD_L"]
    df["TD_vs_published_pct"] = 100.0 * (df["TD_L"] / ref - 1.0)
    df.attrs.update(u0=u0, n_tank=n_tank, records=[r.meta.get("name") for r in train])
    return df


def write_table(df: pd.DataFrame, out: Path, draws: int = 64) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    csv, md = (out / f for f in FILES)
    df.to_csv(csv, index=False, float_format="%.4g")
    show = df.copy()
    show["TD [L] (90 % of posterior draws)"] = [
        f"{r.TD_L:.2f}" + (f" ({r.TD_L_low:.2f}-{r.TD_L_high:.2f}; {r.draws_turned:.0f}/{draws} draws turned)"
                           if np.isfinite(r.TD_L_low) else "")
        for r in df.itertuples()]
    show = show[["model", "TD [L] (90 % of posterior draws)", "TD_vs_published_pct", "advance_L", "n_own_rps",
                 "TD_L_at_tank_rpm", "training_error", "setup_left_out"]]
    show.columns = ["model", "tactical diameter [L] (90 % of posterior draws)", "vs published [%]",
                    "advance [L]", "own self-propulsion [rps]", f"TD at HSVA's {df.attrs['n_tank']:.2f} rps [L]",
                    "training error", "set-up effects left out"]
    md.write_text(
        "# KVLCC2 (L7): the 35 deg turn predicted from HSVA's zigzags\n\n"
        "Written by `python -m study.doctor.turn_prediction` (study/doctor/turn_prediction.py). Training: HSVA's "
        f"free-running zigzags with 1-5 deg switch headings ({len(df.attrs['records'])} records, "
        "../shared/data/real/kvlcc2_hsva); every model turned at 35 deg to starboard from HSVA's approach speed "
        f"({df.attrs['u0']:.3f} m/s) at its own self-propulsion rpm (SIMMAN 2008's rule), and at HSVA's measured "
        f"rpm. The interval is the central 90 % of the {draws} draws from the fit's posterior (identification spread only, "
        "not model error; a draw that diverged or never turned 180 deg is left out). An effect of HSVA's test set-up "
        "(the yaw bias: HSVA's report says its rudder was deflected from the geometric zero) is left out of a turn "
        "predicted for another basin unless kept (keep_setup_effects).\n\n" + show.to_markdown(index=False, floatfmt=".3g") + "\n")
    return [csv, md]


def main(argv=None) -> int:
    from ..cli import OutputExistsError, parser

    ap = parser("study.doctor.turn_prediction", "KVLCC2's 35 deg turn predicted from HSVA's zigzags, with intervals")
    ap.add_argument("--out", default=str(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT}/ in the current "
                    "folder; the committed table: --out paper_figs/doctor --overwrite)")
    ap.add_argument("--overwrite", action="store_true", help="replace the table already in the output folder")
    ap.add_argument("--data", default=None, help="folder of HSVA's .dat files (default: the real-data folder)")
    args = ap.parse_args(argv)
    from ..loaders import real_data_dir

    there = [f for f in FILES if (Path(args.out) / f).exists()]
    if there and not args.overwrite:  # before any work
        raise OutputExistsError(f"--out {args.out}: already holds {', '.join(there)}; refusing to overwrite them "
                                "(--overwrite to overwrite them, or another --out)")
    d = Path(args.data) if args.data else real_data_dir() / "kvlcc2_hsva" / "raw_data"
    if not list(d.glob("HSVA_CPMC_KVLCC2_Z_*_0?.dat")):
        raise FileNotFoundError(f"no HSVA zigzag files (HSVA_CPMC_KVLCC2_Z_*_0?.dat) in {d}; give --data")
    df = kvlcc2_hsva_table(d)
    for p in write_table(df, Path(args.out)):
        print(p)
    print(df.to_string(index=False))
    return 0


if __name__ == "__main__":
    from ..cli import run

    run(main, "study.doctor.turn_prediction")
