"""The regression rows of a run: a model's equation-error rows built from records by a sample
structure, processed (differenced, cleaned, split) into each equation's training rows, with their
noise operators and their errors.

:func:`regression_rows` stacks the rows of every segment of every record; :func:`prepare` takes them
through the structure's processing into one :class:`Prepared` regression per equation
(``study.identify.fit`` fits it); :func:`term_scales` weighs each term in its equation;
:func:`truncation_rows` and :func:`row_errors` give the rows' truncation errors and regressor-noise
probes that emcee's regression likelihood removes; :func:`build` stacks the bare rows of a model
config (for tests and notebooks).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .collinearity import collinearity
from .structures import segments

#: a candidate column explained by the columns kept before it up to this fraction of its sum of squares
#: (uncentred R^2 > 1 - gap) is dropped from SINDy's library as indistinguishable
CANDIDATE_R2_GAP = 1e-3


def regression_rows(model, structure, records, candidates: int | None = None):
    """Per equation ``(Phi, y, segment id)`` stacked over every segment of every record, before
    the structure's post-processing; with ``candidates`` (a degree) the model's extra candidate
    columns are appended (their names in ``model.candidate_names_``)."""
    acc: dict = {}
    cand_names = None
    sid = 0
    for i, rec in enumerate(records):
        df = rec.data if hasattr(rec, "data") else rec
        for seg in segments(df, i, min_len=structure.min_nodes(model.order)):
            seg = structure.measured(seg)
            rows = model.rows(seg, structure)
            if candidates:
                cand_names, C = model.candidates(seg, structure, int(candidates))
            for eq, r in rows.items():
                Phi = np.column_stack([r.Phi, C]) if candidates else r.Phi
                acc.setdefault(eq, []).append((Phi, r.y, np.full(len(r.y), sid)))
            sid += 1
    if not acc:
        raise ValueError(f"no regression rows: every record is shorter than the {structure.min_nodes(model.order)} "
                         f"samples structure '{structure.name}' needs for model '{model.name}'")
    model.candidate_names_ = cand_names or []
    return {eq: tuple(np.concatenate([p[j] for p in parts]) for j in range(3)) for eq, parts in acc.items()}


def noise_operators(model, structure, records) -> list | None:
    """The structure's noise operators (:meth:`Structure.noise_operators`) of every segment of
    every record, in the order of :func:`regression_rows`, block-diagonal over segments: sparse
    (built rows x all nodes). None when the structure has none (its rows are no fixed linear
    stencil of the samples)."""
    import scipy.sparse as sp

    blocks = []
    for i, rec in enumerate(records):
        df = rec.data if hasattr(rec, "data") else rec
        for seg in segments(df, i, min_len=structure.min_nodes(model.order)):
            ops = structure.noise_operators(structure.measured(seg), model.order)
            if ops is None:
                return None
            blocks.append(ops)
    if not blocks:
        return None
    return [sp.block_diag([b[j] for b in blocks], format="csr") for j in range(len(blocks[0]))]


def _drop_duplicate_candidates(Phi: np.ndarray, n_model: int, names: list) -> tuple[np.ndarray, list]:
    """Drop candidate columns (after the first ``n_model``) that the columns kept so far explain
    to ``R^2 > 1 - CANDIDATE_R2_GAP`` by least squares: such a term cannot be told from the
    model's own terms (e.g. the AUV's u v and the candidate (U/U0)^2 v' = U v / U0^2 differ only
    through the small drift), and a sparse regression would split the coefficient between the two
    arbitrarily."""
    keep = list(range(n_model))
    for j in range(n_model, Phi.shape[1]):
        c = Phi[:, j]
        if not np.all(np.isfinite(c)) or not np.any(c):
            continue
        A = Phi[:, keep]
        coef, *_ = np.linalg.lstsq(A, c, rcond=None)
        resid = c - A @ coef
        if np.sum(resid ** 2) > CANDIDATE_R2_GAP * np.sum(c ** 2):
            keep.append(j)
    return Phi[:, keep], [names[j] for j in keep]


@dataclass
class Prepared:
    """One equation's regression after the structure's processing: training rows ``X``
    (DataFrame, columns = model terms then candidate terms), ``y``; held-out rows; the processing
    report; multicollinearity of the model terms."""

    X: pd.DataFrame
    y: np.ndarray
    X_test: np.ndarray
    y_test: np.ndarray
    report: dict
    n_model: int
    collinearity: dict
    noise_operators: object = None  # the training rows' row_noise.RowOperators (prepare(..., operators=True))
    row_map: object = None  # sparse (training rows x built rows): the post-processing's differencing, cleaning, split
    dropped_differences: int = 0  # differenced rows dropped afterwards (cleaning, split): gaps in the chains


def term_scales(model, records, rows: dict | None = None) -> dict:
    """Each model term's weight in its equation: the RMS of the term's regressor over the RMS of
    the equation's left-hand side, on central-difference rows of the training records. The same
    rows serve every structure and estimator of a dataset, so scaled errors of two structures
    compare. ``|estimate - truth| * scale`` is the error's contribution to the equation in units
    of the equation's own size: a coefficient near zero whose term hardly acts no longer
    dominates a median of relative errors, and a zero truth gets a finite figure. Empty for
    models whose reported parameters are not regression columns (Nomoto's K, T, ...) or rows that
    cannot be made. ``rows``: those central-difference rows when the caller has built them
    already (:func:`regression_rows`)."""
    if getattr(model, "type", None) == "nomoto":
        return {}
    if rows is None:
        try:
            rows = regression_rows(model, _central(), records)
        except (ValueError, KeyError):
            return {}
    out = {}
    for eq, (Phi, y, _) in rows.items():
        ry = float(np.sqrt(np.mean(np.square(y)))) if len(y) else 0.0
        if not ry > 0:
            continue
        for j, n in enumerate(model.equations[eq]):
            out[n] = float(np.sqrt(np.mean(np.square(Phi[:, j])))) / ry
    return out


def _central():
    from .structures import make_structure

    return make_structure({"name": "central", "clean": {}, "split": {}})


def same_rows_as_central(structure, candidates) -> bool:
    """Whether ``structure`` builds the rows :func:`term_scales` needs (central differences, no
    candidates): its clean-up and split act only after the rows are built."""
    return not candidates and structure.name == "central" and type(structure) is type(_central())


def prepare(model, structure, records, candidates: int | None = None, seed: int = 0,
            operators: bool = False, rows: dict | None = None) -> dict:
    """Per equation the :class:`Prepared` regression of ``model`` on ``records`` with
    ``structure``; with ``operators`` also the training rows' noise operators
    (:func:`noise_operators` through the post-processing's row map, as a
    :class:`study.identify.row_noise.RowOperators`; None when the structure has none). ``rows``:
    the structure's rows when the caller has built them already (:func:`regression_rows`)."""
    from .row_noise import RowOperators

    if rows is None:
        rows = regression_rows(model, structure, records, candidates=candidates)
    ops = noise_operators(model, structure, records) if operators else None
    out = {}
    for eq, (Phi, y, seg) in rows.items():
        names = list(model.equations[eq])
        n_model = len(names)
        if candidates:
            Phi, names = _drop_duplicate_candidates(Phi, n_model, names + model.candidate_names_)
        post = structure.postprocess(Phi, y, seg, seed=seed)
        # differenced rows then dropped leave gaps, so the differencing cannot be undone (study.identify.truncation)
        dropped = (len(y) - len(np.unique(seg)) - post["rows"].shape[0]) if structure.difference else 0
        if len(post["y"]) < len(names):
            raise ValueError(f"equation {eq}: {len(post['y'])} rows after structure '{structure.name}' for "
                             f"{len(names)} unknowns")
        out[eq] = Prepared(pd.DataFrame(post["Phi"], columns=names), post["y"], post["Phi_test"], post["y_test"],
                           post["report"], n_model, collinearity(post["Phi"][:, :n_model]),
                           None if ops is None else RowOperators([(post["rows"] @ L).tocsr() for L in ops],
                                                                 centred=bool(structure.center)),
                           post["rows"], int(max(dropped, 0)))
    return out


@dataclass
class Regression:
    """Per equation: regressor matrix, target, column names, truth values (when the columns are
    parameters)."""

    Phi: dict
    y: dict
    names: dict
    truth: dict
    n_samples: int


def build(vessel, model, records, structure) -> Regression:
    """Stack the (unprocessed) regression rows of every record for a model config and a structure
    name.

    A convenience for tests and notebooks; the study's runs go through
    ``study.identify.fit.identify``.
    """
    from .models import make_model
    from .structures import make_structure

    m = make_model(model, vessel)
    skip, why = m.skip(None)
    if skip:
        raise ValueError(why)
    s = make_structure(structure)
    rows = regression_rows(m, s, records)
    truth, _, _ = m.truth()
    out = Regression({}, {}, {}, {}, 0)
    for eq, (Phi, y, _seg) in rows.items():
        out.Phi[eq], out.y[eq], out.names[eq] = Phi, y, list(m.equations[eq])
        out.truth[eq] = [truth.get(c, np.nan) for c in m.equations[eq]]
        out.n_samples = int(len(y))
    return out


def truncation_rows(model, structure, records) -> dict:
    """Per equation ``(y_t, Phi_t)``: the truncation errors of the built rows' target and
    regressors (``study.identify.truncation``), in the order of :func:`regression_rows`; empty
    where the structure has no fixed stencil (the RTS smoother's states, r from the heading)."""
    from .truncation import TruncationStructure

    try:
        rows = regression_rows(model, TruncationStructure(structure), records)
    except ValueError:
        return {}
    return {eq: (y, Phi) for eq, (Phi, y, _) in rows.items()}


def row_errors(model, structure, records, prepared: dict, trunc_rows: dict | None = None, seed: int = 0,
               n_probes: int | None = None) -> dict:
    """Per equation the :class:`study.identify.row_errors.RowErrors` of its training rows: their
    truncation errors (:func:`truncation_rows` through the row map) and the probes of the
    regressors' noise (the records with fresh noise at each channel's estimated level, built into
    rows like the records and taken through the same row map; centred like the rows where the
    structure centres). ``n_probes``: None ``row_errors.N_PROBES``, 0 no probes (noise-free
    records). Each probe's rows are built once for every equation."""
    from .row_errors import N_PROBES, RowErrors, noisy_copies

    n_probes = N_PROBES if n_probes is None else int(n_probes)

    trunc = truncation_rows(model, structure, records) if trunc_rows is None else trunc_rows
    eqs = {eq: pr for eq, pr in prepared.items() if pr.row_map is not None and pr.noise_operators is not None}

    def mapper(pr):
        R, centred = pr.row_map, bool(pr.noise_operators.centred)

        def mapped(a):
            a = R @ np.nan_to_num(a)
            return a - a.mean(axis=0) if centred else a
        return mapped

    maps = {eq: mapper(pr) for eq, pr in eqs.items()}
    sds, copies = noisy_copies(records, n_probes, seed)
    # each probe's rows built once for every equation (building them costs 70 ms on an MMG hull)
    store: dict = {eq: [] for eq in eqs}
    if n_probes > 0 and eqs:
        base = regression_rows(model, structure, records)
        for recs in copies:
            rows = regression_rows(model, structure, recs)
            for eq in eqs:
                (Phi, y, _), (Phi0, y0, _) = rows[eq], base[eq]
                store[eq].append((maps[eq](Phi - Phi0), maps[eq](y - y0)))
    out = {}
    for eq, pr in eqs.items():
        ty = tX = None
        if eq in trunc and trunc[eq][1].shape[1] == pr.X.shape[1]:
            ty, tX = maps[eq](trunc[eq][0]), maps[eq](trunc[eq][1])
        out[eq] = RowErrors(ty, tX, (lambda eq=eq: iter(store[eq])) if n_probes > 0 else None, sds)
    return out
