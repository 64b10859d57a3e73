"""Request and response bodies of the HTTP API (pydantic: validated in, documented in the OpenAPI)."""
from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

SweepState = Literal["queued", "running", "completed", "aborted", "failed"]
JobState = Literal["queued", "running", "completed", "failed"]


class Strict(BaseModel):
    """Unknown fields and non-finite numbers (NaN, Infinity, 1e400) are refused with a 422 naming the field."""
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class SweepIn(Strict):
    f_start_hz: float = Field(gt=0, le=1e4, description="start frequency, Hz")
    f_end_hz: float = Field(gt=0, le=1e4, description="end frequency, Hz")
    duration_s: float = Field(gt=0, le=1e5, description="sweep duration, s")
    amplitude_mm: float = Field(gt=0, le=1e3, description="table displacement amplitude, mm")
    settle_s: float = Field(2.0, ge=0, le=60, description="recording after the sweep ends, s")
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


class IdentifyIn(ReadOptions):
    """The options of `shakeid identify`; all optional."""
    degree: int | None = Field(None, ge=1, le=7)
    method: Literal["admm", "stlsq"] | None = None
    selection: Literal["heldout", "paper", "bic"] | None = None
    tolerance: float | None = Field(None, gt=0, le=10)
    max_terms: int | None = Field(None, ge=1, le=100)
    refine: Literal["free-run"] | None = None
    holdout_fraction: float | None = Field(None, gt=0, lt=0.9)
    n_lambdas: int | None = Field(None, ge=2, le=1000)
    extra_terms: list[str] | None = Field(None, max_length=20)
    bias_replicates: int | None = Field(None, ge=0, le=200, description="SIMEX replicates (0: no chain-bias correction)")
    placements: int | None = Field(None, ge=0, le=500, description="held-out placements for inclusion probabilities")


class ExplainIn(ReadOptions):
    """The options of `shakeid explain`: the read options only."""


class JobOut(BaseModel):
    id: str
    kind: Literal["identify", "explain"]
    recording_id: str
    state: JobState
    attempts: int
    error: str | None = None
    options: dict = {}
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
