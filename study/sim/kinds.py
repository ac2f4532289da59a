"""The vessel kinds the simulator knows: kind name -> its module (one line per kind; see
``study.sim``)."""
from __future__ import annotations

import importlib

# kind name -> module path (one line per kind)
KINDS = {
    "mmg": "study.sim.mmg",
    "waterjet": "study.sim.waterjet",
    "abkowitz": "study.sim.abkowitz",
    "auv": "study.sim.auv",
    "nomoto": "study.sim.nomoto",
}


def get_kind(name: str):
    if name not in KINDS:
        raise ValueError(f"unknown vessel kind '{name}'; known kinds: {sorted(KINDS)}")
    return importlib.import_module(KINDS[name])
