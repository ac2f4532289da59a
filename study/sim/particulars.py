"""Mass and yaw inertia from a vessel config, shared by every kind's ``pack``."""
from __future__ import annotations


def mass_and_inertia(vessel: dict) -> tuple[float, float, float, float]:
    """(rho, Lpp, m, IzG): m = rho * volume unless ``mass.m`` is given; IzG = m (kzz_L Lpp)^2 unless
    ``mass.IzG`` is given (kzz_L defaults to 0.25, the usual assumption for merchant hulls)."""
    p = vessel["particulars"]
    ms = vessel["mass"]
    rho = float(p["rho"])
    L = float(p["Lpp"])
    m = float(ms["m"]) if ms.get("m") is not None else rho * float(p["volume"])
    IzG = float(ms["IzG"]) if ms.get("IzG") is not None else m * (float(ms.get("kzz_L", 0.25)) * L) ** 2
    return rho, L, m, IzG
