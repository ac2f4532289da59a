"""The truth simulator: vessel kinds, effects, and the compiled integrator.

Public entry points::

    from study.sim import load_vessel, simulate
    vessel = load_vessel("kvlcc2", effects=[ShallowWater(h_T=1.5)])
    df = simulate(vessel, "zigzag_10_10")          # a schema DataFrame (see docs/schema.md)

A vessel *kind* is a module with ``KIND``, ``PARAM_NAMES``, ``COEFF_SECTION``,
``LINEAR_DERIVATIVES``, ``accel`` (numba) and ``pack(cfg)``; optionally ``ADDED_MASS_KEYS``,
``solve_n(params, U0)`` for self-propulsion, and ``KINEMATIC_SWAY = False`` with
``aux_state_at_rest(P, delta)`` for a model without a sway velocity that carries an auxiliary state
in the integrator's ``v_w`` slot instead (``nomoto``: see ``study.sim.core``). Kinds are listed in
``KINDS`` (``kinds.py``); adding one is one module plus one line there. Manoeuvres
(``study.sim.maneuvers``) and configs (``study.configuration.compose``) come from the layer below:
this package only
simulates.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import pandas as pd

from study.configuration.compose import read_config as _read_config
from .core import ENV_NAMES, OUT_NAMES, make_integrator
from .effects import apply_effects, env_vector, make_effect
from .kinds import KINDS, get_kind  # noqa: F401 - KINDS re-exported (study.sim.KINDS)


@lru_cache(maxsize=None)
def integrator(kind_name: str):
    """Compiled batch integrator of a kind (compiled once per process, on first use)."""
    kind = get_kind(kind_name)
    return make_integrator(kind.accel, len(kind.PARAM_NAMES), getattr(kind, "KINEMATIC_SWAY", True))


@dataclass
class Vessel:
    """A vessel ready to simulate: its config (after effects), kind, packed parameters, operating
    point."""

    name: str
    kind_name: str
    cfg: dict
    env: dict
    params: np.ndarray  # kind parameters followed by the environment block, shape (n_params,)
    U0: float
    n0: float
    effects: list = field(default_factory=list)

    @property
    def kind(self):
        return get_kind(self.kind_name)

    @property
    def L(self) -> float:
        return float(self.cfg["particulars"]["Lpp"])

    @property
    def param_names(self) -> tuple:
        return tuple(self.kind.PARAM_NAMES) + ENV_NAMES

    def with_params(self, **changes) -> "Vessel":
        """Copy with some packed parameters (kind or environment names) replaced."""
        p = self.params.copy()
        names = self.param_names
        for k, v in changes.items():
            if k not in names:
                raise KeyError(f"vessel '{self.name}' has no parameter '{k}'")
            p[names.index(k)] = v
        return Vessel(self.name, self.kind_name, self.cfg, self.env, p, self.U0, self.n0, self.effects)


def _as_effects(effects) -> list:
    out = []
    for e in effects or []:
        if isinstance(e, dict):
            e = dict(e)
            out.append(make_effect(e.pop("name"), **e))
        else:
            out.append(e)
    return out


def load_vessel(vessel, effects=()) -> Vessel:
    """Build a :class:`Vessel` from a config name or dict, applying the effects in order."""
    cfg = _read_config("vessel", vessel) if isinstance(vessel, str) else dict(vessel)
    effects = _as_effects(effects)
    cfg, env = apply_effects(cfg, effects)
    kind = get_kind(cfg["kind"])
    kp = kind.pack(cfg)
    params = np.concatenate([kp, env_vector(env)])
    U0 = float(cfg["operation"]["U0"])
    n_cfg = cfg["operation"].get("n")
    if n_cfg is None and hasattr(kind, "solve_n"):
        n0 = float(kind.solve_n(kp, U0))
    else:
        n0 = float(n_cfg or 0.0)
    return Vessel(cfg["name"], cfg["kind"], cfg, env, params, U0, n0, effects)


def default_dt(vessel: Vessel) -> float:
    """Integration step: about 1 % of the time to travel one ship length, on a 1-2-5 grid, at
    most 0.1 s."""
    target = min(0.1, 0.01 * vessel.L / vessel.U0)
    for dt in (0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001):
        if dt <= target * 1.0001:
            return dt
    return 0.001


def run(vessel: Vessel, P: np.ndarray, y0: np.ndarray, dt: float, nsteps: int, cmd: np.ndarray,
        nprop: np.ndarray, ctrl: np.ndarray, save_every: int = 1) -> np.ndarray:
    """Low-level batch call: P (n_params, B), y0 (6, B) -> output (n_out, 9, B), columns
    ``OUT_NAMES``."""
    P = np.ascontiguousarray(P, dtype=np.float64)
    if P.ndim == 1:
        P = P[:, None]
    y0 = np.ascontiguousarray(y0, dtype=np.float64)
    if y0.ndim == 1:
        y0 = np.repeat(y0[:, None], P.shape[1], axis=1)
    n_out = nsteps // save_every + 1
    out = np.empty((n_out, len(OUT_NAMES), P.shape[1]))
    integrator(vessel.kind_name)(y0, P, float(dt), int(nsteps), int(save_every),
                                 np.ascontiguousarray(cmd, dtype=np.float64),
                                 np.ascontiguousarray(nprop, dtype=np.float64),
                                 np.ascontiguousarray(ctrl, dtype=np.float64), out)
    return out


def initial_state(vessel: Vessel, u0: float | None = None, psi0: float = 0.0) -> np.ndarray:
    """Straight, steady approach at U0 (or u0) through the water, heading psi0."""
    return np.array([vessel.U0 if u0 is None else u0, 0.0, 0.0, 0.0, 0.0, psi0])


def _aux_at_rest(vessel: Vessel, P: np.ndarray, y0: np.ndarray, delta0: float) -> np.ndarray:
    """y0 with the ``v_w`` slot set to the kind's auxiliary state at rest, for a kind whose ``v_w``
    is not a sway velocity (``KINEMATIC_SWAY = False``, e.g. ``nomoto``); other kinds: y0 unchanged.

    The initial rudder of the integrator is the first command clipped to each member's delta_max.
    """
    kind = vessel.kind
    if getattr(kind, "KINEMATIC_SWAY", True):
        return y0
    P = np.asarray(P, float)
    P2 = P if P.ndim == 2 else P[:, None]
    nk = len(kind.PARAM_NAMES)
    dmax = P2[nk + ENV_NAMES.index("delta_max")]
    aux = kind.aux_state_at_rest(P2[:nk], np.clip(float(delta0), -dmax, dmax))  # (B,)
    y0 = np.array(y0, dtype=float)  # a copy: the caller's state is not changed
    if y0.ndim == 1 and P.ndim == 2 and P.shape[1] > 1:
        y0 = np.repeat(y0[:, None], P.shape[1], axis=1)
    y0[1] = aux if y0.ndim == 2 else aux[0]
    return y0


def to_frame(out: np.ndarray, t: np.ndarray, member: int = 0) -> pd.DataFrame:
    df = pd.DataFrame(out[:, :, member], columns=list(OUT_NAMES))
    df.insert(0, "time", t)
    return df


def simulate(vessel, maneuver, effects=(), dt: float | None = None, sample_dt: float | None = None,
             duration: float | None = None, u0: float | None = None, psi0: float = 0.0,
             seed: int = 0) -> pd.DataFrame:
    """Simulate one manoeuvre of one vessel; returns a clean schema DataFrame (no measurement
    noise).

    vessel : name, config dict or :class:`Vessel`; maneuver : name, config dict or
    :class:`study.sim.maneuvers.Maneuver`. ``sample_dt`` (default: ``dt``) must be a multiple of
    ``dt``.
    """
    from study.sim import maneuvers

    if not isinstance(vessel, Vessel):
        vessel = load_vessel(vessel, effects)
    elif effects:
        raise ValueError("pass effects to load_vessel, or a vessel name/config with effects, not both")
    man = maneuvers.get_maneuver(maneuver)
    dt = default_dt(vessel) if dt is None else float(dt)
    sample_dt = dt if sample_dt is None else float(sample_dt)
    save_every = int(round(sample_dt / dt))
    if save_every < 1 or not math.isclose(save_every * dt, sample_dt, rel_tol=1e-6):
        raise ValueError(f"sample_dt={sample_dt} s must be a whole multiple of the step dt={dt} s")
    T = man.duration_for(vessel) if duration is None else float(duration)
    nsteps = int(round(T / dt))
    nsteps -= nsteps % save_every
    ctrl, cmd = man.encode(vessel, dt, nsteps, seed=seed)
    nprop = np.full(nsteps + 1, vessel.n0)
    y0 = _aux_at_rest(vessel, vessel.params, initial_state(vessel, u0, psi0), cmd[0])
    out = run(vessel, vessel.params, y0, dt, nsteps, cmd, nprop, ctrl, save_every)
    t = np.arange(out.shape[0]) * sample_dt
    return to_frame(out, t)


def simulate_batch(vessel: Vessel, maneuver, P: np.ndarray, dt: float | None = None,
                   duration: float | None = None, seed: int = 0):
    """One manoeuvre for every column of the parameter matrix ``P`` (n_params, B) in one compiled
    call, each member closing its own zigzag/turning controller on its own heading (e.g. posterior
    draws of a model).

    Returns ``(t, out)`` with ``out`` of shape (n, 9, B) in the order of
    ``study.sim.core.OUT_NAMES``; the propeller runs at ``vessel.n0`` for every member.
    """
    from study.sim import maneuvers

    man = maneuvers.get_maneuver(maneuver)
    dt = default_dt(vessel) if dt is None else float(dt)
    T = man.duration_for(vessel) if duration is None else float(duration)
    nsteps = int(round(T / dt))
    ctrl, cmd = man.encode(vessel, dt, nsteps, seed=seed)
    nprop = np.full(nsteps + 1, vessel.n0)
    P = np.ascontiguousarray(P, dtype=np.float64)
    y0 = _aux_at_rest(vessel, P, np.repeat(initial_state(vessel)[:, None], P.shape[1], axis=1), cmd[0])
    out = run(vessel, P, y0, dt, nsteps, cmd, nprop, ctrl, 1)
    return np.arange(out.shape[0]) * dt, out


def replay(vessel: Vessel, time: np.ndarray, delta: np.ndarray, n: np.ndarray, state0, P=None,
           substeps: int = 1) -> np.ndarray:
    """Simulate with measured inputs (open loop) on a record's uniform time base.

    ``delta`` is applied as the rudder command: with the vessel's rudder rate, lag and delay (set
    them to 0 to apply the measured angle directly). ``state0`` = [u_w, v_w, r, x0, y0, psi].
    Returns (n, 9, B). For a kind whose ``v_w`` slot is not a sway velocity (``KINEMATIC_SWAY =
    False``: ``nomoto``) the given v_w is ignored: the slot starts at the kind's auxiliary state at
    rest (r' = 0) for the first rudder angle (a record's ``v`` is the drift over ground, not that
    state).
    """
    time = np.asarray(time, float)
    dts = np.diff(time)
    dt_rec = float(np.median(dts))
    if np.max(np.abs(dts - dt_rec)) > 1e-6 * max(1.0, dt_rec) + 1e-9:
        raise ValueError("replay needs a uniformly sampled record; resample it first")
    dt = dt_rec / substeps
    nsteps = (len(time) - 1) * substeps
    tt = np.arange(nsteps + 1) * dt + time[0]
    cmd = np.interp(tt, time, delta)
    nprop = np.interp(tt, time, n)
    from study.sim.maneuvers import open_loop_ctrl

    P = vessel.params if P is None else P
    state0 = _aux_at_rest(vessel, P, np.asarray(state0, float), cmd[0])
    return run(vessel, P, state0, dt, nsteps, cmd, nprop, open_loop_ctrl(), substeps)


@lru_cache(maxsize=1)
def _wind_kernel():
    from .core import make_wind_kernel

    return make_wind_kernel()


def wind_forces(vessel: Vessel, u_w, v_w, psi, speed, direction) -> np.ndarray:
    """Wind forces [N, N, N m] in body axes, (N, 3), of ``vessel``'s windage and wind
    coefficients for a true wind of ``speed`` [m/s] from ``direction`` [rad] (scalars or
    per-sample arrays), the ship moving at the water-relative ``u_w, v_w`` with heading ``psi``
    (and the vessel's current, if any) -- the same compiled function the integrator uses (Fossen
    2011, Sec. 8.1)."""
    n = len(np.asarray(u_w))
    arr = [np.ascontiguousarray(np.broadcast_to(np.asarray(a, float), (n,))) for a in (u_w, v_w, psi, speed,
                                                                                       direction)]
    out = np.empty((n, 3))
    P = np.ascontiguousarray(vessel.params[:, None], dtype=np.float64)
    _wind_kernel()(*arr, P, len(vessel.kind.PARAM_NAMES), out)
    return out


@lru_cache(maxsize=None)
def _accel_kernel(kind_name: str):
    from .core import make_accel_kernel

    kind = get_kind(kind_name)
    return make_accel_kernel(kind.accel, len(kind.PARAM_NAMES), getattr(kind, "KINEMATIC_SWAY", True))


def accelerations(vessel: Vessel, P: np.ndarray, u, v, r, delta, n, ext=None) -> np.ndarray:
    """Accelerations (du, dv, dr) of the kind's equations of motion at given states, for each column
    of P.

    P : (n_params, B); ext : (3, B) external forces [N, N, N m] or None. Returns (B, N, 3). Used to build
    regressors of any kind without re-deriving its force model (see ``study.identify.regression``).
    """
    P = np.ascontiguousarray(P, dtype=np.float64)
    if P.ndim == 1:
        P = P[:, None]
    ext = np.zeros((3, P.shape[1])) if ext is None else np.ascontiguousarray(ext, dtype=np.float64)
    arrs = [np.ascontiguousarray(a, dtype=np.float64) for a in (u, v, r, delta, n)]
    out = np.empty((P.shape[1], arrs[0].shape[0], 3))
    _accel_kernel(vessel.kind_name)(*arrs, ext, P, out)
    return out
