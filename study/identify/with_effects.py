"""Identify a model with a set of effects, and replay it through records: the identification the model doctor
(``study.doctor``) ranks effects with and a study run with ``model.effects`` (``study.pipeline``,
``study.records_run``) uses.

The model is a vessel kind's force model: the vessel config holds the coefficients as the user knows them
(captive tests, CFD, a previous identification); the model config may free some of them (``equations``, each
coefficient under the equation its config declares) and drop some (``omit``); effects (``study.identify.effects``,
discovered from ``conf/effect``) add their physics through their hooks. Identification is by equation error
with variable projection (Golub & Pereyra 1973): for given values of the effects' nonlinear parameters the
rows are built and every linear unknown (free coefficients, the effects' linear parameters) follows by one
weighted least-squares problem over the three equations together (a parameter such as a_H acts in sway and yaw
at once); the nonlinear parameters minimise the training error, from a small grid then Powell's method inside
their bounds; an effect's discrete variants (shallow water's formulas) are each fitted and the best kept. The
identified model is then replayed open loop through each record with its measured rudder and propeller
(``study.sim.replay``), at each record's own water depth, and the error per channel measured.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import linalg, optimize

from .output_error import initial_value
from .regression import kind_regressors
from .structures import Segment, make_structure, segments
from ..sim import load_vessel, replay
from .effects import RecordInfo, describe_values, list_effects, registry

EQUATIONS = ("X", "Y", "N")
CHANNELS = ("u", "v", "r", "psi")
UNITS = {"u": "m/s", "v": "m/s", "r": "rad/s", "psi": "rad", "track": "m"}

#: a replay is stopped as diverged when it leaves this envelope: speed over 5 times the service speed, yaw
#: rate over 20 U0/L (a full turn in a third of a ship length's travel): no ship manoeuvres there
ENVELOPE = {"speed_U0": 5.0, "r_U0_L": 20.0}


def record_h_T(df: pd.DataFrame, meta: dict | None, draft: float) -> float | None:
    """A record's water depth as h/T: its ``depth`` column [m] (median), else ``depth`` in its metadata (metres,
    or a mapping with ``h_T``); None when not measured or deep."""
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


@dataclass
class Fit:
    """One identification: the effects, their nonlinear parameters and variant (``outer``), the linear unknowns
    (``coefs``: free model coefficients and the effects' linear parameters), the training error."""

    effects: tuple
    outer: dict
    coefs: dict
    training_error: float
    rss: dict = field(default_factory=dict)
    evaluations: int = 0

    @property
    def values(self) -> dict:
        return {**self.outer, **self.coefs}


class EffectsProblem:
    """Records and a model, ready to be identified with any set of effects.

    Parameters
    ----------
    vessel_cfg : dict
        The vessel as the user knows it (``conf/vessel``), including a known depth already applied if any.
    model_cfg : dict
        A ``type: kind`` model config: ``equations`` (coefficients to identify, per equation; may be empty: a
        known model), ``omit`` (terms set to zero).
    records : list of Records or DataFrames (training)
    structure : str, dict or None
        The sample structure of the rows. Default: Savitzky-Golay smoothing over a fifth of the time the ship
        takes to travel its length (cubic; measured: it cuts the errors-in-variables bias of the effects'
        estimates several-fold against integral or central rows at 1 % noise, because the nonlinear force
        functions are evaluated on smoothed states).
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
        self._tau = None
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
        """Free vessel parameters -> equation: the model's (unless ``model`` is False: then the vessel config's
        values are kept), then those the effects free."""
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
        """(name, lo, hi, grid) of the nonlinear parameters of ``effects``, bounds in physical units."""
        return [s for e in effects for s in self.effect(e).outer(self)]

    def variants(self, effects) -> list:
        """Every combination of the effects' discrete variants (one dict each)."""
        per = [self.effect(e).variants(self) for e in effects]
        return [dict(kv for d in combo for kv in d.items()) for combo in itertools.product(*per)] or [{}]

    def by_effect(self, fit: Fit) -> dict:
        """Each effect's own values of a fit: its nonlinear parameters, variant, linear unknowns and the
        coefficients it freed (the model's own free coefficients under 'model')."""
        out = {"model": {c: fit.coefs[c] for c in self.model_free if c in fit.coefs}}
        for e in fit.effects:
            eff = self.effect(e)
            own = [s[0] for s in eff.outer(self)] + [k for v in eff.variants(self) for k in v] + \
                list(eff.linear(self)) + list(eff.free_coefficients(self))
            out[e] = {k: fit.values[k] for k in dict.fromkeys(own) if k in fit.values}
        return out

    def describe(self, fit: Fit, effects=None, model: bool = True) -> dict:
        """The fit's parameters in the user's terms (current as speed and direction, ...), for ``effects``
        (default: all of the fit's), and with ``model`` the model's own free coefficients."""
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
        """The simulation vessel of one record: the effects' simulator effects (depth) and parameters, the
        omitted terms zeroed, and with ``coefs`` the identified coefficients (each scaled as the effects scale
        its published value, e.g. by the record's depth) and the effects' constant forces. ``replay``: driven by
        a record's rudder angle (applied as measured unless an effect says it is a command); otherwise
        (closed-loop manoeuvres) the vessel's own steering gear."""
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
        """How the effects scale a coefficient's published value (the depth's factor): 1 when unchanged."""
        b = float(self.base.params[i])
        return float(v.params[i]) / b if b != 0.0 else 1.0

    # ---------------------------------------------------------------------------------------------- rows
    def rows(self, effects, values: dict, segs=None, model: bool = True):
        """(y (m, 3), Phi (m, 3, k), names) of the training segments (or the given ones), every unknown's
        column over the three equations; rows scaled by 0.5 rho L d U0^2 (times L for N). ``model=False``:
        the model's own coefficients at the vessel config's values (not identified)."""
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
        """The kind's regressors of a segment, cached on what they depend on (the vessel's parameters and the
        changed columns): most candidates' outer parameters (wind, steering gear...) leave them unchanged, and
        the compiled equations at every node for every free coefficient are most of an evaluation's cost."""
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
        """The structure's node values of a segment, the unchanged columns' cached (smoothing every column of
        every segment at every evaluation would cost as much as the rest of the rows)."""
        key = (id(seg), seg.record, len(seg.t))
        if key not in self._node_cache:
            self._node_cache[key] = self.structure.nodes(seg)
        nodes = dict(self._node_cache[key])
        if changed:
            nodes.update(self.structure.nodes(Segment(seg.t, {c: seg2.data[c] for c in changed}, seg.record,
                                                      seg.source)))
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

    def reference(self) -> np.ndarray:
        """Per equation the sum of squared targets of the effect-free rows: the scale of the training error."""
        if self._ref is None:
            y, _, _ = self.rows((), {})
            self._ref = np.array([float(np.sum(y[:, k] ** 2)) or 1.0 for k in range(3)])
        return self._ref

    # ------------------------------------------------------------------------------------- identification
    def solve(self, effects, values: dict, model: bool = True, _unanchored: bool = False):
        """Linear unknowns for fixed nonlinear parameters: one least-squares problem over the three equations,
        each weighted by its reference scale (the training error is the mean of rss/reference over X, Y, N).
        Returns (coefs, training error, rss per equation)."""
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
            prior = self._prior(names, len(y)) if (model and self.anchor and not _unanchored) else None
            if prior is not None:  # MAP: the model's coefficients anchored to the vessel config's (see _prior)
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

    def _noise_per_row(self) -> float:
        """The training error's share of one independent row, from the unanchored baseline fit: its error over
        the EFFECTIVE number of rows per equation, m (1 - rho) / (1 + rho) with rho the lag-one autocorrelation
        of its residuals (smoothed rows of a manoeuvre are far from independent: rho is near 1, and counting
        every row would let any misfit overrule the prior)."""
        y, Phi, names = self.rows((), {})
        coefs, J, _ = self.solve((), {}, model=True, _unanchored=True)
        c = np.array([coefs.get(n, 0.0) for n in names])
        r = y - (np.einsum("mek,k->me", Phi, c) if len(names) else 0.0)
        rho = []
        for k in range(3):
            a = r[:, k] - r[:, k].mean()
            den = float(np.dot(a, a))
            if den > 0:
                rho.append(float(np.dot(a[1:], a[:-1])) / den)
        rho = float(np.clip(np.mean(rho), 0.0, 0.999)) if rho else 0.0
        self._m_base = len(y)
        m_eff = max(1.0, len(y) * (1.0 - rho) / (1.0 + rho))
        return J / m_eff

    def _prior(self, names: list, m: int):
        """(prior values, weights) of the unknowns ``names`` in the normal equations: the model's own free
        coefficients anchored to the vessel config's values (the coefficients the user has: published, captive
        tests, CFD) with a standard deviation of ``anchor`` (relative) times their size, at least ``anchor``
        times the median size of the model's nonzero coefficients (a coefficient published as 0 is not known to
        be 0). The data term is the training error (1/3) sum_e rss_e/ref_e; for a Gaussian likelihood whose
        noise is the same fraction of each equation's scale, that fraction is the unanchored baseline's error
        over the effective number of independent rows (``_noise_per_row``), so the prior enters as that
        fraction times sum_j ((theta_j - theta0_j)/s_j)^2 (scaled to the rows of the fit at hand).
        Coefficients an effect frees are anchored the same way when the config has a value for them (an effect
        says they may differ from it, within the prior); terms the model omits, and the effects' own unknowns,
        are not. Assumption labelled: independent priors, no correlation between coefficients."""
        anchored = [j for j, n in enumerate(names) if n in self.model_eq or
                    (n in self.base.param_names and n not in self.omit and self.base_param(n) != 0.0)]
        if not anchored:
            return None
        if self._tau is None:
            self._tau = self._noise_per_row()
        theta0 = np.zeros(len(names))
        lam = np.zeros(len(names))
        prior = np.array([self.base_param(names[j]) for j in anchored])
        nz = np.abs(prior[prior != 0])
        floor = self.anchor * (float(np.median(nz)) if len(nz) else 1.0)
        sd = np.maximum(self.anchor * np.abs(prior), floor)
        theta0[anchored] = prior
        lam[anchored] = (self._tau * self._m_base / m) / sd ** 2
        return theta0, lam

    def posterior(self, fit: Fit) -> dict | None:
        """The Gaussian posterior of a fit's linear unknowns (free model coefficients and the effects' linear
        parameters) with the effects' nonlinear parameters held at their estimates: ``{'names', 'mean', 'cov',
        'tau', 'prior'}``. The covariance is that of the normal equations ``solve`` uses (anchored when the
        problem is), with the data weight of ``_noise_per_row`` (the effective number of independent rows); an
        unanchored fit gets the same data weight and no prior. None when nothing is free."""
        y, Phi, names = self.rows(fit.effects, fit.outer, model=True)
        if not names:
            return None
        prior = self._prior(names, len(y)) if self.anchor else None
        if self._tau is None:
            self._tau = self._noise_per_row()
        w2 = 1.0 / self.reference()
        G = sum(w2[k] * (Phi[:, k, :].T @ Phi[:, k, :]) for k in range(3))
        tau = self._tau * self._m_base / len(y)  # the objective's scale of one unit of -2 log posterior
        A = (G + (np.diag(prior[1]) if prior is not None else 0.0)) / tau
        s = np.sqrt(np.diag(A))
        s[~(s > 0)] = 1.0
        cov = np.linalg.pinv(A / np.outer(s, s), hermitian=True) / np.outer(s, s)
        mean = np.array([float(fit.coefs.get(n, 0.0)) for n in names])
        return {"names": list(names), "mean": mean, "cov": cov, "tau": tau, "prior": prior}

    def identifiability(self, fit: Fit) -> list[dict]:
        """Per anchored model coefficient of a fit: prior, estimate, posterior and prior standard deviation and
        their ratio (near 0: the records determine it; near 1: the prior does), with a plain sentence. The
        posterior covariance is that of the anchored normal equations (``solve``): data weight as there, the
        effects' nonlinear parameters held at their estimates. Empty when the model is not anchored."""
        if not self.anchor or not self.model_free:
            return []
        post = self.posterior(fit)
        if post is None or post["prior"] is None:
            return []
        names, cov, tau = post["names"], post["cov"], post["tau"]
        theta0, lam = post["prior"]
        out = []
        for j, n in enumerate(names):
            if not lam[j] > 0:
                continue
            sd0 = float(np.sqrt(tau / lam[j]))
            sd = float(np.sqrt(max(cov[j, j], 0.0)))
            ratio = sd / sd0
            est = float(fit.coefs.get(n, theta0[j]))
            moved = (est - theta0[j]) / sd0
            if ratio < 0.5:
                say = f"{n}: determined by the records (posterior sd {ratio:.2f} of the prior's)"
            elif ratio < 0.9:
                say = f"{n}: partly determined (posterior sd {ratio:.2f} of the prior's)"
            else:
                say = (f"{n}: NOT determined by these records (posterior sd {ratio:.2f} of the prior's): its value "
                       f"is the prior's, and a prediction that depends on it extrapolates")
            if abs(moved) > 2.0:
                say += (f"; moved {moved:+.1f} prior sd from the prior: the records and the prior disagree (a model "
                        f"error elsewhere can cause this)")
            out.append({"coefficient": n, "prior": float(theta0[j]), "estimate": est, "prior_sd": sd0,
                        "posterior_sd": sd, "ratio": ratio, "moved_prior_sd": float(moved), "sentence": say})
        return out

    def fit(self, effects, start: dict | None = None, grid: bool = True, fixed=(), refine: bool = False,
            max_evals: int = 100) -> Fit:
        """Identify the model with ``effects``: each variant of the effects fitted, the best (lowest training
        error) kept.

        The nonlinear parameters not in ``fixed`` (those keep their ``start`` values) start from ``start``
        where known and from the grid of their effect otherwise; the best start point is polished by a
        Nelder-Mead search inside the bounds (equation error, variable projection). With ``refine`` they are then polished
        on the training records' replay error (output error, the linear unknowns still by equation error at
        each point): less biased by measurement noise than the equation error.
        """
        effects = tuple(effects)
        variants = self.variants(effects)
        if len(variants) == 1:
            return self._fit_variant(effects, variants[0], start, grid, fixed, refine, max_evals)
        # several variants (shallow water's formulas): each screened with a short search, then the best (and any
        # within 2 % of it) searched in full from there -- a full search of each cost four times as much
        screened = [self._fit_variant(effects, v, start, grid, fixed, False, SCREEN_EVALS) for v in variants]
        order = sorted(range(len(variants)), key=lambda i: screened[i].training_error)
        first = screened[order[0]].training_error
        keep = [i for i in order if screened[i].training_error <= first * 1.02 + 1e-12][:2]
        count = sum(f.evaluations for f in screened)
        best = None
        for i in keep:
            f = self._fit_variant(effects, variants[i], {**(start or {}), **screened[i].outer}, False, fixed,
                                  refine, max_evals)
            count += f.evaluations
            if best is None or f.training_error < best.training_error:
                best = f
        best.evaluations = count
        return best

    def _fit_variant(self, effects, variant, start, grid, fixed, refine, max_evals) -> Fit:
        spec = self.outer_params(effects)
        start = dict(start or {})
        fixed_vals = {n: start[n] for n in fixed if n in start}
        spec = [s for s in spec if s[0] not in fixed_vals]
        if not spec:
            vals = {**variant, **fixed_vals}
            coefs, J, rss = self.solve(effects, vals)
            return Fit(effects, vals, coefs, J, rss, 1)
        names = [s[0] for s in spec]
        lo = np.array([s[1] for s in spec])
        hi = np.array([s[2] for s in spec])
        count = [0]

        def outer_of(x):
            return {**variant, **fixed_vals, **dict(zip(names, (float(v) for v in np.clip(x, lo, hi))))}

        def J(x, model=True):
            count[0] += 1
            try:
                j = self.solve(effects, outer_of(x), model=model)[1]
                return j if np.isfinite(j) else 1e6
            except (ValueError, np.linalg.LinAlgError, FloatingPointError):
                return 1e6

        known = {n: float(start[n]) for n in names if isinstance(start.get(n), (int, float))}
        new = [s for s in spec if s[0] not in known]
        if grid and new:
            pts = []
            for combo in itertools.product(*[s[3] for s in new]):
                x = dict(known)
                x.update({s[0]: g for s, g in zip(new, combo)})
                pts.append(np.array([x[n] for n in names]))
        else:
            pts = [np.array([known.get(n, 0.5 * (a + b)) for n, a, b in zip(names, lo, hi)])]
        # a local search from the best start: Nelder-Mead with a simplex of half a grid step (Powell's line
        # searches span the whole box and, measured on an identified hull with a current, jump into another
        # basin)
        steps = np.array([_half_step(s[3], a, b) for s, a, b in zip(spec, lo, hi)])

        def local(x0, model=True, evals=max_evals):
            simplex = np.vstack([x0] + [np.clip(x0 + np.eye(len(x0))[i] * steps[i] *
                                                (1 if x0[i] + steps[i] <= hi[i] else -1), lo, hi)
                                        for i in range(len(x0))])
            res = optimize.minimize(J, x0, args=(model,), method="Nelder-Mead", bounds=list(zip(lo, hi)),
                                    options={"maxfev": evals, "xatol": 1e-4 * float(np.max(hi - lo)),
                                             "fatol": 1e-7, "initial_simplex": simplex})
            return np.clip(res.x, lo, hi), float(res.fun)

        if self.model_free and grid and new:
            # an identified model absorbs most of a wrong effect: its training error is flat except in a basin a
            # few % of U0 wide around the truth (measured: a current on an identified KVLCC2 hull), which a grid
            # misses. With the model's coefficients held at the vessel config's values (its prior) the basin is
            # wide: the effect is located that way first, then everything is identified from there.
            pv = [J(p, False) for p in pts]
            xp, _ = local(pts[int(np.argmin(pv))], False)
            pts = pts + [xp]
        vals = [J(p) for p in pts]
        x0 = pts[int(np.argmin(vals))]
        xb, fb = local(x0)
        best = xb if fb <= min(vals) else x0
        if refine:
            def J_oe(x):
                count[0] += 1
                outer = outer_of(x)
                try:
                    coefs = self.solve(effects, outer)[0]
                except (ValueError, np.linalg.LinAlgError):
                    return 1e6
                f = Fit(effects, outer, coefs, 0.0)
                errs = {i: record_errors(df, self.predict(f, df, self.infos[i]), self.floors)
                        for i, df in enumerate(self.records)}
                e = validation_error(errs)
                return e if np.isfinite(e) else 1e6

            simplex2 = np.vstack([best] + [np.clip(best + np.eye(len(best))[i] * 0.25 * steps[i] *
                                                   (1 if best[i] + 0.25 * steps[i] <= hi[i] else -1), lo, hi)
                                           for i in range(len(best))])
            r2 = optimize.minimize(J_oe, best, method="Nelder-Mead", bounds=list(zip(lo, hi)),
                                   options={"maxfev": max_evals, "xatol": 1e-4 * float(np.max(hi - lo)),
                                            "fatol": 1e-6, "initial_simplex": simplex2})
            if r2.fun < J_oe(best):
                best = np.clip(r2.x, lo, hi)
        outer = outer_of(best)
        coefs, Jb, rss = self.solve(effects, outer)
        return Fit(effects, outer, coefs, Jb, rss, count[0])

    # ------------------------------------------------------------------------------------------- replay
    def predict(self, fit: Fit, df: pd.DataFrame, info: RecordInfo | None = None) -> pd.DataFrame | None:
        """The identified model replayed through a record (its measured rudder and propeller, its own depth),
        from the record's initial state; None when it diverges (leaves the physical envelope ``ENVELOPE``).
        Only the record's first segment (up to a gap)."""
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
        with np.errstate(all="ignore"):
            out = replay(v, tu, data["delta"], data["n"], state0)[:, :, 0]
        if not np.all(np.isfinite(out[:, :6])):
            return None
        if (np.max(np.hypot(out[:, 0], out[:, 1])) > ENVELOPE["speed_U0"] * self.U0
                or np.max(np.abs(out[:, 2])) > ENVELOPE["r_U0_L"] * self.U0 / self.L):
            return None
        return pd.DataFrame({"time": tu, "u": out[:, 0], "v": out[:, 1], "r": out[:, 2], "x0": out[:, 3],
                             "y0": out[:, 4], "psi": out[:, 5], "delta": out[:, 6]})


#: the local search's evaluations when an effect's variants are screened (see ``EffectsProblem.fit``)
SCREEN_EVALS = 25


def _half_step(grid, lo: float, hi: float) -> float:
    """Half the smallest spacing of a start grid (a tenth of the box for a one-point grid): the local search's
    first step."""
    g = np.unique(np.asarray(grid, float))
    d = np.diff(g)
    return float(0.5 * d.min()) if len(d) else 0.1 * float(hi - lo)


#: the NRMSE counted for a channel whose replay stayed within the envelope but is off by more: beyond ten times
#: the channel's spread a prediction has no shape left to compare. A DIVERGED replay is not capped: its errors
#: are inf and it is reported as diverged (never as a percentage).
NRMSE_CAP = 10.0


def record_errors(meas: pd.DataFrame, pred: pd.DataFrame | None, floors: dict | None = None) -> dict:
    """Per channel RMSE and NRMSE (RMSE over the measured spread, or over ``floors[c]`` when that is larger; at
    most ``NRMSE_CAP``) of a prediction; the track error (RMSE of the position over the track's extent); a
    diverged prediction (None) has inf errors and ``diverged`` set."""
    out = {}
    if pred is None:
        for c in CHANNELS + ("track",):
            out[c] = {"rmse": math.inf, "nrmse": math.inf}
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


def record_error(errors_of_record: dict) -> float:
    """One record's validation error: the mean NRMSE of u, v, r and psi (inf when its replay diverged)."""
    return float(np.mean([errors_of_record[c]["nrmse"] for c in CHANNELS]))


def validation_error(errors: dict) -> float:
    """The doctor's single number: the mean over records of the mean NRMSE of u, v, r and psi; inf when a
    replay diverged (see ``diverged_records``)."""
    vals = [record_error(errors[r]) for r in errors]
    return float(np.mean(vals)) if vals else math.nan


def diverged_records(errors: dict) -> list:
    return [r for r, e in errors.items() if e.get("diverged")]


def residuals(problem: EffectsProblem, fit: Fit, names: list) -> list:
    """Inverse dynamics of the fitted model on the training records: per segment the times, the residual
    forces [N, N, N m] (measured inertial forces minus the model's) and the states and inputs at the rows."""
    out, seen = [], set()
    for seg in problem.segments:
        y, Phi, cols = problem.rows(fit.effects, fit.values, segs=[seg])
        ops = problem.structure.ops(seg, 1)
        nodes = problem.structure.nodes(seg)
        r = {"record": seg.record, "name": names[seg.record] if seg.record < len(names) else str(seg.record),
             "time": ops.times, "first": seg.record not in seen}
        seen.add(seg.record)
        c = np.array([fit.coefs.get(n, 0.0) for n in cols])
        res = y - (np.einsum("mek,k->me", Phi, c) if len(cols) else 0.0)
        for k, eq in enumerate(EQUATIONS):
            r[eq] = res[:, k] * problem.scale[k]
        for s in ("u", "v", "r", "delta", "psi", "n", "wind_angle_rel"):
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
    effects = tuple(model_cfg.get("effects") or [])
    pb = EffectsProblem(base.cfg, model_cfg, records, structure_cfg)
    fit = pb.fit(effects, refine=True)
    env = dict(zip(truth.param_names, truth.params))
    q = pb.scale
    truth_eff = {"current_speed": env["current_speed"], "current_direction_deg": math.degrees(env["current_dir"]) % 360,
                 "wind_speed": env["wind_speed"], "wind_direction_deg": math.degrees(env["wind_dir"]) % 360,
                 "rudder_lag": env["rudder_lag"], "rudder_delay": env["rudder_delay"],
                 "yaw_bias_Y": env["ext_Y"] / q[1], "yaw_bias_N": env["ext_N"] / q[2]}
    names = base.param_names
    params = []
    freed = {c: fit.coefs[c] for c in pb.free_coefficients(effects) if c in fit.coefs}
    for k, v in {**pb.describe(fit), **freed}.items():
        if not isinstance(v, (int, float)):
            continue
        eq = pb.equation_of(k) if k in names else "effect"
        t = float(truth.params[names.index(k)]) if k in names else truth_eff.get(k)
        params.append({"equation": eq, "name": k, "estimate": float(v), "truth": t,
                       "truth_kind": "exact" if k in names else "hidden effect"})
    metrics = {"training_error": fit.training_error, "effect_evaluations": fit.evaluations}
    coefs = {k: v for k, v in fit.coefs.items() if k in names}
    return {"estimates": coefs, "params": params, "metrics": metrics,
            "vessel": pb.vessel(effects, fit.values, None, fit.coefs, replay=False)}
