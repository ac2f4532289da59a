"""Identify a model with a set of effects, and replay it through records.

The model is a vessel kind's force model: the vessel config holds the coefficients as the user knows them
(captive tests, CFD, a previous identification); the model config may free some of them (``equations``) and
drop some (``omit``); effects from :mod:`.effects` add their physics. Identification is by equation error with
variable projection (Golub & Pereyra 1973): for given values of the effects' nonlinear parameters (current,
wind, steering-gear lag and delay, h/T) the rows are built and every linear unknown (free coefficients, the
linear effects) follows by least squares; the nonlinear parameters minimise the training error, from a small
grid then Powell's method inside their bounds. The identified model is then replayed open loop through each
record with its measured rudder and propeller (``study.sim.replay``), the error per channel measured.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import linalg, optimize

from ..identify.output_error import initial_value
from ..identify.regression import kind_regressors
from ..identify.structures import make_structure, segments
from ..sim import load_vessel, replay, wind_forces
from ..sim.effects import ShallowWater
from .effects import CATALOGUE, NONLINEAR_HULL, scale_of

EQUATIONS = ("X", "Y", "N")
CHANNELS = ("u", "v", "r", "psi")
UNITS = {"u": "m/s", "v": "m/s", "r": "rad/s", "psi": "rad", "track": "m"}


@dataclass
class Fit:
    """One identification: the effects, their outer parameters, the linear unknowns, the training error."""

    effects: tuple
    outer: dict
    coefs: dict
    training_error: float
    rss: dict = field(default_factory=dict)
    evaluations: int = 0


class DoctorProblem:
    """Records and a model, ready to be identified with any set of effects.

    Parameters
    ----------
    vessel_cfg : dict
        The vessel as the user knows it (``conf/vessel``), including a known depth already applied if any.
    model_cfg : dict
        A ``type: kind`` model config: ``equations`` (coefficients to identify; may be empty: a known model),
        ``omit`` (terms set to zero).
    records : list of DataFrames/Records (training)
    structure : str, dict or None
        The sample structure of the rows. Default: Savitzky-Golay smoothing over a fifth of the time the ship
        takes to travel its length (cubic; measured: it cuts the errors-in-variables bias of the effects'
        estimates several-fold against integral or central rows at 1 % noise, because the nonlinear force
        functions are evaluated on smoothed states).
    """

    def __init__(self, vessel_cfg: dict, model_cfg: dict, records, structure=None):
        self.vessel_cfg = vessel_cfg
        self.base = load_vessel(vessel_cfg)
        if model_cfg.get("type", "kind") != "kind":
            raise ValueError(f"the doctor works with force models (type: kind); model '{model_cfg.get('name')}' "
                             f"is of type '{model_cfg.get('type')}'")
        if model_cfg.get("kind") and model_cfg["kind"] != self.base.kind_name:
            raise ValueError(f"model '{model_cfg.get('name')}' is for vessel kind '{model_cfg['kind']}', but vessel "
                             f"'{self.base.name}' is of kind '{self.base.kind_name}'")
        names = self.base.param_names
        eqs = model_cfg.get("equations") or {}
        self.free = {e: list(eqs.get(e) or []) for e in EQUATIONS}
        self.omit = list(model_cfg.get("omit") or [])
        bad = [c for c in sum(self.free.values(), []) + self.omit if c not in names]
        if bad:
            raise ValueError(f"model '{model_cfg.get('name')}': {bad} are not parameters of vessel kind "
                             f"'{self.base.kind_name}'")
        self.model_name = str(model_cfg.get("name"))
        if structure is None:
            T = float(vessel_cfg["particulars"]["Lpp"]) / float(vessel_cfg["operation"]["U0"])
            structure = {"name": "smoothed", "smoothing": {"window_s": 0.2 * T, "polyorder": 3}}
        self.structure = make_structure(structure) if not hasattr(structure, "ops") else structure
        if self.structure.simulates:
            raise ValueError("the doctor identifies by equation error: choose a regression structure")
        self.records = [r.data if hasattr(r, "data") else r for r in records]
        self.segments = [seg for i, df in enumerate(self.records) for seg in segments(df, i, min_len=10)]
        if not self.segments:
            raise ValueError("no training record has 10 consecutive samples")
        self.measured_wind = all({"wind_speed", "wind_dir"} <= set(df.columns) for df in self.records)
        p = vessel_cfg["particulars"]
        self.L, self.U0 = float(p["Lpp"]), self.base.U0
        q = 0.5 * float(p["rho"]) * self.L * float(p["d"]) * self.U0 ** 2
        self.scale = np.array([q, q, q * self.L])
        # the spread below which a channel is taken as constant when errors are normalised (2 % of the speed,
        # of the yaw rate U0/L, 0.02 rad): a straight run's r has no spread, its error must not blow up
        self.floors = {"u": 0.02 * self.U0, "v": 0.02 * self.U0, "r": 0.02 * self.U0 / self.L, "psi": 0.02}
        self._ref = None
        self._node_cache = {}

    # ---------------------------------------------------------------------------------------- parameters
    def hull_extra(self) -> list:
        """The coefficients ``hull_nonlinear`` frees: the model's omitted terms, else the kind's nonlinear
        hull terms that the model does not already identify."""
        if self.omit:
            return list(self.omit)
        free = set(sum(self.free.values(), []))
        return [c for c in NONLINEAR_HULL.get(self.base.kind_name, ()) if c not in free]

    def outer_params(self, effects) -> list:
        """(name, lo, hi, grid) of the nonlinear parameters of ``effects``, bounds in physical units."""
        out = []
        for e in effects:
            eff = CATALOGUE[e]
            if e == "wind" and self.measured_wind:
                continue  # measured wind: one linear factor instead
            for p in eff.params:
                s = scale_of(p.name, self.U0, self.L)
                out.append((p.name, p.lo * s, p.hi * s, tuple(g * s for g in p.grid)))
        return out

    def vessel(self, effects, outer: dict, coefs: dict | None = None, replay: bool = True):
        """The simulation vessel: depth, identified coefficients and the effects' parameters set. ``replay``:
        driven by a record's rudder angle (applied as measured unless rudder_dynamics says it is a command);
        otherwise (closed-loop manoeuvres) the vessel's own steering gear."""
        cfg = self.vessel_cfg
        v = load_vessel(cfg, [ShallowWater(h_T=outer["h_T"])]) if "shallow_water" in effects else self.base
        ch = {c: 0.0 for c in self.omit}
        for name, val in (coefs or {}).items():
            if name in v.param_names:
                ch[name] = float(val)
        if "current" in effects:
            n, e = outer["current_north"], outer["current_east"]
            ch["current_speed"], ch["current_dir"] = math.hypot(n, e), math.atan2(e, n)
        if "wind" in effects and not self.measured_wind:
            n, e = outer["wind_from_north"], outer["wind_from_east"]
            ch["wind_speed"], ch["wind_dir"] = math.hypot(n, e), math.atan2(e, n)
        if "yaw_bias" in effects and coefs:
            ch["ext_Y"] = float(coefs.get("yaw_bias_Y", 0.0)) * self.scale[1]
            ch["ext_N"] = float(coefs.get("yaw_bias_N", 0.0)) * self.scale[2]
        if "rudder_dynamics" in effects:  # the record's rudder is the command: the steering gear acts on it
            ch["rudder_lag"], ch["rudder_delay"] = outer["rudder_lag"], outer["rudder_delay"]
        elif replay:  # the record's rudder angle is the actual one: applied as measured
            ch.update(rudder_rate=0.0, rudder_lag=0.0, rudder_delay=0.0, delta_max=math.pi)
        return v.with_params(**ch)

    # ---------------------------------------------------------------------------------------------- rows
    def _free_names(self, effects) -> list:
        names = list(dict.fromkeys(sum(self.free.values(), [])))
        if "hull_nonlinear" in effects:
            names += [c for c in self.hull_extra() if c not in names]
        return names

    def rows(self, effects, outer: dict, records=None, segs=None):
        """Per equation (Phi, y, names) of the records (default: the training ones; or the given segments)."""
        v = self.vessel(effects, outer)
        free = self._free_names(effects)
        names = v.param_names
        idx = [names.index(c) for c in free]
        P0 = v.params.copy()
        P0[idx] = 0.0
        for c in self.omit:
            P0[names.index(c)] = 0.0
        if segs is None:
            segs = self.segments if records is None else [s for i, df in enumerate(records)
                                                          for s in segments(df, i, min_len=10)]
        rows_y, rows_phi, rows_extra = [], [], []
        extra_names = []
        for seg in segs:
            data = dict(seg.data)
            changed = []
            psi = data["psi"]
            if "current" in effects:
                n, e = outer["current_north"], outer["current_east"]
                data["u"] = data["u"] - (n * np.cos(psi) + e * np.sin(psi))
                data["v"] = data["v"] - (-n * np.sin(psi) + e * np.cos(psi))
                changed += ["u", "v"]
            if "rudder_dynamics" in effects:
                data["delta"] = self.actual_rudder(v, seg.t, data["delta"], data["n"])
                changed.append("delta")
            seg2 = type(seg)(seg.t, data, seg.record)
            nodes = self._nodes(seg, seg2, changed)
            ops = self.structure.ops(seg2, 1)
            y3, phi3 = kind_regressors(v, P0, idx, nodes, seg2.data, ops, self.scale)
            extra = []
            extra_names = []
            if "wind" in effects:
                if self.measured_wind:  # one factor per coefficient c_x, c_y, c_n (each equation its own)
                    F = wind_forces(v, nodes["u"], nodes["v"], nodes["psi"], nodes["wind_speed"], nodes["wind_dir"])
                    Fv = ops.value(F) / self.scale
                    for k, eq in enumerate(EQUATIONS):
                        col = np.zeros_like(Fv)
                        col[:, k] = Fv[:, k]
                        extra.append(col)
                        extra_names.append(f"wind_factor_{eq}")
                else:
                    n, e = outer["wind_from_north"], outer["wind_from_east"]
                    F = wind_forces(v, nodes["u"], nodes["v"], nodes["psi"], math.hypot(n, e), math.atan2(e, n))
                    y3 = y3 - ops.value(F) / self.scale
            if "yaw_bias" in effects:
                one = np.zeros((len(ops), 3))
                two = np.zeros((len(ops), 3))
                one[:, 1] = 1.0
                two[:, 2] = 1.0
                extra += [one, two]
                extra_names += ["yaw_bias_Y", "yaw_bias_N"]
            rows_y.append(y3)
            rows_phi.append(phi3)
            rows_extra.append(np.stack(extra, axis=2) if extra else np.zeros((len(ops), 3, 0)))
        y = np.concatenate(rows_y)
        phi = np.concatenate(rows_phi)
        ex = np.concatenate(rows_extra, axis=0)
        out = {}
        for e_i, eq in enumerate(EQUATIONS):
            cols = [j for j, c in enumerate(free) if c[0] == eq]
            ecols = [j for j, c in enumerate(extra_names) if c.endswith("_" + eq)]
            Phi = np.column_stack([phi[:, e_i, cols], ex[:, e_i, ecols]]) if (cols or ecols) else np.zeros((len(y), 0))
            out[eq] = (Phi, y[:, e_i], [free[j] for j in cols] + [extra_names[j] for j in ecols])
        return out

    def _nodes(self, seg, seg2, changed):
        """The structure's node values of a segment, the unchanged columns' cached (smoothing every column of
        every segment at every evaluation would cost as much as the rest of the rows)."""
        key = (id(seg), seg.record, len(seg.t))
        if key not in self._node_cache:
            self._node_cache[key] = self.structure.nodes(seg)
        nodes = dict(self._node_cache[key])
        if changed:
            nodes.update(self.structure.nodes(type(seg)(seg.t, {c: seg2.data[c] for c in changed}, seg.record)))
        return nodes

    def actual_rudder(self, v, t, delta, n):
        """The rudder angle the vessel's steering gear (rate, lag, delay) makes of a commanded series: the
        integrator's own actuator, run open loop over the record (its output does not depend on the hull)."""
        t = np.asarray(t, float)
        h = float(np.median(np.diff(t)))
        tu = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
        d_u = np.interp(tu, t, delta)
        out = replay(v, tu, d_u, np.interp(tu, t, n), [self.U0, 0.0, 0.0, 0.0, 0.0, 0.0])
        return np.interp(t, tu, out[:, 6, 0])

    def reference(self) -> dict:
        """Per equation the sum of squared targets of the effect-free rows: the scale of the training error."""
        if self._ref is None:
            rows = self.rows((), {})
            self._ref = {eq: float(np.sum(y ** 2)) or 1.0 for eq, (_, y, _) in rows.items()}
        return self._ref

    # ------------------------------------------------------------------------------------- identification
    def solve(self, effects, outer: dict):
        """Linear unknowns by least squares for fixed outer parameters: (coefs, training error, rss)."""
        rows = self.rows(effects, outer)
        ref = self.reference()
        coefs, rss, J = {}, {}, 0.0
        for eq, (Phi, y, names) in rows.items():
            if Phi.shape[1]:
                c, *_ = linalg.lstsq(Phi, y, lapack_driver="gelsd")
                r = y - Phi @ c
                coefs.update(dict(zip(names, (float(x) for x in c))))
            else:
                r = y
            rss[eq] = float(np.sum(r ** 2))
            J += rss[eq] / ref[eq]
        return coefs, J / len(rows), rss

    def fit(self, effects, start: dict | None = None, grid: bool = True, fixed=(), refine: bool = False,
            max_evals: int = 100) -> Fit:
        """Identify the model with ``effects``.

        The outer parameters not in ``fixed`` (those keep their ``start`` values) start from ``start`` where
        known and from the grid of their effect otherwise; the best start point is polished by Powell's method
        inside the bounds (equation error, variable projection). With ``refine`` they are then polished on the
        training records' replay error (output error, the linear unknowns still by equation error at each
        point): less biased by measurement noise than the equation error.
        """
        effects = tuple(effects)
        spec = self.outer_params(effects)
        if not spec:
            coefs, J, rss = self.solve(effects, {})
            return Fit(effects, {}, coefs, J, rss, 1)
        start = dict(start or {})
        fixed_vals = {n: start[n] for n in fixed if n in start}
        spec = [s for s in spec if s[0] not in fixed_vals]
        names = [s[0] for s in spec]
        lo = np.array([s[1] for s in spec])
        hi = np.array([s[2] for s in spec])
        count = [0]

        def outer_of(x):
            return {**fixed_vals, **dict(zip(names, (float(v) for v in np.clip(x, lo, hi))))}

        def J(x):
            count[0] += 1
            try:
                return self.solve(effects, outer_of(x))[1]
            except (ValueError, np.linalg.LinAlgError, FloatingPointError):
                return 1e6

        if not names:
            coefs, Jb, rss = self.solve(effects, fixed_vals)
            return Fit(effects, fixed_vals, coefs, Jb, rss, 1)
        known = {n: start[n] for n in names if n in start}
        new = [s for s in spec if s[0] not in known]
        if grid and new:
            import itertools

            pts = []
            for combo in itertools.product(*[s[3] for s in new]):
                x = dict(known)
                x.update({s[0]: g for s, g in zip(new, combo)})
                pts.append(np.array([x[n] for n in names]))
        else:
            pts = [np.array([known.get(n, 0.5 * (a + b)) for n, a, b in zip(names, lo, hi)])]
        vals = [J(p) for p in pts]
        x0 = pts[int(np.argmin(vals))]
        res = optimize.minimize(J, x0, method="Powell", bounds=list(zip(lo, hi)),
                                options={"maxfev": max_evals, "xtol": 1e-3, "ftol": 1e-6})
        best = np.clip(res.x, lo, hi) if res.fun <= min(vals) else x0
        if refine:
            def J_oe(x):
                count[0] += 1
                outer = outer_of(x)
                try:
                    coefs = self.solve(effects, outer)[0]
                except (ValueError, np.linalg.LinAlgError):
                    return 1e6
                f = Fit(effects, outer, coefs, 0.0)
                errs = {i: record_errors(df, self.predict(f, df), self.floors) for i, df in enumerate(self.records)}
                e = validation_error(errs)
                return e if np.isfinite(e) else 1e6

            r2 = optimize.minimize(J_oe, best, method="Powell", bounds=list(zip(lo, hi)),
                                   options={"maxfev": max_evals, "xtol": 1e-3, "ftol": 1e-6})
            if r2.fun < J_oe(best):
                best = np.clip(r2.x, lo, hi)
        outer = outer_of(best)
        coefs, Jb, rss = self.solve(effects, outer)
        return Fit(effects, outer, coefs, Jb, rss, count[0])

    # ------------------------------------------------------------------------------------------- replay
    def predict(self, fit: Fit, df: pd.DataFrame) -> pd.DataFrame | None:
        """The identified model replayed through a record (its measured rudder and propeller), from the
        record's initial state; None when a segment diverges. Only the record's first segment (up to a gap)."""
        seg = segments(df, 0, min_len=10)
        if not seg:
            return None
        seg = seg[0]
        t = seg.t
        h = float(np.median(np.diff(t)))
        tu = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
        data = {c: np.interp(tu, t, a) for c, a in seg.data.items()}
        v = self.vessel(fit.effects, fit.outer, fit.coefs)
        x0 = {c: initial_value(tu, data[c]) for c in ("u", "v", "r", "x0", "y0", "psi")}
        if "current" in fit.effects:
            n, e = fit.outer["current_north"], fit.outer["current_east"]
            x0["u"] -= n * math.cos(x0["psi"]) + e * math.sin(x0["psi"])
            x0["v"] -= -n * math.sin(x0["psi"]) + e * math.cos(x0["psi"])
        if "wind" in fit.effects and self.measured_wind:  # constant wind in the replay: the record's mean
            wn = float(np.mean(data["wind_speed"] * np.cos(data["wind_dir"])))
            we = float(np.mean(data["wind_speed"] * np.sin(data["wind_dir"])))
            f = [float(fit.coefs.get(f"wind_factor_{eq}", 0.0)) for eq in EQUATIONS]
            env = dict(zip(v.param_names, v.params))
            v = v.with_params(wind_speed=math.hypot(wn, we), wind_dir=math.atan2(we, wn), wind_cx=env["wind_cx"] * f[0],
                              wind_cy=env["wind_cy"] * f[1], wind_cn=env["wind_cn"] * f[2])
        state0 = [x0["u"], x0["v"], x0["r"], x0["x0"], x0["y0"], x0["psi"]]
        with np.errstate(all="ignore"):
            out = replay(v, tu, data["delta"], data["n"], state0)[:, :, 0]
        if not np.all(np.isfinite(out[:, :6])):
            return None
        return pd.DataFrame({"time": tu, "u": out[:, 0], "v": out[:, 1], "r": out[:, 2], "x0": out[:, 3],
                             "y0": out[:, 4], "psi": out[:, 5], "delta": out[:, 6]})


#: the NRMSE counted for a channel whose prediction diverged or is off by more: a diverged replay is a
#: bad prediction, not an undefined one, so that candidates can still be compared
NRMSE_CAP = 10.0


def record_errors(meas: pd.DataFrame, pred: pd.DataFrame | None, floors: dict | None = None) -> dict:
    """Per channel RMSE and NRMSE (RMSE over the measured spread, or over ``floors[c]`` when that is larger; at
    most ``NRMSE_CAP``) of a prediction; the track error; a diverged prediction counts ``NRMSE_CAP`` (its RMSE
    is inf) and ``diverged`` is set."""
    out = {}
    if pred is None:
        for c in CHANNELS:
            out[c] = {"rmse": math.inf, "nrmse": NRMSE_CAP}
        out["track"] = {"rmse": math.inf, "nrmse": NRMSE_CAP}
        out["diverged"] = True
        return out
    t = pred["time"].to_numpy()
    m = meas[(meas["time"] >= t[0]) & (meas["time"] <= t[-1])]
    for c in CHANNELS:
        a = m[c].to_numpy()
        b = np.interp(m["time"].to_numpy(), t, pred[c].to_numpy())
        rmse = float(np.sqrt(np.mean((b - a) ** 2)))
        sd = max(float(np.std(a)), (floors or {}).get(c, 0.0))
        out[c] = {"rmse": rmse, "nrmse": min(rmse / sd, NRMSE_CAP) if sd > 0 else NRMSE_CAP}
    dx = np.interp(m["time"].to_numpy(), t, pred["x0"].to_numpy()) - m["x0"].to_numpy()
    dy = np.interp(m["time"].to_numpy(), t, pred["y0"].to_numpy()) - m["y0"].to_numpy()
    tr = float(np.sqrt(np.mean(dx ** 2 + dy ** 2)))
    span = float(np.hypot(np.ptp(m["x0"].to_numpy()), np.ptp(m["y0"].to_numpy())))
    out["track"] = {"rmse": tr, "nrmse": min(tr / span, NRMSE_CAP) if span > 0 else NRMSE_CAP}
    out["diverged"] = False
    return out


def validation_error(errors: dict) -> float:
    """The doctor's single number: the mean NRMSE of u, v, r and psi over the records (inf if one diverged)."""
    vals = [errors[r][c]["nrmse"] for r in errors for c in CHANNELS]
    return float(np.mean(vals)) if vals else math.nan


def residuals(problem: DoctorProblem, fit: Fit, names: list) -> list:
    """Inverse dynamics of the fitted model on the training records: per segment the times, the residual
    forces [N, N, N m] (measured inertial forces minus the model's) and the states and inputs at the rows."""
    out, seen = [], set()
    for seg in problem.segments:
        rows = problem.rows(fit.effects, fit.outer, segs=[seg])
        ops = problem.structure.ops(seg, 1)
        nodes = problem.structure.nodes(seg)
        r = {"record": seg.record, "name": names[seg.record] if seg.record < len(names) else str(seg.record),
             "time": ops.times, "first": seg.record not in seen}
        seen.add(seg.record)
        for k, eq in enumerate(EQUATIONS):
            Phi, y, cols = rows[eq]
            c = np.array([fit.coefs.get(n, 0.0) for n in cols])
            r[eq] = (y - (Phi @ c if Phi.shape[1] else 0.0)) * problem.scale[k]
        for s in ("u", "v", "r", "delta", "psi", "wind_angle_rel"):
            if s in nodes:
                r[s] = ops.value(nodes[s])
        out.append(r)
    return out


def identify_in_study(base, model_cfg: dict, records, structure_cfg, truth) -> dict:
    """A study run's identification of a force model with ``model.effects`` (``python -m study
    model.effects=[current]``): the doctor's variable projection, its outer parameters refined on the training
    replays. Returns ``estimates`` (the vessel's coefficients), ``params`` (rows for the table: coefficients and
    the effects' parameters, with the truth from the truth vessel), ``metrics`` and ``vessel`` (the identified
    model with its own steering gear, for closed-loop validation)."""
    from .effects import describe

    effects = tuple(model_cfg.get("effects") or [])
    pb = DoctorProblem(base.cfg, model_cfg, records, structure_cfg)
    fit = pb.fit(effects, refine=True)
    env = dict(zip(truth.param_names, truth.params))
    q = pb.scale
    truth_eff = {"current_speed": env["current_speed"], "current_direction_deg": math.degrees(env["current_dir"]) % 360,
                 "wind_speed": env["wind_speed"], "wind_direction_deg": math.degrees(env["wind_dir"]) % 360,
                 "rudder_lag": env["rudder_lag"], "rudder_delay": env["rudder_delay"],
                 "yaw_bias_Y": env["ext_Y"] / q[1], "yaw_bias_N": env["ext_N"] / q[2]}
    names = base.param_names
    params = []
    for k, v in {**describe(fit.outer), **fit.coefs}.items():
        eq = k[0] if k in names and k[0] in EQUATIONS else "effect"
        t = float(truth.params[names.index(k)]) if k in names else truth_eff.get(k)
        params.append({"equation": eq, "name": k, "estimate": float(v), "truth": t,
                       "truth_kind": "exact" if k in names else "hidden effect"})
    metrics = {"training_error": fit.training_error, "effect_evaluations": fit.evaluations}
    coefs = {k: v for k, v in fit.coefs.items() if k in names}
    return {"estimates": coefs, "params": params, "metrics": metrics,
            "vessel": pb.vessel(effects, fit.outer, fit.coefs, replay=False)}
