"""The schema of a measured (or simulated) manoeuvring record, its validation, reading and writing.

One record = one manoeuvre = one table, SI units and radians, frames and signs of
``docs/conventions.md``. The column specification below is the single source of truth: validation
and ``docs/schema.md`` follow it. Every error names the file and the problem, so a user with a bad
file knows what to fix.
"""
from __future__ import annotations

import glob as globmod
import io
import json
import math
import os
import re
import uuid
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import yaml


@dataclass(frozen=True)
class Column:
    name: str
    unit: str
    required: bool
    meaning: str
    limit: float | None = None  # largest plausible |value|; above it the column is probably in other units


COLUMNS = (
    Column("time", "s", True, "time, strictly increasing"),
    Column("u", "m/s", True, "surge velocity over ground, body axes"),
    Column("v", "m/s", True, "sway velocity over ground, body axes, at the reference point (midship)"),
    Column("r", "rad/s", True, "yaw rate, + turning to starboard", limit=2.0),
    Column("x0", "m", True, "position north (earth-fixed)"),
    Column("y0", "m", True, "position east (earth-fixed)"),
    Column("psi", "rad", True, "heading, clockwise from north, unwrapped"),
    Column("delta", "rad", True, "rudder (or nozzle) angle, + turns the ship to starboard", limit=1.2),
    Column("n", "rps", True, "propeller speed (the waterjet vessel: jet velocity, m/s)"),
    Column("delta_cmd", "rad", False, "commanded rudder angle", limit=1.2),
    Column("wind_speed", "m/s", False, "true wind speed"),
    Column("wind_dir", "rad", False, "true wind direction, where the wind comes FROM, clockwise from north"),
    Column("wind_speed_rel", "m/s", False, "apparent wind speed at the reference point"),
    Column("wind_angle_rel", "rad", False, "apparent wind angle, 0 = from ahead, + from starboard"),
    Column("depth", "m", False, "water depth"),
    Column("thrust", "N", False, "measured propeller thrust"),
    Column("torque", "N m", False, "measured propeller torque"),
)
REQUIRED = tuple(c.name for c in COLUMNS if c.required)
BY_NAME = {c.name: c for c in COLUMNS}
SUPPORTED = (".csv", ".parquet")
META_KEY = b"study.meta"


class SchemaError(ValueError):
    """A record that does not follow the schema; the message names the file and the problem."""


class RecordWarning(UserWarning):
    """A record that follows the schema but looks implausible (``study.records.plausibility``);
    the message names the file, the column, where, and what to check."""


#: what ``validate`` does with the plausibility checks of ``study.records.plausibility``: ``error`` (a certain unit mistake
#: raises, a suspicion warns), ``warn`` (everything warns), ``off``
PLAUSIBILITY = ("error", "warn", "off")


def not_utf8(path, exc: UnicodeDecodeError) -> SchemaError:
    """The one-line error of a text file that is not UTF-8 (a Latin-1 / Windows-1252 export,
    typically)."""
    byte = exc.object[exc.start:exc.start + 1].hex() if isinstance(exc.object, (bytes, bytearray)) else "?"
    return SchemaError(f"{path}: not UTF-8 text (byte 0x{byte} at position {exc.start}; a Latin-1 or Windows-1252 "
                       f"export?): re-save it as UTF-8, e.g. iconv -f latin1 -t utf-8 old.csv > new.csv")


@dataclass
class Record:
    """A record: the data (schema columns), its metadata, and where it came from."""

    data: pd.DataFrame
    meta: dict = field(default_factory=dict)
    path: str | None = None

    def __post_init__(self):
        # where the data came from travels with them (pandas ``attrs``), so a later step's message names the file
        if isinstance(self.data, pd.DataFrame) and (self.path or self.meta.get("name")):
            self.data.attrs.setdefault("source", str(self.path or self.meta.get("name")))

    @property
    def name(self) -> str:
        return str(self.meta.get("name") or (Path(self.path).stem if self.path else "record"))


def _where(path) -> str:
    return str(path) if path else "<in-memory record>"


#: how ``read_record(s)`` gets the body velocities u, v, r (see :func:`read_record`)
STATES = ("measured", "auto", "ekf")
#: the columns the state estimator can supply
ESTIMABLE = ("u", "v", "r")
#: and what it needs
ESTIMATOR_INPUTS = ("x0", "y0", "psi")


def validate(df: pd.DataFrame, path=None, min_samples: int = 20, hint: str = "",
             plausibility: str = "error") -> None:
    """Raise :class:`SchemaError` if ``df`` is not a valid record; extra columns are allowed and
    kept. ``hint``: appended to the message of missing columns (how else the record could be read).

    Then the plausibility checks of ``study.records.plausibility`` (do the channels agree with
    each other in the schema's units?): with ``plausibility="error"`` a certain unit mistake
    (degrees, deg/s, milliseconds, knots, two records joined) raises :class:`SchemaError` and a
    suspicion warns (:class:`RecordWarning`); ``"warn"`` turns every finding into a warning,
    ``"off"`` skips them."""
    if plausibility not in PLAUSIBILITY:
        raise ValueError(f"validate: plausibility={plausibility!r}; expected one of {list(PLAUSIBILITY)}")
    where = _where(path)
    missing = [c for c in REQUIRED if c not in df.columns]
    if missing:
        raise SchemaError(f"{where}: missing required column(s) {missing}; found {list(df.columns)}. "
                          f"Required: {list(REQUIRED)} (see docs/schema.md){hint}")
    if len(df) < min_samples:
        raise SchemaError(f"{where}: too short: {len(df)} samples, at least {min_samples} are needed")
    known = [c.name for c in COLUMNS if c.name in df.columns]
    for c in known:
        col = df[c]
        if not pd.api.types.is_numeric_dtype(col):
            raise SchemaError(f"{where}: column '{c}' is not numeric (dtype {col.dtype})")
        vals = col.to_numpy(dtype=float)
        bad = ~np.isfinite(vals)
        if bad.any():
            i = int(np.argmax(bad))
            t = df["time"].iloc[i] if c != "time" else "?"
            raise SchemaError(f"{where}: column '{c}' has {int(bad.sum())} NaN/inf value(s), the first at row {i} "
                              f"(time {t}); drop or fill those rows")
    t = df["time"].to_numpy(dtype=float)
    dt = np.diff(t)
    if (dt == 0).any():
        i = int(np.argmax(dt == 0)) + 1
        raise SchemaError(f"{where}: duplicated time {t[i]} at row {i}")
    if (dt < 0).any():
        i = int(np.argmax(dt < 0)) + 1
        raise SchemaError(f"{where}: time is not increasing at row {i} ({t[i - 1]} -> {t[i]})")
    for c in known:
        lim = BY_NAME[c].limit
        if lim is not None:
            mx = float(np.max(np.abs(df[c].to_numpy(dtype=float))))
            if mx > lim:
                raise SchemaError(f"{where}: column '{c}' reaches |{c}| = {mx:.4g} {BY_NAME[c].unit}, more than "
                                  f"the plausible {lim}: it looks like degrees where radians are expected; "
                                  f"convert with numpy.deg2rad")
    jumps = np.abs(np.diff(df["psi"].to_numpy(dtype=float)))
    if jumps.size and jumps.max() > math.pi:
        i = int(np.argmax(jumps)) + 1
        raise SchemaError(f"{where}: column 'psi' jumps by {jumps.max():.4g} rad at row {i}: either degrees where "
                          f"radians are expected (convert with numpy.deg2rad) or a wrapped heading "
                          f"(unwrap with numpy.unwrap)")
    if plausibility == "off":
        return
    from study.records.plausibility import check

    with np.errstate(all="ignore"):  # a wild value (1e300) overflows the ratios; the vessel's envelope names it
        findings = check(df)
    for f in findings:
        if f.level == "error" and plausibility == "error":
            raise SchemaError(f"{where}: {f.message}")
        warnings.warn(f"{where}: {f.message}", RecordWarning, stacklevel=2)


def check_meta(meta: dict, path=None) -> None:
    """Metadata keys with a fixed vocabulary: ``facility`` (where the record was measured: one of
    ``study.records.facility.FACILITIES``). An unknown value raises :class:`SchemaError` naming
    the file, the key, the value and what was expected."""
    from study.records.facility import check

    if "facility" in (meta or {}):
        try:
            check(meta["facility"], _where(path))
        except ValueError as exc:
            raise SchemaError(str(exc)) from None


def from_arrays(time, u, v, r, x0, y0, psi, delta, n, **optional) -> pd.DataFrame:
    cols = dict(time=time, u=u, v=v, r=r, x0=x0, y0=y0, psi=psi, delta=delta, n=n)
    for k, val in optional.items():
        if k not in BY_NAME:
            raise SchemaError(f"unknown optional column '{k}'; known: {[c.name for c in COLUMNS]}")
        cols[k] = val
    return pd.DataFrame({k: np.asarray(val, dtype=float) for k, val in cols.items()})


def _jsonable(meta: dict) -> dict:
    return json.loads(json.dumps(meta, default=lambda o: o.item() if hasattr(o, "item") else str(o)))


_DECIMAL_COMMA = re.compile(r"\d,\d")


def _csv_hint(body: list) -> str:
    """Why a CSV table cannot be split into its header's columns (empty when it can): rows with
    more fields than the header (quoted fields counted as one), most likely numbers written with
    a decimal comma."""
    import csv

    if not body:
        return ""
    width = len(next(csv.reader([body[0]]), []))
    if width == 1 and any(sep in body[0] for sep in (";", "\t")):
        sep = ";" if ";" in body[0] else "a tab"
        return (f"header {body[0].strip()[:60]!r}: fields separated by {sep}; expected a comma-separated table "
                "with decimal points (e.g. pandas' to_csv defaults)")
    for i, ln in enumerate(body[1:51], start=2):
        fields = next(csv.reader([ln]), [])
        if ln.strip() and len(fields) > width:
            m = _DECIMAL_COMMA.search(ln)
            what = (f"numbers written with a decimal comma ({m.group(0)!r})?" if m else "a comma inside a field?")
            return (f"line {i} of the table has {len(fields)} fields where the header has {width}: {what} "
                    "expected comma-separated fields with decimal points")
    return ""


def read_record(path, min_samples: int = 20, states: str = "measured", state_options: dict | None = None,
                plausibility: str = "error") -> Record:
    """Read and validate a record from ``.csv`` (``# key: value`` metadata lines) or ``.parquet``.

    ``states`` says where the body velocities ``u, v, r`` come from:

    - ``"measured"`` (default): the record must have them (a missing one is an error naming the file
      and the column, and mentioning this option);
    - ``"auto"``: a record without (some of) ``u, v, r`` but with positions ``x0, y0`` and heading
      ``psi`` gets them estimated by the extended Kalman filter and RTS smoother of
      ``study.records.state_estimation`` (those it has are used as measurements and refined); a
      record that has all three is read as measured;
    - ``"ekf"``: always estimated (measured ``u, v, r`` refined).

    An estimated record has ``u, v, r`` replaced (or added after ``time``) and ``u_dot, v_dot,
    r_dot`` added (positions and heading stay as measured), and its metadata say so:
    ``meta["states"] = "ekf"``, ``meta["state_estimation"]`` the filter's settings (noise standard
    deviations, process noise, how each was chosen). ``state_options``: the estimator's options
    (``state_estimation.DEFAULTS``: absolute standard deviations ``position_std`` [m],
    ``heading_std`` [rad], ``u_std``, ``v_std`` [m/s], ``r_std`` [rad/s], or ``"auto"``;
    ``process``). ``plausibility``: as in :func:`validate`.

    CSV files are UTF-8 (a byte-order mark is skipped); another encoding is an error naming the file
    and the fix. Kept as one function: its format, encoding and ``states`` checks all run before any
    estimation, so that bad input is refused before work; a third of its length is this docstring.
    """
    if states not in STATES:
        raise ValueError(f"read_record: states='{states}'; expected one of {list(STATES)}")
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such record file")
    ext = path.suffix.lower()
    if ext not in SUPPORTED:
        raise SchemaError(f"{path}: unsupported file type '{ext}'; supported: {list(SUPPORTED)}")
    meta: dict = {}
    if ext == ".csv":
        try:
            with open(path, encoding="utf-8-sig") as fh:  # -sig: a byte-order mark (Excel's UTF-8) is skipped
                lines = fh.read().splitlines(keepends=True)
        except UnicodeDecodeError as exc:
            raise not_utf8(path, exc) from exc
        body = []
        for ln in lines:
            if ln.startswith("#") and not body:
                key, sep, value = ln[1:].partition(":")
                if sep:
                    try:
                        meta[key.strip()] = yaml.safe_load(value.strip())
                    except yaml.YAMLError:
                        meta[key.strip()] = value.strip()
            else:
                body.append(ln)
        hint = _csv_hint(body)
        if hint:  # more fields than the header: pandas would take the first for an index and shift the rest
            raise SchemaError(f"{path}: {hint}")
        try:
            df = pd.read_csv(io.StringIO("".join(body)))
        except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
            raise SchemaError(f"{path}: not a readable CSV table ({exc})") from exc
    else:
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(path)
        except Exception as exc:  # pyarrow raises several types for a damaged file
            raise SchemaError(f"{path}: not a readable parquet file ({exc})") from exc
        raw = (table.schema.metadata or {}).get(META_KEY)
        try:
            meta = json.loads(raw) if raw else {}
        except ValueError as exc:
            raise SchemaError(f"{path}: its '{META_KEY.decode()}' metadata is not JSON ({exc})") from exc
        if not isinstance(meta, dict):
            raise SchemaError(f"{path}: its '{META_KEY.decode()}' metadata is a {type(meta).__name__}, expected a "
                              f"JSON object")
        try:
            df = table.to_pandas()
        except Exception as exc:  # noqa: BLE001 - pyarrow types pandas cannot hold
            raise SchemaError(f"{path}: its table cannot be read into columns ({exc})") from exc
    check_meta(meta, path)
    lacking = [c for c in ESTIMABLE if c not in df.columns]
    if states == "measured" or (states == "auto" and not lacking):
        hint = ""
        if lacking and all(c in df.columns for c in ESTIMATOR_INPUTS):
            hint = (f"; to estimate {lacking} from x0, y0, psi (EKF + RTS smoother), read it with "
                    f"states='auto' (on the command line: states=auto)")
        validate(df, path, min_samples=min_samples, hint=hint, plausibility=plausibility)
    else:
        df, meta = _estimate_states(df, meta, path, min_samples, lacking, state_options, plausibility)
    known = [c.name for c in COLUMNS if c.name in df.columns]
    df[known] = df[known].astype(float)  # CSV gives int64 for whole numbers
    return Record(data=df, meta=meta, path=str(path))


def with_estimated_states(record: Record, state_options: dict | None = None, min_samples: int = 20) -> Record:
    """A valid record (any loader's) with ``u, v, r`` estimated and refined as ``read_record(...,
    states="ekf")`` does; the record itself is not changed."""
    df, meta = _estimate_states(record.data, record.meta, record.path, min_samples,
                                [c for c in ESTIMABLE if c not in record.data.columns], state_options)
    return Record(data=df, meta=meta, path=record.path)


def _estimate_states(df: pd.DataFrame, meta: dict, path, min_samples: int, lacking: list,
                     state_options: dict | None, plausibility: str = "error") -> tuple[pd.DataFrame, dict]:
    """The record with u, v, r (and u_dot, v_dot, r_dot) from the state estimator; validated
    before (with stand-ins for the missing u, v, r, so that every other problem gets its usual
    message) and after."""
    need = [c for c in ESTIMATOR_INPUTS if c not in df.columns]
    if need:
        validate(df, path, min_samples=min_samples,
                 hint=f"; estimating {lacking or list(ESTIMABLE)} needs the positions and heading "
                      f"{list(ESTIMATOR_INPUTS)}")
    stand_in = df.assign(**{c: 0.0 for c in lacking})
    # the stand-ins cannot agree with the track: the plausibility checks wait for the estimated u, v, r
    validate(stand_in, path, min_samples=min_samples, plausibility="off" if lacking else plausibility)
    if plausibility != "off":  # ... but a mirrored track would corrupt the estimate: judged from the track alone
        from study.records.plausibility import mirrored_track

        with np.errstate(all="ignore"):
            f = mirrored_track(df.assign(**{c: 0.0 for c in ESTIMABLE}))
        if f is not None and plausibility == "error":
            raise SchemaError(f"{_where(path)}: {f.message}")
        if f is not None:
            warnings.warn(f"{_where(path)}: {f.message}", RecordWarning, stacklevel=2)
    from study.records.state_estimation import apply_to_frame

    src = df.copy()
    for c in ("time",) + ESTIMATOR_INPUTS + tuple(c for c in ESTIMABLE if c in df.columns):
        src[c] = src[c].astype(float)
    try:
        out, settings = apply_to_frame(src, state_options)
    except ValueError as exc:
        raise SchemaError(f"{_where(path)}: estimating u, v, r failed: {exc}") from exc
    validate(out, path, min_samples=min_samples, plausibility=plausibility)
    meta = dict(meta)
    meta["states"] = "ekf"
    settings = {k: v for k, v in settings.items() if k != "seconds"}  # metadata stay reproducible
    meta["state_estimation"] = _jsonable({**settings, "estimated": lacking, "refined": [
        c for c in ESTIMABLE if c not in lacking and c in settings.get("measured", [])]})
    return out, meta


def write_record(record: Record, path, overwrite: bool = False) -> Path:
    """Validate and write a record atomically; an existing file is never replaced unless
    ``overwrite``."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in SUPPORTED:
        raise SchemaError(f"{path}: unsupported file type '{ext}'; supported: {list(SUPPORTED)}")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite it (pass overwrite=True / overwrite=true)")
    validate(record.data, path)
    check_meta(record.meta, path)
    meta = _jsonable(record.meta)
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:8]}.tmp"
    try:
        if ext == ".csv":
            head = "".join(f"# {k}: {json.dumps(v)}\n" for k, v in meta.items())
            with open(tmp, "w", encoding="utf-8") as fh:
                fh.write(head)
                record.data.to_csv(fh, index=False, float_format="%.10g")
        else:
            import pyarrow as pa
            import pyarrow.parquet as pq

            table = pa.Table.from_pandas(record.data, preserve_index=False)
            table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                                   META_KEY: json.dumps(meta).encode()})
            pq.write_table(table, tmp)
        if overwrite:
            os.replace(tmp, path)
        else:
            _create_exclusively(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def _create_exclusively(tmp: Path, path: Path) -> None:
    """Give the finished ``tmp`` the name ``path`` only if nothing has that name: of two
    processes writing the same file, one wins and the other gets ``FileExistsError`` (a hard link
    is created atomically and never replaces; ``os.replace`` would silently let the second
    writer's file replace the first's)."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise FileExistsError(f"{path} exists (written meanwhile by another process); refusing to overwrite it "
                              "(pass overwrite=True / overwrite=true)") from None
    except OSError:  # a file system without hard links: claim the name exclusively, then move the file onto it
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        os.close(fd)
        os.replace(tmp, path)


def read_records(spec, min_samples: int = 20, states: str = "measured",
                 state_options: dict | None = None, plausibility: str = "error") -> list[Record]:
    """Records from a file, a folder (every .csv/.parquet inside, sorted) or a glob pattern;
    ``states``, ``state_options`` and ``plausibility`` as in :func:`read_record`."""
    if states not in STATES:
        raise ValueError(f"read_records: states='{states}'; expected one of {list(STATES)}")
    p = Path(str(spec)).expanduser()
    if p.is_file():
        files = [p]
    elif p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in SUPPORTED)
    else:
        files = sorted(Path(f) for f in globmod.glob(str(spec)) if Path(f).suffix.lower() in SUPPORTED)
    if not files:
        raise FileNotFoundError(f"{spec}: no record files (.csv/.parquet) found")
    return [read_record(f, min_samples=min_samples, states=states, state_options=state_options,
                        plausibility=plausibility) for f in files]
