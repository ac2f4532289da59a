"""Prior knowledge of a model's coefficients: a mean and a standard deviation for each, from where a
naval architect would take them.

Sources (``prior.source`` of an estimator or of the doctor):

- ``vessel``: the vessel config's own coefficients (published captive-test or CFD values). In a
  simulation they ARE the truth, so a study on simulated records that uses them says so
  (``prior_is_truth``).
- ``empirical``: regressions on the main particulars (MMG kind only, :func:`empirical_mmg_hull`),
  for a vessel with no published set. Independent of any vessel config's coefficients.
- ``offset``: the truth moved by ``offset`` (relative), alternately up and down coefficient by
  coefficient (the first up): a study device that stands for "a published set from another basin,
  some 20 % off", never the truth itself.

The standard deviation of each coefficient is ``sd`` (relative) times its prior size, at least
``sd`` times the median size of the model's nonzero prior coefficients (a coefficient given as 0 is
not known to be 0). Assumption labelled: independent priors, no correlation between coefficients.
"""
from __future__ import annotations

import math

import numpy as np

#: relative standard deviation of the empirical regressions' hull coefficients (assumption: the scatter of
#: the regressions' data about their fit is of the order of the coefficients' size for the nonlinear terms
#: and about a third for the linear ones; checked below against KVLCC2's published set)
EMPIRICAL_SD = {"linear": 0.35, "nonlinear": 1.0}
LINEAR_MMG = ("Yv", "Yr", "Nv", "Nr")


def empirical_mmg_hull(particulars: dict, m_nd: float | None = None) -> dict:
    """MMG hull coefficients (non-dimensional as in Yasukawa & Yoshimura 2015) from the main
    particulars.

    Linear derivatives: Kijima, Katsuno, Nakiri & Furukawa (1990), "On the manoeuvring performance
    of a ship with the parameter of loading condition", J Soc Nav Arch Japan 168, 141-148 (k =
    2d/L)::

        Y'v = -(pi/2 k + 1.4 Cb B/L)          N'v = -k
        Y'r = m' + m'x - 1.5 Cb B/L            N'r = -0.54 k + k^2

    Nonlinear terms: the regressions of Yoshimura & Masumoto (2012), "Hydrodynamic database and
    manoeuvring prediction method with medium high-speed merchant ships and fishing vessels", MARSIM
    2012 (as carried by public MMG implementations; the printed tables were not available here:
    labelled)::

        X'vv = 1.15 Cb/(L/B) - 0.18            X'rr = -0.085 Cb/(L/B) + 0.008
        X'vr = -m'y + 1.91 Cb/(L/B) - 0.08
        Y'vvv = -0.185 L/B - 0.48              N'vvv = 0.69 Cb - 0.66
        Y'vvr = -0.75                          N'vvr = 1.55 Cb B/L - 0.76
        Y'vrr = -0.26 (1 - Cb) L/B - 0.11      N'vrr = -0.075 (1 - Cb) L/B + 0.098
        Y'rrr = -0.051                         N'rrr = 0.25 Cb B/L - 0.056

    X'vvvv has no regression here: 0 (assumption). R'0 from ITTC 1957 friction with a form factor is
    left to the caller (it is known from the approach speed and rpm far better than from any
    regression). Added masses (Zhou, Yan & Feng's regressions as used in MMG practice; labelled:
    checked against KVLCC2, 0.224 and 0.0112 against the published 0.223 and 0.011)::

        m_y/m = 0.882 - 0.54 Cb (1 - 1.6 d/B) - 0.156 (1 - 0.673 Cb) L/B
                + 0.826 (d/B)(L/B)(1 - 0.678 d/B) - 0.638 Cb (L/B)(d/B)(1 - 0.669 d/B)
        J_z = m (0.01 L (33 - 76.85 Cb (1 - 0.784 Cb) + 3.43 L/B (1 - 0.63 Cb)))^2
        m_x = 0.05 m (assumption, a common rule of thumb)

    ``m_nd`` is m' = m / (0.5 rho L^2 d); by default from the block coefficient (m' = 2 Cb B / L).
    Returns {parameter name (``study.sim.mmg`` names and the config's added-mass keys): value}.
    """
    L, B, d, Cb = (float(particulars[k]) for k in ("Lpp", "B", "d", "Cb"))
    k = 2.0 * d / L
    cbl = Cb * B / L
    LB, dB = L / B, d / B
    m_nd = float(m_nd) if m_nd is not None else 2.0 * Cb * B / L
    my_m = (0.882 - 0.54 * Cb * (1 - 1.6 * dB) - 0.156 * (1 - 0.673 * Cb) * LB
            + 0.826 * dB * LB * (1 - 0.678 * dB) - 0.638 * Cb * LB * dB * (1 - 0.669 * dB))
    kzz_add = 0.01 * (33 - 76.85 * Cb * (1 - 0.784 * Cb) + 3.43 * LB * (1 - 0.63 * Cb))
    m_x, m_y, J_z = 0.05 * m_nd, my_m * m_nd, m_nd * kzz_add ** 2
    return {
        "m_x": m_x, "m_y": m_y, "J_z": J_z,
        "Xvv": 1.15 * Cb / LB - 0.18, "Xvr": -m_y + 1.91 * Cb / LB - 0.08, "Xrr": -0.085 * Cb / LB + 0.008,
        "Xvvvv": 0.0,
        "Yv": -(0.5 * math.pi * k + 1.4 * cbl), "Yr": m_nd + m_x - 1.5 * cbl,
        "Yvvv": -0.185 * LB - 0.48, "Yvvr": -0.75, "Yvrr": -0.26 * (1 - Cb) * LB - 0.11, "Yrrr": -0.051,
        "Nv": -k, "Nr": -0.54 * k + k ** 2,
        "Nvvv": 0.69 * Cb - 0.66, "Nvvr": 1.55 * cbl - 0.76, "Nvrr": -0.075 * (1 - Cb) * LB + 0.098,
        "Nrrr": 0.25 * cbl - 0.056,
    }


def empirical_resistance(particulars: dict, U: float, nu: float = 1.14e-6, form_factor: float = 0.3) -> float:
    """R'0 = C_T S / (L d) with the ITTC-1957 friction line C_F = 0.075 / (log10 Re - 2)^2, C_T =
    (1 + k) C_F (no wave resistance at manoeuvring Froude numbers of a full hull: assumption), k
    = 0.3 (assumption: a typical form factor of a full-form tanker) and the wetted surface by
    Mumford's formula S = 1.7 L d + Cb L B (Molland, Turnock & Hudson 2017, Sec. 10.3); nu of
    fresh water at 15 deg C."""
    L, B, d, Cb = (float(particulars[k]) for k in ("Lpp", "B", "d", "Cb"))
    Re = U * L / nu
    C_F = 0.075 / (np.log10(Re) - 2.0) ** 2
    S = 1.7 * L * d + Cb * L * B
    return float((1.0 + form_factor) * C_F * S / (L * d))


def empirical_sd(name: str, value: float) -> float:
    """The empirical prior's standard deviation of one MMG coefficient (see
    :data:`EMPIRICAL_SD`)."""
    rel = EMPIRICAL_SD["linear"] if name in LINEAR_MMG else EMPIRICAL_SD["nonlinear"]
    return rel * abs(value)


def vessel_m_nd(vessel) -> float:
    p = vessel.cfg["particulars"]
    m = float(vessel.cfg.get("mass", {}).get("m") or float(p["rho"]) * float(p.get("volume") or 0.0))
    if not m:
        return 2.0 * float(p["Cb"]) * float(p["B"]) / float(p["Lpp"])
    return m / (0.5 * float(p["rho"]) * float(p["Lpp"]) ** 2 * float(p["d"]))


def prior_for(model, cfg: dict | None) -> dict | None:
    """``{coefficient: (mean, sd)}`` of the model's regression columns for an estimator's or the
    doctor's ``prior`` config ``{source: vessel|empirical|offset, sd: 0.3, offset: 0.2}``; None
    without one.

    Raises ValueError (one line, naming the source and the model) when the source has nothing for
    the model.
    """
    if not cfg or not cfg.get("source"):
        return None
    source = str(cfg["source"])
    rel = float(cfg.get("sd", 0.3))
    names = [n for eq in model.equations.values() for n in eq]
    if source == "vessel" or source == "offset":
        truth, _, _ = model.truth()
        phys = dict(truth)
        if source == "offset":
            off = float(cfg.get("offset", 0.2))
            phys = {n: v * (1.0 + off * (1 if i % 2 == 0 else -1)) for i, (n, v) in enumerate(phys.items())}
        mean = model.regression_from_physical(phys) if hasattr(model, "regression_from_physical") else phys
    elif source == "empirical":
        if getattr(model, "type", None) != "kind" or model.vessel.kind_name != "mmg":
            raise ValueError(f"prior.source=empirical: no empirical regressions for model '{model.name}' on a "
                             f"'{model.vessel.kind_name}' vessel (only the MMG hull: Kijima et al. 1990, "
                             f"Yoshimura & Masumoto 2012); use prior.source=vessel or offset")
        emp = empirical_mmg_hull(model.vessel.cfg["particulars"], vessel_m_nd(model.vessel))
        truth, _, _ = model.truth()
        mean = {n: emp.get(n, truth.get(n, 0.0)) for n in names}
        sd = {n: (empirical_sd(n, mean[n]) if n in emp else rel * abs(mean[n])) for n in names}
        return _with_floor(mean, sd, rel, names)
    else:
        raise ValueError(f"prior.source={source!r}: expected one of vessel, empirical, offset")
    missing = [n for n in names if n not in mean]
    if missing:
        raise ValueError(f"prior.source={source}: no prior value for {missing} of model '{model.name}'")
    return _with_floor({n: mean[n] for n in names}, {n: rel * abs(mean[n]) for n in names}, rel, names)


def _with_floor(mean: dict, sd: dict, rel: float, names: list) -> dict:
    nz = np.abs([mean[n] for n in names if mean[n] != 0.0])
    floor = rel * (float(np.median(nz)) if len(nz) else 1.0)
    return {n: (float(mean[n]), float(max(sd[n], floor))) for n in names}
