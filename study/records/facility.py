"""Where a record was measured (its *facility*), what can exist there, and the test set-up a record
belongs to.

A facility is one of :data:`FACILITIES`: ``towing_tank``, ``basin``, ``pond`` or ``sea``. A record
names it in its metadata (``# facility: towing_tank`` in a CSV header, ``facility`` in a Parquet
file's ``study.meta``; the loaders of ``study.records.loaders`` set it for the real datasets), else
the vessel config may (``facility:`` at its top level); a record with neither has no known facility,
and nothing is ruled out for it.

What the facility rules out (the model doctor's candidates, ``study.doctor.diagnose``):

- **indoors** (a towing tank, a basin) there is no wind: an effect that needs wind (``needs =
  ("wind",)``, the wind effect) is no candidate;
- **still water** (a towing tank, a basin: the water at rest between runs) has no current: an effect
  that needs a current is no candidate. A facility that generates wind or current is not one of
  these: name it ``sea``;
- in a **pond** (outdoors, closed water) a current can only be the wind's drift. Wu (1975, J. Fluid
  Mech. 68, 49-70) measured the surface drift at 3.5 % of the wind speed at long fetch and a larger
  share at the short fetches of a laboratory tank; the drift falls quickly below the surface
  (Glossary of Meteorology, American Meteorological Society: "2.5-3.0 % of the wind speed ...
  decreases rapidly in the uppermost meter"), so the current a hull feels over its draft is below
  the surface drift. A fitted current faster than :data:`POND_DRIFT_SHARE` (twice Wu's 3.5 %, this
  project's margin for the short fetch) of the largest mean true wind speed of the training records
  is rejected as implausible there; with no measured wind there is no bound.

The *set-up* of a record is its facility and its ``scale`` metadata (e.g. ``model``, ``full``,
``1:45.714``): an effect the doctor attributes to the test set-up (``setup_effect = True`` on the
effect class, or in its YAML: a yaw bias from a rudder zero offset) belongs to the set-up its
training records were measured in, and is left out of predictions for another facility or scale
unless the user asks to keep it (:func:`other_setup`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FACILITIES", "Facility", "check", "facility_of", "ruled_out", "implausible", "setup_of", "other_setup",
           "POND_DRIFT_SHARE"]


@dataclass(frozen=True)
class Facility:
    name: str
    indoor: bool
    still_water: bool
    text: str

    def lacks(self, need: str) -> str | None:
        """Why ``need`` (``wind`` or ``current``) cannot exist here, or None."""
        if need == "wind" and self.indoor:
            return f"{self.text} is indoors: no wind"
        if need == "current" and self.still_water:
            return f"{self.text} has still water: no current"
        return None


FACILITIES = {f.name: f for f in (
    Facility("towing_tank", True, True, "a towing tank"),
    Facility("basin", True, True, "a manoeuvring basin"),
    Facility("pond", False, False, "a pond (outdoors, closed water)"),
    Facility("sea", False, False, "open water"),
)}

#: a pond's current is the wind's drift: at most this share of the true wind speed (Wu 1975: 3.5 % at long fetch,
#: more at short fetch; doubled as this project's margin)
POND_DRIFT_SHARE = 2 * 0.035


def check(value, where: str) -> str:
    """A facility name as given (``value``), or a ``ValueError`` in one line naming ``where``
    (the file) and what was expected (``study.records.schema`` raises it as its ``SchemaError``).
    ``None`` passes (no facility stated)."""
    if value is None:
        return None
    if not isinstance(value, str) or value not in FACILITIES:
        raise ValueError(f"{where}: facility: {value}: expected one of {', '.join(FACILITIES)}")
    return value


def facility_of(meta: dict | None, vessel_cfg: dict | None = None) -> str | None:
    """A record's facility: its metadata's, else the vessel config's, else None (not stated)."""
    f = (meta or {}).get("facility")
    if f is None and vessel_cfg:
        f = vessel_cfg.get("facility")
    return f


def ruled_out(effect, facilities: list) -> str | None:
    """Why ``effect`` cannot act in any of the training records' ``facilities`` (one per record),
    or None. A record of unknown facility (None) rules nothing out."""
    needs = tuple(getattr(effect, "needs", ()) or ())
    if not needs or not facilities or any(f is None for f in facilities):
        return None
    reasons = []
    for f in dict.fromkeys(facilities):
        why = next((FACILITIES[f].lacks(n) for n in needs if FACILITIES[f].lacks(n)), None)
        if why is None:
            return None  # it can act in one of them
        reasons.append(why)
    return "; ".join(reasons) + " (the records' facility)"


def implausible(effect, values: dict, facilities: list, records: list) -> str | None:
    """Why the fitted ``values`` (the effect's parameters in the user's terms, ``describe``)
    cannot be, in the training records' ``facilities``; None when plausible or when nothing
    bounds them."""
    needs = tuple(getattr(effect, "needs", ()) or ())
    if "current" not in needs or not facilities or set(facilities) != {"pond"}:
        return None
    speed = values.get("current_speed")
    winds = [float(np.mean(df["wind_speed"])) for df in records if "wind_speed" in getattr(df, "columns", ())]
    if speed is None or len(winds) != len(records) or not winds:
        return None
    bound = POND_DRIFT_SHARE * max(winds)
    if float(speed) <= bound:
        return None
    return (f"a current of {float(speed):.3g} m/s in a pond, where a current is the wind's drift: at most "
            f"{100 * POND_DRIFT_SHARE:.0f} % of the largest mean true wind ({max(winds):.3g} m/s), "
            f"{bound:.3g} m/s (Wu 1975)")


def setup_of(meta: dict | None, vessel_cfg: dict | None = None) -> tuple:
    """A record's test set-up: (facility, scale), each None when not stated."""
    scale = (meta or {}).get("scale")
    return facility_of(meta, vessel_cfg), (str(scale) if scale is not None else None)


def other_setup(setup: tuple, training: list) -> str | None:
    """Why a prediction in ``setup`` is for another set-up than the ``training`` records' (a list
    of set-ups), or None when it is the same or cannot be told (a facility or scale not stated on
    either side)."""
    facility, scale = setup
    fs = {f for f, _ in training}
    if facility is not None and None not in fs and facility not in fs:
        return f"another facility ({facility}; trained in {', '.join(sorted(fs))})"
    ss = {s for _, s in training}
    if scale is not None and None not in ss and scale not in ss:
        return f"another scale ({scale}; trained at {', '.join(sorted(ss))})"
    return None
