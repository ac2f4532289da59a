"""emcee's posteriors as ArviZ ``InferenceData``: the chains a run saved (one ``chain.npz`` per
equation for the regression likelihoods, one for output error), joined into one posterior, with
ArviZ's r-hat and effective sample sizes (Vehtari et al. 2021, rank-normalised split-R-hat and bulk
/ tail ESS).

The walkers of the affine-invariant ensemble are taken as ArviZ's chains, as ``arviz.from_emcee``
does; they are not independent chains, so r-hat over walkers says whether the ensemble has mixed,
not more. The equations are sampled independently, so their draws, truncated to the shortest chain
and the fewest walkers of any equation, pair up into draws of the joint posterior of every
coefficient.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np


def _load(src) -> dict:
    data = src if isinstance(src, (bytes, bytearray)) else Path(src).read_bytes()
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def inference_data(chains: dict, attrs: dict | None = None):
    """One ``arviz.InferenceData`` from ``{equation: chain.npz (bytes or path)}`` (``""`` for an
    output-error run's single chain): group ``posterior`` with a variable per coefficient
    (``<equation>.<name>``, or the name alone), dims ``(chain, draw)`` = (walker, saved step);
    group ``sample_stats`` with each equation's log posterior (``lp`` or ``lp_<equation>``).
    ``attrs``: written into both groups (run id, configuration...)."""
    import arviz as az

    if not chains:
        raise ValueError("no chain to convert: the run saved no chain.npz (not an emcee run?)")
    loaded = {eq: _load(src) for eq, src in sorted(chains.items())}
    walkers = min(d["chain"].shape[1] for d in loaded.values())
    draws = min(d["chain"].shape[0] for d in loaded.values())
    post, stats = {}, {}
    for eq, d in loaded.items():
        ch = d["chain"][-draws:, :walkers, :]  # (draw, walker, parameter), the last saved steps
        for j, name in enumerate(str(n) for n in d["names"]):
            post[f"{eq}.{name}" if eq else name] = np.ascontiguousarray(ch[:, :, j].T)
        if "log_prob" in d:
            stats[f"lp_{eq}" if eq else "lp"] = np.ascontiguousarray(d["log_prob"][-draws:, :walkers].T)
    return az.from_dict(posterior=post, sample_stats=stats or None, attrs=dict(attrs or {}))


def diagnostics(idata):
    """ArviZ's r-hat and bulk / tail effective sample sizes of every coefficient (a DataFrame
    indexed by it)."""
    import arviz as az

    return az.summary(idata, kind="diagnostics", round_to="none")[["r_hat", "ess_bulk", "ess_tail", "mcse_mean"]]


def run_chains(artefact_dir) -> dict:
    """``{equation: path}`` of the chains a run saved under its artefact folder (``""``: output
    error)."""
    d = Path(artefact_dir)
    out = {}
    if (d / "chain.npz").is_file():
        out[""] = d / "chain.npz"
    for p in sorted(d.glob("*/chain.npz")):
        out[p.parent.name] = p
    return out
