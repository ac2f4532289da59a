"""Identification models: what is identified, how its regression rows are built, and what its truth
is.

A model config (``conf/model/<name>.yaml``) has a ``type``:

- ``kind``: the coefficients of a vessel kind's own force model (``mmg_hull``, ``mmg_simplified``,
  ``usv_full``, ``abkowitz``, ``auv``). The regressors are read off the kind's compiled equations of
  motion (:mod:`study.identify.regression`), so the physics is written once. Known parts come from
  the vessel: mass, added mass, propeller and rudder forces, and every coefficient the model neither
  identifies nor ``omit``\\ s. Omitted terms are zero in the model. The truth is the vessel's value
  of each coefficient: *exact* when the omitted terms are zero in the truth vessel, otherwise
  *approximate* (and the report says which terms differ).
- ``nomoto``: the first- or second-order Nomoto (KT) response model, linear or with the cubic term
  (Nomoto et al. 1957; nonlinear form of Zheng & Xiao 2017, eqs. 12-13)::

      order 1:  T r' + r + alpha r^3 = K delta
      order 2:  T1 T2 r'' + (T1 + T2) r' + r + alpha r^3 = K delta + K T3 delta'

  regressed as r' (or r'') on r, r^3, delta (and r', delta'); K, T, alpha (T1, T2, T3) follow from
  the regression coefficients (:meth:`NomotoModel.physical`). The truth is *exact* for a Nomoto-kind
  vessel and *derived* for any other: linearised sway-yaw dynamics for K, T (T1, T2, T3) and a fit
  to the vessel's steady turns for alpha (:mod:`study.sim.linearize`); labelled so in the parameter
  table.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from study.configuration.compose import read_config
from ..sim import Vessel

EQUATIONS = ("X", "Y", "N")


@dataclass
class Rows:
    """Regression rows of one equation (before the structure's post-processing)."""

    Phi: np.ndarray
    y: np.ndarray
    seg: np.ndarray  # segment number of each row (for differencing consecutive rows)


def force_scales(vessel: Vessel) -> np.ndarray:
    """0.5 rho L d U0^2 (X, Y) and 0.5 rho L^2 d U0^2 (N): keeps the regression O(1) in the
    kind's units."""
    p = vessel.cfg["particulars"]
    q = 0.5 * float(p["rho"]) * float(p["Lpp"]) * float(p["d"]) * vessel.U0 ** 2
    return np.array([q, q, q * float(p["Lpp"])])


class Model:
    """Base class of the identification models (see the module docstring)."""

    type = "base"
    order = 1
    channels = ("u", "v", "r", "psi")  # what the model predicts (validation, output error)

    def __init__(self, cfg: dict, vessel: Vessel):
        self.cfg = dict(cfg)
        self.name = str(cfg.get("name"))
        self.vessel = vessel
        self.source = str(cfg.get("source", ""))

    @property
    def effects(self) -> tuple:
        """The effects identified with the model (``model.effects``: names of ``conf/effect``),
        empty for none."""
        return tuple(self.cfg.get("effects") or ())

    # -- to be provided
    equations: dict  # eq -> regression column names
    physical_names: dict  # eq -> physical parameter names

    def skip(self, structure) -> tuple[bool, str]:
        return False, ""

    def rows(self, seg, structure) -> dict:
        raise NotImplementedError

    def candidates(self, seg, structure, degree: int) -> tuple[list, np.ndarray]:
        raise NotImplementedError

    def physical(self, coefs: dict) -> dict:
        return dict(coefs)

    def truth(self) -> tuple[dict, str, bool]:
        raise NotImplementedError

    def model_vessel(self, phys: dict, pass_through: bool = False) -> Vessel:
        raise NotImplementedError

    # -- output error: the parameters simulated, packed into the kind's parameter matrix
    oe_names: list

    def oe_vessel(self) -> Vessel:
        return self.model_vessel(self.truth_guess(), pass_through=True)

    def oe_pack(self, theta: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def truth_guess(self) -> dict:
        """Any valid parameter set (used only to build the simulation vessel; values are
        replaced)."""
        return {n: 0.0 for n in self.oe_names}


def _pass_through(vessel: Vessel) -> Vessel:
    """The vessel with its steering gear switched off: a replayed rudder angle is applied as
    measured."""
    return vessel.with_params(rudder_rate=0.0, rudder_lag=0.0, rudder_delay=0.0, delta_max=math.pi)


# ------------------------------------------------------------------------------------------- kind models

class KindModel(Model):
    """Coefficients of a vessel kind's own force model (``type: kind``)."""

    type = "kind"

    def __init__(self, cfg: dict, vessel: Vessel):
        super().__init__(cfg, vessel)
        self.kind = cfg.get("kind")
        eqs = cfg.get("equations") or {}
        bad = [e for e in eqs if e not in EQUATIONS]
        if bad:
            raise ValueError(f"model '{self.name}': unknown equation(s) {bad}, expected some of {EQUATIONS}")
        self.omit = list(cfg.get("omit") or [])
        # a term in omit is left out of the model (zero) even where its equations list it: model.omit=[Nvvr]
        # makes "the model without N'vvr" from any model that has it
        self.equations = {e: [c for c in eqs[e] if c not in self.omit] for e in EQUATIONS if eqs.get(e)}
        self.physical_names = self.equations
        self.oe_names = [c for e in self.equations for c in self.equations[e]]
        self._mismatch = None
        if self.kind and self.kind != vessel.kind_name:
            self._mismatch = (f"model '{self.name}' identifies the coefficients of vessel kind '{self.kind}', "
                              f"but vessel '{vessel.name}' is of kind '{vessel.kind_name}'")
            return
        names = vessel.param_names
        unknown = [c for c in self.oe_names + self.omit if c not in names]
        if unknown:
            raise ValueError(f"model '{self.name}': {unknown} are not parameters of vessel kind "
                             f"'{vessel.kind_name}' (known: {list(vessel.kind.PARAM_NAMES)})")
        self._idx = [names.index(c) for c in self.oe_names]
        P0 = vessel.params.copy()
        P0[self._idx] = 0.0
        for c in self.omit:
            P0[names.index(c)] = 0.0
        self._P0 = P0
        self._scale = force_scales(vessel)

    def skip(self, structure):
        if self._mismatch:
            return True, self._mismatch
        return False, ""

    def rows(self, seg, structure):
        """Rows M (a_measured - a_known) = sum_i theta_i phi_i per equation (see
        study.identify.regression)."""
        from .regression import kind_regressors

        ops = structure.ops(seg, self.order)
        nodes = structure.nodes(seg)
        y3, phi3 = kind_regressors(self.vessel, self._P0, self._idx, nodes, seg.data, ops, self._scale)
        out = {}
        for e, eq in enumerate(EQUATIONS):
            if eq not in self.equations:
                continue
            cols = [self.oe_names.index(c) for c in self.equations[eq]]
            out[eq] = Rows(phi3[:, e, cols], y3[:, e], np.zeros(len(ops), int))
        return out

    def candidates(self, seg, structure, degree):
        """Non-dimensional monomials (U/U0)^2 v'^a r'^b delta^c, 1 <= a + b + c <= degree
        (SINDy's extra library), in the units of the scaled equations; columns duplicating a
        model term are dropped later."""
        ops = structure.ops(seg, self.order)
        nd = structure.nodes(seg)
        U = np.sqrt(nd["u"] ** 2 + nd["v"] ** 2)
        Us = np.where(U > 1e-9, U, 1e-9)
        vp, rp, d = nd["v"] / Us, nd["r"] * self.vessel.L / Us, nd["delta"]
        q = (U / self.vessel.U0) ** 2
        names, cols = [], []
        for a in range(degree + 1):
            for b in range(degree + 1 - a):
                for c in range(degree + 1 - a - b):
                    if a + b + c == 0:
                        continue
                    names.append("*".join(f"{s}^{k}" if k > 1 else s
                                          for s, k in (("v'", a), ("r'", b), ("delta", c)) if k))
                    cols.append(ops.value(q * vp ** a * rp ** b * d ** c))
        return names, np.column_stack(cols)

    def truth(self):
        names = self.vessel.param_names
        vals = {c: float(self.vessel.params[names.index(c)]) for c in self.oe_names}
        off = {c: float(self.vessel.params[names.index(c)]) for c in self.omit
               if self.vessel.params[names.index(c)] != 0.0}
        if off:
            how = ("approximate: the model omits " + ", ".join(f"{k} = {v:.4g}" for k, v in off.items())
                   + " of the truth vessel")
            return vals, how, False
        return vals, f"exact: the coefficients of vessel '{self.vessel.name}' (kind {self.vessel.kind_name})", True

    def model_vessel(self, phys, pass_through=False):
        v = self.vessel.with_params(**{n: 0.0 for n in self.omit}, **{k: float(phys[k]) for k in self.oe_names})
        return _pass_through(v) if pass_through else v

    def truth_guess(self):
        return self.truth()[0]

    def oe_pack(self, theta):
        theta = np.atleast_2d(np.asarray(theta, float))
        if theta.shape[0] != len(self._idx):
            theta = theta.T
        base = _pass_through(self.model_vessel(self.truth_guess())).params
        P = np.repeat(base[:, None], theta.shape[1], axis=1)
        P[self._idx, :] = theta
        return P


# ------------------------------------------------------------------------------------------ Nomoto models

class NomotoModel(Model):
    """Nomoto (KT) response model of order 1 or 2, linear or with alpha r^3 (``type: nomoto``)."""

    type = "nomoto"
    channels = ("r", "psi")

    def __init__(self, cfg: dict, vessel: Vessel):
        super().__init__(cfg, vessel)
        self.order = int(cfg.get("order", 1))
        if self.order not in (1, 2):
            raise ValueError(f"model '{self.name}': order must be 1 or 2, got {self.order}")
        self.nonlinear = bool(cfg.get("nonlinear", False))
        if self.order == 1:
            reg = ["r", "r3", "delta"] if self.nonlinear else ["r", "delta"]
            phys = ["K", "T", "alpha"] if self.nonlinear else ["K", "T"]
        else:
            reg = ["r_dot", "r", "r3", "delta", "delta_dot"] if self.nonlinear else ["r_dot", "r", "delta",
                                                                                   "delta_dot"]
            phys = ["K", "T1", "T2", "T3", "alpha"] if self.nonlinear else ["K", "T1", "T2", "T3"]
        self.equations = {"N": reg}
        self.physical_names = {"N": phys}
        self.oe_names = phys
        self._truth = None

    def rows(self, seg, structure):
        ops = structure.ops(seg, self.order)
        nd = structure.nodes(seg)
        r_raw, d_raw = seg.data["r"], seg.data["delta"]
        r, d = nd["r"], nd["delta"]
        cols = {"r": ops.value(r), "r3": ops.value(r ** 3), "delta": ops.value(d)}
        if self.order == 2:
            cols["r_dot"] = ops.d(r_raw, 1)
            cols["delta_dot"] = ops.d(d_raw, 1)
        Phi = np.column_stack([cols[c] for c in self.equations["N"]])
        y = ops.d(r_raw, self.order)
        return {"N": Rows(Phi, y, np.zeros(len(ops), int))}

    def candidates(self, seg, structure, degree):
        """Monomials r^a delta^b (1 <= a + b <= degree) and r|r|, delta|delta| (SINDy's extra
        library)."""
        ops = structure.ops(seg, self.order)
        nd = structure.nodes(seg)
        r, d = nd["r"], nd["delta"]
        names, cols = [], []
        for a in range(degree + 1):
            for b in range(degree + 1 - a):
                if a + b == 0:
                    continue
                names.append("*".join(f"{s}^{k}" if k > 1 else s for s, k in (("r", a), ("delta", b)) if k))
                cols.append(ops.value(r ** a * d ** b))
        names += ["r|r|", "delta|delta|"]
        cols += [ops.value(r * np.abs(r)), ops.value(d * np.abs(d))]
        return names, np.column_stack(cols)

    def physical(self, coefs):
        """K, T, alpha (T1, T2, T3) from the regression coefficients; arrays give arrays (posterior
        draws).

        order 1: r' = c_r r + c_r3 r^3 + c_delta delta  ->  T = -1/c_r, K = c_delta T, alpha = -c_r3 T.
        order 2: r'' = a1 r' + a2 r + a3 r^3 + b1 delta + b2 delta'  ->  T1 T2 = -1/a2, T1 + T2 = a1/a2,
        K = -b1/a2, T3 = b2/b1, alpha = a3/a2; T1, T2 the roots of s^2 - (T1+T2) s + T1 T2, |T1| >= |T2|
        (NaN if complex).
        """
        g = {k: np.asarray(v, float) for k, v in coefs.items()}
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.order == 1:
                T = -1.0 / g["r"]
                out = {"K": g["delta"] * T, "T": T}
                if self.nonlinear:
                    out["alpha"] = -g["r3"] * T
            else:
                a1, a2, b1, b2 = g["r_dot"], g["r"], g["delta"], g["delta_dot"]
                P = -1.0 / a2
                S = a1 / a2
                disc = S * S - 4.0 * P
                root = np.sqrt(np.where(disc >= 0, disc, np.nan))
                ta, tb = 0.5 * (S + root), 0.5 * (S - root)
                swap = np.abs(tb) > np.abs(ta)  # T1 the larger in magnitude (study.sim.linearize's convention:
                out = {"K": -b1 / a2, "T1": np.where(swap, tb, ta), "T2": np.where(swap, ta, tb),  # T1 < 0 when
                       "T3": b2 / b1}  # the ship is course-unstable)
                if self.nonlinear:
                    out["alpha"] = g["r3"] / a2
        return {k: (float(v) if np.ndim(v) == 0 else v) for k, v in out.items()}

    def regression_from_physical(self, phys: dict) -> dict:
        """The regression coefficients of K, T, alpha (T1, T2, T3): the inverse of
        :meth:`physical` (a prior given on the physical parameters becomes a prior on the
        regression's columns)."""
        K, a = float(phys["K"]), float(phys.get("alpha", 0.0))
        if self.order == 1:
            T = float(phys["T"])
            out = {"r": -1.0 / T, "delta": K / T, "r3": -a / T}
        else:
            T1, T2, T3 = float(phys["T1"]), float(phys["T2"]), float(phys["T3"])
            P = T1 * T2
            out = {"r_dot": -(T1 + T2) / P, "r": -1.0 / P, "r3": -a / P, "delta": K / P, "delta_dot": K * T3 / P}
        return {n: out[n] for n in self.equations["N"]}

    def truth(self):
        if self._truth is None:
            from ..sim.linearize import nomoto_truth

            t = nomoto_truth(self.vessel, self.order, self.nonlinear)
            how = t.pop("how")
            exact = False
            if self.vessel.kind_name == "nomoto":
                p = dict(zip(self.vessel.param_names, self.vessel.params))
                first = p["T2"] == 0.0 and p["T3"] == 0.0
                missing = []
                if self.order == 1 and not first:
                    missing.append(f"the second order (T2 = {p['T2']:g} s, T3 = {p['T3']:g} s)")
                if not self.nonlinear and p["alpha"] != 0.0:
                    missing.append(f"alpha = {p['alpha']:.4g} s^2")
                exact = not missing
                if missing:
                    how = "approximate: the model omits " + " and ".join(missing) + " of the truth vessel; " + how
                elif self.order == 2 and first:
                    # a second-order model of a first-order truth: T2 = T3 = 0 is a limit the model can only
                    # approach (the poles and the zero cancel), so no estimate of T2 or T3 can be "exact"
                    exact = False
                    how = ("degenerate: the truth is first order (T2 = T3 = 0), which the second-order model "
                           "reaches only in the limit of a cancelling pole and zero; " + how)
            self._truth = ({k: float(t[k]) for k in self.oe_names}, how, exact)
        return self._truth

    def model_vessel(self, phys, pass_through=False):
        from ..sim import load_vessel

        cfg = nomoto_vessel_config(self.vessel, phys, self.order)
        v = load_vessel(cfg)
        return _pass_through(v) if pass_through else v

    def truth_guess(self):
        return dict(self.truth()[0])

    def oe_pack(self, theta):
        theta = np.atleast_2d(np.asarray(theta, float))
        if theta.shape[0] != len(self.oe_names):
            theta = theta.T
        vessel = self.model_vessel(self.truth_guess(), pass_through=True)
        names = vessel.param_names
        P = np.repeat(vessel.params[:, None], theta.shape[1], axis=1)
        ph = dict(zip(self.oe_names, theta))
        if self.order == 1:
            P[names.index("T1")] = ph["T"]
            P[names.index("T2")] = 0.0
            P[names.index("T3")] = 0.0
        else:
            for k in ("T1", "T2", "T3"):
                P[names.index(k)] = ph[k]
        P[names.index("K")] = ph["K"]
        P[names.index("alpha")] = ph.get("alpha", 0.0)
        return P


def nomoto_vessel_config(vessel: Vessel, phys: dict, order: int) -> dict:
    """A ``nomoto``-kind vessel config with the given K, T (T1, T2, T3), alpha, and the
    particulars, steering gear, windage and operating speed of ``vessel`` (the model predicts
    that ship's response)."""
    cfg = {k: (dict(v) if isinstance(v, dict) else v) for k, v in vessel.cfg.items()
           if k in ("particulars", "mass", "actuator", "windage", "operation", "description")}
    cfg["name"] = f"nomoto_model_of_{vessel.name}"
    cfg["kind"] = "nomoto"
    T1 = phys["T"] if order == 1 else phys["T1"]
    cfg["nomoto"] = {"K": float(phys["K"]), "T1": float(T1), "T2": 0.0 if order == 1 else float(phys["T2"]),
                     "T3": 0.0 if order == 1 else float(phys["T3"]), "alpha": float(phys.get("alpha", 0.0))}
    cfg["operation"] = {"U0": vessel.U0, "n": 0.0}
    cfg.setdefault("mass", {"m": None, "IzG": None})
    return cfg


MODEL_TYPES = {"kind": KindModel, "nomoto": NomotoModel}


def make_model(cfg, vessel: Vessel) -> Model:
    """An identification model from its config (dict or name) for a (base) vessel."""
    if isinstance(cfg, str):
        cfg = read_config("model", cfg)
    t = cfg.get("type", "kind")
    if t not in MODEL_TYPES:
        raise ValueError(f"model '{cfg.get('name')}': unknown type '{t}', expected one of {sorted(MODEL_TYPES)}")
    return MODEL_TYPES[t](cfg, vessel)

