"""The doctor's report schema (study/doctor/report_schema.py): every worked example's report.json reads into a
``Report`` and serialises back to the same keys, order, values and text; a report with a required key missing, an
unknown key or a key of the wrong type is refused with one line naming it; an older report without the keys added
since reads and writes back without them."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from study.doctor.report_schema import Report, ReportError

EXAMPLES = sorted((Path(__file__).resolve().parents[2] / "paper_figs" / "doctor").glob("*/report.json"))


def _same(a, b) -> bool:
    """Equal, key order included (NaN equal to NaN)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.parent.name for p in EXAMPLES])
def test_worked_examples_round_trip(path):
    text = path.read_text(encoding="utf-8")
    d = json.loads(text)
    rep = Report.from_dict(d)
    assert _same(rep.to_dict(), d)
    assert rep.to_json() == text  # serialised as the doctor writes it
    assert Report.from_dict(rep) is rep


def _example() -> dict:
    return json.loads(EXAMPLES[0].read_text(encoding="utf-8"))


def _refusal(d) -> str:
    with pytest.raises(ReportError) as e:
        Report.from_dict(d)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


def test_a_missing_required_key_is_refused_with_its_name():
    d = _example()
    del d["verdict"]
    assert _refusal(d) == "the doctor's report has no key 'verdict' (required)"


def test_a_key_of_the_wrong_type_is_refused_with_its_name():
    d = _example()
    d["ranking"] = "current"
    assert _refusal(d) == "the doctor's report: 'ranking' is a str, not a list"
    d = _example()
    d["ranking"][1]["validation_error"] = "0.3"
    assert _refusal(d) == "the doctor's report: 'ranking'[1]['validation_error'] is a str, not a number"
    d = _example()
    del d["ladder"][0]["step"]
    assert _refusal(d) == "the doctor's report: 'ladder'[0] has no key 'step' (required)"
    d = _example()
    d["missing_effect"] = 3
    assert _refusal(d) == "the doctor's report: 'missing_effect' is an int, not a str or null"
    d = _example()
    d["seconds"] = True
    assert "'seconds' is a bool, not a number" in _refusal(d)
    assert _refusal(None) == "the doctor's report is a NoneType, not a JSON object"


def test_an_unknown_key_is_refused():
    d = _example()
    d["verdikt"] = "typo"
    assert _refusal(d) == "the doctor's report has an unknown key 'verdikt'"


def test_an_older_report_without_the_later_keys_reads_and_writes_back_without_them():
    d = _example()
    for k in ("separating_maneuver", "rudder_residual", "prediction_uncertainty", "provenance", "units"):
        del d[k]
    rep = Report.from_dict(d)
    assert rep.separating_maneuver is None and rep.provenance is None and rep.units is None
    assert _same(rep.to_dict(), d)
    # null where the report says null: kept as said
    d = _example()
    d["separating_maneuver"] = None
    assert "separating_maneuver" in Report.from_dict(d).to_dict()
