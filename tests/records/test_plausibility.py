"""Plausibility checks of the schema reader (study.records.plausibility through study.records.schema.validate / read_record).

Each broken record is made from a good one, written to a file and read back: a heading in degrees (unwrapped, so
the old jump check misses it), a yaw rate in deg/s below 2 (a full-scale ship: the old limit misses it), both in
degrees, time in milliseconds, speeds in knots, u, v off the track by a calibration factor, two records joined end
to end, a position glitch, a channel not logged; n in rpm is a check against the vessel (study.records.vessel_checks), run
on the record read from its file. Each error names the file, the column, the rows and the fix. Good records raise
nothing and warn nothing: simulated records of every vessel kind at every noise definition (the real records of
../shared/data/real: tests/records/test_schema.py).
"""
import re
import warnings

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from study.commands.app import CONF_DIR
from study.records.schema import PLAUSIBILITY, RecordWarning, SchemaError, read_record, validate
from study.commands.simulate import make_record


def _simulated(vessel: str, maneuver: str, noise: str, seed: int = 0, **sim) -> pd.DataFrame:
    overrides = [f"vessel={vessel}", f"maneuver={maneuver}", f"noise={noise}", f"seed={seed}", "out=unused"]
    overrides += [f"sim.{k}={v}" for k, v in sim.items()]
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        conf = OmegaConf.to_container(compose(config_name="simulate", overrides=overrides), resolve=True)
    return make_record(conf).data


@pytest.fixture(scope="module")
def good() -> pd.DataFrame:
    """KVLCC2 full scale, 20/20 zigzag, 600 s, sampled at 0.5 s with the default (absolute, low) noise."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        conf = OmegaConf.to_container(compose(config_name="simulate", overrides=[
            "vessel=kvlcc2", "maneuver=zigzag_20_20", "noise=low", "noise.sample_dt=0.5", "sim.duration=600",
            "out=unused"]), resolve=True)
    return make_record(conf).data


def _write(tmp_path, df, name="rec.csv"):
    p = tmp_path / name
    df.to_csv(p, index=False)
    return p


def _read_silently(path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordWarning)
        return read_record(path)


def test_good_record_reads_without_a_finding(tmp_path, good):
    assert np.degrees(good["r"].abs().max()) < 2.0  # a full-scale ship: r in deg/s would pass the old limit
    _read_silently(_write(tmp_path, good))


def _error(tmp_path, df, *patterns):
    p = _write(tmp_path, df)
    with pytest.raises(SchemaError) as err:
        read_record(p)
    msg = str(err.value)
    assert msg.startswith(f"{p}: ") and "\n" not in msg
    for pat in patterns:
        assert re.search(pat, msg), msg
    return msg


def test_heading_in_degrees(tmp_path, good):
    bad = good.assign(psi=np.degrees(good["psi"]))
    assert np.abs(np.diff(bad["psi"])).max() < np.pi  # unwrapped: the jump check alone does not see it
    _error(tmp_path, bad, r"column 'psi': psi looks like degrees", r"ratio 57\.\d", r"rows \d+-\d+",
           r"numpy\.deg2rad")


def test_yaw_rate_in_degrees_per_second_below_2(tmp_path, good):
    bad = good.assign(r=np.degrees(good["r"]))
    assert bad["r"].abs().max() < 2.0
    _error(tmp_path, bad, r"column 'r': r looks like deg/s", r"ratio 0\.017\d", r"convert r with numpy\.deg2rad")


def test_heading_and_yaw_rate_both_in_degrees(tmp_path, good):
    bad = good.assign(psi=np.degrees(good["psi"]), r=np.degrees(good["r"]))
    _error(tmp_path, bad, r"column 'psi': psi looks like degrees .*track's course", r"so is r",
           r"numpy\.deg2rad and r too")


def test_time_in_milliseconds(tmp_path, good):
    bad = good.assign(time=good["time"] * 1000.0)
    _error(tmp_path, bad, r"column 'time': time looks like milliseconds", r"median sample interval 500",
           r"divide time by 1000")


def test_speeds_in_knots(tmp_path, good):
    bad = good.assign(u=good["u"] * 1.943844, v=good["v"] * 1.943844)
    _error(tmp_path, bad, r"columns 'u', 'v' against x0, y0: u, v look like knots", r"multiply u and v by 0\.514")


def test_velocities_off_the_track_warn(tmp_path, good):
    bad = good.assign(u=good["u"] * 0.6, v=good["v"] * 0.6)  # a log calibrated 40 % low: no unit, a suspicion
    p = _write(tmp_path, bad)
    with pytest.warns(RecordWarning, match=r"columns 'u', 'v' disagree with the track x0, y0: it moves 1\.6\d* times"):
        read_record(p)


def test_two_records_joined_end_to_end(tmp_path, good):
    second = good.assign(time=good["time"] + good["time"].iloc[-1] + 0.5)  # restamped: time keeps increasing
    bad = pd.concat([good, second], ignore_index=True)
    row = len(good)
    _error(tmp_path, bad, rf"columns 'x0', 'y0' jump by [\d.]+ m at row {row} ", r"joined end to end",
           rf"split the file at row {row}")


def test_position_glitch_warns(tmp_path, good):
    bad = good.copy()
    bad.loc[300, "x0"] += 0.5 * np.ptp(good["x0"])
    with pytest.warns(RecordWarning, match=r"jump by .* at row 300 .* and back at the next row: a position glitch"):
        read_record(_write(tmp_path, bad))


@pytest.mark.parametrize("column", ["delta", "r", "v"])
def test_constant_channel_warns(tmp_path, good, column):
    bad = good.assign(**{column: 0.0})
    with pytest.warns(RecordWarning, match=rf"column '{column}' is 0 in all {len(good)} rows: a sensor that was not "
                                           r"logged"):
        read_record(_write(tmp_path, bad))


def test_plausibility_option(tmp_path, good):
    bad = good.assign(r=np.degrees(good["r"]))
    p = _write(tmp_path, bad)
    with pytest.warns(RecordWarning, match="r looks like deg/s"):
        read_record(p, plausibility="warn")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordWarning)
        read_record(p, plausibility="off")
    assert PLAUSIBILITY == ("error", "warn", "off")
    with pytest.raises(ValueError, match="plausibility='loud'"):
        validate(bad, p, plausibility="loud")


def test_n_in_rpm_is_checked_against_the_vessel(tmp_path):
    """The schema cannot know the vessel's propeller speed: the doctor's check does it (study.records.vessel_checks), on
    the record as read from its file (what `python -m study train=...` and `python -m study diagnose` do)."""
    from study.records.vessel_checks import RecordCheckError, check_records
    from study.configuration.compose import read_config

    df = _simulated("kvlcc2_l7", "zigzag_10_10", "low", **{"duration": 200})
    p = _write(tmp_path, df.assign(n=df["n"] * 60.0))
    rec = _read_silently(p)
    with pytest.raises(RecordCheckError, match=rf"{re.escape(str(p))}: column 'n' .* rpm.*divide by 60"):
        check_records(read_config("vessel", "kvlcc2_l7"), [rec])


# ------------------------------------------------------------------------------------------------ file formats
def test_latin1_csv_names_the_file_and_the_fix(tmp_path, good):
    p = tmp_path / "latin.csv"
    p.write_bytes(("# source: Kiel, Förde\n" + good.to_csv(index=False)).encode("latin-1"))
    with pytest.raises(SchemaError, match=rf"{re.escape(str(p))}: not UTF-8 text \(byte 0xf6 .*iconv"):
        read_record(p)


def test_byte_order_mark_is_skipped(tmp_path, good):
    p = tmp_path / "bom.csv"
    p.write_bytes(("\ufeff# name: with a BOM\n" + good.to_csv(index=False)).encode("utf-8"))
    rec = _read_silently(p)
    assert rec.meta["name"] == "with a BOM" and len(rec.data) == len(good)


def test_garbage_parquet_names_the_file(tmp_path, good):
    import pyarrow as pa
    import pyarrow.parquet as pq

    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"PAR1" + bytes(range(256)) * 8 + b"PAR1")
    with pytest.raises(SchemaError, match=rf"{re.escape(str(junk))}: not a readable parquet file"):
        read_record(junk)
    table = pa.Table.from_pandas(good, preserve_index=False)
    bad_meta = tmp_path / "bad_meta.parquet"
    pq.write_table(table.replace_schema_metadata({b"study.meta": b"{not json"}), bad_meta)
    with pytest.raises(SchemaError, match=rf"{re.escape(str(bad_meta))}: its 'study.meta' metadata is not JSON"):
        read_record(bad_meta)
    text = tmp_path / "text.parquet"
    pq.write_table(pa.Table.from_pandas(good.assign(u="fast"), preserve_index=False), text)
    with pytest.raises(SchemaError, match=rf"{re.escape(str(text))}: column 'u' is not numeric"):
        read_record(text)


@pytest.mark.parametrize("body, message", [
    ("one\ntwo\n", r"2 line\(s\); an HSVA \.dat has 4 header lines"),
    ("a\nb\nc\nd\n" + "1 2 3 4 5 6 7 8 9 10 11 x\n" * 30, r"not 12 numeric columns after the 4 header lines"),
    ("a\nb\nc\nd\n" + "1 2 3\n" * 30, r"expected 12 whitespace-separated columns"),
])
def test_bad_dat_names_the_file(tmp_path, body, message):
    from study.records.loaders import load_real

    p = tmp_path / "HSVA_CPMC_KVLCC2_bad.dat"
    p.write_text(body, encoding="cp1252")
    with pytest.raises(SchemaError, match=rf"{re.escape(str(p))}: {message}"):
        load_real(p)


# -------------------------------------------------------------------------------------- no false alarms
NOISES = ["none", "low", "medium", "high", "low_outputs", "low_relative", "medium_relative", "high_relative",
          "low_outputs_relative"]
CASES = [("kvlcc2", "zigzag_10_10"), ("kvlcc2_l7", "turning_35"), ("usv_waterjet", "random_rudder"),
         ("mariner", "zigzag_35_35"), ("auv", "zigzag_10_10"), ("kt_mariner", "turning_35"),
         ("esso_osaka", "random_rudder")]


@pytest.mark.parametrize("vessel, maneuver", CASES)
def test_simulated_records_pass_at_every_noise(vessel, maneuver):
    for noise in NOISES:
        df = _simulated(vessel, maneuver, noise, seed=3)
        with warnings.catch_warnings():
            warnings.simplefilter("error", RecordWarning)
            validate(df, f"{vessel}_{maneuver}_{noise}")


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_swapped_positions_are_refused_with_measured_or_estimated_states(tmp_path, good):
    """x0 and y0 swapped mirror the track: its course turns against the heading. Judged from positions and heading
    alone, so the record is refused too when u, v, r are to be estimated from them (states=ekf)."""
    bad = good.rename(columns={"x0": "y0", "y0": "x0"})
    _error(tmp_path, bad, r"x0 and y0 swapped", r"swap x0 and y0", r"'x0', 'y0'")
    with pytest.raises(SchemaError, match="x0 and y0 swapped"):
        read_record(_write(tmp_path, bad[["time", "x0", "y0", "psi", "delta", "n"]], "pos.csv"), states="ekf")
    # the unswapped record with positions and heading only is estimated without a finding
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordWarning)
        read_record(_write(tmp_path, good[["time", "x0", "y0", "psi", "delta", "n"]], "ok.csv"), states="ekf")


def test_a_decimal_comma_is_refused_naming_the_line(tmp_path, good):
    p = tmp_path / "comma.csv"
    good.head(40).to_csv(p, index=False, float_format="%.3f")
    p.write_text(p.read_text().replace(".", ","))
    with pytest.raises(SchemaError, match=r"comma\.csv: line 2 of the table has \d+ fields where the header has "
                                          r"\d+: numbers written with a decimal comma"):
        read_record(p)
    p.write_text(good.head(40).to_csv(index=False, sep=";", decimal=","))  # the other European export
    with pytest.raises(SchemaError, match=r"fields separated by ;"):
        read_record(p)
    # a quoted field with a comma is one field, not a decimal comma
    q = good.head(40).assign(note="a, b")
    ok = tmp_path / "quoted.csv"
    q.to_csv(ok, index=False)
    assert "note" in read_record(ok).data
