"""The model doctor's HTML report (study/doctor/html.py and its templates): a self-contained page, every string
escaped, every figure embedded, an optional key of the report missing leaves its section out and a report off the
schema is refused in one line, every link of its contents to an anchor on the page; and,
in a real headless Chromium (Debian's ``chromium`` and ``chromium-driver``, driven by Selenium), the figures and
the ranking actually render.

The browser test is skipped when Chromium, chromedriver or Selenium is missing, unless STUDY_REQUIRE_BROWSER=1
(set by .ci/run once it has installed them), in which case it fails instead of silently skipping."""
from __future__ import annotations

import base64
import io
import math
import struct
from html.parser import HTMLParser

import pytest

from study.doctor.html import fmt_num, fmt_pct, render_html
from study.doctor.report_schema import Report, ReportError

EVIL = "<script>alert(1)</script>"
EVIL_ESC = "&lt;script&gt;alert(1)&lt;/script&gt;"


# --------------------------------------------------------------------------------------------- fixtures


def _png(kind: str, w_in: float, h_in: float) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(w_in, h_in), dpi=60)
    t = np.linspace(0.0, 100.0, 200)
    if kind == "compare":
        ax.plot(t, 20 * np.sin(t / 8), label="measured")
        ax.plot(t, 18 * np.sin(t / 8 + 0.2), "--", label="model")
        ax.legend()
    elif kind == "residuals":
        ax.plot(t, np.cos(t / 3) * np.exp(-t / 80))
    else:
        ax.bar(["baseline", "+current", "+wind"], [1.0, 0.38, 0.35])
    ax.set_title(kind)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def figures() -> dict[str, bytes]:
    return {
        "compare_zz1.png": _png("compare", 4.0, 2.5),
        "residuals_zz1.png": _png("residuals", 4.0, 2.0),
        "ladder.png": _png("ladder", 3.0, 2.0),
    }


def _report() -> dict:
    return {
        "title": "Model doctor: KVLCC2 MMG hull against free-running records",
        "verdict": ("The model misses a steady current (0.4 m/s from 030 deg); adding it cuts the validation "
                    "error by 62 %."),
        "created_by": "python -m study diagnose",
        "vessel": "kvlcc2",
        "model": "mmg_hull",
        "structure": "output_error",
        "mode": "held_out",
        "train": ["zz10_stbd", EVIL],
        "validate": ["zz20_port", "tc35_stbd & pull-out"],
        "baseline": {"validation_error": 0.8, "training_error": 0.6, "effects": [], "diverged": [], "errors": {},
                     "parameters": {"X_vv": -0.0401234567, "Y_v": -0.315123, "N_r": -0.0499999}},
        "ranking": [
            {"effect": "current", "validation_error": 0.304, "improvement": 0.62, "significant": True,
             "p_value": 0.0002, "parameters": {"u_c": 0.41234567, "psi_c": 0.523598}, "training_error": 0.25,
             "note": "steady, uniform"},
            {"effect": "wind", "validation_error": 0.61, "improvement": 0.2375, "significant": True,
             "p_value": 0.012, "parameters": {"C_wind": 1.234567e-05}, "training_error": 0.5, "note": ""},
            {"effect": "shallow_water", "validation_error": 0.79, "improvement": 0.0125, "significant": False,
             "p_value": None, "parameters": {"h_T": float("nan")}, "training_error": 0.6,
             "note": "h/T bounded to [1.2, 10]"},
            {"effect": "yaw_bias", "validation_error": float("nan"), "improvement": float("nan"),
             "significant": False, "p_value": float("nan"), "parameters": {}, "training_error": 0.6, "note": EVIL},
        ],
        "missing_effect": "current",
        "ambiguous": [],
        "ladder": [
            {"step": "baseline", "effects": [], "validation_error": 0.8, "training_error": 0.6},
            {"step": "+ current", "effects": ["current"], "validation_error": 0.304, "training_error": 0.25},
            {"step": "+ wind", "effects": ["current", "wind"], "validation_error": 0.30, "training_error": 0.24},
        ],
        "errors_table": [
            {"record": EVIL, "channel": "psi", "unit": "rad", "baseline_rmse": 0.12, "final_rmse": 0.031,
             "baseline_nrmse": 0.4, "final_nrmse": 0.1},
            {"record": "zz20_port", "channel": "r", "unit": "rad/s", "baseline_rmse": None, "final_rmse": 0.002,
             "baseline_nrmse": float("nan"), "final_nrmse": 0.05},
        ],
        "worst_windows": [{"record": "zz20_port", "t_start": 120.0, "t_end": 180.5, "nrmse": 0.91}],
        "catalogue": [
            {"name": "current", "physics": "uniform steady current; the hull sees the relative velocity",
             "parameters": "u_c [m/s], psi_c [rad (towards, clockwise from north)]",
             "enters": "kinematics (ground = water + current)", "source": "Fossen (2021), 10.3", "applies": "yes"},
            {"name": "hull_nonlinear", "physics": "higher-order hull terms", "parameters": "none",
             "enters": "extra coefficients", "source": "Abkowitz (1964)",
             "applies": "the model already identifies every nonlinear hull term"},
        ],
        "units": {"u_c": "m/s", "psi_c": "rad (towards, clockwise from north)", "C_wind": "- (C / 0.5 rho A U^2)",
                  "h_T": "- (water depth / draft)", "X_vv": "- (non-dimensional)", "Y_v": "- (non-dimensional)",
                  "N_r": "- (non-dimensional)"},
        "conventions": "Body axes x forward, y starboard; heading psi clockwise from north",
        "definitions": {"NRMSE": "RMS error over the spread of the measured channel",
                        "validation error": "the mean NRMSE over the validation records",
                        "training error": "the equation-error misfit on the training records",
                        "improvement": "the relative fall of the validation error",
                        "diverged": "a replay that leaves the envelope",
                        "track error": "RMS distance between replayed and measured positions"},
        "stability": [{"step": 1, "k": 3, "n": 4, "text": "current: named in 3 of 4", "outcomes": []}],
        "diverged": {"baseline": []},
        "final": {"effects": ["current", "wind"], "validation_error": 0.30, "diverged": [], "errors": {},
                  "parameters": {"X_vv": -0.041, "u_c": 0.41, "C_wind": 1.2e-05}},
        "seconds": 12.5,
        "not_applicable": {"hull_nonlinear": "the model already identifies every nonlinear hull term"},
        "depths_h_T": {"zz10_stbd": None, "zz20_port": 2.5},
        "maneuver_metrics": [
            {"record": "zz20_port", "metric": "first_overshoot", "unit": "deg", "measured": 8.03,
             "baseline": 11.7, "final": 8.31},
            {"record": "zz20_port", "metric": "second_overshoot", "unit": "deg", "measured": 15.3,
             "baseline": float("nan"), "final": 14.3},
        ],
        "notes": ["Records resampled to 1 Hz.", "A & B < C"],
        "figures": [
            {"file": "compare_zz1.png", "title": "Heading, zz10", "caption": "measured vs baseline",
             "section": "compare"},
            {"file": "ladder.png", "title": "Error ladder", "caption": "validation error per step",
             "section": "ladder"},
            {"file": "residuals_zz1.png", "title": "Residuals " + EVIL, "caption": "yaw rate residual",
             "section": "residuals"},
        ],
    }


def _minimal(**keys) -> dict:
    """A report with only its required keys (each as empty as it can be), and ``keys``."""
    base = {"validation_error": 0.5, "training_error": 0.4, "effects": [], "parameters": {}, "errors": {}}
    return {"verdict": "No significant missing effect", "baseline": base, "ranking": [], "missing_effect": None,
            "ambiguous": [], "ladder": [], "final": dict(base), "errors_table": [], "notes": [], "mode": "given",
            "train": [], "validate": [], "seconds": 1.0, "title": "", "created_by": "", "vessel": "", "model": "",
            "structure": "", "worst_windows": [], "catalogue": [], "figures": [], **keys}


class _Tree(HTMLParser):
    """The few facts the tests need from a page: images, elements by id, rows of the ranking, links."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.imgs: list[dict] = []
        self.ids: list[str] = []
        self.tags: list[tuple[str, dict]] = []
        self.candidate_rows_in_ranking = 0
        self._stack: list[tuple[str, dict]] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append((tag, a))
        if "id" in a:
            self.ids.append(a["id"])
        if tag == "img":
            self.imgs.append(a)
        if (tag == "tr" and "candidate" in (a.get("class") or "").split()
                and any(t == "table" and x.get("id") == "ranking" for t, x in self._stack)):
            self.candidate_rows_in_ranking += 1
        if tag not in {"img", "meta", "br", "link", "input", "hr"}:
            self._stack.append((tag, a))

    def handle_endtag(self, tag):
        for i in range(len(self._stack) - 1, -1, -1):
            if self._stack[i][0] == tag:
                del self._stack[i:]
                break


def _parse(page: str) -> _Tree:
    t = _Tree()
    t.feed(page)
    t.close()
    return t


# --------------------------------------------------------------------------------------------- unit tests


def test_every_figure_is_a_data_uri(figures):
    page = render_html(_report(), figures)
    tree = _parse(page)
    assert len(tree.imgs) == len(figures)
    for name, data in figures.items():
        assert f"data:image/png;base64,{base64.b64encode(data).decode('ascii')}" in page, name
    for img in tree.imgs:
        assert img["src"].startswith("data:image/png;base64,")
        assert img.get("alt", "").strip(), "every image needs a meaningful alt"
    # inside <figure> with a <figcaption>, in section order: compare, residuals, ..., ladder
    assert page.count("<figure") == len(figures) and page.count("<figcaption>") == len(figures)
    order = [page.index(f'data-file="{f}"') for f in ("compare_zz1.png", "residuals_zz1.png", "ladder.png")]
    assert order == sorted(order)


def test_self_contained_no_external_requests(figures):
    page = render_html(_report(), figures)
    tree = _parse(page)
    for tag, a in tree.tags:
        assert tag not in {"script", "link", "iframe", "object", "embed"}, tag
        for attr in ("src", "href", "srcset", "action", "data"):
            if attr in a:
                assert a[attr].startswith(("data:", "#")), (tag, attr, a[attr][:80])
    assert "http://" not in page and "https://" not in page
    assert "@import" not in page and "url(" not in page
    assert page.startswith("<!DOCTYPE html>")


def test_strings_are_escaped(figures):
    page = render_html(_report(), figures)
    assert "<script" not in page.lower()
    assert EVIL_ESC in page
    assert "A &amp; B &lt; C" in page
    tree = _parse(page)
    assert not any(t == "script" for t, _ in tree.tags)
    # alt attributes are escaped too: the parser reads back the original text
    assert any(img["alt"] == "Residuals " + EVIL for img in tree.imgs)


def test_ranking_has_one_row_per_candidate(figures):
    rep = _report()
    page = render_html(rep, figures)
    tree = _parse(page)
    assert tree.ids.count("ranking") == 1
    assert tree.candidate_rows_in_ranking == len(rep["ranking"])
    assert page.count('class="candidate significant') == 2  # current and wind
    # improvements as %, parameters with 4 significant digits, NaN/None as n/a
    assert "62.0 %" in page and "23.8 %" in page
    assert "u_c&nbsp;=&nbsp;0.4123" in page and "C_wind&nbsp;=&nbsp;1.235e-05" in page
    assert "h_T&nbsp;=&nbsp;n/a" in page
    assert "0.41234567" not in page


def test_verdict_at_the_top(figures):
    rep = _report()
    page = render_html(rep, figures)
    assert "adding it cuts the validation error by 62 %" in page
    assert '<strong class="missing">current</strong>' in page
    # verdict, then ladder, then ranking, then the per-record errors, then figures
    idx = [page.index(s) for s in ('id="verdict"', 'id="ladder"', 'id="ranking"', 'id="errors"', 'id="figures"',
                                   'id="worst"', 'id="catalogue"', 'id="notes"', 'id="data"')]
    assert idx == sorted(idx)

    none = dict(rep, missing_effect=None, ambiguous=[])
    assert "No significant missing effect" in render_html(none, {})
    amb = dict(rep, missing_effect=None, ambiguous=["wind", "current"])
    p = render_html(amb, {})
    assert "Ambiguous" in p and "<strong>wind</strong>" in p and "<strong>current</strong>" in p


def test_ladder_fall_relative_to_baseline(figures):
    page = render_html(_report(), figures)
    ladder = page[page.index('id="ladder"'):page.index('id="candidates"')]
    # (0.8 - 0.304) / 0.8 = 62.0 %, (0.8 - 0.30) / 0.8 = 62.5 %, the baseline itself 0.0 %
    assert "0.0 %" in ladder and "62.0 %" in ladder and "62.5 %" in ladder
    assert "current, wind" in ladder


def test_number_formatting():
    assert fmt_num(float("nan")) == "n/a" and fmt_num(None) == "n/a" and fmt_num("abc") == "n/a"
    assert fmt_num(True) == "n/a"
    assert fmt_num(0.123456) == "0.1235" and fmt_num(-1234.5678) == "-1235" and fmt_num(1.5e-7) == "1.5e-07"
    assert fmt_num(math.inf) == "inf"
    assert fmt_pct(0.62) == "62.0 %" and fmt_pct(None) == "n/a" and fmt_pct(float("nan")) == "n/a"
    np = pytest.importorskip("numpy")
    assert fmt_num(np.float32(0.5)) == "0.5" and fmt_num(np.float64("nan")) == "n/a"


OPTIONAL = [k for k, v in Report.__dataclass_fields__.items() if v.default is None]


@pytest.mark.parametrize("key", list(_report()))
def test_an_optional_key_may_be_missing_a_required_one_is_refused_by_name(key, figures):
    rep = _report()
    del rep[key]
    if key in OPTIONAL:
        page = render_html(rep, figures)
        assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    else:
        with pytest.raises(ReportError, match=f"^the doctor's report has no key '{key}' \\(required\\)$"):
            render_html(rep, figures)


def test_a_minimal_report_renders():
    page = render_html(_minimal(), {})
    assert page.startswith("<!DOCTYPE html>") and "</html>" in page
    assert "<img" not in page


@pytest.mark.parametrize("report, where", [
    ({}, "has no key 'verdict'"), (None, "is a NoneType, not a JSON object"),
    (_minimal(ranking=["current", 3]), "'ranking'[0] is a str, not an object"),
    (_minimal(ladder="baseline"), "'ladder' is a str, not a list"),
    (_minimal(train="zz10"), "'train' is a str, not a list"),
    (_minimal(figures=[{"file": "absent.png"}]), "'figures'[0] has no key 'title'"),
    (_minimal(ranking=[{}]), "'ranking'[0] has no key 'effect'"),
    (_minimal(notes=[None]), "'notes'[0] is null, not a str"),
    (_minimal(units=[]), "'units' is a list, not an object or null"),
    (_minimal(provenance={"command": "x", "records": [1, None]}), "'provenance' has no key 'package'"),
], ids=["empty", "none", "ranking-names", "ladder-text", "train-text", "figure-untitled", "empty-row",
        "null-note", "units-list", "odd-provenance"])
def test_a_report_off_the_schema_is_refused_in_one_line_naming_the_key(report, where):
    with pytest.raises(ReportError) as e:
        render_html(report, {})
    assert where in str(e.value) and "\n" not in str(e.value)


def test_missing_and_unlisted_figures(figures):
    rep = _report()
    figs = dict(figures)
    del figs["ladder.png"]  # listed but absent -> a note, not a broken image
    figs["extra.png"] = figures["ladder.png"]  # present but unlisted -> still shown
    page = render_html(rep, figs)
    assert "Figure file ladder.png is missing." in page
    assert 'data-file="extra.png"' in page
    assert len(_parse(page).imgs) == 3


# --------------------------------------------------------------------------------------------- the rules


def _section_html(page: str, sid: str) -> str:
    """The HTML of ``<section id=sid>`` (up to its closing tag)."""
    i = page.index(f'<section id="{sid}"')
    return page[i:page.index("</section>", i)]


def _visible_text(page: str) -> str:
    """The page without its style sheet and its images' data (where "inf" could occur by chance)."""
    import re

    page = re.sub(r"<style>.*?</style>", "", page, flags=re.S)
    return re.sub(r'src="data:[^"]*"', "", page)


def _diverged_report() -> dict:
    """The baseline diverges on zz20_port: no validation error (inf in the JSON), no improvement, no verdict."""
    rep = _report()
    inf = float("inf")
    rep["verdict"] = ("Diverged: the baseline model diverges when replayed through 1 of 2 validation record(s) "
                      "(zz20_port); no missing effect can be named")
    rep["missing_effect"] = None
    rep["baseline"] = dict(rep["baseline"], validation_error=inf, diverged=["zz20_port"])
    rep["final"] = dict(rep["final"], effects=[], validation_error=inf, diverged=["zz20_port"])
    rep["diverged"] = {"baseline": ["zz20_port"]}
    rep["ladder"] = [{"step": "baseline", "effects": [], "validation_error": inf, "training_error": 0.6,
                      "diverged": ["zz20_port"]}]
    rep["stability"] = []
    for c in rep["ranking"]:
        c.update(improvement=None, significant=False, p_value=None, diverged=False, diverged_records=[])
    rep["ranking"][1].update(validation_error=inf, diverged=True, diverged_records=["zz10_stbd"])
    rep["errors_table"] = [
        {"record": "zz20_port", "channel": "r", "unit": "rad/s", "baseline_rmse": inf, "final_rmse": inf,
         "baseline_nrmse": inf, "final_nrmse": inf, "baseline_diverged": True, "final_diverged": True},
        {"record": "zz10_stbd", "channel": "r", "unit": "rad/s", "baseline_rmse": 0.01, "final_rmse": 0.01,
         "baseline_nrmse": 0.3, "final_nrmse": 0.3, "baseline_diverged": False, "final_diverged": False},
    ]
    for m in rep["maneuver_metrics"]:
        m.update(baseline=float("nan"), final=float("nan"))
    return rep


def test_a_diverged_baseline_is_the_warning_headline_and_never_a_number(figures):
    page = render_html(_diverged_report(), figures)
    tree = _parse(page)
    verdict = next(a for t, a in tree.tags if a.get("id") == "verdict")
    assert verdict["class"].split() == ["verdict", "diverged"] and verdict["role"] == "alert"
    head = page[page.index('id="verdict"'):page.index("</div>", page.index('id="verdict"'))]
    assert "<strong class=\"diverged-word\">DIVERGED</strong>" in head and "zz20_port" in head
    assert page.index('id="verdict"') < page.index('id="ladder"')
    # the baseline's validation error, its fall and the improvements: "diverged" or n/a, never a % or a number
    ladder = _section_html(page, "ladder")
    row = ladder[ladder.index("<tbody>"):ladder.index("</tbody>")]
    assert '<td class="num"><span class="dv">diverged</span></td>' in row  # its validation error
    assert '<td class="num fallcell"><span class="dv">diverged</span></td>' in row  # its fall
    assert "diverged</span> on zz20_port" in row and "%" not in row
    cands = _section_html(page, "candidates")
    assert 'Baseline (no added effect): validation error <span class="dv">diverged</span>' in cands
    table = cands[cands.index('id="ranking"'):cands.index("</table>")]
    assert "%" not in table
    wind = table[table.index(">wind<"):].split("</tr>")[0]  # the candidate that diverges itself
    assert wind.count('<span class="dv">diverged</span>') == 2 and "zz10_stbd" in wind
    errors = _section_html(page, "errors")
    bad = errors[errors.index("<td>zz20_port"):].split("</tr>")[0]
    assert bad.count('<span class="dv">diverged</span>') == 5 and "%" not in bad
    # the manoeuvre metrics of a diverged replay say so too (the measured ones stay)
    man = _section_html(page, "maneuvers")
    assert man.count('<span class="dv">diverged</span>') == 4 and "8.03" in man
    # inf never printed anywhere on the page
    import re

    assert not re.search(r"\binf\b|Infinity", _visible_text(page)), re.findall(r".{40}\binf\b.{20}", page)


def test_diverged_and_rejected_ladder_steps(figures):
    rep = _report()
    rep["ladder"].append({"step": "+ shallow_water", "effects": ["current", "wind", "shallow_water"],
                          "validation_error": float("inf"), "training_error": 0.2, "diverged": ["zz20_port"],
                          "rejected": True, "reason": "diverges on zz20_port"})
    rep["ladder"][2].update(rejected=True, reason="its validation error 0.31 is not below the previous step's 0.304")
    rep["diverged"] = {"baseline": [], "+ shallow_water": ["zz20_port"]}
    page = render_html(rep, figures)
    ladder = _section_html(page, "ladder")
    rows = ladder[ladder.index("<tbody>"):].split("</tr>")
    assert 'class="rejected"' in rows[2] and "is not below the previous step" in rows[2] and "62.5 %" in rows[2]
    assert 'class="rejected diverged-row"' in rows[3] and rows[3].count('<span class="dv">diverged</span>') == 2
    assert "%" not in rows[3]
    assert "<b>rejected</b>" in ladder and "<b>diverged</b>" in ladder  # both terms defined under the table
    # a headline of its own for the diverged step, the verdict (a missing effect) kept
    box = page[page.index('id="divergence"'):page.index("</div>", page.index('id="divergence"'))]
    assert "DIVERGED" in box and "+ shallow_water" in box and "zz20_port" in box
    assert page.index('id="verdict"') < page.index('id="divergence"') < page.index('id="ladder"')
    assert "verdict found" in page
    # the caption of the ladder figure says hatched and marked only when the ladder has such steps
    rep["figures"][1]["caption"] = ("Validation error of the baseline and of each step with an effect added; a "
                                    "rejected step (its error not lower) is hatched, a diverged one marked.")
    assert "hatched" in render_html(rep, figures) and "DIVERGED, with no bar" in render_html(rep, figures)
    plain = _report()
    plain["figures"][1]["caption"] = rep["figures"][1]["caption"]
    cap = render_html(plain, figures)
    assert "Validation error of the baseline and of each step with an effect added." in cap
    assert "hatched" not in cap and "marked" not in cap


def test_units_beside_every_parameter(figures):
    rep = _report()
    page = render_html(rep, figures)
    cands = _section_html(page, "candidates")
    assert 'u_c&nbsp;=&nbsp;0.4123</span> <span class="unit">[m/s]</span>' in cands
    assert 'psi_c&nbsp;=&nbsp;0.5236</span> <span class="unit">[rad]<sup>' in cands
    assert 'C_wind&nbsp;=&nbsp;1.235e-05</span> <span class="unit">[-]<sup>' in cands
    # the long remarks of the units once, as footnotes under the ranking table
    notes = cands[cands.index("</table>"):]
    assert "C / 0.5 rho A U^2" in notes and "towards, clockwise from north" in notes
    # baseline and final parameters side by side, each with its unit
    data = _section_html(page, "data")
    row = data[data.index('<td class="param">u_c</td>'):].split("</tr>")[0]
    assert "0.41" in row and "m/s" in row
    row = data[data.index('<td class="param">X_vv</td>'):].split("</tr>")[0]
    assert "-0.04012" in row and "-0.041" in row and "- (non-dimensional)" in row
    # the catalogue's parameter text keeps its units
    cat = _section_html(page, "catalogue")
    assert 'u_c <span class="unit">[m/s]</span>' in cat
    # and a verdict naming parameters gets their units
    rep["verdict"] = "Missing effect: current (u_c = 0.4123, psi_c = 0.52)"
    v = render_html(rep, figures)
    assert 'u_c = 0.4123 <span class="unit">[m/s]</span>' in v
    # no unit known: no empty brackets
    rep["units"] = {}
    assert "u_c&nbsp;=&nbsp;0.4123</span><br>" in render_html(rep, figures)


def test_definitions_under_each_table_and_conventions_on_top(figures):
    rep = _report()
    page = render_html(rep, figures)
    d = rep["definitions"]
    cands = _section_html(page, "candidates")
    after = cands[cands.index("</table>"):]
    assert d["validation error"] in after and d["improvement"] in after
    assert d["diverged"] not in after  # nothing diverged here: not defined where it is not used
    ladder = _section_html(page, "ladder")
    after = ladder[ladder.index("</table>"):]
    assert d["validation error"] in after and d["training error"] in after
    errors = _section_html(page, "errors")
    after = errors[errors.index("</table>"):]
    assert d["NRMSE"] in after
    assert 'id="definitions"' in page  # and all of them once more at the end
    conv = page.index('id="conventions"')
    assert page.index('id="verdict"') < conv < page.index('id="ladder"')
    assert rep["conventions"] in page[conv:page.index("</p>", conv)]
    # without definitions in the report: none invented, no empty footnote
    del rep["definitions"]
    cands = _section_html(render_html(rep, figures), "candidates")
    assert "<b>validation error</b>" not in cands and "<b>improvement</b>" not in cands
    assert '<ul class="defs"></ul>' not in cands


def test_maneuver_metrics_section(figures):
    page = render_html(_report(), figures)
    assert any(f"Manoeuvres in the ship{q}s terms" in page for q in ("'", "&#x27;", "&#39;"))  # escaped or not
    man = _section_html(page, "maneuvers")
    assert man.count('<table class="maneuver-metrics">') == 1
    assert man.count('<td class="record">zz20_port</td>') == 2
    assert "first_overshoot" in man and "8.03" in man and "11.7" in man and "n/a" in man
    assert "heading change beyond the switch heading" in man  # the metrics defined under the table
    assert page.index('id="errors"') < page.index('id="maneuvers"') < page.index('id="figures"')
    rep = _report()
    rep["maneuver_metrics"] = []
    assert "No turning circle or zigzag" in render_html(rep, figures)


def test_stability_beside_the_verdict_and_in_the_ladder(figures):
    page = render_html(_report(), figures)
    head = page[page.index('id="verdict"'):page.index("</div>", page.index('id="verdict"'))]
    assert "named in 3 of 4 with one validation record left out" in head
    ladder = _section_html(page, "ladder")
    rows = ladder[ladder.index("<tbody>"):].split("</tr>")
    assert "named in 3 of 4" in rows[1] and "named in" not in rows[0] and "named in" not in rows[2]


def test_not_applicable_depths_and_catalogue_applies(figures):
    page = render_html(_report(), figures)
    cands = _section_html(page, "candidates")
    assert "hull_nonlinear" in cands and "the model already identifies every nonlinear hull term" in cands
    cat = _section_html(page, "catalogue")
    assert "<th>Applies here</th>" in cat and "no: the model already identifies" in cat
    data = _section_html(page, "data")
    assert "zz20_port: h/T = 2.5" in data and "zz10_stbd: not given (deep water)" in data


def test_no_caption_for_a_curve_that_is_not_drawn(figures):
    rep = _report()
    rep["final"] = dict(rep["final"], effects=[])  # no effect added: compare plots have no blue curve
    rep["figures"][0]["caption"] = ("Measured (dots), the baseline model (red) and the model with the effects "
                                    "found (blue), replayed open loop.")
    page = render_html(rep, figures)
    assert "blue" not in page and "Measured (dots) and the baseline model (red), replayed open loop." in page
    rep["final"]["effects"] = ["current"]
    assert "the model with the effects found (blue)" in render_html(rep, figures)


def _plot_inputs():
    np = pytest.importorskip("numpy")
    pd = pytest.importorskip("pandas")
    t = np.arange(0.0, 60.0, 0.5)
    meas = pd.DataFrame({"time": t, "u": 1 + 0 * t, "v": 0.1 * np.sin(t / 5), "r": 0.01 * np.cos(t / 5),
                         "psi": 0.1 * np.sin(t / 5), "x0": t, "y0": np.sin(t / 5)})
    steps = [{"step": "baseline", "validation_error": 0.8, "diverged": []},
             {"step": "+ current", "validation_error": 0.3, "diverged": []},
             {"step": "+ wind", "validation_error": 0.35, "diverged": [], "rejected": True},
             {"step": "+ yaw_bias", "validation_error": float("inf"), "diverged": ["zz"], "rejected": True}]
    return np, t, meas, steps


def _texts(fig) -> list[str]:
    out = [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text"))]
    return [x for x in out if x]


def test_figures_show_diverged_and_rejected_steps(monkeypatch):
    """The figures say what diverged and what was rejected, with a legend and a unit on every axis."""
    from study.doctor import plots

    np, t, meas, steps = _plot_inputs()
    monkeypatch.setattr(plots, "_png", lambda fig: fig)  # the figures themselves, to look inside

    fig = plots.ladder(steps)
    texts = _texts(fig)
    assert "DIVERGED" in texts and any("rejected" in x for x in texts)
    bars = [p for p in fig.axes[0].patches if p.get_height() > 0]
    assert len(bars) == 3 and all(np.isfinite(b.get_height()) for b in bars)  # none for the diverged step
    assert [b.get_hatch() for b in bars] == [None, None, "///"]  # the rejected one hatched
    assert fig.axes[0].get_ylim()[1] < 2.0  # scaled to the finite errors, not to inf
    labels = [x.get_text() for x in fig.legends[0].get_texts()]
    assert labels == ["baseline", "effect added (accepted)", "rejected step", "diverged (no error)"]
    assert "[-]" in fig.axes[0].get_ylabel()
    # no rejected or diverged step: the legend does not name them
    labels = [x.get_text() for x in plots.ladder(steps[:2]).legends[0].get_texts()]
    assert labels == ["baseline", "effect added (accepted)"]

    fig = plots.compare("zz", meas, None, None, "baseline", "")
    labels = [x.get_text() for x in fig.legends[0].get_texts()]
    assert labels == ["measured", "baseline: DIVERGED (not drawn)"]  # no "final" curve named when none is drawn
    fig = plots.compare("zz", meas, meas, meas * 1.01, "baseline", "with current")
    assert [x.get_text() for x in fig.legends[0].get_texts()] == ["measured", "baseline", "with current"]
    ylabels = [a.get_ylabel() for a in fig.axes]
    assert "r [deg/s]" in ylabels and "psi [deg]" in ylabels and "u [m/s]" in ylabels
    for ax in fig.axes:  # units on every axis that has a label
        for lab in (ax.get_xlabel(), ax.get_ylabel()):
            assert not lab or ("[" in lab and "]" in lab), lab

    fig = plots.growth([("zz", t, np.full(len(t), np.nan), None)], [])
    assert any("DIVERGED" in x for x in _texts(fig))
    fig = plots.residuals_states([{"record": 0, "name": "zz", "first": True, "time": t, "X": t, "Y": t, "N": t,
                                   "u": t, "r": t}], ("u", "r"))
    assert [a.get_xlabel() for a in fig.axes[-2:]] == ["u [m/s]", "r [deg/s]"]
    assert fig.axes[0].get_ylabel() == "residual X [N]" and fig.legends


@pytest.mark.slow
def test_figures_fit_the_page():
    from study.doctor import plots

    np, t, meas, steps = _plot_inputs()
    res = [{"record": i, "name": f"rec{i}", "first": True, "time": t, "X": t, "Y": t, "N": t, "u": t, "v": t,
            "r": t, "delta": t, "psi": t} for i in range(3)]
    pngs = [plots.ladder(steps), plots.compare("zz", meas, meas, None, "baseline", ""),
            plots.growth([("a", t, t, t), ("b", t, t, None)], []), plots.residuals_time(res),
            plots.residuals_states(res, ("u", "v", "r", "delta", "psi"))]
    for png in pngs:
        w, h = _png_size(png)
        assert 500 < w <= 1100 and 300 < h <= 1100, (w, h)  # about the page's width at 1:1, never tiny


# --------------------------------------------------------------------------------------------- in Chromium

@pytest.mark.slow  # the slow tier: a real browser (Chromium), installed by .ci/run
def test_figures_and_ranking_render_in_chromium(browser, figures, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    rep = _report()
    page = tmp_path / "report.html"
    page.write_text(render_html(rep, figures), encoding="utf-8")
    browser.get(page.as_uri())
    WebDriverWait(browser, 15).until(
        lambda d: d.execute_script("return document.readyState === 'complete' && "
                                   "Array.from(document.images).every(i => i.complete)"))

    imgs = browser.execute_script(
        "return Array.from(document.images).map(i => ({complete: i.complete, w: i.naturalWidth, "
        "h: i.naturalHeight, alt: i.alt, shown: i.getBoundingClientRect().height}))")
    assert len(imgs) == len(figures)
    sizes = sorted(_png_size(d) for d in figures.values())
    assert sorted((i["w"], i["h"]) for i in imgs) == sizes, imgs  # decoded at their true size
    for i in imgs:
        assert i["complete"] is True and i["w"] > 0 and i["shown"] > 0, i
        assert i["alt"], i

    ranking = browser.find_element(By.ID, "ranking")
    assert ranking.is_displayed() and ranking.size["height"] > 0
    rows = browser.find_elements(By.CSS_SELECTOR, "#ranking tr.candidate")
    assert len(rows) == len(rep["ranking"])
    assert all(r.is_displayed() and r.size["height"] > 0 for r in rows)
    assert "current" in rows[0].text and "62.0 %" in rows[0].text

    verdict = browser.find_element(By.ID, "verdict")
    assert verdict.is_displayed() and "current" in verdict.text
    # the verdict is at the top: above the ladder, which is above the ranking
    assert verdict.location["y"] < browser.find_element(By.ID, "ladder").location["y"] < ranking.location["y"]

    # nothing was fetched from anywhere and no script ran (the page has none; CSP would report a violation)
    assert browser.execute_script("return performance.getEntriesByType('resource').length") == 0
    assert browser.execute_script("return document.scripts.length") == 0
    severe = [e for e in browser.get_log("browser") if e.get("level") == "SEVERE"]
    assert not severe, severe

    # still laid out in print (A4): the ranking and the images keep a height
    browser.execute_cdp_cmd("Emulation.setEmulatedMedia", {"media": "print"})
    assert browser.find_element(By.ID, "ranking").size["height"] > 0
    assert browser.execute_script("return Array.from(document.images).every(i => i.getBoundingClientRect().height > 0)")
    browser.execute_cdp_cmd("Emulation.setEmulatedMedia", {"media": ""})


def test_identifiability_section_counts_undetermined_coefficients_and_conflicts_and_escapes_text():
    from study.doctor.html import render_html

    r = {"identifiability": [
        {"coefficient": "Yvvv", "prior": -1.6, "estimate": -2.6, "prior_sd": 0.48, "posterior_sd": 0.37,
         "ratio": 0.78, "moved_prior_sd": -2.1, "sentence": "Yvvv: partly determined"},
        {"coefficient": "Nvvv", "prior": -0.03, "estimate": -0.03, "prior_sd": 0.01, "posterior_sd": 0.0099,
         "ratio": 0.99, "moved_prior_sd": 0.0, "sentence": "Nvvv: NOT determined <b>"},
        {"coefficient": "Nv", "prior": -0.137, "estimate": -0.14, "prior_sd": 0.04, "posterior_sd": 0.001,
         "ratio": 0.03, "moved_prior_sd": -0.1, "sentence": "Nv: determined"}]}
    h = render_html(_minimal(**r))
    sec = h[h.index('id="identifiability"'):]
    sec = sec[:sec.index("</section>")]
    assert "1 of 3 anchored coefficients are not determined" in sec
    assert "1 moved more than two prior sd" in sec
    assert sec.count('class="undetermined"') == 2
    assert "&lt;b&gt;" in sec and "<b>" not in sec.split("<tbody>")[1].split("</tbody>")[0].replace("<b>ratio", "")
    assert 'id="identifiability"' not in render_html(_minimal())


# --------------------------------------------------------------------------------------------- the templates


def _contents(page: str) -> tuple[list[str], set[str]]:
    """The table of contents' link targets, in order, and every id on the page."""
    import re

    toc = page[page.index('<nav id="contents"'):page.index("</nav>")]
    return re.findall(r'href="#([^"]+)"', toc), set(re.findall(r'\sid="([^"]+)"', page))


def test_a_minimal_report_renders_from_the_templates_and_every_contents_link_has_its_anchor():
    from importlib import resources

    from study.doctor.html import environment

    names = set(environment().list_templates())
    assert {"report.html.j2", "verdict.html.j2", "ladder.html.j2", "candidates.html.j2", "provenance.html.j2"} <= names
    rep = _minimal(ladder=[{"step": "baseline", "effects": [], "validation_error": 0.5, "training_error": 0.4}],
                   notes=["a <note>"])
    page = render_html(rep)
    css = resources.files("study.doctor").joinpath("templates", "report.css").read_text(encoding="utf-8")
    assert f"<style>{css}</style>" in page  # the package's style sheet, inlined as it is
    links, ids = _contents(page)
    assert links == ["verdict", "ladder", "candidates", "notes", "data"]
    assert set(links) <= ids and "a &lt;note&gt;" in page
    for sid in links[1:]:  # each section's heading is the contents' entry
        assert page.count(f'<section id="{sid}">') == 1


def test_a_report_without_an_optional_section_still_renders(figures):
    """Each optional part of the report left out (or empty): its section is absent from the page and from the
    contents, every other section is still there, and every link of the contents has its anchor."""
    full = render_html(_report(), figures)
    links_full, _ = _contents(full)
    for key, sid in (("worst_windows", "worst"), ("catalogue", "catalogue"), ("maneuver_metrics", "maneuvers"),
                     ("notes", "notes"), ("errors_table", "errors"), ("definitions", "definitions")):
        rep = _report()
        if key in OPTIONAL:
            del rep[key]
        else:
            rep[key] = []
        page = render_html(rep, figures)
        links, ids = _contents(page)
        assert sid in links_full and sid not in links and f'id="{sid}"' not in page, key
        assert links == [x for x in links_full if x != sid], key
        assert set(links) <= ids, key


def test_every_contents_link_of_the_committed_examples_has_its_anchor():
    import json
    from pathlib import Path

    reports = sorted((Path(__file__).resolve().parents[2] / "paper_figs" / "doctor").glob("*/report.json"))
    if not reports:
        pytest.skip("no committed example report")
    for path in reports:
        page = render_html(json.loads(path.read_text(encoding="utf-8")), {})
        links, ids = _contents(page)
        assert {"verdict", "ladder", "candidates", "provenance"} <= set(links), path
        assert set(links) <= ids, path
