"""The state estimator's names and options: the state order, the measured channels, the options
with their defaults and their check (:func:`resolve_options`), and the fixed numbers of the
filter and the search."""
from __future__ import annotations

import math

#: state order of the filter
STATES = ("x0", "y0", "psi", "u", "v", "r", "u_dot", "v_dot", "r_dot")
#: measured channels (the first six states, in the same order)
CHANNELS = ("x0", "y0", "psi", "u", "v", "r")
#: what ``options`` may hold, with their defaults (see :func:`estimate_states`)
DEFAULTS = {
    "position_std": "auto",  # m, absolute standard deviation of x0 and y0 (GNSS), or "auto"
    "heading_std": "auto",  # rad, of psi, or "auto"
    "u_std": "auto",  # m/s, of a measured u (used only when the record has u), or "auto"
    "v_std": "auto",  # m/s
    "r_std": "auto",  # rad/s
    "use_velocities": True,  # fuse measured u, v, r where the record has them (false: positions and heading only)
    "process": "ml",  # "ml" (maximum likelihood over q_r and q_uv) or {"q_uv": m^2/s^5, "q_r": rad^2/s^5}
}
#: a step longer than this many median steps is split (a dropout bridged by prediction)
GAP_FACTOR = 1.5
#: the largest heading change [rad] of one prediction sub-step
MAX_TURN_STEP = 0.05
#: bandwidth grid of the likelihood search: points per decade of omega
GRID_PER_DECADE = 4


def resolve_options(options: dict | None) -> dict:
    """``options`` merged over :data:`DEFAULTS`; unknown keys refused (a misspelt option must not
    pass)."""
    opts = dict(DEFAULTS)
    for k, v in (options or {}).items():
        if k not in DEFAULTS:
            raise ValueError(f"state estimation: unknown option '{k}'; known: {sorted(DEFAULTS)}")
        opts[k] = v
    proc = opts["process"]
    if isinstance(proc, str):
        if proc != "ml":
            raise ValueError(f"state estimation: process must be 'ml' or {{q_uv: ..., q_r: ...}}, got '{proc}'")
    else:
        proc = dict(proc)
        bad = sorted(set(proc) - {"q_uv", "q_r"})
        if bad or not {"q_uv", "q_r"} <= set(proc):
            raise ValueError(f"state estimation: process needs exactly q_uv [m^2/s^5] and q_r [rad^2/s^5], got "
                             f"{sorted(proc)}")
        if not all(float(v) > 0 and math.isfinite(float(v)) for v in proc.values()):
            raise ValueError(f"state estimation: process noise must be positive and finite, got {proc}")
        opts["process"] = {k: float(v) for k, v in proc.items()}
    for k in ("position_std", "heading_std", "u_std", "v_std", "r_std"):
        v = opts[k]
        if v is None or v == "auto":
            opts[k] = "auto"
            continue
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"state estimation: {k} must be a number (absolute standard deviation) or 'auto', "
                             f"got {v!r}") from None
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"state estimation: {k} must be positive and finite, got {v}")
        opts[k] = v
    opts["use_velocities"] = bool(opts["use_velocities"])
    return opts

