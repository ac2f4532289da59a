"""The residual yaw moment against the rudder angle: what a model misses of the rudder's force, per
rudder-angle bin.

:func:`residual_by_rudder` bins the inverse-dynamics residuals of a fit
(``study.identify.with_effects.residuals``: the measured inertial forces minus the model's at the
training rows) by the rudder angle and gives per bin the mean non-dimensional residual N' (by 0.5
rho L^2 d U0^2) and Y' (by 0.5 rho L d U0^2), with the spread of the bin means (largest minus
smallest) and the RMS of N'. A model whose rudder force is right leaves bin means that do not change
with the rudder angle; a rudder too weak or too strong leaves a ramp, a rudder force that differs to
port and to starboard (the flow straightening gamma_R of Yasukawa & Yoshimura 2015, eq. 24, taken as
one value where the ship has two) a kink at zero. A dict of plain numbers, for a report's data.

``python -m study rudder_residual`` writes the KVLCC2 case (HSVA's zigzags, the doctor's training
records in ``study.doctor.examples``; ``../shared/data/real``) to
``<out>/kvlcc2_rudder_residual.{json,md}`` (default ``rudder_residual/`` in the current folder): the
published set and the hull identified from the records (the doctor's anchor, 30 %), each with no
effect, the yaw bias, the rudder's inflow free, both, and the propeller from the measured thrust;
with the validation error on the doctor's validation records.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

#: rudder-angle bin edges [deg] (positive: to starboard, the schema's convention)
BINS_DEG = (-40.0, -25.0, -15.0, -7.5, -2.5, 2.5, 7.5, 15.0, 25.0, 40.0)
DEFAULT_OUT = Path("rudder_residual")
EFFECT_SETS = ((), ("yaw_bias",), ("rudder_inflow",), ("yaw_bias", "rudder_inflow"), ("propeller_thrust",))


def residual_by_rudder(problem, fit, names=None, bins=BINS_DEG) -> dict:
    """Per rudder-angle bin (edges ``bins`` [deg]) the mean residual N' and Y' of ``fit`` on
    ``problem``'s training rows and the number of rows; the spread of the N' bin means and the
    RMS of N' over all rows."""
    from ..identify.with_effects import residuals

    names = names or [i.name for i in problem.infos]
    res = residuals(problem, fit, names)
    delta = np.degrees(np.concatenate([r["delta"] for r in res]))
    N = np.concatenate([r["N"] for r in res]) / problem.scale[2]
    Y = np.concatenate([r["Y"] for r in res]) / problem.scale[1]
    idx = np.digitize(delta, bins)
    rows = []
    for i in range(1, len(bins)):
        m = idx == i
        rows.append({"delta_from_deg": float(bins[i - 1]), "delta_to_deg": float(bins[i]), "rows": int(m.sum()),
                     "N_mean": float(N[m].mean()) if m.any() else None,
                     "Y_mean": float(Y[m].mean()) if m.any() else None})
    means = [r["N_mean"] for r in rows if r["N_mean"] is not None]
    return {"bins": rows, "N_spread": float(max(means) - min(means)) if means else None,
            "N_rms": float(np.sqrt(np.mean(N ** 2))), "rows": int(len(N))}


def kvlcc2_hsva(data_dir=None) -> dict:
    """The KVLCC2 case (see the module docstring): model -> effects -> residual table, errors,
    parameters."""
    from study.configuration.compose import read_config
    from ..identify.with_effects import (EffectsProblem, identify_effects, record_errors, scored_channels,
                                         validation_error)
    from study.records.loaders import load_records, real_data_dir

    d = Path(data_dir) if data_dir else real_data_dir() / "kvlcc2_hsva" / "raw_data"
    train = load_records(str(d / "HSVA_CPMC_KVLCC2_Z_*_0?.dat"))
    val = load_records(str(d / "HSVA_CPMC_KVLCC2_Z_*_10_?.dat"))
    vessel = read_config("vessel", "kvlcc2_l7")
    names = [r.meta["name"] for r in train]
    out = {}
    for label, model, anchor in (("published set (Yasukawa & Yoshimura 2015)",
                                  {"name": "known", "type": "kind", "equations": {}}, None),
                                 ("hull identified, anchored 30 %", read_config("model", "mmg_hull"), 0.3)):
        pb = EffectsProblem(vessel, model, train, anchor=anchor, names=names)
        for effs in EFFECT_SETS:
            fit = identify_effects(pb, effs)
            errs = {r.meta["name"]: record_errors(r.data, pb.predict(fit, r.data, pb.info_for(r.data, r.meta)),
                                                  pb.floors, scored_channels(r.meta)) for r in val}
            desc = {k: v for k, v in pb.describe(fit, model=False).items() if isinstance(v, (int, float))}
            out.setdefault(label, {})["+".join(effs) or "none"] = {
                "training_error": fit.training_error, "validation_error": validation_error(errs),
                "effect_parameters": desc, "residual": residual_by_rudder(pb, fit, names)}
    return out


def write(res: dict, out: Path) -> list:
    out.mkdir(parents=True, exist_ok=True)
    js, md = out / "kvlcc2_rudder_residual.json", out / "kvlcc2_rudder_residual.md"
    js.write_text(json.dumps(res, indent=1))
    head = None
    lines = ["# KVLCC2 (L7): the residual yaw moment against the rudder angle on HSVA's zigzags", "",
             "Written by `python -m study rudder_residual` (study/doctor/rudder_residual.py). Mean residual "
             "N' x 1e4 (non-dimensional by 0.5 rho L^2 d U0^2) of the training rows per rudder-angle bin [deg, + to "
             "starboard]; spread: largest minus smallest bin mean; validation error: the doctor's (mean NRMSE of "
             "u, v, r, psi over HSVA's 10/10 and 20/10 zigzags).", ""]
    for model, by in res.items():
        for effs, r in by.items():
            bins = r["residual"]["bins"]
            if head is None:
                head = [f"{b['delta_from_deg']:+g}..{b['delta_to_deg']:+g}" for b in bins]
                lines += ["| model | effects | " + " | ".join(head) + " | spread | N' RMS | training error | "
                          "validation error | effect parameters |", "|---" * (len(head) + 7) + "|"]
            cells = [f"{1e4 * b['N_mean']:+.1f}" if b["N_mean"] is not None else "-" for b in bins]
            pars = ", ".join(f"{k} {v:.3g}" for k, v in r["effect_parameters"].items())
            lines.append(f"| {model} | {effs} | " + " | ".join(cells) +
                         f" | {1e4 * r['residual']['N_spread']:.1f} | {1e4 * r['residual']['N_rms']:.1f} | "
                         f"{r['training_error']:.4f} | {r['validation_error']:.3f} | {pars} |")
    md.write_text("\n".join(lines) + "\n")
    return [js, md]


def main(argv=None) -> int:
    from study.configuration.cli import OutputExistsError, parser

    ap = parser("study rudder_residual", "KVLCC2's residual yaw moment against the rudder angle (HSVA)")
    ap.add_argument("--out", default=str(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT}/)")
    ap.add_argument("--overwrite", action="store_true", help="replace the table already in the output folder")
    ap.add_argument("--data", default=None, help="folder of HSVA's .dat files (default: the real-data folder)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if (out / "kvlcc2_rudder_residual.md").exists() and not args.overwrite:
        raise OutputExistsError(f"--out {out}: already holds kvlcc2_rudder_residual.md; refusing to overwrite it "
                                "(--overwrite, or another --out)")
    for p in write(kvlcc2_hsva(args.data), out):
        print(p)
    return 0
