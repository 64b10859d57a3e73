"""Request and response bodies of the HTTP API (pydantic: validated in, documented in the OpenAPI)."""
from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt, create_model, field_validator

from daq.campaign import MAX_SWEEPS, NAME_PATTERN
from identify import params

from .catalog import ID_PATTERN
from .uploads import FILENAME_WORDS

SweepState = Literal["queued", "running", "completed", "aborted", "failed"]
JobState = Literal["queued", "running", "completed", "failed"]
CampaignState = Literal["running", "pausing", "paused", "completed", "aborted"]


class Strict(BaseModel):
    """Unknown fields and non-finite numbers (NaN, Infinity, 1e400) are refused with a 422 naming the field."""
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


#: A number in a request that moves the table: a JSON number only. Pydantic's lax mode turned true and "1"
#: into 1.0, and a sweep with "amplitude_mm": true ran at 1 mm.
Number = StrictFloat

#: Upper bounds of the request schemas' frequencies (Hz) and amplitudes (mm): numbers beyond any rig, so
#: that a request above the rig's own limits is refused by those limits, in their words ("amplitude
#: 2000 mm above the stroke limit 5 mm"), not by the schema ("less than or equal to 1000").
MAX_HZ, MAX_MM = 1e6, 1e6


class SweepIn(Strict):
    f_start_hz: Number = Field(gt=0, le=MAX_HZ, description="start frequency, Hz")
    f_end_hz: Number = Field(gt=0, le=MAX_HZ, description="end frequency, Hz")
    duration_s: Number = Field(gt=0, le=1e5, description="sweep duration, s")
    amplitude_mm: Number = Field(gt=0, le=MAX_MM, description="table displacement amplitude, mm")
    settle_s: Number = Field(2.0, ge=0, le=60, description="recording after the sweep ends, s")
    note: str = Field("", max_length=500)


class SweepOut(BaseModel):
    id: str
    state: SweepState
    progress: float = Field(description="0..1")
    recording_id: str | None = None
    error: str | None = None
    request: dict = {}
    operator: str | None = None
    created: float
    updated: float


class Accepted(BaseModel):
    id: str
    state: str


class Health(BaseModel):
    status: Literal["ok"]
    version: str
    rig_simulated: bool
    controller: Literal["attached", "unreachable"] = Field(description="the rig controller process")
    jobs_queued: int
    stop_url: str | None = Field(None, description="POST the emergency stop here first: the rig controller's "
                                                   "stop listener, where no viewer traffic waits (None: none)")


class RecordingOut(BaseModel):
    id: str
    created: float
    origin: Literal["sweep", "upload"]
    filename: str
    status: str
    sweep_id: str | None = None
    info: dict = {}


class ReadOptions(Strict):
    """How to read the recording (as `shakeid identify/explain`): stretch, layout, columns, band."""
    samples: tuple[int, int] | None = Field(None, description="rows [a, b) of the recording")
    band_hz: tuple[float, float] | None = Field(None, description="integration band (f_lo, f_hi), Hz")
    layout: Literal["base", "force"] | None = None
    input: str | None = Field(None, max_length=64)
    output: str | None = Field(None, max_length=64)
    time: str | None = Field(None, max_length=64)
    fs_hz: float | None = Field(None, gt=0, le=1e7)
    accept_faulty: bool | None = Field(None, description="go on with a recording that is not complete or whose "
                                                         "quality flags make it unusable (the result says so)")

    @field_validator("band_hz", "samples")
    @classmethod
    def _in_order(cls, pair, info):
        """A band 0 <= f_lo < f_hi, rows 0 <= a < b: refused with the request (422) rather than by the job it
        would fail (whether b is within the recording, the job's read says)."""
        if pair is not None and not 0 <= pair[0] < pair[1]:
            what = "band {} Hz must satisfy 0 <= f_lo < f_hi" if info.field_name == "band_hz" else \
                "rows {} must satisfy 0 <= a < b"
            raise ValueError(what.format(list(pair)))
        return pair


def _estimator_field(p: params.Param):
    """A request field for one identify.params.PARAMS entry: its type, default, range or choices, help."""
    if p.kind == "terms":
        kind = list[Annotated[str, Field(max_length=64)]]
    elif p.choices:
        kind = Literal[p.choices]
    else:
        kind = StrictBool if p.kind is bool else (StrictInt if p.kind is int else float)
    bounds = {} if p.low is None else {"gt" if p.low_open else "ge": p.low}
    if p.high is not None:
        bounds["lt" if p.high_open else "le"] = p.high
    if p.max_items is not None:
        bounds["max_length"] = p.max_items
    default = list(p.default) if isinstance(p.default, tuple) else p.default
    unit = f" ({p.unit})" if p.unit else ""
    return (kind | None if p.nullable else kind), Field(default, description=p.help + unit, **bounds)


#: The options of `shakeid identify`, every one with its default: the read options and the estimator's
#: parameters, derived from identify.params.PARAMS (as the CLI's options and the estimator's checks are).
IdentifyIn = create_model("IdentifyIn", __base__=ReadOptions, __doc__="The options of `shakeid identify`; "
                          "all optional.", **{p.name: _estimator_field(p) for p in params.PARAMS})


class JointIdentifyIn(IdentifyIn):
    """Several recordings fitted as one model (`shakeid identify A.h5 B.h5 ...`, identify.joint); the
    options apply to every recording."""
    recording_ids: list[Annotated[str, Field(pattern=ID_PATTERN)]] = Field(
        min_length=2, max_length=500, description="the recordings, in the order the result lists them")


class ExplainIn(ReadOptions):
    """The options of `shakeid explain`: the read options only."""


class JobOut(BaseModel):
    id: str
    kind: Literal["identify", "explain", "identify_joint", "explain_campaign"] = Field(
        description="identify_joint: one model of several recordings (options.recording_ids, in order; "
                    "recording_id is the first); its result_dir holds joint.json. explain_campaign: one "
                    "explanation of a campaign's recordings (options.campaign_id, recording_ids), explain.json")
    recording_id: str
    state: JobState
    attempts: int
    error: str | None = None
    options: dict = {}
    created: float
    updated: float


class CampaignSweepDefaults(Strict):
    """Every sweep of a campaign: an "up" sweep goes f_start_hz -> f_end_hz, a "down" one back."""
    f_start_hz: Number = Field(gt=0, le=MAX_HZ, description="the lower frequency, Hz (below f_end_hz)")
    f_end_hz: Number = Field(gt=0, le=MAX_HZ, description="the upper frequency, Hz")
    duration_s: Number = Field(gt=0, le=1e5, description="each sweep's duration, s")
    settle_s: Number = Field(2.0, ge=0, le=60, description="recording after each sweep ends, s")


class AmplitudeRange(Strict):
    """Amplitudes start, start + step, ... up to stop (included when it is on the grid), mm."""
    start: Number = Field(gt=0, le=MAX_MM)
    stop: Number = Field(gt=0, le=MAX_MM)
    step: Number = Field(gt=0, le=MAX_MM)


class CampaignIn(Strict):
    """A campaign's plan (the same keys as a `shakeid campaign` TOML plan): for each repeat, for each
    amplitude, for each direction, one sweep; `rest_between_s` of wall time with the table at rest between two."""
    name: str = Field(pattern=NAME_PATTERN, description="letters, digits, . _ - (1-64)")
    sweep: CampaignSweepDefaults
    amplitudes_mm: list[Annotated[Number, Field(gt=0, le=MAX_MM)]] | AmplitudeRange = Field(
        description="table displacement amplitudes, mm: a list or {start, stop, step}")
    directions: list[Literal["up", "down"]] = Field(["up"], min_length=1, max_length=2)
    repeats: int = Field(1, ge=1, le=MAX_SWEEPS)
    rest_between_s: Number = Field(0.0, ge=0, le=86400, description="table at rest between two sweeps, s")
    note: str = Field("", max_length=500)


class CampaignSweepOut(BaseModel):
    index: int = Field(description="1-based, in run order")
    amplitude_mm: float
    direction: Literal["up", "down"]
    repeat: int
    f_start_hz: float = Field(description="where this sweep starts (the plan's f_end_hz for a down sweep)")
    f_end_hz: float
    duration_s: float
    settle_s: float
    status: Literal["planned", "running", "complete", "failed"]
    sweep_id: str | None = None
    recording_id: str | None = None
    path: str | None = None
    reason: str | None = Field(None, description="why a failed sweep does not count")
    attempts: list[dict] = Field([], description="earlier attempts of this sweep (re-run on resume)")


class CampaignProgress(BaseModel):
    done: int
    total: int
    current: int | None = Field(None, description="index of the sweep running now")


class CampaignOut(BaseModel):
    id: str
    name: str
    state: CampaignState
    reason: str | None = Field(None, description="why it is paused or aborted")
    operator: str | None = None
    plan: dict
    sweeps: list[CampaignSweepOut]
    progress: CampaignProgress
    recording_ids: list[str] = Field(description="complete recordings in plan order (for a joint identification)")
    joint_identification: JobOut | None = Field(
        None, description="the joint identification of recording_ids queued when the campaign completed "
                          "(job kind identify_joint; GET /api/jobs/{id}); None before that")
    explanation: JobOut | None = Field(
        None, description="the latest explanation of recording_ids together (job kind explain_campaign, asked for "
                          "by POST /api/campaigns/{id}/explain; GET /api/campaigns/{id}/explanation); None before that")
    created: float
    updated: float


class EstopOut(BaseModel):
    state: Literal["estop"]
    aborted_sweep: str | None = None


class ResetOut(BaseModel):
    state: Literal["idle", "done"]


class Problem(BaseModel):
    """An error: `detail` says what is wrong (a list of field errors when the request did not validate)."""
    detail: str | list[dict]


#: What a pattern asks for, in words, by where the parameter is and its name: pydantic's message quotes the
#: regex. ("path", "name") is a plot's name; ("body", "name") a campaign's (one word, two meanings)
PATTERN_WORDS = {
    ("query", "filename"): FILENAME_WORDS,
    ("path", "name"): "a plot's file name: lower-case letters, digits and '_', ending in .png",
    ("body", "name"): "a campaign name: 1-64 letters, digits, '.', '_' or '-', beginning with a letter or digit "
                      "(it names the campaign's files)",
}
#: bound checks whose message would quote a bound a non-finite number (NaN, inf) cannot be compared with
_BOUND_TYPES = {"greater_than", "greater_than_equal", "less_than", "less_than_equal", "finite_number"}


def _finite(value) -> bool:
    """False for NaN and infinities, as floats or as the text a query string carries them in."""
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError, OverflowError):
        return True  # not a number at all: pydantic's own message says so


def in_words(err: dict) -> str:
    """A validation error's message, a pattern mismatch said in words (PATTERN_WORDS; an id: 12 hex digits)."""
    loc = err.get("loc", ())
    if err.get("type") in _BOUND_TYPES and not _finite(err.get("input")):
        return "should be a finite number (NaN and infinity are not measurements)"
    if err.get("type") == "string_pattern_mismatch" and loc:
        field = str(loc[-1])
        if (str(loc[0]), field) in PATTERN_WORDS:
            return f"should be {PATTERN_WORDS[str(loc[0]), field]}"
        if field.endswith("id"):
            return "should be an id: 12 hex digits"
    return err.get("msg", "")
