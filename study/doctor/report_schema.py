"""The doctor's report as one schema: :class:`Report`, whose fields are the top-level keys of
``report.json`` in their order, and the rows with a stable shape (a ranked candidate, a ladder step,
a manoeuvre metric...) as
``TypedDict``.

A report is serialised once (:meth:`Report.to_dict`, :meth:`Report.to_json`) and read back once
(:meth:`Report.from_dict`), which refuses a report whose key is missing or of the wrong type with
one line naming it (:class:`ReportError`). A key the doctor has written from its first version on is
required; a key added later is optional (None when a report does not have it), so older reports
still read. What the report does not type beyond ``dict[str, Any]`` (a model's parameters and
errors, the prediction uncertainty, the rudder residual, the separating manoeuvre's scores) is owned
by the module that writes it and read by name where it is shown.
"""
# no ``from __future__ import annotations``: ``TypedDict`` reads ``NotRequired`` from evaluated annotations only
import json
import types
import typing
from dataclasses import dataclass, field, fields
from typing import Any, NotRequired, TypedDict, Union

__all__ = ["CatalogueRow", "ErrorRow", "FigureEntry", "IdentifiabilityRow", "LadderStep", "ManoeuvreMetricRow",
           "ModelSummary", "Provenance", "ProvenanceRecord", "RankingRow", "Report", "ReportError",
           "SeparatingManoeuvre", "SetupEffects", "StabilityEntry", "WorstWindow"]


class ReportError(ValueError):
    """A report that does not follow the schema: a key missing or of the wrong type (one line,
    naming it)."""


# --------------------------------------------------------------------------------------------- the rows


class ModelSummary(TypedDict):
    """The baseline or the final model (``baseline``, ``final``)."""

    validation_error: float  # mean NRMSE over the validation records; inf when a replay diverged
    training_error: NotRequired[float]  # equation-error misfit on the training records (the baseline's only)
    effects: list[str]  # the effects the model has
    parameters: dict[str, Any]  # name -> value (a number, or a word)
    errors: dict[str, Any]  # record -> channel -> {rmse, nrmse} (and ``diverged``)
    diverged: NotRequired[list[str]]  # the validation records whose replay diverged


class RankingRow(TypedDict):
    """A candidate effect added to the baseline, ranked by its validation error (``ranking``)."""

    effect: str  # the candidate
    validation_error: float  # with it added; inf when a replay diverged
    improvement: float | None  # relative fall of the validation error; None when no comparison was possible
    p_value: float | None  # of the paired test of the per-record errors; None with too few records
    significant: bool  # it lowers the error by enough (and consistently, when tested)
    diverged: NotRequired[bool]  # a replay with it diverged
    parameters: dict[str, Any]  # its parameters' estimates
    training_error: float  # equation-error misfit with it
    note: str  # what else to know about it ("" when nothing)
    diverged_records: NotRequired[list[str]]  # where its replay diverged
    stabilises: NotRequired[list[str]]  # records where the baseline diverges and it does not
    setup_effect: NotRequired[bool]  # an effect of the test set-up, not of the ship
    left_out_of: NotRequired[dict[str, str]]  # record -> why the set-up effect was left out of its prediction
    implausible: NotRequired[str]  # why it is physically implausible where the records were measured
    metrics: NotRequired[dict[str, Any]]  # its effect on the manoeuvre metrics: n, baseline_error, error, worse
    metrics_worse: NotRequired[bool]  # it lowers the NRMSE but worsens the manoeuvre metrics


class LadderStep(TypedDict):
    """A step of the error ladder: the baseline, then each effect added in turn (``ladder``)."""

    step: str  # ``baseline`` or ``+ effect``
    effects: list[str]  # the model's effects at this step
    validation_error: float  # over every validation record; inf when one diverged
    scored_error: NotRequired[float]  # over the scored records (those where the baseline did not diverge)
    scored_records: NotRequired[list[str]]  # those records
    training_error: float  # equation-error misfit
    diverged: NotRequired[list[str]]  # records whose replay diverged
    rejected: NotRequired[bool]  # the step failed the ranking's bar: the ladder stops before it
    reason: NotRequired[str]  # why it was rejected


class StabilityEntry(TypedDict):
    """A ladder step's verdict repeated with each validation record left out (``stability``)."""

    k: int | None  # in how many of the n the verdict is the same; None when not assessable
    n: int  # how many refits (validation records)
    text: str  # the same in words
    outcomes: NotRequired[list[dict[str, Any]]]  # each refit: left_out, named, ambiguous
    step: NotRequired[int]  # the ladder step (1: the first effect)


class ErrorRow(TypedDict):
    """One validation record's and channel's errors, baseline and final (``errors_table``)."""

    record: str
    channel: str  # u, v, r, psi or track
    unit: str
    baseline_rmse: float | None
    final_rmse: float | None
    baseline_nrmse: float | None
    final_nrmse: float | None
    baseline_diverged: NotRequired[bool]
    final_diverged: NotRequired[bool]


class WorstWindow(TypedDict):
    """A window of a record where the baseline's error is largest (``worst_windows``)."""

    record: str
    t_start: float  # [s]
    t_end: float  # [s]
    nrmse: float  # mean normalised error of u, v, r and psi over the window


class CatalogueRow(TypedDict):
    """A candidate effect of the catalogue (``catalogue``)."""

    name: str
    physics: str  # what it models
    parameters: str  # its parameters with their units, as text
    enters: str  # how it enters the model
    source: str  # where it comes from
    applies: NotRequired[str]  # ``yes``, or why it cannot act here


class FigureEntry(TypedDict):
    """A figure of the report, its PNG in ``figures/`` (``figures``)."""

    file: str
    title: str
    caption: str
    section: str  # compare, residuals, growth, ladder, intervals...


class ManoeuvreMetricRow(TypedDict):
    """A manoeuvre metric of a validation record, measured and predicted (``maneuver_metrics``;
    the rows of ``study.records.maneuver_metrics.maneuver_metrics`` with their intervals from
    ``study.doctor.uncertainty``)."""

    record: str
    metric: str  # tactical_diameter, first_overshoot...
    unit: str
    measured: float  # NaN when the record does not show it
    baseline: float  # NaN when the replay does not
    final: float
    final_low: NotRequired[float]  # the final model's 90 % interval
    final_high: NotRequired[float]
    final_uncertainty: NotRequired[dict[str, Any]]  # its parts: s_id, s_struct, s_extrap, why, caveat...
    measured_low: NotRequired[float]  # the measured value's own 90 % interval (its record's noise, replayed)
    measured_high: NotRequired[float]
    measured_noise: NotRequired[dict[str, Any]]  # s_meas (sd of the log), probes
    tie: NotRequired[float]  # under a tie: the tied readings' equal mixture (its median), with its 90 % interval
    tie_low: NotRequired[float]
    tie_high: NotRequired[float]
    tie_readings: NotRequired[dict[str, Any]]  # {effect: {value, low, high}}
    carriers: NotRequired[list[dict[str, Any]]]  # the coefficients that carry the prediction, each a sentence
    baseline_low: NotRequired[float]  # the baseline's 90 % interval
    baseline_high: NotRequired[float]
    baseline_uncertainty: NotRequired[dict[str, Any]]


class IdentifiabilityRow(TypedDict):
    """An anchored coefficient of the baseline fit, and whether the records determine it
    (``identifiability``)."""

    coefficient: str
    prior: float
    estimate: float
    prior_sd: float
    posterior_sd: float
    ratio: float  # posterior sd / prior sd
    moved_prior_sd: float  # (estimate - prior) / prior sd
    sentence: str


class SeparatingManoeuvre(TypedDict):
    """The manoeuvre that would best tell the two leading candidates apart (``separating_maneuver``;
    written by
    ``study.doctor.separating``)."""

    pair: list[str]  # the two candidates
    scale: dict[str, float]  # channel -> its scale
    noise: dict[str, Any]
    misfit: dict[str, Any]
    menu: list[dict[str, Any]]  # each manoeuvre scored: maneuver, side, speed_U0, S, channel, max, diverged
    recorded: list[dict[str, Any]]  # the records in hand scored the same way
    best: dict[str, Any] | None  # the best of the menu
    text: str  # the recommendation in words


class SetupEffects(TypedDict):
    """The final model's set-up effects and where they were left out (``setup_effects``)."""

    effects: list[str]
    kept: bool  # kept in every prediction (``keep_setup_effects``)
    left_out: dict[str, Any]  # record -> {effects, why}


class ProvenanceRecord(TypedDict):
    role: str  # train or validate
    name: str
    path: NotRequired[str | None]
    sha256: str
    sha256_of: str  # ``file``, or the data as CSV


class Provenance(TypedDict):
    """What made the report (``provenance``)."""

    package: str
    version: str | None
    revision: str | None  # git revision; None outside a checkout
    modified: bool | None  # tracked files differ from it
    command: str
    date: str  # UTC, ISO 8601
    records: list[ProvenanceRecord]


# --------------------------------------------------------------------------------------------- the report


@dataclass(kw_only=True)
class Report:
    """The doctor's report: the fields are the keys of ``report.json``, in its order. Optional
    fields (keys added after the first reports) are None when a report does not have them."""

    verdict: str  # the one-line verdict
    baseline: ModelSummary  # the model as given (with the user's effects)
    ranking: list[RankingRow]  # the candidates of the first step, best first
    not_applicable: dict[str, str] | None = None  # effect -> why it was not tried here
    missing_effect: str | None  # the effect named; None when none is (or two cannot be told apart)
    missing_effects: list[str] | None = None  # the first step's effects: the one named, or a pair named together
    ambiguous: list[str]  # the two candidates the data cannot tell apart, else empty
    ladder: list[LadderStep]  # the baseline, then each effect added in turn
    stability: list[StabilityEntry] | None = None  # each step's verdict with one validation record left out
    separating_maneuver: SeparatingManoeuvre | None = None  # for a weak verdict, the manoeuvre that would settle it
    rudder_residual: dict[str, dict[str, Any]] | None = None  # baseline/final -> residual per rudder-angle bin
    scored_records: list[str] | None = None  # the validation records compared on (the baseline did not diverge)
    diverged: dict[str, list[str]] | None = None  # ladder step -> the records where it diverged
    final: ModelSummary  # the model with the effects found
    units: dict[str, str] | None = None  # parameter -> unit
    identifiability: list[IdentifiabilityRow] | None = None  # the anchored coefficients the records determine
    errors_table: list[ErrorRow]  # per validation record and channel, baseline and final
    notes: list[str]  # what the reader should know beside the verdict
    setup_effects: SetupEffects | None = None  # the final model's set-up effects
    facilities: dict[str, str | None] | None = None  # record -> the facility it was measured in
    mode: str  # ``given`` (validation records given) or ``held_out`` (each training record held out)
    train: list[str]  # the training records
    validate: list[str]  # the validation records (empty when held out)
    depths_h_T: dict[str, float | None] | None = None  # record -> water depth over draft; None: not given
    seconds: float  # the diagnosis's wall time [s]
    title: str  # the page's title
    created_by: str  # the command that wrote it
    vessel: str
    model: str
    structure: str  # the identification's sample structure
    worst_windows: list[WorstWindow]  # where the baseline's error is largest
    catalogue: list[CatalogueRow]  # the candidate effects
    figures: list[FigureEntry]  # the figures, in ``figures/``
    maneuver_metrics: list[ManoeuvreMetricRow] | None = None  # turning-circle and zigzag metrics with intervals
    prediction_uncertainty: dict[str, Any] | None = None  # how far the predictions can be trusted
    conventions: str | None = None  # the axes' and angles' conventions
    definitions: dict[str, str] | None = None  # term -> its definition
    provenance: Provenance | None = None  # package, revision, command line, date, records' sha256
    absent: tuple[str, ...] = field(default=(), repr=False, compare=False)
    """Optional keys the report read did not have (left out of :meth:`to_dict` again)."""

    def to_dict(self) -> dict:
        """The report as ``report.json`` holds it (the same keys in the same order)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name != "absent" and f.name not in self.absent}

    def to_json(self) -> str:
        """``report.json``'s text: indented, ``Infinity``/``NaN`` for an infinite or undefined
        number."""
        return json.dumps(self.to_dict(), indent=1, allow_nan=True, default=float)

    @classmethod
    def from_dict(cls, d: Any) -> "Report":
        """The report of a ``report.json`` read: refused (:class:`ReportError`, one line naming
        the key) when a required key is missing, a key is unknown or one has the wrong type."""
        if isinstance(d, Report):
            return d
        if not isinstance(d, dict):
            raise ReportError(f"the doctor's report is a {type(d).__name__}, not a JSON object")
        hints, known, absent = _hints(), {}, []
        for f in fields(cls):
            if f.name == "absent":
                continue
            if f.name in d:
                _check(d[f.name], hints[f.name], repr(f.name))
                known[f.name] = d[f.name]
            elif f.default is None:
                absent.append(f.name)
            else:
                raise ReportError(f"the doctor's report has no key {f.name!r} (required)")
        unknown = [k for k in d if k not in known]
        if unknown:
            raise ReportError(f"the doctor's report has an unknown key {unknown[0]!r}")
        return cls(**known, absent=tuple(absent))


def _hints() -> dict:
    return typing.get_type_hints(Report)


def _describe(tp: Any) -> str:
    if tp is float:
        return "a number"
    if tp in (int, str, bool):
        return _kind(tp())
    origin = typing.get_origin(tp)
    if origin is list:
        return "a list"
    if origin is dict or typing.is_typeddict(tp):
        return "an object"
    if origin in (Union, types.UnionType):
        return " or ".join("null" if a is type(None) else _describe(a) for a in typing.get_args(tp))
    return str(tp)


def _check(v: Any, tp: Any, where: str) -> None:
    """Refuse ``v`` (at ``where``) when it is not of type ``tp``; rows are checked key by key."""
    if tp is Any:
        return
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        for a in args:
            try:
                _check(v, a, where)
                return
            except ReportError:
                if a is not type(None) and _matches_shallow(v, a):
                    raise  # the right kind of value, wrong inside: say where
        raise ReportError(f"the doctor's report: {where} is {_kind(v)}, not {_describe(tp)}")
    ok = (v is None if tp is type(None) else
          isinstance(v, (int, float)) and not isinstance(v, bool) if tp is float else
          isinstance(v, int) and not isinstance(v, bool) if tp is int else
          isinstance(v, list) if origin is list else
          isinstance(v, dict) if origin is dict or typing.is_typeddict(tp) else isinstance(v, tp))
    if not ok:
        raise ReportError(f"the doctor's report: {where} is {_kind(v)}, not {_describe(tp)}")
    if origin is list:
        for i, x in enumerate(v):
            _check(x, args[0], f"{where}[{i}]")
    elif origin is dict:
        for k, x in v.items():
            _check(x, args[1], f"{where}[{k!r}]")
    elif typing.is_typeddict(tp):
        row = typing.get_type_hints(tp)
        for k in sorted(tp.__required_keys__, key=list(row).index):
            if k not in v:
                raise ReportError(f"the doctor's report: {where} has no key {k!r} (required)")
        for k, x in v.items():
            if k in row:  # a row may say more than the schema names
                _check(x, row[k], f"{where}[{k!r}]")


def _matches_shallow(v: Any, tp: Any) -> bool:
    origin = typing.get_origin(tp)
    return (isinstance(v, list) if origin is list else
            isinstance(v, dict) if origin is dict or typing.is_typeddict(tp) else False)


def _kind(v: Any) -> str:
    name = type(v).__name__
    return "null" if v is None else f"{'an' if name[0] in 'aeiou' else 'a'} {name}"
