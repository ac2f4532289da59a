"""Loaders of the real free-running data in ``../shared/data/real`` into the record schema.

The data are read where they are and never copied into this repository (their licences differ from
ours; see each folder's SOURCE.md). Where: the folder named by the environment variable
``STUDY_REAL_DATA``, else the first ``shared/data/real`` beside the repository or beside any folder
above it (``<clone>/../shared/data/real`` for a clone next to ``shared/``; a git worktree deeper
down finds the same folder). :func:`real_data_dir` says where it looked when nothing is there.

- Esso Osaka 3 m model, Osaka University (Wakita et al. 2022, J Mar Sci Technol 27, 772-785;
  Miyauchi et al. 2022, J Mar Sci Technol 27, 1065-1083), CC BY-NC-SA 4.0. Already SI, radians, body
  velocities at midship, delta > 0 to starboard (our convention). Wind directions were checked
  against the data here: the true and apparent wind directions are where the wind comes FROM
  (recomputing the apparent wind from the true wind and the ship's motion with that reading matches
  the logged apparent wind to 1e-3; the opposite reading misses by 0.2-0.4 rad), the true one
  clockwise from x0, the apparent one from the bow, + from starboard.
- KVLCC2 L7 model at HSVA, SIMMAN 2008 (Stern et al. 2011, J Ship Res 55, 135-147; HSVA report by A.
  Cura Hochbaum 2006; redistributed by Alexandersson et al. 2022, Ocean Eng 266, 112940). Degrees,
  earth-fixed velocities and delta > 0 to PORT in the files: converted here. The CPMC reference
  point is not stated in the report excerpt we have; positions and velocities are taken as given
  (assumed midship, labelled in meta).

Each record's metadata name its facility (``study.records.facility``): Esso Osaka's ``pond`` (the
Inukai pond of Osaka University, outdoors, SOURCE.md), HSVA's ``towing_tank`` (HSVA's large towing
tank, 300 x 18 x 6 m, the CPMC carriage following the model; SOURCE.md), with its ``scale``
1:45.714.

:func:`load_records` reads the records a pattern names (a file, folder, glob or comma-separated list
of them), schema files and the real datasets' own formats alike (the doctor's reading; a run on
files reads them one by one).
"""
from __future__ import annotations

import glob as globmod
import os
from pathlib import Path

import numpy as np
import pandas as pd

from study.records.schema import Record, SchemaError, not_utf8, validate

DATASETS = ("esso_osaka", "kvlcc2_hsva")


ENV_VAR = "STUDY_REAL_DATA"
_SUBDIR = Path("shared") / "data" / "real"


def _candidates() -> list[Path]:
    """``shared/data/real`` beside the repository and beside each folder above it, nearest first."""
    repo = Path(__file__).resolve().parents[2]
    return [parent / _SUBDIR for parent in repo.parents]


def real_data_dir() -> Path:
    """The folder of the real datasets: ``$STUDY_REAL_DATA`` if set, else the nearest existing
    ``shared/data/real`` above the repository, else where it is expected
    (``<repo>/../shared/data/real``; it may not exist: :func:`missing_real_data` says so in one
    line)."""
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env).expanduser()
    cands = _candidates()
    for c in cands:
        if c.is_dir():
            return c
    return cands[0]


def missing_real_data(dataset: str | None = None) -> str:
    """One line saying where the real data were looked for and how to point the project at them."""
    what = f"real dataset '{dataset}'" if dataset else "real data"
    sub = {"kvlcc2_hsva": "kvlcc2_hsva/raw_data/*.dat", "esso_osaka": "esso_osaka_frt/data/*/*.csv"}.get(
        dataset or "", "kvlcc2_hsva/ and esso_osaka_frt/")
    if os.environ.get(ENV_VAR):
        return (f"{what} not found in {ENV_VAR}={os.environ[ENV_VAR]} (expected {sub} inside it): point "
                f"{ENV_VAR} at the folder real/ of the project's shared data")
    return (f"{what} not found: expected {sub} in {_candidates()[0]} (or in a shared/data/real further up); "
            f"put the shared data there or set {ENV_VAR}=/path/to/shared/data/real")


class RealDataMissing(FileNotFoundError):
    """The real datasets are not where the project looks for them (the message says where and how
    to fix)."""


def require_real_records(dataset: str, data_dir=None, kind: str | None = None) -> list[Path]:
    """:func:`list_real_records`, raising :class:`RealDataMissing` with a one-line fix when there
    are none."""
    files = list_real_records(dataset, data_dir, kind)
    if not files:
        if data_dir:
            raise RealDataMissing(f"the real dataset '{dataset}' not found in {data_dir}")
        raise RealDataMissing(missing_real_data(dataset))
    return files


ESSO_COLUMNS = {
    "t [s]": "time", "x_position_mid [m]": "x0", "y_position_mid [m]": "y0", "u_velo [m/s]": "u",
    "vm_velo [m/s]": "v", "psi_hat [rad]": "psi", "r_angvelo [rad/s]": "r", "n_prop [rps]": "n",
    "delta_rudder [rad]": "delta", "wind_velo_true [m/s]": "wind_speed", "wind_dir_true [rad]": "wind_dir",
    "wind_velo_relative_mid [m/s]": "wind_speed_rel", "wind_dir_relative_mid [rad]": "wind_angle_rel",
}


def load_esso_osaka(path, trim: bool = False) -> Record:
    """One CSV of ``esso_osaka_frt/data/{zigzag,turning,random}``.

    ``trim=True`` keeps the manoeuvre proper: from the first sample with |delta| >= 0.9 max|delta|
    after the speed has built up (u above 80 % of its maximum) to the last sample with the propeller
    running (the rule suggested in SOURCE.md).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such Esso Osaka file")
    try:
        raw = pd.read_csv(path, encoding="utf-8-sig").dropna(how="all")  # one file ends with 327 all-empty rows
    except UnicodeDecodeError as exc:
        raise not_utf8(path, exc) from exc
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise SchemaError(f"{path}: not a readable CSV table ({exc})") from exc
    missing = [c for c in ESSO_COLUMNS if c not in raw.columns]
    if missing:
        raise SchemaError(f"{path}: not an Esso Osaka free-running file: missing columns {missing}")
    try:
        df = raw[list(ESSO_COLUMNS)].rename(columns=ESSO_COLUMNS).astype(float)
    except ValueError as exc:
        raise SchemaError(f"{path}: a column is not numeric ({exc})") from exc
    df["psi"] = np.unwrap(df["psi"].to_numpy())  # psi_hat is wrapped to (-pi, pi]
    df["wind_dir"] = np.mod(df["wind_dir"], 2 * np.pi)
    df["wind_angle_rel"] = np.angle(np.exp(1j * df["wind_angle_rel"]))
    if trim:
        d = np.abs(df["delta"].to_numpy())
        u = df["u"].to_numpy()
        fast = u >= 0.8 * u.max()
        start = int(np.argmax(fast & (d >= 0.9 * d[fast].max()))) if fast.any() else 0
        running = np.where(df["n"].to_numpy() > 0)[0]
        end = int(running[-1]) + 1 if running.size else len(df)
        df = df.iloc[start:end]
    df = df.reset_index(drop=True)
    validate(df, path)
    kind = path.parent.name
    meta = {
        "name": path.stem, "vessel": "esso_osaka", "maneuver": kind, "source": "Esso Osaka 3 m model, "
        "Osaka University free-running tests (Wakita et al. 2022; Miyauchi et al. 2022), CC BY-NC-SA 4.0",
        "reference_point": "midship", "x0_axis": "pond x0 (not north)", "trimmed": bool(trim),
        "facility": "pond",  # SOURCE.md: Inukai pond, Osaka University, outdoors (with measured wind)
    }
    return Record(data=df, meta=meta, path=str(path))


def load_kvlcc2_hsva(path) -> Record:
    """One ``.dat`` of ``kvlcc2_hsva/raw_data`` (cp1252, 4 header lines, 12 columns; see
    SOURCE.md)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such HSVA file")
    try:
        with open(path, encoding="cp1252") as fh:
            header = [ln.strip() for _, ln in zip(range(4), fh)]
        arr = np.loadtxt(path, skiprows=4, encoding="cp1252", ndmin=2) if len(header) == 4 else None
    except UnicodeDecodeError as exc:
        raise SchemaError(f"{path}: not a Windows-1252 text file (byte at position {exc.start}): not an HSVA "
                          f".dat") from exc
    except ValueError as exc:  # a text field or a ragged row among the numbers
        raise SchemaError(f"{path}: not 12 numeric columns after the 4 header lines ({exc})") from exc
    if arr is None:
        raise SchemaError(f"{path}: {len(header)} line(s); an HSVA .dat has 4 header lines, then 12 columns")
    if arr.ndim != 2 or arr.shape[1] != 12:
        raise SchemaError(f"{path}: expected 12 whitespace-separated columns after 4 header lines, "
                          f"found shape {arr.shape}")
    t, x0, y0, psi_deg, xd, yd, r_deg, phi_deg, delta_deg, n, thrust, torque = arr.T
    psi = np.unwrap(np.radians(psi_deg))
    df = pd.DataFrame({
        "time": t, "x0": x0, "y0": y0, "psi": psi,
        "u": xd * np.cos(psi) + yd * np.sin(psi),  # earth-fixed velocities to body axes
        "v": -xd * np.sin(psi) + yd * np.cos(psi),
        "r": np.radians(r_deg),
        "delta": -np.radians(delta_deg),  # file: + to port (SIMMAN); schema: + to starboard
        "n": n, "thrust": thrust, "torque": torque,
    })
    validate(df, path)
    meta = {
        "name": path.stem, "vessel": "kvlcc2_l7", "maneuver": header[2],
        "source": "HSVA free-running tests of KVLCC2 (SIMMAN 2008; Stern et al. 2011), via Alexandersson "
                  "et al. 2022", "reference_point": "as measured by the CPMC (assumed midship)",
        "roll_deg_column_dropped": True,
        # SOURCE.md: HSVA's large towing tank (300 x 18 x 6 m), the CPMC carriage following the model; scale 1:45.714
        "facility": "towing_tank", "scale": "1:45.714",
    }
    return Record(data=df, meta=meta, path=str(path))


def list_real_records(dataset: str, data_dir=None, kind: str | None = None) -> list[Path]:
    """Sorted paths of a real dataset ('esso_osaka' optionally by kind
    'zigzag'/'turning'/'random')."""
    root = Path(data_dir) if data_dir else real_data_dir()
    if dataset == "esso_osaka":
        base = root / "esso_osaka_frt" / "data"
        kinds = [kind] if kind else ["random", "turning", "zigzag"]
        return sorted(p for k in kinds for p in (base / k).glob("*.csv"))
    if dataset == "kvlcc2_hsva":
        return sorted((root / "kvlcc2_hsva" / "raw_data").glob("*.dat"))
    raise ValueError(f"unknown real dataset '{dataset}'; known: {list(DATASETS)}")


def load_real(path) -> Record:
    """Load a real file by its location/extension."""
    path = Path(path)
    if path.suffix.lower() == ".dat" and "kvlcc2" in path.name.lower():
        return load_kvlcc2_hsva(path)
    if path.suffix.lower() == ".csv" and "esso" in str(path).lower():
        return load_esso_osaka(path)
    raise SchemaError(f"{path}: not a known real-data file (HSVA KVLCC2 .dat or Esso Osaka .csv)")


# ------------------------------------------------------------------------ record files named by patterns
def patterns(spec) -> list:
    """A ``train``/``validate`` value as a list of patterns: a list as it is, a string split at
    commas."""
    if spec is None:
        return []
    items = list(spec) if isinstance(spec, (list, tuple)) else [p for p in str(spec).split(",")]
    return [str(p).strip() for p in items if str(p).strip()]


def is_real(path: Path) -> bool:
    """A file in one of the real datasets' own formats (HSVA ``.dat``, an Esso Osaka CSV), not a
    schema file."""
    if path.suffix.lower() == ".dat":
        return True
    if path.suffix.lower() == ".csv":
        with open(path, encoding="utf-8", errors="replace") as fh:
            head = fh.readline()
        return "u_velo [m/s]" in head  # an Esso Osaka file
    return False


def load_records(spec, states: str = "measured", state_options: dict | None = None) -> list:
    """Records from a file, folder or glob, or a comma-separated list of them: schema files, or
    the real datasets' own formats. ``states`` (``measured | auto | ekf``) and ``state_options``:
    where u, v, r come from (``study.records.schema.read_record``; the real datasets' loaders
    always give u, v, r, which ``ekf`` refines)."""
    from study.records.schema import STATES, SUPPORTED, read_record, with_estimated_states

    if states not in STATES:
        raise ValueError(f"states={states}: expected one of {list(STATES)}")

    files = []
    for pattern in patterns(spec):  # a comma-separated list, as ``python -m study train=...`` takes
        p = Path(pattern).expanduser()
        if p.is_file():
            found = [p]
        elif p.is_dir():
            found = sorted(f for f in p.iterdir() if f.suffix.lower() in SUPPORTED + (".dat",))
        else:
            found = sorted(Path(f) for f in globmod.glob(pattern) if Path(f).suffix.lower() in SUPPORTED + (".dat",))
        if not found:
            raise FileNotFoundError(f"{pattern}: no record files (.csv, .parquet, .dat) found")
        files += [f for f in found if f not in files]
    out = []
    for f in files:
        if is_real(f):
            rec = load_real(f)
            if states == "ekf":
                rec = with_estimated_states(rec, state_options)
        else:
            rec = read_record(f, states=states, state_options=state_options)
        rec.meta.setdefault("name", f.stem)
        out.append(rec)
    return out

