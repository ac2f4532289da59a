"""KVLCC2 against reality: the MMG model of ``kvlcc2_l7`` through the zigzags HSVA ran free (SIMMAN
2008).

``python -m study reality_check`` simulates the 10/10 and 20/10 zigzags, both sides first, from the
measured approach speed, with the published MMG coefficients (Yasukawa & Yoshimura 2015) and the
helm rate of the HSVA report, and puts overshoots and periods beside the measured ones in
``<out>/kvlcc2_zigzags_vs_tank.{csv,md}`` and ``<out>/kvlcc2_zigzags_vs_tank.{png,pdf}`` (default
``reality_check/`` in the current folder; the committed ones: ``--out paper_figs --overwrite``).

Two propeller settings are simulated, because they are the two defensible readings of "the HSVA
test": ``mmg_self_propulsion`` (n solved so that the MMG model runs straight at the measured speed:
the model is self-consistent) and ``hsva_rpm`` (the measured 10.23 rps: the MMG model's resistance
and thrust then decide the speed, as in the tank). Measured data: HSVA (A. Cura Hochbaum) 2006,
redistributed by Alexandersson et al. (2022); see ../shared/data/real/kvlcc2_hsva/SOURCE.md.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from study.records.loaders import RealDataMissing, load_kvlcc2_hsva, require_real_records
from study.sim.maneuvers import Maneuver
from study.records.metrics import zigzag_metrics
from study.sim import load_vessel, simulate

RUNS = ("Z_10_10_P", "Z_10_10_S", "Z_20_10_P", "Z_20_10_S")
OUT_DIR = Path(__file__).resolve().parents[2] / "paper_figs"
#: the command's default output: a folder of the current directory, never a committed one
DEFAULT_OUT = Path("reality_check")
FILES = tuple(f"kvlcc2_zigzags_vs_tank.{e}" for e in ("csv", "md", "png", "pdf"))


def _execution(df: pd.DataFrame) -> tuple[float, float]:
    """(time of rudder execution, sign of the first rudder) of a measured zigzag."""
    d = df["delta"].to_numpy()
    i = int(np.argmax(np.abs(d - d[0]) > math.radians(0.5)))
    return float(df["time"].iloc[i]), float(np.sign(d[i] - d[0]))


def simulate_like(measured: pd.DataFrame, amp_deg: float, switch_deg: float, propeller: str):
    """Simulate the MMG model through the zigzag the measured record shows."""
    t_exec, side = _execution(measured)
    vessel = load_vessel("kvlcc2_l7")
    u0 = float(measured["u"].iloc[0])
    vessel = vessel_at(vessel, u0, float(measured["n"].mean()) if propeller == "hsva_rpm" else None)
    man = Maneuver(name="hsva", type="zigzag", first="starboard" if side > 0 else "port",
                   t_start=t_exec - float(measured["time"].iloc[0]),
                   stages=[{"amp_deg": amp_deg, "switch_deg": switch_deg, "switches": 99}],
                   duration=float(measured["time"].iloc[-1] - measured["time"].iloc[0]))
    df = simulate(vessel, man, dt=0.01, sample_dt=0.05, u0=u0, psi0=float(measured["psi"].iloc[0]))
    df["time"] += float(measured["time"].iloc[0])
    return df


def vessel_at(vessel, u0: float, n: float | None):
    """The vessel with its operating point moved to the measured approach speed (and, optionally,
    rpm)."""
    from study.sim import get_kind

    kind = get_kind(vessel.kind_name)
    n_k = len(kind.PARAM_NAMES)
    n_new = float(kind.solve_n(vessel.params[:n_k], u0)) if n is None else n
    v = vessel.with_params()
    v.U0, v.n0 = u0, n_new
    return v


def build_table(data_dir=None) -> tuple[pd.DataFrame, dict]:
    rows, traces = [], {}
    files = {Path(p).stem.replace("HSVA_CPMC_KVLCC2_", ""): p for p in require_real_records("kvlcc2_hsva", data_dir)}
    lacking = [f"HSVA_CPMC_KVLCC2_{run}.dat" for run in RUNS if run not in files]
    if lacking:
        raise RealDataMissing(f"{Path(files[next(iter(files))]).parent}: lacks {lacking} of the HSVA zigzags")
    for run in RUNS:
        meas = load_kvlcc2_hsva(files[run]).data
        amp, sw = float(run.split("_")[1]), float(run.split("_")[2])
        m_meas = zigzag_metrics(meas, psi_switch=math.radians(sw))
        traces[run] = {"measured": meas}
        for prop in ("mmg_self_propulsion", "hsva_rpm"):
            sim = simulate_like(meas, amp, sw, prop)
            traces[run][prop] = sim
            m_sim = zigzag_metrics(sim, psi_switch=math.radians(sw))
            for key in ("overshoot_1", "overshoot_2", "period"):
                rows.append({"run": run, "propeller": prop, "quantity": key,
                             "measured": m_meas.get(key, np.nan), "simulated": m_sim.get(key, np.nan)})
    table = pd.DataFrame(rows)
    table["difference"] = table["simulated"] - table["measured"]
    table["ratio"] = table["simulated"] / table["measured"]
    return table, traces


def write_outputs(table: pd.DataFrame, traces: dict, out_dir: Path = OUT_DIR) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    csv = out_dir / "kvlcc2_zigzags_vs_tank.csv"
    table.round(4).to_csv(csv, index=False)
    md = out_dir / "kvlcc2_zigzags_vs_tank.md"
    md.write_text("# KVLCC2 (L7 model) zigzags: MMG standard method against HSVA free-running tests\n\n"
                  "Overshoots in degrees, periods in seconds (model scale). Rebuilt by "
                  "`python -m study reality_check`.\n\n" + table.round(2).to_markdown(index=False) + "\n")
    paths += [csv, md]
    from study.figures.style import PRINT_WIDTH_IN, rc

    plt.rcParams.update(rc())
    fig, axes = plt.subplots(len(traces), 1, figsize=(PRINT_WIDTH_IN, 2.3 * len(traces) + 0.6), sharex=False,
                             squeeze=False, layout="constrained")
    for ax, (run, tr) in zip(axes[:, 0], traces.items()):
        m = tr["measured"]
        amp, sw, side = run.split("_")[1:]
        ax.plot(m.time, np.degrees(m.psi - m.psi.iloc[0]), "k", lw=1.5, label="heading psi, HSVA measured")
        ax.plot(m.time, np.degrees(m.delta), "k:", lw=1, label="rudder delta, measured")
        for prop, colour, ls in (("mmg_self_propulsion", "#0072B2", "-"), ("hsva_rpm", "#D55E00", "--")):
            s = tr[prop]
            ax.plot(s.time, np.degrees(s.psi - s.psi.iloc[0]), color=colour, ls=ls, lw=1.2,
                    label=f"heading psi, MMG, {prop}")
        ax.set_title(f"HSVA {run}: {int(amp)}/{int(sw)} zigzag, {'port' if side == 'P' else 'starboard'} first")
        ax.set_ylabel("psi, delta [deg]")
        ax.set_xlabel("time [s] (model scale)")
        ax.grid(alpha=0.3)
    h, lab = axes[0, 0].get_legend_handles_labels()
    fig.legend(h, lab, loc="outside lower center", ncol=2)
    for ext in ("png", "pdf"):
        p = out_dir / f"kvlcc2_zigzags_vs_tank.{ext}"
        fig.savefig(p, dpi=120, metadata={"CreationDate": None} if ext == "pdf" else {"Software": None})
        paths.append(p)
    plt.close(fig)
    return paths


def main(argv=None) -> int:
    from study.configuration.cli import OutputExistsError, parser

    ap = parser("study reality_check", __doc__.splitlines()[0])
    ap.add_argument("--out", default=str(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT}/ in the current "
                    "folder; the committed outputs: --out paper_figs --overwrite)")
    ap.add_argument("--overwrite", action="store_true", help="replace the outputs already in the output folder")
    args = ap.parse_args(argv)
    there = [f for f in FILES if (Path(args.out) / f).exists()]
    if there and not args.overwrite:  # before any work
        raise OutputExistsError(f"--out {args.out}: already holds {', '.join(there)}; refusing to overwrite them "
                                "(--overwrite to overwrite them, or another --out)")
    table, traces = build_table()
    for p in write_outputs(table, traces, Path(args.out)):
        print(f"wrote {p}")
    print(table.round(2).to_string(index=False))
    return 0


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    from study.configuration.cli import run

    run(main, "study reality_check")
