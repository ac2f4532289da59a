"""The model doctor's report as one self-contained HTML5 page, rendered from the Jinja2 templates of
``templates/``.

:func:`render_html` turns the report dict written to ``report.json`` (see :mod:`.report`) and the
figures' PNG bytes into a page that needs nothing else: the style sheet (``templates/report.css``)
inline, images as ``data:`` URIs, no JavaScript, and a Content-Security-Policy that forbids the
browser any request (so nothing can leak from, or be fetched by, a report that is mailed around).
The templates escape every string (record names come from users' files). The report is read once
into the page's view data (:mod:`.html_view`): an optional key the report does not have leaves its
section out.

Layout, for a naval architect reading on a laptop or on A4 paper: the verdict at the top (a diverged
baseline is its own warning headline, and any other diverged replay gets a warning box under it),
the direction conventions, the error ladder, the ranked candidate effects (``<table id="ranking">``,
one ``<tr class="candidate">`` each), the per-record errors, the manoeuvres in the ship's terms, how
far the predictions can be trusted, which coefficients the records determine, the figures grouped by
section, the worst windows, the catalogue of effects, the notes, what was trained and validated on
(with the parameters), the definitions and the provenance (package version, git revision, command
line, date, each record's sha256). A table of contents under the verdict links to every section: it
is built from the sections on the page, so each of its links has its
anchor.

Rules the page keeps:

- every parameter is shown with its unit (the report's ``units``);
- every error figure is defined where it appears: a short footnote under each table from the
  report's
  ``definitions``;
- a diverged replay (``validation_error`` infinite, or named in a ``diverged`` list) is shown as
  *diverged*, never as a number or a percentage; ``inf`` is never printed;
- a figure's caption does not describe what the figure does not show (no "blue" curve when no effect
  was added, no "hatched" step when none was rejected).
"""
from __future__ import annotations

from collections.abc import Mapping
from functools import cache
from importlib import resources

from markupsafe import Markup

from .html_format import fmt_num, fmt_pct
from .html_view import metric_rows, view
from .report_schema import Report

__all__ = ["fmt_num", "fmt_pct", "metrics_table_html", "render_html"]

# the page may load nothing from anywhere: images are data: URIs, styles inline, no scripts at all
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'; base-uri 'none'; form-action 'none'"


@cache
def environment():
    """The templates' environment: HTML autoescaped, the templates read from the package (so an
    installed package renders as a checkout does)."""
    from jinja2 import Environment, PackageLoader, StrictUndefined, select_autoescape

    return Environment(loader=PackageLoader("study.doctor", "templates"),
                       autoescape=select_autoescape(["html", "html.j2"], default_for_string=True),
                       undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)


@cache
def _css():
    # the package's own style sheet, trusted: inlined as it is
    return Markup(resources.files("study.doctor").joinpath("templates", "report.css").read_text(encoding="utf-8"))


def render_html(report: Report | dict, figures: Mapping[str, bytes] | None = None) -> str:
    """The self-contained HTML5 page of a doctor's report.

    ``report`` is a :class:`.report_schema.Report`, or the dict of a ``report.json`` (read by
    :meth:`.report_schema.Report.from_dict`, which refuses one off the schema); ``figures`` maps a
    figure's file name (as in ``report.figures[i]["file"]``) to its PNG bytes, embedded as data
    URIs.
    """
    page = environment().get_template("report.html.j2")
    return page.render(**view(Report.from_dict(report), figures), css=_css(), csp=Markup(CSP))  # both the package's own


def metrics_table_html(rows: list[dict]) -> str:
    """A small self-contained HTML ``<table class="maneuver-metrics">`` of
    ``study.records.maneuver_metrics.maneuver_metrics`` rows: record, metric (its definition as a
    tooltip), unit, measured, baseline, final (with its 90 % interval under it when the row has
    one); numbers to 4 significant digits, NaN as ``n/a``; every string escaped. No rows: a table
    with one row saying so."""
    rows = [r for r in rows or [] if isinstance(r, dict)]
    table = environment().get_template("maneuver_metrics.html.j2").module.metrics_table(metric_rows(rows))
    return str(table).strip()
