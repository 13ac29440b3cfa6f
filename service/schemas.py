"""Request and response bodies of the HTTP API."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from hairport.solver import pipeline

HairFormat = Literal["data", "hair", "ply", "npz", "obj"]
JobState = Literal["queued", "running", "succeeded", "failed", "cancelled"]
HairlinePresetName = Literal[pipeline.HAIRLINE_PRESETS]
#: most points of a drawn hairline accepted in a request
MAX_CURVE_POINTS = 10_000


class ErrorInfo(BaseModel):
    code: str
    message: str


class CharacterOut(BaseModel):
    id: str
    vertices: int
    faces: int
    bones: list[str]
    has_skeleton: bool
    units: str
    sha256: str = Field(description="SHA-256 of the mesh file.")
    skeleton_sha256: str | None = None
    created_at: float


class PreprocessingOut(BaseModel):
    state: Literal["queued", "running", "ready", "failed"]
    error: ErrorInfo | None = None


class HairstyleOut(BaseModel):
    id: str
    source_character_id: str
    strands: int
    particles: int
    sha256: str = Field(description="SHA-256 of the hair file.")
    format: HairFormat
    units: str
    options: dict
    preprocessing: PreprocessingOut
    created_at: float


class RetargetOptionsIn(BaseModel):
    """Solver options (Table 1, meters). ``guides`` and ``k`` default to the hairstyle's; other
    values preprocess the hairstyle again (once per combination, cached)."""

    model_config = ConfigDict(extra="forbid")

    method: str = "multiscale"
    guides: int | None = Field(None, ge=1, description="guide strands of the multi-scale solve")
    k: int | None = Field(None, ge=1, description="inter-strand neighbours per particle (Eq. 8)")
    alpha: float = 3e3
    beta: float = 1e3
    eps_c: float = 5e-4
    eps_s: float = 0.3
    max_iterations: int = Field(30, ge=1, le=1000)
    step_tolerance: float = 1e-5
    qp_backend: Literal["active-set", "osqp"] = "active-set"


class HairlineCurveIn(BaseModel):
    """A drawn front hairline, from one ear to the other (``hairport hairline`` writes the
    current one to start from)."""

    model_config = ConfigDict(extra="forbid")
    units: Literal["m", "dm", "cm", "mm"] = "m"
    points: list[list[float]] = Field(min_length=3, max_length=MAX_CURVE_POINTS,
                                      description="[x, y, z] points on the target's head")
    turning_points: list[int] = Field(default_factory=list, max_length=MAX_CURVE_POINTS,
                                      description="indices of the corners matched to the hairline's, in order")


class HairlineIn(BaseModel):
    """A hairline edit (paper Sec. 6): a preset or a drawn curve, exactly one."""

    model_config = ConfigDict(extra="forbid")
    preset: HairlinePresetName | None = None
    amount: float = Field(1.0, ge=0.0, le=1.0, description="strength of the preset (0: no change)")
    curve: HairlineCurveIn | None = None
    method: Literal[pipeline.RELOCATION_METHODS] = Field(
        "membrane", description="how the roots follow: the embedded membrane, or a Sec. 7.5 baseline")
    parameterization: Literal[pipeline.PARAMETERIZATIONS] = "harmonic"


class RetargetIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    hairstyle_id: str
    target_character_ids: list[str] = Field(min_length=1)
    options: RetargetOptionsIn = Field(default_factory=RetargetOptionsIn)
    hairline: HairlineIn | None = None
    output_format: HairFormat = "data"


class JobOut(BaseModel):
    id: str
    state: JobState
    stage: str | None = None
    progress: float = 0.0
    message: str | None = None
    hairstyle_id: str
    target_character_id: str
    output_format: HairFormat
    options: dict
    attempts: int = Field(0, description="deliveries so far: a job whose worker died runs again")
    worker: str | None = Field(None, description="the worker running (or last running) the job")
    created_at: float
    started_at: float | None = None
    finished_at: float | None = None
    timings: dict | None = None
    metrics: dict | None = None
    error: ErrorInfo | None = None
    links: dict[str, str] = Field(default_factory=dict)


class JobsCreated(BaseModel):
    jobs: list[JobOut]


class JobPage(BaseModel):
    jobs: list[JobOut]
    total: int
    limit: int
    offset: int
    next_offset: int | None = None
