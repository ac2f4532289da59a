"""Plausibility checks of records against the vessel, run on every training and validation record
before the model doctor or a run on files (``study.run.records_run``) fits anything.

The schema (``study.records.schema.validate``) checks what a record can say about itself (columns,
NaN, time, degrees for radians). What needs the vessel is checked here:

1. **rudder sign**: by the project's convention ``delta > 0`` turns the ship to starboard (r > 0,
   ``docs/conventions.md``). The sign of the vessel's own steady yaw response to the rudder, and its
   response time, come from a short simulation of the vessel (a 10 deg rudder step, cached per
   vessel); the record's sign is the sign of the correlation of ``delta`` with ``r`` one response
   time later. It is only judged with enough rudder motion and a clear correlation; otherwise
   nothing is said.
2. **speed against the vessel's scale**: the record's operating speed over ground (95th percentile:
   a manoeuvre loses speed, so the median would not do) against the vessel's U0; far outside, with a
   ratio near sqrt(scale) of a plausible model scale, a full-scale record for a model-scale vessel
   (or the reverse) is named, with the vessel config of the same hull at the other scale if
   ``conf/vessel/`` has one, else the Froude scaling.
3. **propeller speed**: the record's operating ``n`` (95th percentile) against the vessel's own n
   (``load_vessel(cfg).n0``); rpm for rps (a ratio near 60) is named. Skipped for vessels without a
   propeller speed (n0 = 0), the waterjet (its ``n`` is a jet velocity) and the Nomoto kind.

``check_records`` returns one line per problem, each naming the file, the column, the value found,
what was expected and the likely fix; with ``strict=True`` it raises :class:`RecordCheckError`
listing them.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

# --------------------------------------------------------------------------------------------- thresholds
# Rudder sign: judged only when the rudder moves enough to drive a yaw response above noise and disturbances
# (the same 2 deg spread below which the doctor calls a record too little excited), and when the lagged
# correlation is clear: on the vessels of conf/vessel/ (zigzags, turning circles, random rudder, 1 % noise) the
# correct sign gives +0.5 to +0.99 (and all 45 real records of ../shared/data/real pass), so 0.3 leaves a margin
# while a rudder column of pure noise stays far below it (|corr| ~ 0.03).
MIN_RUDDER_SPREAD_DEG = 2.0
MIN_RUDDER_CORR = 0.3
# The rudder step of the vessel's reference simulation: large enough for a clear steady turn of every kind,
# small enough to stay near the linear range where the response time means something.
REFERENCE_RUDDER_DEG = 10.0
# Its length in ship-length times L/U0: the slowest vessel here (KVLCC2, course-unstable) reaches 63 % of its
# steady yaw rate after 1.4 L/U0 at 10 deg, so 15 L/U0 is steady.
REFERENCE_DURATION_L = 15.0
# Which of delta and r is flipped: r against the change of psi over this fraction of the record (at least one
# response time); long enough for the heading's noise to average out, short against a drift of a biased r.
HEADING_WINDOW_FRACTION = 0.05
# Fewest overlapping samples for the lagged correlation to mean anything.
MIN_LAG_SAMPLES = 20

# Speed and propeller speed are judged at the record's operating level, a high percentile (robust to a few
# spikes): not the median, because a manoeuvre loses speed (a turning circle down to 0.3 U0 and less). On the
# real records of ../shared/data/real the median speed goes down to 0.14 U0 (Esso Osaka's slow random runs) and
# to 0.28 U0 on the turning circles the doctor's example validates on; the 95th percentile stays within
# 0.32-1.17 U0 (speed) and 0.63-1.31 n0 (n) on all 45 of them.
OPERATING_PERCENTILE = 95.0
# Speed: the record's operating speed sqrt(u^2 + v^2) against the vessel's U0. Tests run at other speeds than
# the design one (Esso Osaka's pond runs at 0.3-1.2 U0), but not 2.5 times faster; slower runs are common, so the
# lower bound sits below the slowest real record (0.32) and still catches a model-scale record given to a
# full-scale vessel for any scale above 1:16 (speed ratio 1/sqrt(scale)).
SPEED_RATIO_MIN = 0.25
SPEED_RATIO_MAX = 2.5
# Scales lambda = L_full / L_model of free-running model tests (1:5 for large models up to 1:150 for pond
# models); a speed ratio near sqrt(lambda) in this range points at a record of the other scale (Froude).
MODEL_SCALE_RANGE = (5.0, 150.0)
# A vessel config of conf/vessel/ whose U0 is within this factor of the record's speed is suggested.
SUGGEST_SPEED_FACTOR = 1.5

# Propeller speed: the record's operating n against the vessel's n0 (self-propulsion point or configured value);
# the same band as the speed (n is roughly proportional to the speed at a given loading).
N_RATIO_MIN = 0.4
N_RATIO_MAX = 2.5
# Unit mix-ups recognised from the ratio, within N_UNIT_TOLERANCE (a record's n differs from the vessel's
# self-propulsion point by up to ~20 %: HSVA's KVLCC2 ran 10.23 rps, the MMG model's point is 11.8 rps).
N_UNIT_FACTORS = ((60.0, "rpm", "divide by 60"), (2.0 * math.pi, "rad/s", "divide by 2*pi"))
N_UNIT_TOLERANCE = 1.25
# Kinds whose n is not a propeller speed in rps (waterjet: jet velocity in m/s) or carries none (nomoto).
N_SKIP_KINDS = ("waterjet", "nomoto")


class RecordCheckError(ValueError):
    """Records that fail a plausibility check; ``problems`` holds one line per problem (the first
    is the first line of the message)."""

    def __init__(self, problems):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


# ------------------------------------------------------------------------------------------- the vessel
@dataclass(frozen=True)
class VesselFacts:
    """What the checks need to know about a vessel (computed once per vessel config)."""

    name: str
    kind: str
    scale: str | None
    L: float
    U0: float
    n0: float
    yaw_sign: float  # sign of the steady yaw rate for delta > 0 (+1 by the convention), 0 if undetermined
    response_time: float  # s: time for r to reach 63 % of its steady value after the reference rudder step


_FACTS: dict = {}


def _plain(cfg) -> dict:
    if isinstance(cfg, dict):
        return cfg
    try:  # a Hydra/OmegaConf config
        from omegaconf import OmegaConf

        return OmegaConf.to_container(cfg, resolve=True)
    except Exception:  # noqa: BLE001 - anything mapping-like
        return dict(cfg)


def _key(cfg: dict) -> str:
    return json.dumps(cfg, sort_keys=True, default=str)


def vessel_facts(vessel_cfg) -> VesselFacts:
    """The vessel's name, kind, scale, L, U0, n0, and its yaw response to a rudder step
    (simulated once per vessel config and cached)."""
    cfg = _plain(vessel_cfg)
    key = _key(cfg)
    if key in _FACTS:
        return _FACTS[key]
    from study.sim import load_vessel, simulate

    vessel = load_vessel(cfg)
    L, U0 = vessel.L, vessel.U0
    sign, t63 = 0.0, L / U0
    try:
        calm = vessel.with_params(current_speed=0.0, wind_speed=0.0, ext_X=0.0, ext_Y=0.0, ext_N=0.0)
        step = {"name": "rudder_step", "type": "turning", "first": "starboard", "amp_deg": REFERENCE_RUDDER_DEG,
                "pullout_deg": 1e9, "t_start": 0.0, "duration": REFERENCE_DURATION_L * L / U0}
        df = simulate(calm, step)
        t, r = df["time"].to_numpy(float), df["r"].to_numpy(float)
        r_ss = float(np.mean(r[-max(1, len(r) // 10):]))
        if np.all(np.isfinite(r)) and abs(r_ss) * L / U0 > 1e-4:  # a turn, not numerical noise
            sign = math.copysign(1.0, r_ss)
            reached = np.flatnonzero(r * sign >= 0.632 * abs(r_ss))
            if reached.size:
                t63 = float(t[reached[0]] - t[0])
    except Exception:  # noqa: BLE001 - a vessel the simulator cannot run: the rudder check is skipped
        sign = 0.0
    facts = VesselFacts(str(cfg.get("name", "vessel")), str(cfg.get("kind", "")), cfg.get("scale"), L, U0,
                        float(vessel.n0), sign, t63)
    _FACTS[key] = facts
    return facts


_CONFIGS: list | None = None


def _other_configs() -> list:
    """(name, kind, Lpp, U0, hull key) of every vessel config in conf/vessel/ (read once)."""
    global _CONFIGS
    if _CONFIGS is None:
        from study.configuration.compose import list_configs, read_config

        out = []
        for name in list_configs("vessel"):
            try:
                c = read_config("vessel", name)
                out.append((name, c.get("kind"), float(c["particulars"]["Lpp"]), float(c["operation"]["U0"]),
                            _key(c.get("hull") or c.get("nomoto"))))
            except Exception:  # noqa: BLE001 - a config that does not parse is simply not suggested
                continue
        _CONFIGS = out
    return _CONFIGS


def _same_hull_at_speed(vessel_cfg: dict, facts: VesselFacts, speed: float) -> list:
    """Configs of the same hull (equal non-dimensional coefficients: the same ship at another
    scale) whose U0 is within SUGGEST_SPEED_FACTOR of ``speed``."""
    hull = _key(vessel_cfg.get("hull") or vessel_cfg.get("nomoto"))
    out = []
    for name, kind, L, U0, h in _other_configs():
        if name == facts.name or kind != facts.kind or h != hull:
            continue
        if 1.0 / SUGGEST_SPEED_FACTOR <= speed / U0 <= SUGGEST_SPEED_FACTOR:
            out.append((abs(math.log(speed / U0)), name, L, U0))
    return [o[1:] for o in sorted(out)]


# ------------------------------------------------------------------------------------------- the checks
def _g(x: float) -> str:
    return f"{x:.4g}"


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    den = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / den if den > 0 else float("nan")


def _operating(x: np.ndarray) -> float:
    return float(np.percentile(x, OPERATING_PERCENTILE))


def _check_speed(where, df, facts: VesselFacts, cfg: dict):
    """(problem or None, Froude speed factor of the record against the vessel: 1 when the speed
    is plausible, else the record's operating speed over U0)."""
    if facts.U0 <= 0:
        return None, 1.0
    speed = _operating(np.hypot(df["u"].to_numpy(float), df["v"].to_numpy(float)))
    ratio = speed / facts.U0
    if SPEED_RATIO_MIN <= ratio <= SPEED_RATIO_MAX:
        return None, 1.0
    head = (f"{where}: columns 'u', 'v' give an operating speed (95th percentile of sqrt(u^2 + v^2)) of "
            f"{_g(speed)} m/s, {_g(ratio)} times the vessel's U0 = {_g(facts.U0)} m/s ({facts.name}, Lpp "
            f"{_g(facts.L)} m; expected {SPEED_RATIO_MIN}-{SPEED_RATIO_MAX} times U0)")
    lam = ratio ** 2 if ratio > 1 else 1.0 / ratio ** 2 if ratio > 0 else math.inf
    lo, hi = MODEL_SCALE_RANGE
    if lo <= lam <= hi and (facts.scale != "full" if ratio > 1 else facts.scale != "model"):
        s = math.sqrt(lam)
        if ratio > 1:
            what = (f"full-scale record for a model-scale vessel? ({_g(ratio)} = sqrt({lam:.3g}): a ship of Lpp "
                    f"about {facts.L * lam:.3g} m at the same Froude number)")
            froude = (f"Froude-scale the record to the model at 1:{lam:.3g} (time and speeds / {s:.3g}, x0 and y0 "
                      f"/ {lam:.3g}, r and n * {s:.3g})")
        else:
            what = (f"model-scale record for a full-scale vessel? (1/{_g(1 / ratio)} = 1/sqrt({lam:.3g}): a model "
                    f"of Lpp about {facts.L / lam:.3g} m at the same Froude number)")
            froude = (f"Froude-scale the record to full scale at {lam:.3g}:1 (time and speeds * {s:.3g}, x0 and y0 "
                      f"* {lam:.3g}, r and n / {s:.3g})")
        alt = _same_hull_at_speed(cfg, facts, speed)
        if alt:
            fix = ("use the vessel config " + " or ".join(f"{n} (Lpp {_g(L)} m, U0 {_g(U)} m/s)" for n, L, U in alt)
                   + f" from conf/vessel/ (vessel={alt[0][0]}), or {froude}")
        else:
            fix = f"use the vessel config of that scale, or {froude}"
        return f"{head}: {what}: {fix}", ratio
    fix = ("check the vessel config (vessel=...) and that u, v are in m/s" if ratio > 1 else
           "check the vessel config (vessel=...), that u, v are in m/s and that the record is not at rest")
    return f"{head}: {fix}", ratio


def _check_n(where, df, facts: VesselFacts, speed_factor: float):
    if facts.kind in N_SKIP_KINDS or not facts.n0 > 0:
        return None
    n = _operating(df["n"].to_numpy(float))
    ratio = n / facts.n0
    if N_RATIO_MIN <= ratio <= N_RATIO_MAX:
        return None
    head = (f"{where}: column 'n' has an operating value (95th percentile) of {_g(n)}, {_g(ratio)} times the "
            f"vessel's n0 = {_g(facts.n0)} rps ({facts.name}; expected {N_RATIO_MIN}-{N_RATIO_MAX} times n0, in rps)")
    # a record at another scale (Froude: n scales as 1/sqrt(scale), the speed as sqrt(scale))
    tol = math.log(N_UNIT_TOLERANCE)
    if speed_factor not in (0.0, 1.0) and ratio > 0 and abs(math.log(ratio * speed_factor)) <= tol:
        return (f"{head}: consistent with the speed, a record at another scale (n scales as 1/sqrt(scale)): "
                "use the vessel config of the record's scale")
    for factor, unit, fix in N_UNIT_FACTORS:
        if ratio > 0 and abs(math.log(ratio / factor)) <= tol:
            return f"{head}: n looks like {unit}, the schema wants rps: {fix}"
    if ratio <= 0:
        return f"{head}: a propeller running astern or stopped; check the sign and the column of n"
    return f"{head}: check the units of n (rps) and the vessel config"


def _check_rudder(where, df, facts: VesselFacts, speed_factor: float):
    if facts.yaw_sign == 0:
        return None
    t = df["time"].to_numpy(float)
    delta = df["delta"].to_numpy(float)
    if math.degrees(float(np.std(delta))) <= MIN_RUDDER_SPREAD_DEG:
        return None
    r = df["r"].to_numpy(float)
    # a record at another scale: the Froude time scale sqrt(scale) is the speed factor (1 at a plausible speed)
    lag = facts.response_time * speed_factor if speed_factor > 0 else facts.response_time
    keep = t + lag <= t[-1]
    if keep.sum() < MIN_LAG_SAMPLES:
        return None
    d = delta[keep]
    c = _corr(d, np.interp(t[keep] + lag, t, r))
    if not (abs(c) > MIN_RUDDER_CORR) or math.copysign(1.0, c) == facts.yaw_sign:
        return None
    expected = "> 0" if facts.yaw_sign > 0 else "< 0"
    found = (f"corr(delta, r {_g(lag)} s later) = {c:+.2f}; expected {expected} for vessel {facts.name}, "
             "delta > 0 turns to starboard")
    # which one is flipped: r against the heading, as the change of psi and the integral of r over a window
    # (integrating, not differentiating, and a long window keep the noise of both low)
    h = max(lag, HEADING_WINDOW_FRACTION * (t[-1] - t[0]))
    R = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])
    psi = df["psi"].to_numpy(float)
    w = t + h <= t[-1]
    c_psi = (_corr(np.interp(t[w] + h, t, psi) - psi[w], np.interp(t[w] + h, t, R) - R[w])
             if w.sum() >= MIN_LAG_SAMPLES else float("nan"))
    if c_psi < -MIN_RUDDER_CORR:
        return (f"{where}: column 'r' has the opposite sign to the rudder and to the heading ({found}; "
                f"corr(change of psi, integral of r) = {c_psi:+.2f}, expected > 0): flip the yaw rate sign "
                "(r = -r)")
    return f"{where}: column 'delta' has the opposite sign to the yaw response ({found}): flip the rudder sign " \
           "(delta = -delta)"


def _where(i: int, rec, names) -> str:
    if names is not None and i < len(names) and names[i]:
        return str(names[i])
    path = getattr(rec, "path", None)
    if path:
        return str(path)
    meta = getattr(rec, "meta", None) or {}
    if meta.get("name"):
        return str(meta["name"])
    return f"record {i}"


# The physical envelope of a record's channels for the vessel's scale: a value outside it is no measurement
# (one sample of u = 1e300 changed every estimate of a run that then ended "ok"). Generous on purpose: speeds up
# to ENVELOPE_SPEED U0 and yaw rates up to ENVELOPE_SPEED U0/L (a record of the same hull at another scale, which
# the speed check names, stays inside for scale factors up to ENVELOPE_SPEED^2), positions no farther from the
# start than that speed carries the ship in the record's time plus ten ship lengths, a rudder angle within 90 deg,
# a propeller speed within 100 times the vessel's.
ENVELOPE_SPEED = 20.0


def _envelope(df, facts: VesselFacts) -> dict:
    """column -> (low, high, what) of the channels the record has."""
    L, U0 = facts.L, facts.U0
    out = {}
    if not (L > 0 and U0 > 0 and math.isfinite(L) and math.isfinite(U0)):
        return out
    vmax = ENVELOPE_SPEED * U0
    for c in ("u", "v"):
        out[c] = (-vmax, vmax, f"|{c}| <= {ENVELOPE_SPEED:g} U0 = {vmax:.3g} m/s")
    rmax = ENVELOPE_SPEED * U0 / L
    out["r"] = (-rmax, rmax, f"|r| <= {ENVELOPE_SPEED:g} U0/L = {rmax:.3g} rad/s")
    for c in ("delta", "delta_cmd"):
        out[c] = (-math.pi / 2, math.pi / 2, f"|{c}| <= pi/2 rad (90 deg)")
    if "time" in df.columns and len(df):
        t = df["time"].to_numpy(float)
        span = float(np.nanmax(t) - np.nanmin(t)) if np.isfinite(t).any() else 0.0
        reach = vmax * span + 10 * L
        for c in ("x0", "y0"):
            if c in df.columns and len(df):
                first = df[c].to_numpy(float)[0]
                if math.isfinite(first):
                    out[c] = (first - reach, first + reach, f"within {reach:.3g} m of its first value "
                              f"({ENVELOPE_SPEED:g} U0 over the record's {span:.3g} s, plus 10 L)")
    if facts.n0 > 0:
        nmax = 100 * facts.n0
        out["n"] = (-nmax, nmax, f"|n| <= 100 n0 = {nmax:.3g} rps")
    return out


def check_envelope(vessel_cfg, records: list, names: list[str] | None = None) -> None:
    """Refuse the first value outside its channel's physical envelope for the vessel
    (:data:`ENVELOPE_SPEED`), naming the file, the column, the row (the record's data rows from
    1) and the value; raises :class:`RecordCheckError`. Not switched off by ``checks=off``: such
    a value is no measurement."""
    facts = vessel_facts(_plain(vessel_cfg))
    for i, rec in enumerate(records):
        df = rec.data if hasattr(rec, "data") else rec
        for col, (lo, hi, what) in _envelope(df, facts).items():
            if col not in df.columns:
                continue
            x = df[col].to_numpy(float)
            bad = np.flatnonzero(~((x >= lo) & (x <= hi)) & np.isfinite(x))
            if bad.size:
                j = int(bad[0])
                t = f" (time {df['time'].iloc[j]:g} s)" if "time" in df.columns else ""
                more = f", and {bad.size - 1} more row(s)" if bad.size > 1 else ""
                raise RecordCheckError([f"{_where(i, rec, names)}: column '{col}', row {j + 1}{t}: {x[j]:.6g}: "
                                        f"expected {what} for vessel {facts.name}{more}"])


def check_records(vessel_cfg: dict, records: list, names: list[str] | None = None, strict: bool = True) -> list[str]:
    """Plausibility checks of records against the vessel (rudder sign, speed against the vessel's
    scale, propeller speed against the vessel's): see the module docstring.

    records: :class:`study.records.schema.Record` objects (with ``.data``, ``.path``, ``.meta``) or
    plain schema DataFrames. names: what to call each record in the messages (default: its path,
    else ``meta['name']``, else ``record <i>``). Returns the problems found, one line each, in
    record order; with ``strict=True`` raises :class:`RecordCheckError` listing them (the first line
    the first problem) when any is found. A column the record lacks is not checked here (that is the
    schema's job).
    """
    cfg = _plain(vessel_cfg)
    facts = vessel_facts(cfg)
    problems: list[str] = []
    for i, rec in enumerate(records):
        df = rec.data if hasattr(rec, "data") else rec
        where = _where(i, rec, names)
        cols = set(df.columns)
        factor = 1.0
        if {"u", "v"} <= cols and len(df):
            p, factor = _check_speed(where, df, facts, cfg)
            if p:
                problems.append(p)
        if {"time", "delta", "r", "psi"} <= cols and len(df) >= MIN_LAG_SAMPLES:
            p = _check_rudder(where, df, facts, factor)
            if p:
                problems.append(p)
        if "n" in cols and len(df):
            p = _check_n(where, df, facts, factor)
            if p:
                problems.append(p)
    if strict and problems:
        raise RecordCheckError(problems)
    return problems
