"""The model doctor's HTML report (study/doctor/html.py): a self-contained page, every string escaped, every
figure embedded, robust to missing keys; and, in a real headless Chromium (Debian's ``chromium`` and
``chromium-driver``, driven by Selenium), the figures and the ranking actually render.

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
        "created_by": "study.diagnose 0.1.0",
        "vessel": "kvlcc2",
        "model": "mmg_hull",
        "structure": "output_error",
        "mode": "held_out",
        "train": ["zz10_stbd", EVIL],
        "validate": ["zz20_port", "tc35_stbd & pull-out"],
        "baseline": {"validation_error": 0.8, "training_error": 0.6,
                     "parameters": {"X_vv": -0.0401234567, "Y_v": -0.315123, "N_r": -0.0499999}},
        "ranking": [
            {"effect": "current", "validation_error": 0.304, "improvement": 0.62, "significant": True,
             "p_value": 0.0002, "parameters": {"u_c": 0.41234567, "psi_c": 0.523598}, "note": "steady, uniform"},
            {"effect": "wind", "validation_error": 0.61, "improvement": 0.2375, "significant": True,
             "p_value": 0.012, "parameters": {"C_wind": 1.234567e-05}, "note": ""},
            {"effect": "shallow_water", "validation_error": 0.79, "improvement": 0.0125, "significant": False,
             "p_value": None, "parameters": {"h_T": float("nan")}, "note": "h/T bounded to [1.2, 10]"},
            {"effect": "yaw_bias", "validation_error": float("nan"), "improvement": float("nan"),
             "significant": False, "p_value": float("nan"), "parameters": {}, "note": EVIL},
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
             "parameters": "u_c, psi_c", "enters": "kinematics (ground = water + current)",
             "source": "Fossen (2021), 10.3"},
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


@pytest.mark.parametrize("key", list(_report()))
def test_any_key_may_be_missing(key, figures):
    rep = _report()
    del rep[key]
    page = render_html(rep, figures)
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert "could not be rendered" not in page


@pytest.mark.parametrize("report", [
    {}, None,
    {k: None for k in _report()},
    {k: [] for k in _report()},
    {k: {} for k in _report()},
    {"ranking": [{}], "ladder": [{}], "errors_table": [{}], "worst_windows": [{}], "catalogue": [{}],
     "figures": [{}], "baseline": {"parameters": {"a": None}}},
    {"ranking": ["current", 3], "ladder": "baseline", "train": "zz10", "figures": [{"file": "absent.png"}]},
], ids=["empty", "none", "all-none", "all-lists", "all-dicts", "empty-entries", "odd-types"])
def test_empty_or_odd_reports_do_not_crash(report):
    page = render_html(report, {})
    assert page.startswith("<!DOCTYPE html>") and "</html>" in page
    assert "<img" not in page


def test_missing_and_unlisted_figures(figures):
    rep = _report()
    figs = dict(figures)
    del figs["ladder.png"]  # listed but absent -> a note, not a broken image
    figs["extra.png"] = figures["ladder.png"]  # present but unlisted -> still shown
    page = render_html(rep, figs)
    assert "Figure file ladder.png is missing." in page
    assert 'data-file="extra.png"' in page
    assert len(_parse(page).imgs) == 3


# --------------------------------------------------------------------------------------------- in Chromium

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
