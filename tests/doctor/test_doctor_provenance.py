"""The doctor's report finds its way and says where it came from: a table of contents whose every link has its
anchor on the page, and provenance (package version, git revision, command line, date, each record's sha256) in
report.json and report.html; beside each candidate's NRMSE its effect on the validation manoeuvres' metrics, and a
candidate that lowers the NRMSE but worsens the metrics says so. A small real run: 60 s records read from files, one candidate."""
import hashlib
import json
import re

import pytest

from study.doctor.diagnose import Doctor, Options
from study.doctor.report import write_report
from study.doctor.html import render_html
from study.records.schema import Record, read_record, write_record

from test_doctor import KNOWN, VESSEL, records


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("prov")
    train, val = records([{"name": "yaw_bias", "Y": 0.0, "N": 5e-4}], duration=60.0)
    files = []
    for role, dfs in (("train", train), ("val", val)):
        for i, df in enumerate(dfs):
            p = write_record(Record(data=df, meta={"name": f"{role}{i}", "facility": "basin"}), tmp / f"{role}{i}.csv")
            files.append(p)
    recs = [read_record(p) for p in files]
    d = Doctor(VESSEL, KNOWN, recs[:3], recs[3:], Options(candidates=("yaw_bias", "wind")))
    d.run()
    rep = write_report(d, tmp / "report", "kvlcc2_l7", "known")
    return tmp, files, rep, d


def test_report_json_has_provenance_with_each_records_sha256(written):
    tmp, files, _, _ = written
    rep = json.loads((tmp / "report" / "report.json").read_text())
    p = rep["provenance"]
    assert p["package"] == "study" and p["version"]
    assert re.fullmatch(r"[0-9a-f]{40}", p["revision"]) and isinstance(p["modified"], bool)
    assert p["command"] and re.match(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00$", p["date"])
    got = {r["path"]: r for r in p["records"]}
    assert len(got) == len(files) == 5
    for f in files:
        assert got[str(f)]["sha256"] == hashlib.sha256(f.read_bytes()).hexdigest()
        assert got[str(f)]["sha256_of"] == "file"
    assert [r["role"] for r in p["records"]] == ["train"] * 3 + ["validate"] * 2
    # the report as written follows its schema, and reads back to the dict write_report returned
    from study.doctor.report_schema import Report

    assert Report.from_dict(rep).to_json() == (tmp / "report" / "report.json").read_text()
    assert list(written[2]) == list(rep)


def test_report_html_has_a_toc_whose_anchors_exist_and_the_provenance(written):
    tmp, files, _, _ = written
    page = (tmp / "report" / "report.html").read_text()
    toc = re.search(r'<nav id="contents".*?</nav>', page, re.S).group(0)
    links = re.findall(r'href="#([^"]+)"', toc)
    ids = set(re.findall(r'\sid="([^"]+)"', page))
    assert len(links) >= 8 and links[0] == "verdict"
    assert {"candidates", "notes", "provenance", "definitions"} <= set(links)
    assert not [a for a in links if a not in ids]
    assert page.index('id="contents"') < page.index('id="candidates"')  # near the top
    prov = page[page.index('<section id="provenance"'):]
    for f in files:
        assert hashlib.sha256(f.read_bytes()).hexdigest() in prov


def test_the_basins_wind_and_the_setup_effect_are_in_the_report(written):
    _, _, rep, _ = written
    assert rep["facilities"] == {"train0": "basin", "train1": "basin", "train2": "basin", "val0": "basin",
                                 "val1": "basin"}
    assert "indoors" in rep["not_applicable"]["wind"]
    assert rep["missing_effect"] == "yaw_bias"  # the same basin: the bias stays in the prediction
    assert rep["setup_effects"]["effects"] == ["yaw_bias"] and rep["setup_effects"]["left_out"] == {}


def test_the_provenance_is_escaped_and_an_odd_one_refused():
    from study.doctor.report_schema import ReportError
    from test_doctor_html import _minimal

    prov = {"package": "study", "version": None, "revision": None, "modified": None, "date": "2024-01-01T00:00:00",
            "command": "python -m study diagnose train=<a>", "records": []}
    page = render_html(_minimal(provenance=prov))
    assert "train=&lt;a&gt;" in page and 'href="#provenance"' in page
    with pytest.raises(ReportError, match=r"'provenance'\['records'\]\[0\] is an int, not an object"):
        render_html(_minimal(provenance=dict(prov, records=[1, None])))
    empty = render_html(_minimal())
    ids = set(re.findall(r'\sid="([^"]+)"', empty))
    assert set(re.findall(r'href="#([^"]+)"', empty)) <= ids


def test_each_candidate_has_its_manoeuvre_metrics_beside_its_nrmse(written):
    tmp, _, rep, _ = written
    row = next(r for r in rep["ranking"] if r["effect"] == "yaw_bias")
    m = row["metrics"]  # the hidden bias found: the turn's and the zigzag's metrics come closer
    assert m["n"] >= 4 and m["error"] < m["baseline_error"]
    assert "worsens" not in row["note"]
    page = (tmp / "report" / "report.html").read_text()
    assert "Manoeuvre metrics error" in page and f"baseline {100 * m['baseline_error']:.1f} %" in page


def test_a_candidate_that_lowers_the_nrmse_but_worsens_the_metrics_says_so(written, monkeypatch):
    import copy

    import study.records.maneuver_metrics as mmod
    from study.doctor.report import candidate_metrics, manoeuvre_predictions, predictions

    _, _, rep, d = written
    rep = copy.deepcopy(rep)
    row = next(r for r in rep["ranking"] if r["effect"] == "yaw_bias")
    assert row["improvement"] > 0
    rep["ranking"] = [dict(row, note="")]

    def worse(name, measured, baseline, final, L):  # the candidate's replay further from the measurement
        return [{"record": name, "metric": "tactical_diameter", "unit": "m", "measured": 10.0, "baseline": 10.5,
                 "final": 12.0}]

    monkeypatch.setattr(mmod, "maneuver_metrics", worse)
    meas = dict(zip(d.val_names, d.val_df))
    candidate_metrics(d, rep, meas, manoeuvre_predictions(d, d.result["base"], predictions(d, d.result["base"])))
    r = rep["ranking"][0]
    assert r["metrics_worse"] and r["metrics"]["error"] == pytest.approx(0.2)
    assert "lowers the NRMSE but worsens the manoeuvre metrics (mean relative error 5.0 % -> 20.0 %" in r["note"]


def test_the_metrics_measured_against_their_intervals_are_a_figure_of_the_report(written):
    tmp, _, rep, _ = written
    listed = {f["file"]: f for f in rep["figures"]}
    assert listed["metric_intervals.png"]["section"] == "intervals"
    assert (tmp / "report" / "figures" / "metric_intervals.png").read_bytes().startswith(b"\x89PNG")
    assert "Manoeuvre metrics and their intervals" in (tmp / "report" / "report.html").read_text()


def test_the_interval_figure_needs_a_measured_value_and_an_interval():
    from study.doctor import plots

    row = {"record": "turn", "metric": "tactical_diameter_L", "measured": 3.1, "final": 3.3, "final_low": 3.0,
           "final_high": 3.6}
    assert plots.metric_intervals([row]).startswith(b"\x89PNG")
    assert plots.metric_intervals([{**row, "final_low": float("nan")}]) is None
    assert plots.metric_intervals([{**row, "metric": "steady_turning_rate"}]) is None
    assert plots.metric_intervals([]) is None
