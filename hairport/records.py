"""Typed records of characters, hairstyles, preprocessing, jobs and idempotency keys.

The API creates records, the worker updates them (state, stage, progress, outputs); both go
through these models, so the record layout is written once. Records are JSON documents in the
shared storage (:mod:`hairport.storage`) under their kind (``characters``, ``hairstyles``,
``artifacts``, ``preprocessing``, ``jobs``, ``idempotency``, and the workers' caches ``bodies`` and
``wraps``); :class:`Records` reads and writes them typed.

Job states: ``queued`` -> ``running`` -> ``succeeded`` | ``failed`` | ``cancelled``. A running
job whose heartbeat stopped (its worker died) becomes ``stale`` and is queued again; it goes
back to ``running`` on its next start (``attempts`` counts the starts, and a job started
``max_attempts`` times whose worker died again fails with ``worker_lost``). Each message sent
for a job carries the record's ``task_id`` and each start writes a new ``run_token``: a message
or a run that is not the record's current one changes nothing (see :mod:`hairport.worker.runner`).
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

JobState = Literal["queued", "running", "stale", "succeeded", "failed", "cancelled"]
JOB_STATES: tuple[str, ...] = get_args(JobState)
QUEUED, RUNNING, STALE, SUCCEEDED, FAILED, CANCELLED = JOB_STATES
TERMINAL_STATES = (SUCCEEDED, FAILED, CANCELLED)
#: states of a job no worker is running, waiting for its message to be taken
WAITING_STATES = (QUEUED, STALE)
#: error code of a job (or preprocessing) whose worker died ``max_attempts`` times while running it
WORKER_LOST = "worker_lost"
#: error code of a job whose message the broker lost ``max_attempts`` times
MESSAGE_LOST = "message_lost"

PreprocessingState = Literal["queued", "running", "ready", "failed"]
READY = "ready"

#: a batch's state, read from its jobs: none started, some not ended, every one ended
BatchState = Literal["queued", "running", "done"]
BATCH_STATES: tuple[str, ...] = get_args(BatchState)
BATCH_QUEUED, BATCH_RUNNING, BATCH_DONE = BATCH_STATES

#: a job's progress counts in integer millionths in a batch's progress: sums of integers are exact, so a batch's
#: progress is the same summed from its jobs or kept as a running total (jobs write theirs rounded to 1e-4)
PROGRESS_UNITS = 1_000_000

ChunkState = Literal["queued", "running", "done", "failed"]
CHUNK_STATES: tuple[str, ...] = get_args(ChunkState)
CHUNK_QUEUED, CHUNK_RUNNING, CHUNK_DONE, CHUNK_FAILED = CHUNK_STATES


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
    #: a per-strand attribute whose flagged strands are the guides (then ``guides`` is their count)
    guides_from: str | None = None


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
    #: USD/Alembic: the one curves prim or object read (None: all of them)
    prim: str | None = None


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


class BodyRecord(Record):
    """A target body's collision surface (the faces that separate its inside), kept for every job and worker:
    keyed by the body's content digest (:func:`hairport.solver.body_key`), the mask stored as a ``.npy`` blob."""

    KIND: ClassVar[str] = "bodies"
    key: str
    sha256: str
    suffix: str = ".npy"
    faces: int
    seconds: float = Field(description="what building it took")
    created_at: float


class WrapRecord(Record):
    """A source body wrapped onto a target of another topology, kept for every job and worker: keyed by the wrap's
    content key (:func:`hairport.solver.wrap_key`: both bodies, the region the groom reaches, the wrap's options),
    the wrapped vertices and the wrap's report stored as one ``.npz`` blob."""

    KIND: ClassVar[str] = "wraps"
    key: str
    sha256: str
    suffix: str = ".npz"
    vertices: int = Field(description="the source's vertex count (the wrapped vertices' rows)")
    seconds: float = Field(description="what the wrap took")
    created_at: float


class RunInfo(BaseModel):
    """Who runs a job or a preprocessing, and how recently it said so (see :mod:`hairport.records`)."""

    task_id: str | None = Field(None, description="the message that may start it (an older one is a no-op)")
    enqueued_at: float | None = None
    requeues: int = 0
    attempts: int = 0
    run_token: str | None = None
    heartbeat_at: float | None = None
    worker: str | None = None
    worker_host: str | None = None
    worker_pid: int | None = None
    stale_at: float | None = None


class PreprocessingRecord(Record, RunInfo):
    KIND: ClassVar[str] = "preprocessing"
    key: str
    state: PreprocessingState
    error: ErrorInfo | None = None
    seconds: float | None = None
    updated_at: float = 0.0
    #: what a sweeper needs to send the preprocessing again
    hairstyle_id: str | None = None
    options: dict | None = None


class FineChunk(BaseModel):
    """One chunk of a job's multi-scale fine level: a run of whole normal strands, solved by whichever
    worker claims it first (a ``fine`` task, or the job's own run while it waits)."""

    index: int
    first_strand: int = Field(description="first normal strand (index among the strands that are not guides)")
    stop_strand: int = Field(description="one past its last normal strand")
    particles: int
    state: ChunkState = CHUNK_QUEUED
    task_id: str | None = Field(None, description="the message that may claim it")
    claim: str | None = Field(None, description="token of the run that holds it")
    attempts: int = 0
    worker: str | None = None
    worker_host: str | None = None
    worker_pid: int | None = None
    heartbeat_at: float | None = None
    progress: float = 0.0
    seconds: float | None = Field(None, description="from its claim to its points saved")
    solve_seconds: float | None = Field(None, description="its solve alone (the rest: loading and building its problem)")
    error: ErrorInfo | None = None
    #: not named ``sha256``: no reference that keeps the blob (the orphan sweep takes it once the job has ended)
    result: str | None = Field(None, description="digest of the blob of its points (.npz), once done")


class FineRun(BaseModel):
    """A job's fine level spread over workers: its chunks, for the job run ``run_token``."""

    run_token: str
    inputs: str = Field(description="digest of the blob of the level's inputs (.npz)")
    chunks: list[FineChunk]


#: a job's output that is the lossless copy of its result (other formats are converted from it; a sequence's is its
#: frame 0, the layout of every frame)
LOSSLESS_OUTPUT = "npz"
#: a sequence job's output holding every frame (:class:`hairport.solver.sequence.SolvedFrames`)
FRAMES_OUTPUT = "frames"

#: where a sequence job's frames come from: its target character's animation, or several characters in order
FramesFrom = Literal["animation", "characters"]
FRAMES_FROM: tuple[str, ...] = get_args(FramesFrom)
FROM_ANIMATION, FROM_CHARACTERS = FRAMES_FROM


class SequencePlan(BaseModel):
    """A job onto a sequence of bodies: where its frames come from and how each is solved from the one before."""

    frames_from: FramesFrom = FROM_ANIMATION
    #: ``START:END[:STEP]`` (None: every frame of a list of characters, or every row of ``morph_weights``)
    frames: str | None = None
    #: the characters of the sequence in order (``frames_from`` characters; the job's target is the first)
    character_ids: list[str] = Field(default_factory=list)
    #: one glTF target's morph-target weights per frame, instead of its animation
    morph_weights: list[list[float]] | None = None
    warm_start: bool = True
    temporal: float = 0.0


class JobRecord(Record, RunInfo):
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
    #: the request's landmarks (each mesh's file coordinates), for the wrap
    landmarks: dict | None = None
    preprocess_options: PreprocessSettings
    artifact_key: str
    output_format: str
    #: write the guides the solve used as the per-strand attribute groom_guide
    flag_guides: bool = False
    created_at: float
    updated_at: float
    started_at: float | None = None
    finished_at: float | None = None
    cancel_requested: bool = False
    error: ErrorInfo | None = None
    metrics: dict | None = None
    timings: dict | None = None
    outputs: dict[str, BlobRef] | None = None
    #: the fine level's chunks when it ran over several workers (None: in the job's own process)
    fine: FineRun | None = None
    #: the batch the job is a pair of
    batch_id: str | None = None
    #: a job onto a sequence of bodies (:class:`SequencePlan`), None for one body
    sequence: SequencePlan | None = None
    #: a sequence job's frame count, once its frames are read, and how many of them are solved
    frames: int | None = None
    frames_done: int = 0


class IdempotencyRecord(Record):
    KIND: ClassVar[str] = "idempotency"
    request: str
    jobs: list[str] = Field(default_factory=list)
    #: the batch a batch request created
    batch_id: str | None = None
    created_at: float


class BatchRecord(Record):
    """Hairstyles x targets, one job per pair (``job_ids`` hairstyle by hairstyle, targets in order); its
    state and counts are its jobs'."""

    KIND: ClassVar[str] = "batches"
    id: str
    owner: str
    created_at: float
    hairstyle_ids: list[str]
    target_character_ids: list[str]
    output_format: str
    job_ids: list[str]


#: a batch's progress while any of its jobs has not ended: never shown as complete before it is
MAX_PROGRESS_NOT_DONE = 0.9999


class BatchTotals(BaseModel):
    """A batch's jobs summed: the one rule for its state, progress and end, whether the sums come from its job
    records (:meth:`of_jobs`) or from the record index."""

    counts: dict[str, int] = Field(description="jobs by state (every state)")
    progress_units: int = Field(0, description="progress of the jobs that have not ended, in PROGRESS_UNITS")
    finished_at: float | None = Field(None, description="the latest end of its jobs")

    @classmethod
    def of_jobs(cls, jobs: list[JobRecord]) -> BatchTotals:
        counts = dict.fromkeys(JOB_STATES, 0)
        for job in jobs:
            counts[job.state] += 1
        ends = [job.finished_at for job in jobs if job.finished_at is not None]
        return cls(counts=counts, progress_units=sum(progress_units(job.progress) for job in jobs
                                                     if job.state not in TERMINAL_STATES),
                   finished_at=max(ends, default=None))

    @property
    def state(self) -> str:
        """queued: no job started; done: every job ended (a batch whose jobs were all purged too); else running."""
        total = sum(self.counts.values())
        if sum(self.counts.get(state, 0) for state in TERMINAL_STATES) == total:
            return BATCH_DONE
        return BATCH_QUEUED if self.counts.get(QUEUED, 0) == total else BATCH_RUNNING

    @property
    def progress(self) -> float:
        """Mean progress of the jobs, an ended job counting 1 (rounded to 1e-4); below 1 until the batch is done
        (a job at progress 1 is still writing its outputs)."""
        ended = sum(self.counts.get(state, 0) for state in TERMINAL_STATES)
        total = max(1, sum(self.counts.values()))
        mean = round((ended * PROGRESS_UNITS + self.progress_units) / (total * PROGRESS_UNITS), 4)
        return mean if self.state == BATCH_DONE else min(mean, MAX_PROGRESS_NOT_DONE)

    @property
    def ended_at(self) -> float | None:
        """When the batch was done (its last job's end), None before."""
        return self.finished_at if self.state == BATCH_DONE else None


def progress_units(progress: float) -> int:
    """A job's progress as an integer count of :data:`PROGRESS_UNITS`."""
    return round(progress * PROGRESS_UNITS)


class PurgeClock(Record):
    """When the retention purge last ran (shared by all workers)."""

    KIND: ClassVar[str] = "maintenance"
    last_purge: float = 0.0


class SweepClock(Record):
    """When the last sweep for stale jobs and lost messages ran (shared by workers and API)."""

    KIND: ClassVar[str] = "maintenance"
    last_sweep: float = 0.0


class OrphanSweepClock(Record):
    """When the last sweep for orphan blobs ran (shared by workers and API)."""

    KIND: ClassVar[str] = "maintenance"
    last_sweep: float = 0.0


def artifact_key(character: CharacterRecord, hair_sha256: str, units: str, options: PreprocessSettings,
                 format_version: int, prim: str | None = None) -> str:
    """Content hash of everything preprocessing depends on (the character's axes and the hair's prim when
    given)."""
    axes = [character.up_axis, character.front_axis] if character.up_axis or character.front_axis else []
    chosen = [f"prim:{prim}"] if prim is not None else []
    return digest(
        "artifact", character.mesh.sha256, character.skeleton.sha256 if character.skeleton else None,
        character.units, hair_sha256, units, options.model_dump(), format_version, *axes, *chosen,
    )
