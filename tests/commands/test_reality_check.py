"""The published MMG model of KVLCC2 against HSVA's free-running zigzags (tolerances: README, 'Checked
against reality'). Skipped when ../shared/data/real is not there."""
import pytest

from study.records.loaders import list_real_records

pytestmark = pytest.mark.skipif(not list_real_records("kvlcc2_hsva"), reason="../shared/data/real not available")


@pytest.fixture(scope="module")
def table():
    from study.commands.reality_check import build_table

    return build_table()[0]


def _rows(table, quantity, propeller="hsva_rpm"):
    return table[(table.quantity == quantity) & (table.propeller == propeller)]


def test_periods_agree_within_10_percent(table):
    rows = _rows(table, "period")
    assert len(rows) == 4 and rows["measured"].notna().all()
    assert ((rows["ratio"] - 1).abs() <= 0.10).all(), rows


def test_first_overshoots_agree_within_5_degrees(table):
    rows = _rows(table, "overshoot_1")
    assert (rows["difference"].abs() <= 5.0).all(), rows


def test_the_disagreement_the_readme_reports_is_real(table):
    # README: the model under-predicts every overshoot, the 10/10 port-first second overshoot by about half.
    over = table[(table.propeller == "hsva_rpm") & table.quantity.str.startswith("overshoot")]
    assert (over["simulated"] < over["measured"]).all(), over
    zz = over[(over.run == "Z_10_10_P") & (over.quantity == "overshoot_2")]
    assert float(zz["ratio"].iloc[0]) < 0.7
