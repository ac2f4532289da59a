"""Records and a force model, ready to be identified with any set of effects
(:class:`EffectsProblem`): the parameters each effect adds, the simulation vessel of a record,
the regression rows, the linear solve and the replay through a record."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd
from scipy import linalg

from . import uncertainty
from .initial_state import fitted_initial_state
from .replay_errors import states_estimated
from .search import Fit
from ..output_error import initial_value
from ..regression import kind_regressors
from ..structures import Segment, make_structure, segments
from ...sim import load_vessel, replay
from ..effects import RecordInfo, describe_values, list_effects, registry

EQUATIONS = ("X", "Y", "N")

#: rate over 20 U0/L (a full turn in a third of a ship length's travel): no ship manoeuvres there
ENVELOPE = {"speed_U0": 5.0, "r_U0_L": 20.0}



def record_h_T(df: pd.DataFrame, meta: dict | None, draft: float) -> float | None:
    """A record's water depth as h/T: its ``depth`` column [m] (median), else ``depth`` in its
    metadata (metres, or a mapping with ``h_T``); None when not measured or deep."""
    if "depth" in df.columns:
        d = pd.to_numeric(df["depth"], errors="coerce").to_numpy(float)
        d = d[np.isfinite(d)]
        if len(d):
            return float(np.median(d)) / draft
    dm = (meta or {}).get("depth")
    if isinstance(dm, dict):
        h = dm.get("h_T")
        return float(h) if h is not None and math.isfinite(float(h)) else None
    if isinstance(dm, (int, float)) and math.isfinite(float(dm)):
        return float(dm) / draft
    return None


def as_frame(r):
    return r.data if hasattr(r, "data") else r



class EffectsProblem:
    """Records and a model, ready to be identified with any set of effects.

    Parameters
    ----------
    vessel_cfg : dict
        The vessel as the user knows it (``conf/vessel``), including a known depth already applied
        if any.
    model_cfg : dict
        A ``type: kind`` model config: ``equations`` (coefficients to identify, per equation; may be
        empty: a known model), ``omit`` (terms set to zero).
    records : list of Records or DataFrames (training)
    structure : str, dict or None
        The sample structure of the rows. Default: Savitzky-Golay smoothing over a fifth of the time
        the ship takes to travel its length (cubic; measured: it cuts the errors-in-variables bias
        of the effects' estimates several-fold against integral or central rows at 1 % noise,
        because the nonlinear force functions are evaluated on smoothed states).
    effects : dict name -> Effect, or None (every discovered effect)
    """

    def __init__(self, vessel_cfg: dict, model_cfg: dict, records, structure=None, effects=None, names=None,
                 anchor: float | None = None):
        self.vessel_cfg = vessel_cfg
        self.base = load_vessel(vessel_cfg)
        if model_cfg.get("type", "kind") != "kind":
            raise ValueError(f"identification with effects works with force models (type: kind); model "
                             f"'{model_cfg.get('name')}' is of type '{model_cfg.get('type')}'")
        if model_cfg.get("kind") and model_cfg["kind"] != self.base.kind_name:
            raise ValueError(f"model '{model_cfg.get('name')}' is for vessel kind '{model_cfg['kind']}', but vessel "
                             f"'{self.base.name}' is of kind '{self.base.kind_name}'")
        self.effects = effects if effects is not None else registry(list_effects())
        pnames = self.base.param_names
        eqs = model_cfg.get("equations") or {}
        bad_eq = [e for e in eqs if e not in EQUATIONS]
        if bad_eq:
            raise ValueError(f"model '{model_cfg.get('name')}': equations {bad_eq}; expected X, Y, N")
        # every free coefficient belongs to the equation its config declares (nothing inferred from its name)
        self.model_eq = {c: e for e in EQUATIONS for c in (eqs.get(e) or [])}
        self.model_free = list(self.model_eq)
        omit = model_cfg.get("omit") or []
        self.omit = [c for e in EQUATIONS for c in (omit.get(e) or [])] if isinstance(omit, dict) else list(omit)
        self.omit_eq = {c: e for e in EQUATIONS for c in ((omit.get(e) or []) if isinstance(omit, dict) else [])}
        bad = [c for c in self.model_free + self.omit if c not in pnames]
        if bad:
            raise ValueError(f"model '{model_cfg.get('name')}': {bad} are not parameters of vessel kind "
                             f"'{self.base.kind_name}'")
        self.model_name = str(model_cfg.get("name"))
        if structure is None:
            T = float(vessel_cfg["particulars"]["Lpp"]) / float(vessel_cfg["operation"]["U0"])
            structure = {"name": "smoothed", "smoothing": {"window_s": 0.2 * T, "polyorder": 3}}
        self.structure = make_structure(structure) if not hasattr(structure, "ops") else structure
        if self.structure.simulates:
            raise ValueError("identification with effects is by equation error: choose a regression structure")
        p = vessel_cfg["particulars"]
        self.L, self.U0, self.draft = float(p["Lpp"]), self.base.U0, float(p["d"])
        self.records = [as_frame(r) for r in records]
        metas = [getattr(r, "meta", None) or {} for r in records]
        names = names or [str(m.get("name") or f"record_{i}") for i, m in enumerate(metas)]
        self.infos = [RecordInfo(i, df, names[i], record_h_T(df, metas[i], self.draft), metas[i])
                      for i, df in enumerate(self.records)]
        self.segments = [seg for i, df in enumerate(self.records) for seg in segments(df, i, min_len=10)]
        if not self.segments:
            raise ValueError("no training record has 10 consecutive samples")
        self.measured_wind = all({"wind_speed", "wind_dir"} <= set(df.columns) for df in self.records)
        q = 0.5 * float(p["rho"]) * self.L * float(p["d"]) * self.U0 ** 2
        self.scale = np.array([q, q, q * self.L])
        # the spread below which a channel is taken as constant when errors are normalised (2 % of the speed,
        # of the yaw rate U0/L, 0.02 rad): a straight run's r has no spread, its error must not blow up
        self.floors = {"u": 0.02 * self.U0, "v": 0.02 * self.U0, "r": 0.02 * self.U0 / self.L, "psi": 0.02}
        self.labels = {}  # parameter -> equation(s), as the rows found them
        # the model's free coefficients anchored to the vessel config's values, relative standard deviation
        # (None or 0: plain least squares)
        self.anchor = float(anchor) if anchor else 0.0
        self.tau = None  # the data weight of one row (uncertainty.noise_per_row), computed once
        self.m_base = None
        self._ref = None
        self._node_cache = {}
        self._reg_cache = {}
        self._vessels = {}

    # ---------------------------------------------------------------------------------------- parameters
    def info_for(self, df: pd.DataFrame, meta: dict | None = None, name: str = "") -> RecordInfo:
        """A record that is not one of the training records (a validation record): its own depth."""
        return RecordInfo(-1, df, name, record_h_T(df, meta, self.draft), meta or {})

    def needs_fitted_depth(self) -> bool:
        return any(i.h_T is None for i in self.infos)

    def base_param(self, name: str) -> float:
        return float(self.base.params[self.base.param_names.index(name)])

    def coef_unit(self, name: str) -> str:
        if name in ("xR", "xH", "xP", "xG"):
            return "m"
        return "- (non-dimensional, the kind's convention)"

    def equation_of(self, name: str) -> str:
        if name in self.model_eq:
            return self.model_eq[name]
        if name in self.omit_eq:
            return self.omit_eq[name]
        return self.labels.get(name, "?")

    def effect(self, name: str):
        if name not in self.effects:
            raise ValueError(f"unknown effect '{name}'; the catalogue has {sorted(self.effects)}")
        return self.effects[name]

    def free_coefficients(self, effects, model: bool = True) -> dict:
        """Free vessel parameters -> equation: the model's (unless ``model`` is False: then the
        vessel config's values are kept), then those the effects free."""
        out = dict(self.model_eq) if model else {}
        for e in effects:
            for c, eq in self.effect(e).free_coefficients(self).items():
                out.setdefault(c, eq)
        return out

    def linear_unknowns(self, effects) -> dict:
        out = {}
        for e in effects:
            out.update({k: eq for k, (_, eq) in self.effect(e).linear(self).items()})
        return out

    def outer_params(self, effects) -> list:
        """(name, lo, hi, grid) of the nonlinear parameters of ``effects``, bounds in physical
        units."""
        return [s for e in effects for s in self.effect(e).outer(self)]

    def variants(self, effects) -> list:
        """Every combination of the effects' discrete variants (one dict each)."""
        per = [self.effect(e).variants(self) for e in effects]
        return [dict(kv for d in combo for kv in d.items()) for combo in itertools.product(*per)] or [{}]

    def by_effect(self, fit: Fit) -> dict:
        """Each effect's own values of a fit: its nonlinear parameters, variant, linear unknowns
        and the coefficients it freed (the model's own free coefficients under 'model')."""
        out = {"model": {c: fit.coefs[c] for c in self.model_free if c in fit.coefs}}
        for e in fit.effects:
            eff = self.effect(e)
            own = [s[0] for s in eff.outer(self)] + [k for v in eff.variants(self) for k in v] + \
                list(eff.linear(self)) + list(eff.free_coefficients(self))
            out[e] = {k: fit.values[k] for k in dict.fromkeys(own) if k in fit.values}
        return out

    def describe(self, fit: Fit, effects=None, model: bool = True) -> dict:
        """The fit's parameters in the user's terms (current as speed and direction, ...), for
        ``effects`` (default: all of the fit's), and with ``model`` the model's own free
        coefficients."""
        own = self.by_effect(fit)
        keep = set(fit.effects if effects is None else effects) | ({"model"} if model else set())
        return describe_values(self.effects, {k: v for k, v in own.items() if k in keep})

    def units(self, effects) -> dict:
        out = {c: self.coef_unit(c) for c in self.model_free}
        for e in effects:
            out.update(self.effect(e).units(self))
        return out

    # -------------------------------------------------------------------------------------------- vessel
    def _load(self, sim_effects: list):
        key = repr(sim_effects)
        if key not in self._vessels:
            if len(self._vessels) > 256:
                self._vessels.clear()
            self._vessels[key] = load_vessel(self.vessel_cfg, sim_effects) if sim_effects else self.base
        return self._vessels[key]

    def vessel(self, effects, values: dict, info: RecordInfo | None = None, coefs: dict | None = None,
               replay: bool = True):
        """The simulation vessel of one record: the effects' simulator effects (depth) and
        parameters, the omitted terms zeroed, and with ``coefs`` the identified coefficients
        (each scaled as the effects scale its published value, e.g. by the record's depth) and
        the effects' constant forces. ``replay``: driven by a record's rudder angle (applied as
        measured unless an effect says it is a command); otherwise (closed-loop manoeuvres) the
        vessel's own steering gear."""
        effs = [self.effect(e) for e in effects]
        sim = [s for eff in effs for s in eff.sim_effects(self, values, info)]
        v = self._load(sim)
        ch = {c: 0.0 for c in self.omit}
        for eff in effs:
            ch.update(eff.vessel_changes(self, values, info))
        if coefs is not None:
            names = v.param_names
            for name, val in coefs.items():
                if name in names:
                    ch[name] = float(val) * self._factor(v, names.index(name))
            ext = np.sum([eff.replay_force(self, values, info) for eff in effs], axis=0) if effs else np.zeros(3)
            env = dict(zip(names, v.params))
            ch.update(ext_X=env["ext_X"] + ext[0], ext_Y=env["ext_Y"] + ext[1], ext_N=env["ext_N"] + ext[2])
        if replay and not any(eff.rudder_is_command for eff in effs):
            ch.update(rudder_rate=0.0, rudder_lag=0.0, rudder_delay=0.0, delta_max=math.pi)
        return v.with_params(**ch)

    def _factor(self, v, i: int) -> float:
        """How the effects scale a coefficient's published value (the depth's factor): 1 when
        unchanged."""
        b = float(self.base.params[i])
        return float(v.params[i]) / b if b != 0.0 else 1.0

    # ---------------------------------------------------------------------------------------------- rows
    def rows(self, effects, values: dict, segs=None, model: bool = True):
        """(y (m, 3), Phi (m, 3, k), names) of the training segments (or the given ones), every
        unknown's column over the three equations; rows scaled by 0.5 rho L d U0^2 (times L for
        N). ``model=False``: the model's own coefficients at the vessel config's values (not
        identified)."""
        effs = [self.effect(e) for e in effects]
        free = list(self.free_coefficients(effects, model))
        lin = list(self.linear_unknowns(effects))
        segs = self.segments if segs is None else segs
        ys, phis = [], []
        for seg in segs:
            info = self.infos[seg.record]
            sim = [s for eff in effs for s in eff.sim_effects(self, values, info)]
            v = self.vessel(effects, values, info)
            names = v.param_names
            idx = [names.index(c) for c in free]
            P0 = v.params.copy()
            P0[idx] = 0.0
            data = dict(seg.data)
            changed = []
            for eff in effs:
                changed += eff.transform(self, seg.t, data, values, v, info)
            seg2 = Segment(seg.t, data, seg.record, seg.source)
            nodes = self._nodes(seg, seg2, changed)
            ops = self.structure.ops(seg2, 1)
            y3, phi3 = self._regressors(seg, v, P0, idx, nodes, seg2, ops, changed)
            if idx:
                loaded = self._load(sim)
                phi3 = phi3 * np.array([self._factor(loaded, i) for i in idx])
            cols = [phi3[:, :, j] for j in range(len(idx))]
            lin_cols = {}
            for eff in effs:
                F = eff.known_forces(self, nodes, values, v, info)
                if F is not None:
                    y3 = y3 - ops.value(F) / self.scale
                for k, F in eff.linear_forces(self, nodes, values, v, info).items():
                    lin_cols[k] = ops.value(F) / self.scale
            cols += [lin_cols[k] for k in lin]
            ys.append(y3)
            phis.append(np.stack(cols, axis=2) if cols else np.zeros(y3.shape + (0,)))
        return np.concatenate(ys), np.concatenate(phis), free + lin

    def _regressors(self, seg, v, P0, idx, nodes, seg2, ops, changed):
        """The kind's regressors of a segment, cached on what they depend on (the vessel's
        parameters and the changed columns): most candidates' outer parameters (wind, steering
        gear...) leave them unchanged, and the compiled equations at every node for every free
        coefficient are most of an evaluation's cost."""
        nk = len(v.kind.PARAM_NAMES)  # the kinds' equations read only their own parameters, not the environment
        key = (id(seg), seg.record, P0[:nk].tobytes(), tuple(idx),
               tuple((c, hash(np.asarray(nodes[c]).tobytes()), hash(np.asarray(seg2.data[c]).tobytes()))
                     for c in changed))
        hit = self._reg_cache.get(key)
        if hit is None:
            hit = kind_regressors(v, P0, idx, nodes, seg2.data, ops, self.scale)
            if len(self._reg_cache) >= 48:
                self._reg_cache.pop(next(iter(self._reg_cache)))
            self._reg_cache[key] = hit
        return hit

    def _nodes(self, seg, seg2, changed):
        """The structure's node values of a segment, the unchanged columns' cached (smoothing
        every column of every segment at every evaluation would cost as much as the rest of the
        rows)."""
        key = (id(seg), seg.record, len(seg.t))
        if key not in self._node_cache:
            self._node_cache[key] = self.structure.nodes(seg)
        nodes = dict(self._node_cache[key])
        if changed:
            nodes.update(self.structure.nodes(Segment(seg.t, {c: seg2.data[c] for c in changed}, seg.record,
                                                      seg.source)))
        return nodes

    def actual_rudder(self, v, t, delta, n):
        """The rudder angle the vessel's steering gear (rate, lag, delay) makes of a commanded
        series: the integrator's own actuator, run open loop over the record (its output does not
        depend on the hull)."""
        t = np.asarray(t, float)
        h = float(np.median(np.diff(t)))
        tu = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
        d_u = np.interp(tu, t, delta)
        out = replay(v, tu, d_u, np.interp(tu, t, n), [self.U0, 0.0, 0.0, 0.0, 0.0, 0.0])
        return np.interp(t, tu, out[:, 6, 0])

    def reference(self) -> np.ndarray:
        """Per equation the sum of squared targets of the effect-free rows: the scale of the
        training error."""
        if self._ref is None:
            y, _, _ = self.rows((), {})
            self._ref = np.array([float(np.sum(y[:, k] ** 2)) or 1.0 for k in range(3)])
        return self._ref

    # ------------------------------------------------------------------------------------- identification
    def solve(self, effects, values: dict, model: bool = True, _unanchored: bool = False):
        """Linear unknowns for fixed nonlinear parameters: one least-squares problem over the
        three equations, each weighted by its reference scale (the training error is the mean of
        rss/reference over X, Y, N). Returns (coefs, training error, rss per equation)."""
        y, Phi, names = self.rows(effects, values, model=model)
        ref = self.reference()
        w = 1.0 / np.sqrt(ref)
        coefs = {}
        penalty = 0.0
        if names:
            # normal equations summed over the equations (the stacked rows are 3 x longer and least squares on
            # them cost most of an evaluation), columns scaled to unit norm (their units differ by orders of
            # magnitude) and solved by SVD, so a rank-deficient set of unknowns still gets the minimum-norm answer
            G = sum(w[k] ** 2 * (Phi[:, k, :].T @ Phi[:, k, :]) for k in range(3))
            h = sum(w[k] ** 2 * (Phi[:, k, :].T @ y[:, k]) for k in range(3))
            anchored = model and self.anchor and not _unanchored
            prior = uncertainty.anchor_prior(self, names, len(y)) if anchored else None
            if prior is not None:  # MAP: the model's coefficients anchored to the vessel config's (see uncertainty.prior)
                theta0, lam = prior
                G = G + np.diag(lam)
                h = h + lam * theta0
            s = np.sqrt(np.diag(G))
            ok = s > 0
            c = np.zeros(len(names))
            if ok.any():
                Gs = G[np.ix_(ok, ok)] / np.outer(s[ok], s[ok])
                cs, *_ = linalg.lstsq(Gs, h[ok] / s[ok], cond=1e-13, lapack_driver="gelsd")
                c[ok] = cs / s[ok]
            r = y - np.einsum("mek,k->me", Phi, c)
            if prior is not None:
                penalty = float(np.sum(prior[1] * (c - prior[0]) ** 2)) / 3.0
            coefs = dict(zip(names, (float(x) for x in c)))
            for j, n in enumerate(names):  # the equations each column acts in, as the rows show it
                norms = np.sqrt(np.sum(Phi[:, :, j] ** 2, axis=0))
                if n not in self.labels and norms.max() > 0:
                    self.labels[n] = ",".join(EQUATIONS[k] for k in range(3) if norms[k] > 1e-9 * norms.max())
        else:
            r = y
        rss = {eq: float(np.sum(r[:, k] ** 2)) for k, eq in enumerate(EQUATIONS)}
        J = float(np.mean([rss[eq] / ref[k] for k, eq in enumerate(EQUATIONS)])) + penalty
        return coefs, J, rss

    def posterior(self, fit: Fit, nonlinear: bool = False) -> dict | None:
        """The Gaussian posterior of a fit's linear unknowns (:func:`uncertainty.posterior`), with
        ``nonlinear`` together with the effects' nonlinear parameters
        (:func:`uncertainty.joint_posterior`)."""
        return uncertainty.joint_posterior(self, fit) if nonlinear else uncertainty.posterior(self, fit)

    def identifiability(self, fit: Fit) -> list[dict]:
        """Per anchored model coefficient, how far the records determine it
        (:func:`uncertainty.identifiability`)."""
        return uncertainty.identifiability(self, fit)

    # ------------------------------------------------------------------------------------------- replay
    def predict(self, fit: Fit, df: pd.DataFrame, info: RecordInfo | None = None) -> pd.DataFrame | None:
        """The identified model replayed through a record (its measured rudder and propeller, its
        own depth), from the record's initial state; None when it diverges (leaves the physical
        envelope ``ENVELOPE``). Only the record's first segment (up to a gap)."""
        seg = segments(df, 0, min_len=10)
        if not seg:
            return None
        seg = seg[0]
        info = info if info is not None else self.info_for(df)
        t = seg.t
        h = float(np.median(np.diff(t)))
        tu = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
        data = {c: np.interp(tu, t, a) for c, a in seg.data.items()}
        values = fit.values
        v = self.vessel(fit.effects, values, info, coefs=fit.coefs)
        x0 = {c: initial_value(tu, data[c]) for c in ("u", "v", "r", "x0", "y0", "psi")}
        for e in fit.effects:
            self.effect(e).initial_state(self, values, x0)
        state0 = [x0["u"], x0["v"], x0["r"], x0["x0"], x0["y0"], x0["psi"]]
        if states_estimated(info.meta):  # estimated u, v, r: the smoother's first estimates are its worst
            state0 = fitted_initial_state(v, tu, data, state0, info.meta, self.L, self.U0)
        with np.errstate(all="ignore"):
            out = replay(v, tu, data["delta"], data["n"], state0)[:, :, 0]
        if not np.all(np.isfinite(out[:, :6])):
            return None
        if (np.max(np.hypot(out[:, 0], out[:, 1])) > ENVELOPE["speed_U0"] * self.U0
                or np.max(np.abs(out[:, 2])) > ENVELOPE["r_U0_L"] * self.U0 / self.L):
            return None
        return pd.DataFrame({"time": tu, "u": out[:, 0], "v": out[:, 1], "r": out[:, 2], "x0": out[:, 3],
                             "y0": out[:, 4], "psi": out[:, 5], "delta": out[:, 6]})

