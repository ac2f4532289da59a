"""How every figure of ``python -m study figures`` looks: one colour and marker per estimator and
per sample structure (keyed by name, so a figure that shows a subset keeps each one's colour), fonts
sized for print, log axes with enough labelled ticks, heatmap cell numbers only where they fit, the
units of the identified parameters, and :func:`readability_problems`, the rules a figure is checked
against (tests/figures/test_figure_style.py).

Print size: the figures are drawn at most :data:`PRINT_WIDTH_IN` wide, Elsevier's double-column
width (190 mm; Elsevier, "Artwork sizing",
https://www.elsevier.com/about/policies-and-standards/author/artwork-and-media-instructions/artwork-sizing),
so a font of :data:`MIN_FONT_PT` or more on the figure is that size or more in print (a wider figure
is scaled down, and the check scales its fonts with it).
"""
from __future__ import annotations

import math
import re
import zlib

import numpy as np

#: the widest a figure is printed: Elsevier's double-column width, 190 mm (see the module docstring)
PRINT_WIDTH_IN = 190 / 25.4
#: the smallest font at the printed size (Elsevier's artwork guidelines ask for 7 pt at least; 8 pt leaves margin)
MIN_FONT_PT = 8.0

#: Paul Tol's 'muted' qualitative scheme, nine colours (P. Tol, "Colour schemes", SRON/EPS/TN/09-002, 2021, Fig. 4;
#: https://personal.sron.nl/~pault/), built to stay apart for colour-blind readers
TOL_MUTED = ["#332288", "#88CCEE", "#44AA99", "#117733", "#999933", "#DDCC77", "#CC6677", "#882255", "#AA4499"]
#: Okabe & Ito's colour-universal-design set (Okabe & Ito 2008, https://jfly.uni-koeln.de/color/), black left out
#: (black is the truth in every figure)
OKABE_ITO = ["#E69F00", "#56B4E9", "#009E73", "#F0E442", "#0072B2", "#D55E00", "#CC79A7"]
#: posterior bands and truth lines of the emcee figures
OKABE_BLUE = "#0072B2"

#: estimator -> (colour, marker), the same in every figure. Thirteen colours drawn from matplotlib's tab10 and tab20,
#: Okabe & Ito's set and Tol's muted and vibrant schemes, chosen so that any two are at least 20 apart in CIEDE2000
#: (G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula", Color Res. Appl. 30, 2005) and every
#: one has a CIE lightness L* of 30-72: no near-black line beside the black truth, no pale line on white, and no
#: two dark purples (tested: tests/figures/test_figure_style.py). Each estimator also has its own marker, so two estimators
#: differ even in greyscale. A new estimator (conf/estimator/<name>.yaml) needs its entry here (the test fails
#: without it; until then it is drawn grey with a marker picked from its name).
ESTIMATOR_STYLE = {
    "ls": ("#1F77B4", "o"),            # tab10 blue
    "ridge": ("#33BBEE", "s"),         # Tol vibrant cyan
    "lasso": ("#44AA99", "^"),         # Tol muted teal
    "lssvm": ("#117733", "v"),         # Tol muted green
    "tlssvm": ("#999933", "D"),        # Tol muted olive
    "lssvm_online": ("#C49C94", "<"),  # tab20 light brown
    "svr_eps": ("#EE3377", ">"),       # Tol vibrant magenta
    "svr_nu": ("#882255", "P"),        # Tol muted wine
    "sindy": ("#9467BD", "X"),         # tab10 purple
    "de": ("#E69F00", "*"),            # Okabe-Ito orange
    "de_staged": ("#665500", "d"),     # dark ochre, DE's family (searched for: at least 25 from every other colour)
    "emcee": ("#8C564B", "h"),         # tab10 brown
    "map": ("#D55E00", "p"),           # Okabe-Ito vermillion
    "variable_projection": ("#3D5C5C", "H"),  # dark slate (searched for: at least 22 from every other colour)
}

#: sample structure -> (colour, marker, hatch, line style): Okabe-Ito colours; hatches and line styles tell them
#: apart in greyscale
STRUCTURE_STYLE = {
    "euler": ("#E69F00", "o", "", "-"),
    "diff_center": ("#56B4E9", "s", "//", "--"),
    "central": ("#009E73", "^", "\\\\", "-."),
    "integral": ("#0072B2", "D", "..", ":"),
    "smoothed": ("#CC79A7", "v", "xx", (0, (5, 1))),
    "output_error": ("#D55E00", "P", "--", (0, (3, 1, 1, 1, 1, 1))),
}

#: the truth in every figure
TRUTH_STYLE = {"color": "black", "lw": 1.6}

_FALLBACK_MARKERS = ["o", "s", "^", "v", "D", "<", ">", "P", "X", "*", "h", "p", "d", "8", "H"]


def _fallback(name: str, markers=_FALLBACK_MARKERS) -> str:
    return markers[zlib.crc32(name.encode("utf-8")) % len(markers)]  # crc32: the same in every run (hash() is not)


def estimator_style(name: str) -> dict:
    """``color`` and ``marker`` of an estimator, the same in every figure."""
    c, m = ESTIMATOR_STYLE.get(name, ("#777777", _fallback(name)))
    return {"color": c, "marker": m}


def structure_style(name: str) -> dict:
    """``color``, ``marker``, ``hatch`` and ``ls`` of a sample structure, the same in every
    figure."""
    c, m, h, ls = STRUCTURE_STYLE.get(name, ("#777777", _fallback(name), "", "-"))
    return {"color": c, "marker": m, "hatch": h, "ls": ls}


def rc() -> dict:
    """matplotlib settings of every figure: fonts of 8-10 pt (the figures are at most
    PRINT_WIDTH_IN wide), Tol's muted colours for anything not keyed by name, no dates or hash
    randomness in the files."""
    from cycler import cycler

    return {"svg.hashsalt": "study", "figure.dpi": 100, "font.size": 9, "axes.titlesize": 9, "axes.labelsize": 9,
            "xtick.labelsize": 8, "ytick.labelsize": 8, "legend.fontsize": 8, "legend.title_fontsize": 8,
            "figure.titlesize": 10, "pdf.fonttype": 42, "lines.markersize": 5, "axes.grid": False,
            "axes.prop_cycle": cycler(color=TOL_MUTED)}


def log_ticks(ax, axis: str = "y") -> None:
    """At least three labelled ticks on a log axis, whatever it spans: decades (10^-3) when the
    view spans three or more, 1-2-5 in each decade (0.002, 0.005) when it spans one to three,
    evenly spaced values below one decade (where a log axis is nearly linear). Call it when the
    limits are final (after the last plot on the axes); shared axes share the locator."""
    from matplotlib.ticker import (
        FuncFormatter, LogFormatterSciNotation, LogLocator, MaxNLocator, NullFormatter,
    )

    ax_ = ax.yaxis if axis == "y" else ax.xaxis
    lo, hi = ax.get_ylim() if axis == "y" else ax.get_xlim()
    lo, hi = min(lo, hi), max(lo, hi)
    if not (lo > 0 and np.isfinite(lo) and np.isfinite(hi)):
        return
    span = math.log10(hi / lo)
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    if span >= 3:
        ax_.set_major_locator(LogLocator(base=10, numticks=12))
        ax_.set_major_formatter(LogFormatterSciNotation(base=10))
    elif span >= 1:
        ax_.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0), numticks=12))
        ax_.set_major_formatter(plain)
    else:
        ax_.set_major_locator(MaxNLocator(nbins=5))
        ax_.set_major_formatter(plain)
    ax_.set_minor_locator(LogLocator(base=10, subs=tuple(float(k) for k in range(2, 10)), numticks=12))
    ax_.set_minor_formatter(NullFormatter())


def signed_axis(ax, values, axis: str = "y", linthresh: float = 1.0, linear_below: float = 5.0,
                linscale: float = 1.0, inner: tuple = (), allow_log: bool = True) -> str:
    """An axis chosen from the values it shows, with labelled ticks a reader can read: log (with
    :func:`log_ticks`) when every value is positive (and ``allow_log``); linear when none exceeds
    ``linear_below`` in magnitude; else symmetric-log, linear within +-``linthresh`` (stretched
    to ``linscale`` decades each side), with ticks at 0, +-``inner``, +-``linthresh`` and every
    power of ten beyond, written plainly (-100, -10, -1, 0, 1, 10, 100), never matplotlib's
    default symlog labels. Call it after the last plot on the axes. Returns the scale chosen."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullLocator

    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    ax_ = ax.yaxis if axis == "y" else ax.xaxis
    set_scale = ax.set_yscale if axis == "y" else ax.set_xscale
    plain = FuncFormatter(lambda x, _: f"{x:g}")
    if allow_log and len(v) and (v > 0).all():
        set_scale("log")
        log_ticks(ax, axis)
        return "log"
    big = float(np.abs(v).max()) if len(v) else 0.0
    if big <= linear_below:
        ax_.set_major_locator(MaxNLocator(nbins=6))
        ax_.set_major_formatter(plain)
        return "linear"
    set_scale("symlog", linthresh=linthresh, linscale=linscale)
    lo, hi = ax.get_ylim() if axis == "y" else ax.get_xlim()
    lo, hi = min(lo, hi), max(lo, hi)
    top = max(abs(lo), abs(hi))
    # the decades (10, 100, ...) beyond the threshold, and the threshold itself
    decades = [10.0 ** e for e in range(math.ceil(math.log10(linthresh) + 1e-9), math.ceil(math.log10(top)) + 1)]
    ticks = [0.0] + [sgn * t for t in {*inner, linthresh, *(d for d in decades if d > linthresh)} for sgn in (-1, 1)]
    ax_.set_major_locator(FixedLocator(sorted(t for t in ticks if lo <= t <= hi)))
    ax_.set_major_formatter(plain)
    ax_.set_minor_locator(NullLocator())
    return "symlog"


def short_number(v: float, digits: int = 2) -> str:
    """A cell number in at most six characters with two digits (0.031, 16, 3.8e-6, 1.5e2), four
    with one (0.03, 2e1, 4e-6): no '+' and no leading zero in exponents."""
    if not np.isfinite(v):
        return ""
    if v == 0:
        return "0"
    if 0.01 <= abs(v) < 10 ** digits:
        return f"{v:.{digits}g}"
    m, e = f"{v:.{digits - 1}e}".split("e")
    return f"{m}e{int(e)}"


def annotate_cells(fig, ax, values: np.ndarray, fmt=short_number, fontsize: float = 8.0, dark=None) -> bool:
    """Write each finite cell's value on an imshow heatmap, at ``fontsize``, if every label fits
    its cell at the figure's layout (else nothing is written and False is returned: the caller
    says where the numbers are). ``dark(v)``: cells whose colour is dark get white text."""
    fig.canvas.draw()  # the layout decides the cell size
    bb = ax.get_window_extent()
    nrow, ncol = values.shape
    cw, ch = bb.width / ncol * 72 / fig.dpi, bb.height / nrow * 72 / fig.dpi
    labels = [[fmt(v) for v in row] for row in values]
    longest = max((len(s) for row in labels for s in row), default=0)
    # 0.6 em a character (a conservative mean advance of DejaVu Sans digits) and 1 pt each side
    if longest * 0.6 * fontsize + 2 > cw or fontsize + 2 > ch:
        return False
    for i in range(nrow):
        for j in range(ncol):
            if labels[i][j]:
                ax.text(j, i, labels[i][j], ha="center", va="center", fontsize=fontsize,
                        color="white" if dark is not None and dark(values[i, j]) else "black")
    return True


#: units of the identified parameters that have them: the Nomoto models' K [1/s], time constants [s] and alpha
#: [s^2] (T r' + r + alpha r^3 = K delta with r in rad/s). MMG, Abkowitz and AUV coefficients are
#: non-dimensional (primes): [-].
PARAM_UNITS = {"K": "1/s", "T": "s", "T1": "s", "T2": "s", "T3": "s", "alpha": "s^2"}


def param_label(name: str) -> str:
    """A parameter's axis label with its unit: ``K [1/s]``, ``Xvv [-]``."""
    return f"{name} [{PARAM_UNITS.get(name, '-')}]"


def sampling_label(df) -> str:
    """The sampling interval of the rows a figure shows, in seconds and in the ship's time scale
    L/U0: 'sampled at 0.1 s (0.0082 L/U0)'; a range where vessels or speeds differ; '' for a
    table without the columns."""
    if "m_sample_dt" not in df or not df["m_sample_dt"].notna().any():
        return ""
    s = df["m_sample_dt"].dropna()
    lu = df["m_sample_dt_LU"].dropna() if "m_sample_dt_LU" in df else s.iloc[:0]
    req = df["cfg_noise.sample_dt_LU"].dropna() if "cfg_noise.sample_dt_LU" in df else s.iloc[:0]
    sec = f"{s.min():g} s" if s.min() == s.max() else f"{s.min():g}-{s.max():g} s"
    if req.nunique() == 1:
        return f"sampled at {sec} ({req.iloc[0]:g} L/U0)"
    if len(lu):  # decimation rounds each vessel's interval: within 12 % is one value
        one = lu.max() <= 1.12 * lu.min()
        return f"sampled at {sec} ({lu.median():.2g} L/U0)" if one else \
            f"sampled at {sec} ({lu.min():.2g}-{lu.max():.2g} L/U0)"
    return f"sampled at {sec}"


_UNIT = re.compile(r"\[[^\]]+\]")


_MATH = re.compile(r"\\mathdefault|\\times|[${}^\s]")


def _categorical(labels) -> bool:
    """Tick labels that are names (estimators, h/T classes), not numbers ('0.5',
    '$\\mathdefault{10^{-2}}$')."""
    return any(not re.fullmatch(r"[-+0-9.,eE]*", _MATH.sub("", t.get_text()).replace("\u2212", "-")) for t in labels)


def _labelled_ticks(axis) -> list:
    lo, hi = sorted(axis.get_view_interval())
    span = hi - lo
    out = []
    for ticks in (axis.get_major_ticks(), axis.get_minor_ticks()):
        for t in ticks:
            lab = t.label1 if t.label1.get_visible() else t.label2
            if (t.get_visible() and (t.label1.get_visible() or t.label2.get_visible()) and lab.get_text().strip()
                    and lo - 1e-9 * span <= t.get_loc() <= hi + 1e-9 * span):
                out.append(lab)
    return out


def readability_problems(fig, width_in: float = PRINT_WIDTH_IN, min_pt: float = MIN_FONT_PT) -> list[str]:
    """What keeps a figure from print: any text below ``min_pt`` at the printed size (the figure
    scaled to at most ``width_in``), an axis with tick labels but no label, a numeric axis whose
    label has no unit in brackets ('[m/s]', '[-]' when non-dimensional; categorical axes need a
    label only), a log axis with fewer than three labelled ticks. The figure is drawn first (tick
    labels exist only then)."""
    fig.canvas.draw()
    scale = min(1.0, width_in / fig.get_size_inches()[0])
    problems = []

    def small(t, where):
        if t.get_visible() and t.get_text().strip() and t.get_fontsize() * scale < min_pt - 1e-6:
            problems.append(f"{where}: text {t.get_text()[:30]!r} is {t.get_fontsize() * scale:.1f} pt in print")

    for t in fig.texts:
        small(t, "figure")
    for leg in fig.legends:
        for t in leg.get_texts() + [leg.get_title()]:
            small(t, "figure legend")
    for k, ax in enumerate(fig.axes):
        if not ax.get_visible() or not ax.axison:
            continue
        name = f"axes {k} ({ax.get_title() or ax.get_label() or 'untitled'})"[:80]
        for t in (ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label, *ax.texts):
            small(t, name)
        if ax.get_legend() is not None:
            for t in ax.get_legend().get_texts() + [ax.get_legend().get_title()]:
                small(t, name + " legend")
        for axis, which in ((ax.xaxis, "x"), (ax.yaxis, "y")):
            labs = _labelled_ticks(axis)
            for t in labs:
                small(t, f"{name} {which} ticks")
            if not labs:
                continue
            label = axis.get_label_text().strip()
            sup = getattr(fig, f"_sup{which}label", None)
            if not label and sup is not None and sup.get_text().strip():
                label = sup.get_text().strip()
            if not label:
                problems.append(f"{name}: the {which} axis has tick labels but no label")
            elif not _categorical(labs) and not _UNIT.search(label):
                problems.append(f"{name}: the {which} axis label {label!r} names no unit ([...], [-] if none)")
            if axis.get_scale() in ("log", "symlog") and len(labs) < 3:
                problems.append(f"{name}: the log {which} axis has {len(labs)} labelled ticks (fewer than 3)")
    return problems
