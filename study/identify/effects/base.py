"""The contract every candidate effect follows (discovered from ``conf/effect/*.yaml``): what
identification with effects adds to a model, and the model doctor's candidates.

An effect is one class (normally one module in this package, or anywhere importable) and one YAML::

    name: yaw_bias
    _target_: study.identify.effects.yaw_bias.YawBias
    params: []            # its nonlinear parameters (outer search): name, unit, lo, hi, grid, scale
    options: {}           # passed to the class
    example: {...}        # a hidden-effect case the generated tests run (tests/doctor/test_doctor_effects.py)

A model is identified with effects by equation error with variable projection
(``study.identify.with_effects``): for given values of the effects' nonlinear parameters the
regression rows are built and every linear unknown (free model coefficients and the effects' linear
parameters) follows by least squares. An effect says, through the hooks below, what it estimates and
how it enters

- the **rows** ``M (a_measured - a_known) = sum_i theta_i phi_i`` (forces, per equation X, Y, N): it
  may change the measured columns (``transform``: e.g. water-relative velocities), add a known force
  (``known_forces``), add linear unknowns with their force per unit (``linear_forces``), or free
  vessel parameters that enter the kind's own equations linearly (``free_coefficients``: their
  columns come from the compiled equations);
- the **simulation** (the rows' known part and the replay through a record): effects of the truth
  simulator applied when the vessel is built (``sim_effects``: shallow water), packed vessel
  parameters set (``vessel_changes``: current, wind, steering gear), a constant body force during a
  replay (``replay_force``), the replay's initial state (``initial_state``), and whether the
  record's rudder is a command
  (``rudder_is_command``).

Every hook gets the :class:`study.identify.with_effects.EffectsProblem` (vessel, scale, records),
the parameter ``values`` (nonlinear parameters, the chosen variant, and in the replay also the
linear unknowns) and, where it depends on the record, a :class:`RecordInfo` (its data, its water
depth). Forces are in N (N m for yaw), body axes, each an ``(n, 3)`` array of X, Y, N at the
structure's nodes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Param:
    """A nonlinear (outer) parameter: bounds and start grid in units of ``scale`` (``1``: as
    given; ``U0``: the vessel's service speed; ``T``: the ship's time scale L/U0, at least 5 s)."""

    name: str
    unit: str
    lo: float
    hi: float
    grid: tuple
    scale: str = "1"

    def bounds(self, U0: float, L: float) -> tuple:
        s = {"1": 1.0, "U0": U0, "T": max(5.0, L / U0)}[self.scale]
        return self.lo * s, self.hi * s, tuple(float(g) * s for g in self.grid)

    @classmethod
    def from_cfg(cls, d: dict) -> "Param":
        missing = [k for k in ("name", "unit", "lo", "hi", "grid") if k not in d]
        if missing:
            raise ValueError(f"effect parameter {d}: missing {missing} (expected name, unit, lo, hi, grid, scale)")
        if str(d.get("scale", "1")) not in ("1", "U0", "T"):
            raise ValueError(f"effect parameter '{d['name']}': scale {d.get('scale')!r}, expected 1, U0 or T")
        return cls(str(d["name"]), str(d["unit"]), float(d["lo"]), float(d["hi"]), tuple(float(g) for g in d["grid"]),
                   str(d.get("scale", "1")))


@dataclass
class RecordInfo:
    """What an effect may need of one record: its index among the problem's records, its data
    (DataFrame), its name, and its water depth as h/T (None: not measured)."""

    index: int
    data: object
    name: str = ""
    h_T: float | None = None
    meta: dict = field(default_factory=dict)


class Effect:
    """Base class: a candidate effect with nothing to estimate. Subclasses override the hooks they
    need.

    Class attributes (shown in the report's catalogue): ``physics``, ``enters``, ``source``; and
    where the effect can be (``study.records.facility``): ``needs``, what must exist where the
    records were measured (``"wind"``, ``"current"``: no wind candidate indoors, no current in still
    water), and ``setup_effect``, True when the effect belongs to the test set-up rather than to the
    ship (a rudder zero offset, a yaw bias): it is then left out of predictions for another facility
    or scale unless the user keeps it. An effect's YAML may set both (``needs: [wind]``,
    ``setup_effect: true``); the YAML's value wins. ``params`` (instance): the nonlinear parameters,
    from the YAML (or the class's ``default_params``).
    """

    physics: str = ""
    enters: str = ""
    source: str = ""
    default_params: tuple = ()
    needs: tuple = ()
    setup_effect: bool = False

    def __init__(self, name: str, params=None, **options):
        self.name = name
        self.params = tuple(Param.from_cfg(p) if isinstance(p, dict) else p for p in params) \
            if params is not None else tuple(self.default_params)
        self.options = options

    # -------------------------------------------------------------------------------- what it estimates
    def applies(self, problem) -> str | None:
        """None when the effect can act on this problem, else the reason it cannot (shown in the
        report)."""
        return None

    def outer(self, problem) -> list:
        """The nonlinear parameters to search: ``(name, lo, hi, grid)`` in physical units."""
        return [(p.name,) + p.bounds(problem.U0, problem.L) for p in self.params]

    def variants(self, problem) -> list:
        """Discrete alternatives, each a dict merged into ``values``; the fit keeps the one with
        the lowest training error (e.g. shallow water's published formulas)."""
        return [{}]

    def free_coefficients(self, problem) -> dict:
        """Vessel parameters this effect frees (they enter the kind's equations linearly): name
        -> equation."""
        return {}

    def linear(self, problem) -> dict:
        """Linear unknowns of the effect itself: name -> (unit, equation or 'X,Y,N')."""
        return {}

    # ------------------------------------------------------------------------------------------- rows
    def transform(self, problem, t, data: dict, values: dict, vessel, info: RecordInfo) -> list:
        """Change the measured columns of a segment (``data``, in place; ``t`` its times) before
        the rows are built; return the names of the columns changed."""
        return []

    def known_forces(self, problem, nodes: dict, values: dict, vessel, info: RecordInfo):
        """A force known once ``values`` are [N, N, N m], (n, 3), or None."""
        return None

    def linear_forces(self, problem, nodes: dict, values: dict, vessel, info: RecordInfo) -> dict:
        """name -> the force (n, 3) of one unit of each linear unknown of :meth:`linear`."""
        return {}

    # ------------------------------------------------------------------------------------- simulation
    def sim_effects(self, problem, values: dict, info: RecordInfo | None) -> list:
        """Effects of the truth simulator (``study.sim.effects``) applied when the vessel is
        built."""
        return []

    def vessel_changes(self, problem, values: dict, info: RecordInfo | None) -> dict:
        """Packed vessel parameters (kind or environment names) to set."""
        return {}

    def replay_force(self, problem, values: dict, info: RecordInfo | None) -> tuple:
        """A constant body-fixed force (X [N], Y [N], N [N m]) during a replay (the integrator's
        ext_X/Y/N)."""
        return (0.0, 0.0, 0.0)

    def initial_state(self, problem, values: dict, state: dict) -> None:
        """Change the replay's initial state (``u, v`` water-relative, ``r``, ``x0``, ``y0``,
        ``psi``) in place."""

    rudder_is_command: bool = False  # the record's rudder column is the command, the steering gear acts on it

    # ----------------------------------------------------------------------------------------- report
    def describe(self, values: dict) -> dict:
        """The effect's estimates (``values``: its own parameters, variant and linear unknowns)
        in a user's terms; default: as they are."""
        return dict(values)

    def units(self, problem=None) -> dict:
        """Unit of every reported parameter (``describe``'s keys)."""
        out = {p.name: p.unit for p in self.params}
        if problem is not None:
            out.update({k: u for k, (u, _) in self.linear(problem).items()})
            out.update({k: problem.coef_unit(k) for k in self.free_coefficients(problem)})
        return out

    def param_text(self, problem=None) -> str:
        u = self.units(problem)
        return ", ".join(f"{k} [{v}]" for k, v in u.items()) or "none"


def unit_forces(problem, n: int, eq: str) -> np.ndarray:
    """(n, 3) of the non-dimensional unit force in ``eq`` (0.5 rho L d U0^2, times L for N): the
    MMG scale."""
    out = np.zeros((n, 3))
    k = "XYN".index(eq)
    out[:, k] = problem.scale[k]
    return out


def polar(north: float, east: float) -> tuple:
    """(speed, direction in degrees clockwise from north) of a north/east pair."""
    return math.hypot(north, east), math.degrees(math.atan2(east, north)) % 360.0
