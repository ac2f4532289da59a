"""The record schema: every kind of malformed file gets an error naming the file and the problem; round
trips keep data and metadata; nothing is overwritten; the real loaders give valid records with our signs."""
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from study.records.loaders import DATASETS, list_real_records, load_esso_osaka, load_kvlcc2_hsva, load_real
from study.records.schema import Record, SchemaError, from_arrays, read_record, read_records, validate, write_record


def good_frame(n=200):
    """A consistent record (psi the integral of r, the track that of u, v turned by psi): no plausibility finding."""
    t = np.arange(n) * 0.1
    psi, u, v = 0.1 * np.sin(t), 1.0 + 0 * t, 0.01 * np.sin(t)
    vx, vy = u * np.cos(psi) - v * np.sin(psi), u * np.sin(psi) + v * np.cos(psi)
    x0 = np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * 0.1)])
    y0 = np.concatenate([[0.0], np.cumsum(0.5 * (vy[1:] + vy[:-1]) * 0.1)])
    return from_arrays(t, u, v, 0.1 * np.cos(t), x0, y0, psi, 0.17 * np.sign(np.sin(t)), 10.0 + 0 * t)


def _write_csv(tmp_path, df, name="bad.csv"):
    p = tmp_path / name
    df.to_csv(p, index=False)
    return p


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.drop(columns=["r", "psi"]), r"missing required column\(s\) \['r', 'psi'\]"),
    (lambda d: d.assign(u=d.u.where(d.index != 17)), r"column 'u' has 1 NaN/inf value\(s\), the first at row 17"),
    (lambda d: d.assign(time=d.time.where(d.index != 50, 1.0)), r"time is not increasing at row 50"),
    (lambda d: d.assign(time=d.time.where(d.index != 50, d.time[49])), r"duplicated time .* at row 50"),
    (lambda d: d.assign(delta=np.degrees(d.delta)), r"column 'delta' reaches .* degrees where radians"),
    (lambda d: d.assign(psi=np.degrees(d.psi) * 50), r"column 'psi' jumps .* numpy.deg2rad"),
    (lambda d: d.iloc[:5], r"too short: 5 samples, at least 20"),
    (lambda d: d.assign(u="fast"), r"column 'u' is not numeric"),
])
def test_malformed_files_get_clear_errors(tmp_path, mutate, message):
    p = _write_csv(tmp_path, mutate(good_frame()))
    with pytest.raises(SchemaError, match=message) as err:
        read_record(p)
    assert str(p) in str(err.value)


def test_missing_file_and_unknown_extension(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.csv"):
        read_record(tmp_path / "nope.csv")
    p = tmp_path / "data.xlsx"
    p.write_text("x")
    with pytest.raises(SchemaError, match=r"data.xlsx: unsupported file type '.xlsx'"):
        read_record(p)
    with pytest.raises(FileNotFoundError, match="no record files"):
        read_records(tmp_path / "*.csv")


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_round_trip_and_no_silent_overwrite(tmp_path, ext):
    rec = Record(good_frame(), {"name": "zz", "vessel": "kvlcc2", "hidden_effects": [{"name": "current",
                                                                                       "speed": 0.5}]})
    p = tmp_path / f"rec{ext}"
    write_record(rec, p)
    back = read_record(p)
    pd.testing.assert_frame_equal(back.data, rec.data, check_exact=False, rtol=1e-9)
    assert back.meta == rec.meta
    before = p.read_bytes()
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_record(Record(good_frame(100), {}), p)
    assert p.read_bytes() == before
    assert len(read_records(tmp_path)) == 1


def test_invalid_record_is_not_written(tmp_path):
    with pytest.raises(SchemaError):
        write_record(Record(good_frame().drop(columns=["n"]), {}), tmp_path / "x.csv")
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_simulate_cli_writes_a_valid_record_with_its_hidden_effect(tmp_path):
    out = tmp_path / "zz.csv"
    args = [sys.executable, "-m", "study", "simulate", "vessel=kvlcc2_l7", "maneuver=zigzag_10_10",
            "environment=current", "noise=low", "sim.duration=60", f"out={out}"]
    p = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    rec = read_record(out)
    assert rec.meta["hidden_effects"][0]["name"] == "current"
    assert rec.data["time"].iloc[-1] == pytest.approx(60.0)
    again = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert again.returncode != 0 and "refusing to overwrite" in again.stderr


REAL = [(ds, p) for ds in DATASETS for p in list_real_records(ds)]


@pytest.mark.skipif(not REAL, reason="../shared/data/real not available")
@pytest.mark.parametrize("dataset, path", REAL, ids=[p.name for _, p in REAL])
def test_every_real_file_loads_valid(dataset, path):
    """... and without a plausibility finding (study.records.plausibility: no error, no warning on real data)."""
    import warnings

    from study.records.schema import RecordWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordWarning)
        rec = load_real(path)
        validate(rec.data, path)
    assert rec.meta["vessel"] in ("esso_osaka", "kvlcc2_l7")


@pytest.mark.skipif(not REAL, reason="../shared/data/real not available")
def test_real_sign_conventions():
    hsva = {p.stem: p for p in list_real_records("kvlcc2_hsva")}
    d = load_kvlcc2_hsva(hsva["HSVA_CPMC_KVLCC2_Z_10_10_S"]).data
    i = int(np.argmax(np.abs(d["delta"]) > 0.01))
    assert d["delta"].iloc[i] > 0  # starting to starboard = delta > 0 after the flip
    assert d["r"].iloc[i + 100] > 0  # and the ship turns to starboard
    assert d["u"].iloc[0] == pytest.approx(1.178, abs=0.005)  # body u from earth-fixed velocities
    assert abs(d["v"].iloc[0]) < 0.01
    for p in list_real_records("esso_osaka", kind="zigzag"):
        e = load_esso_osaka(p).data
        lag = 30  # 3 s: the yaw rate follows the rudder
        c = np.corrcoef(e["delta"].to_numpy()[:-lag], e["r"].to_numpy()[lag:])[0, 1]
        assert c > 0, p.name
    trimmed = load_esso_osaka(list_real_records("esso_osaka", kind="zigzag")[0], trim=True).data
    assert (trimmed["n"] > 0).all()
