"""The figures' readability rules (study/figures/style.py): every estimator and sample structure in conf/ has its own
colour and marker, far enough apart to be told apart; the checker finds small text, unlabelled axes, axes without
units and log axes with too few ticks; the figures of the studies without a committed table (grand, emcee_kt)
pass it on a small synthetic table, and an estimator keeps its colour when a figure shows a subset. (The committed
studies' figures are checked when they are rebuilt: tests/figures/test_figures.py.)"""
import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.figures import build_study
from study.figures.plots import Builder, _plt
from study.figures.style import (
    ESTIMATOR_STYLE, STRUCTURE_STYLE, estimator_style, log_ticks, readability_problems,
)

REPO = Path(__file__).resolve().parents[2]


def _lab(hexc: str) -> np.ndarray:
    """CIE 1976 L*a*b* (D65) of an sRGB colour (IEC 61966-2-1 transfer function and matrix; CIE 15:2004)."""
    rgb = np.array([int(hexc[i:i + 2], 16) / 255 for i in (1, 3, 5)])
    lin = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = m @ lin / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


#: two categories' colours at least this far apart (CIE76 Delta E*ab; about 2.3 is just noticeable side by side,
#: lines in a legend need far more: an assumption of this test, met by the palette with some margin)
MIN_DELTA_E = 20.0


@pytest.mark.parametrize("group, styles", [("estimator", ESTIMATOR_STYLE), ("structure", STRUCTURE_STYLE)])
def test_every_option_in_conf_has_its_own_colour_and_marker(group, styles):
    names = sorted(f.stem for f in (REPO / "conf" / group).glob("*.yaml"))
    assert names
    missing = [n for n in names if n not in styles]
    assert not missing, f"no style for {missing}: add them to study/figures/style.py"
    colours = [styles[n][0].lower() for n in names]
    markers = [styles[n][1] for n in names]
    assert len(set(colours)) == len(names) and len(set(markers)) == len(names)
    for a, b in itertools.combinations(names, 2):
        de = float(np.linalg.norm(_lab(styles[a][0]) - _lab(styles[b][0])))
        assert de >= MIN_DELTA_E, f"{a} and {b}: colours {styles[a][0]} and {styles[b][0]} only {de:.1f} apart"
    for n in names:  # black is the truth
        assert np.linalg.norm(_lab(styles[n][0]) - _lab("#000000")) >= MIN_DELTA_E, n


def _de2000(lab1, lab2) -> float:
    """CIEDE2000 colour difference (G. Sharma, W. Wu, E. N. Dalal, Color Res. Appl. 30, 21-30, 2005, eqs. 1-22)."""
    (L1, a1, b1), (L2, a2, b2) = lab1, lab2
    cb = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    g = 0.5 * (1 - np.sqrt(cb ** 7 / (cb ** 7 + 25 ** 7)))
    a1p, a2p = (1 + g) * a1, (1 + g) * a2
    c1, c2 = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1 = np.degrees(np.arctan2(b1, a1p)) % 360 if c1 else 0.0
    h2 = np.degrees(np.arctan2(b2, a2p)) % 360 if c2 else 0.0
    dh = 0.0 if c1 * c2 == 0 else (h2 - h1 + 180) % 360 - 180
    dH = 2 * np.sqrt(c1 * c2) * np.sin(np.radians(dh / 2))
    lb, cbp = (L1 + L2) / 2, (c1 + c2) / 2
    if c1 * c2 == 0:
        hb = h1 + h2
    elif abs(h1 - h2) <= 180:
        hb = (h1 + h2) / 2
    else:
        hb = (h1 + h2 + 360) / 2 if h1 + h2 < 360 else (h1 + h2 - 360) / 2
    t = (1 - 0.17 * np.cos(np.radians(hb - 30)) + 0.24 * np.cos(np.radians(2 * hb))
         + 0.32 * np.cos(np.radians(3 * hb + 6)) - 0.20 * np.cos(np.radians(4 * hb - 63)))
    rt = -np.sin(np.radians(60 * np.exp(-((hb - 275) / 25) ** 2))) * 2 * np.sqrt(cbp ** 7 / (cbp ** 7 + 25 ** 7))
    sl = 1 + 0.015 * (lb - 50) ** 2 / np.sqrt(20 + (lb - 50) ** 2)
    sc, sh = 1 + 0.045 * cbp, 1 + 0.015 * cbp * t
    dl, dc = (L2 - L1) / sl, (c2 - c1) / sc
    return float(np.sqrt(dl ** 2 + dc ** 2 + (dH / sh) ** 2 + rt * dc * (dH / sh)))


def test_ciede2000_matches_sharmas_test_data():
    """Pairs 1, 2, 17, 25 and 34 of Sharma, Wu & Dalal's Table 1, to the 4 decimals published."""
    for lab1, lab2, want in (((50, 2.6772, -79.7751), (50, 0, -82.7485), 2.0425),
                             ((50, -1.3802, -84.2814), (50, 0, -82.7485), 1.0000),
                             ((50, 2.5, 0), (73, 25, -18), 27.1492),
                             ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
                             ((2.0776, 0.0795, -1.135), (0.9033, -0.0636, -0.5514), 0.9082)):
        assert _de2000(lab1, lab2) == pytest.approx(want, abs=5e-5)


#: any two estimators' colours at least this far apart in CIEDE2000, the perceptual difference (CIE76 overstates
#: differences among saturated blues and purples: three dark purples passed MIN_DELTA_E and looked alike in a
#: figure of eleven estimators); an assumption of this test
MIN_DE2000 = 20.0
#: every estimator's CIE lightness L* in this range: a line darker than 30 is hard to tell from the black truth and
#: from other dark lines, one lighter than 72 fades on white
LIGHTNESS = (30.0, 72.0)


def test_every_estimator_colour_is_clearly_distinct():
    names = sorted(f.stem for f in (REPO / "conf" / "estimator").glob("*.yaml"))
    assert len(names) >= 11
    close = [(a, b, round(_de2000(_lab(ESTIMATOR_STYLE[a][0]), _lab(ESTIMATOR_STYLE[b][0])), 1))
             for a, b in itertools.combinations(names, 2)]
    close = [c for c in close if c[2] < MIN_DE2000]
    assert not close, f"estimator colours closer than CIEDE2000 {MIN_DE2000}: {close}"
    for n in names:
        lightness = _lab(ESTIMATOR_STYLE[n][0])[0]
        assert LIGHTNESS[0] <= lightness <= LIGHTNESS[1], f"{n}: {ESTIMATOR_STYLE[n][0]} has L* {lightness:.0f}"


def test_the_distinctness_check_can_fail():
    """The palette the estimators had before (Tol's muted scheme): indigo, wine and purple pass CIE76 at 20 but not
    CIEDE2000 at 20, and the indigo is too dark."""
    wine, purple, indigo = _lab("#882255"), _lab("#AA4499"), _lab("#332288")
    assert np.linalg.norm(wine - purple) >= MIN_DELTA_E
    assert _de2000(wine, purple) < MIN_DE2000
    assert indigo[0] < LIGHTNESS[0]


def test_the_checker_finds_what_keeps_a_figure_from_print():
    plt = _plt()
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([1, 2, 3], [0.05, 0.6, 7.0])
    ax.set_yscale("log")  # two decades: matplotlib labels 0.1 and 1 only
    ax.set_ylabel("drift")  # no unit
    ax.text(1.5, 0.6, "tiny", fontsize=5)
    found = readability_problems(fig)
    assert any("'tiny'" in p and "5.0 pt" in p for p in found)
    assert any("x axis has tick labels but no label" in p for p in found)
    assert any("'drift' names no unit" in p for p in found)
    assert any("log y axis" in p for p in found)
    ax.texts[0].set_fontsize(8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("drift [-]")
    log_ticks(ax)
    assert readability_problems(fig) == []
    fig.set_size_inches(15, 3)  # printed at 190 mm, 8 pt on a 15 in figure is 4 pt
    assert any("in print" in p for p in readability_problems(fig))
    plt.close(fig)


def _synthetic_grand(estimators):
    """A results table shaped like the grand study's: two vessels, depths, noise levels, structures; errors that
    grow with the noise."""
    rng = np.random.default_rng(0)
    runs, params = [], []
    k = 0
    for vessel, model, L in (("kvlcc2", "mmg_hull", 320.0), ("kt_mariner", "nomoto2_nl", 160.9)):
        for h_T in (np.nan, 2.9):
            for nz, lvl in (("low", 0.01), ("medium", 0.05)):
                for st in ("euler", "central"):
                    for e in estimators:
                        rid = f"{k:016x}"
                        k += 1
                        runs.append({"run_id": rid, "status": "ok", "cfg_study": "grand", "cfg_vessel.name": vessel,
                                     "cfg_model.name": model, "cfg_structure.name": st, "cfg_estimator.name": e,
                                     "cfg_noise.name": nz, "cfg_depth.h_T": h_T, "cfg_seed": 0,
                                     "t_fit": float(rng.uniform(1e-3, 2.0)), "m_sample_dt": 0.1 if L > 200 else 0.05,
                                     "m_sample_dt_LU": 0.1 / (L / 8.0), "m_cond_corr_N": 10.0, "m_cond_N": 5.0,
                                     "m_vif_max_N": 3.0, "m_corr_max_N": 0.9})
                        for n, t in (("Nv", -0.13), ("Nr", -0.05), ("Nrrr", 0.02)):
                            err = lvl * (1 + ESTIMATOR_ORDER_INDEX.get(e, 0)) * rng.uniform(0.5, 1.5)
                            params.append({"run_id": rid, "equation": "N", "name": n, "estimate": t * (1 + err),
                                           "truth": t, "rel_error": err, "abs_error": abs(t * err),
                                           "truth_kind": "exact", "cfg_vessel.name": vessel, "cfg_model.name": model,
                                           "cfg_estimator.name": e, "cfg_structure.name": st})
    return pd.DataFrame(runs), pd.DataFrame(params)


ESTIMATOR_ORDER_INDEX = {e: i for i, e in enumerate(ESTIMATOR_STYLE)}


class _Keep(Builder):
    """A builder that also keeps each figure's lines (label -> colour, marker) before writing it."""

    def figure(self, fig, study, name, what):
        self.lines = getattr(self, "lines", {})
        self.lines[name] = {ln.get_label(): (ln.get_color(), ln.get_marker()) for ax in fig.axes
                            for ln in ax.get_lines() if not ln.get_label().startswith("_")}
        self.axes = getattr(self, "axes", {})
        self.axes[name] = [(ax.get_ylabel(), ax.get_ylim()) for ax in fig.axes]
        super().figure(fig, study, name, what)


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_grand_figures_are_fit_for_print_and_keep_each_estimators_colour(tmp_path):
    from study.figures.studies import grand

    seen = {}
    for k, ests in enumerate((list(ESTIMATOR_STYLE)[:11], ["svr_nu", "ls", "emcee"])):
        runs, params = _synthetic_grand(ests)
        b = _Keep(tmp_path, tmp_path / f"out{k}")
        build_study(b, grand, runs, params, table=False)
        assert b.problems == [], b.problems
        assert {"drift_vs_noise", "drift_vs_hT", "fit_time"} <= set(b.lines)
        for e in ests:
            st = estimator_style(e)
            assert b.lines["drift_vs_noise"][e] == (st["color"], st["marker"]), e
            seen.setdefault(e, set()).add(b.lines["drift_vs_noise"][e])
    assert all(len(v) == 1 for v in seen.values())  # the same colour and marker with 11 estimators and with 3


@pytest.mark.slow
def test_emcee_figures_are_fit_for_print_and_the_band_is_visible(tmp_path):
    """emcee_kt on a synthetic table with a chain and a posterior-predictive band whose width is a thousandth of
    the motion (as on the exact KT model): the band is drawn again around the posterior median, where it fills
    the axes."""
    from study.figures.studies import emcee_kt

    rng = np.random.default_rng(1)
    runs, params = [], []
    truth = {"K": 0.1858, "T": 107.3, "alpha": 4.48e4}
    for seed in (1, 0):
        for st, nz in (("output_error", "low_outputs"), ("central", "low")):
            # seed 1's run ids sort first: the figures must still show seed 0
            rid = f"{'a' if seed else 'b'}{st[:3]}{nz[:3]}".ljust(16, "0")
            runs.append({"run_id": rid, "status": "ok", "cfg_study": "emcee_kt", "cfg_structure.name": st,
                         "cfg_noise.name": nz, "cfg_seed": seed, "cfg_model.name": "nomoto1_nl",
                         "cfg_estimator.name": "emcee", "cfg_vessel.name": "kt1_mariner", "m_sample_dt": 0.1,
                         "m_sample_dt_LU": 0.0048, "cfg_noise.sample_dt_LU": 0.0048, "t_fit": 10.0})
            for n, t in truth.items():
                est = t * (1 + rng.normal(0, 0.003))
                params.append({"run_id": rid, "equation": "N", "name": n, "estimate": est, "truth": t,
                               "rel_error": est / t - 1, "abs_error": abs(est - t), "ci_low": est - 0.01 * t,
                               "ci_high": est + 0.01 * t, "truth_kind": "exact", "cfg_model.name": "nomoto1_nl",
                               "cfg_estimator.name": "emcee", "cfg_structure.name": st,
                               "cfg_vessel.name": "kt1_mariner"})
            art = tmp_path / "artefacts" / rid
            (art / "validation").mkdir(parents=True)
            names = np.array(["K", "T", "alpha", "r0[0]", "log_sigma_r"])
            chain = np.stack([np.array([*truth.values(), 0.0, -5.0]) * (1 + rng.normal(0, 0.003, (200, 16, 5)))])[0]
            np.savez(art / "chain.npz", chain=chain, names=names)
            t = np.linspace(0, 800, 801)
            r = 0.75 * np.tanh(np.sin(2 * np.pi * t / 260) * 4) * np.pi / 180
            psi = np.cumsum(r) * (t[1] - t[0])
            band = {"time": t, "draws": 200}
            for c, x in (("r", r), ("psi", psi)):
                w = 1e-3 * np.abs(x).max()
                band.update({f"truth_{c}": x + 0.3 * w, f"q05_{c}": x - w, f"q50_{c}": x, f"q95_{c}": x + w})
            pd.DataFrame(band).to_csv(art / "validation" / "zigzag_35_35_band.csv", index=False)
    b = _Keep(tmp_path, tmp_path / "out")
    build_study(b, emcee_kt, pd.DataFrame(runs), pd.DataFrame(params), table=False)
    assert b.problems == [], b.problems
    out = tmp_path / "out" / "emcee_kt"
    assert (out / "corner.png").is_file() and (out / "posterior_band_zigzag_35_35.png").is_file()
    assert {p[0] for p in b.read} == {"boutlow".ljust(16, "0")}  # the lowest seed, not the first run id
    dev = [lim for lab, lim in b.axes["posterior_band_zigzag_35_35"] if lab.startswith("r - median")]
    width = 2e-3 * 0.75  # q95 - q05 of r in deg/s
    assert dev and dev[0][1] - dev[0][0] < 3 * width  # the band fills a third of its axes or more


def test_signed_axis_is_chosen_from_the_data_with_plain_ticks():
    """Values of either sign reaching hundreds: symmetric-log ticks at 0, +-1, +-10, +-100 written plainly (not
    '-10^0' or '7.60718x10^-1'); small values of either sign: a linear axis; positive values: a log axis."""
    from study.figures.style import signed_axis

    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(7, 2.5), layout="constrained")
    cases = (([-312.0, -23.0, 0.4, 7.8, 150.0], "symlog"), ([-0.14, -0.01, 0.3, 0.76], "linear"),
             ([0.9, 3.0, 80.0], "log"))
    for ax, (y, want) in zip(axes, cases):
        ax.plot(range(len(y)), y)
        assert signed_axis(ax, y) == want
        ax.set_xlabel("h/T [-]")
        ax.set_ylabel("K' [-]")
    fig.canvas.draw()
    labels = [t.get_text() for t in axes[0].get_yticklabels() if t.get_text()]
    assert labels == ["-100", "-10", "-1", "0", "1", "10", "100"], labels
    for ax in axes[1:]:
        assert all("10^" not in t.get_text() and "times" not in t.get_text() for t in ax.get_yticklabels())
    assert readability_problems(fig) == []
    plt.close(fig)
