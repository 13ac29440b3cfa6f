"""Typed records of characters, hairstyles, preprocessing, jobs and idempotency keys.

The API creates records, the worker updates them (state, stage, progress, outputs); both go
through these models, so the record layout is written once. Records are JSON documents in the
shared storage (:mod:`hairport.storage`) under their kind (``characters``, ``hairstyles``,
``artifacts``, ``preprocessing``, ``jobs``, ``idempotency``); :class:`Records` reads and writes
them typed.

Job states: ``queued`` -> ``running`` -> ``succeeded`` | ``failed`` | ``cancelled``; a job
whose worker died goes back to ``running`` on its next delivery (``attempts`` counts them).
Preprocessing states (per artifact key, shared by every hairstyle of the same inputs):
``queued`` -> ``running`` -> ``ready`` | ``failed``.

Conventions: times in seconds since the epoch, ids of 32 lower-case hex characters, digests
of 64.
"""

from __future__ import annotations

import hashlib
import json
import time
import uuid
from typing import ClassVar, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field

JobState = Literal["queued", "running", "succeeded", "failed", "cancelled"]
JOB_STATES: tuple[str, ...] = get_args(JobState)
QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED = JOB_STATES
TERMINAL_STATES = (SUCCEEDED, FAILED, CANCELLED)

PreprocessingState = Literal["queued", "running", "ready", "failed"]
READY = "ready"


def now() -> float:
    return time.time()


def digest(*parts: object) -> str:
    """SHA-256 hex of the JSON of ``parts`` (stable key order)."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def owned_id(owner: str, content_key: str) -> str:
    """A content-addressed id scoped to its owner: the same upload by one key gives one id."""
    return digest("id", owner, content_key)[:32]


def new_job_id() -> str:
    return uuid.uuid4().hex


class Record(BaseModel):
    """A stored document; ``KIND`` names its folder in the storage."""

    model_config = ConfigDict(extra="ignore")
    KIND: ClassVar[str]


class BlobRef(BaseModel):
    """A stored file: its content digest, the suffix it is stored under, its size (bytes)."""

    sha256: str
    suffix: str = ""
    size: int | None = None


class ErrorInfo(BaseModel):
    """Why something failed: a stable ``code`` and a message for people."""

    code: str
    message: str


class PreprocessSettings(BaseModel):
    """The preprocessing options a hairstyle's artifact depends on (Eq. 8 ``k``, guide count, anchoring)."""

    k: int
    guides: int
    anchoring: str = "auto"


class CharacterRecord(Record):
    KIND: ClassVar[str] = "characters"
    id: str
    owner: str
    created_at: float
    mesh: BlobRef
    skeleton: BlobRef | None = None
    units: str | None = None
    up_axis: str | None = None
    front_axis: str | None = None
    vertices: int
    faces: int
    bones: list[str]


class HairstyleRecord(Record):
    KIND: ClassVar[str] = "hairstyles"
    id: str
    owner: str
    created_at: float
    source_character_id: str
    hair: BlobRef
    format: str
    units: str
    options: PreprocessSettings
    artifact_key: str
    strands: int
    particles: int


class ArtifactRecord(Record):
    """A preprocessed (adaptable) hairstyle, keyed by the content hash of its inputs."""

    KIND: ClassVar[str] = "artifacts"
    key: str
    sha256: str
    suffix: str = ".hpa"
    size: int
    format_version: int
    seconds: float
    guides: int
    created_at: float


class PreprocessingRecord(Record):
    KIND: ClassVar[str] = "preprocessing"
    key: str
    state: PreprocessingState
    error: ErrorInfo | None = None
    seconds: float | None = None
    updated_at: float = 0.0


class JobRecord(Record):
    KIND: ClassVar[str] = "jobs"
    id: str
    owner: str
    kind: Literal["retarget"] = "retarget"
    state: JobState = QUEUED
    stage: str | None = "queued"
    progress: float = 0.0
    message: str | None = None
    hairstyle_id: str
    target_character_id: str
    options: dict
    hairline: dict | None = None
    preprocess_options: PreprocessSettings
    artifact_key: str
    output_format: str
    attempts: int = 0
    created_at: float
    updated_at: float
    started_at: float | None = None
    finished_at: float | None = None
    task_id: str | None = None
    worker: str | None = None
    worker_pid: int | None = None
    cancel_requested: bool = False
    error: ErrorInfo | None = None
    metrics: dict | None = None
    timings: dict | None = None
    outputs: dict[str, BlobRef] | None = None


class IdempotencyRecord(Record):
    KIND: ClassVar[str] = "idempotency"
    request: str
    jobs: list[str] = Field(default_factory=list)
    created_at: float


class PurgeClock(Record):
    """When the retention purge last ran (shared by all workers)."""

    KIND: ClassVar[str] = "maintenance"
    last_purge: float = 0.0


def artifact_key(character: CharacterRecord, hair_sha256: str, units: str, options: PreprocessSettings,
                 format_version: int) -> str:
    """Content hash of everything preprocessing depends on (the character's axes when given)."""
    axes = [character.up_axis, character.front_axis] if character.up_axis or character.front_axis else []
    return digest(
        "artifact", character.mesh.sha256, character.skeleton.sha256 if character.skeleton else None,
        character.units, hair_sha256, units, options.model_dump(), format_version, *axes,
    )
