"""Request and response bodies of the HTTP API.

Choices and defaults are derived from the solver's and the records' own definitions (formats,
units, methods, presets, options, job states), so the API cannot drift from what runs.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StringConstraints

from hairport import solver
from hairport.records import (
    FROM_ANIMATION,
    FROM_CHARACTERS,
    SUCCEEDED,
    BatchState,
    CharacterRecord,
    ChunkState,
    ErrorInfo,
    FramesFrom,
    HairstyleRecord,
    JobRecord,
    JobState,
    PreprocessingState,
)
from hairport.solver import display
from hairport.solver import options as solver_options
from hairport.solver import sequence as solver_sequence

HairFormat = Literal[solver.HAIR_FORMATS]
Units = Literal[solver.UNITS]
HairlinePresetName = Literal[solver_options.HAIRLINE_PRESETS]
Anchoring = Literal[solver_options.ANCHORINGS]
#: the hair format of a result unless the request names one
DEFAULT_OUTPUT_FORMAT = "data"
#: ... and of a sequence's (one animated file)
DEFAULT_SEQUENCE_FORMAT = "usdc"
#: most points of a drawn hairline accepted in a request
MAX_CURVE_POINTS = 10_000
_RETARGET = solver.RetargetOptions()
_PREPROCESS = solver.PreprocessOptions()
_SEQUENCE = solver_sequence.SequenceOptions()
_HAIRLINE = solver.HairlineEdit(preset=solver_options.HAIRLINE_PRESETS[0])
_WRAP_AUTO, _WRAP_ALWAYS, _WRAP_OFF = solver_options.WRAP_MODES



def listed(extensions) -> str:
    """``".a, .b or .c"``: file extensions for a description."""
    *others, last = [name if name.startswith(".") else f".{name}" for name in extensions]
    return f"{', '.join(others)} or {last}" if others else last


HAIR_FILE_DESCRIPTION = f"hair file: {listed(solver.HAIR_FORMATS)}"
MESH_FILE_DESCRIPTION = f"body mesh: {listed(solver.MESH_EXTENSIONS)}"

__all__ = ["CharacterOut", "ErrorInfo", "HairFormat", "HairlineIn", "HairstyleOut", "JobOut", "JobPage", "JobState",
           "JobsCreated", "PreprocessingOut", "RetargetIn", "RetargetOptionsIn", "Units"]


class CharacterOut(BaseModel):
    id: str
    vertices: int
    faces: int
    bones: list[str]
    has_skeleton: bool
    units: str = Field(description="the mesh's units: given, stated by its files, or auto (inferred when used)")
    up_axis: str = Field(solver.AUTO, description="the mesh's up axis, or auto (inferred when used)")
    front_axis: str = Field(solver.AUTO, description="the axis the face looks along, or auto")
    sha256: str = Field(description="SHA-256 of the mesh file.")
    skeleton_sha256: str | None = None
    created_at: float

    @classmethod
    def of(cls, record: CharacterRecord) -> CharacterOut:
        return cls(
            id=record.id, vertices=record.vertices, faces=record.faces, bones=record.bones,
            has_skeleton=bool(record.bones), units=record.units or solver.AUTO, up_axis=record.up_axis or solver.AUTO,
            front_axis=record.front_axis or solver.AUTO, sha256=record.mesh.sha256,
            skeleton_sha256=record.skeleton.sha256 if record.skeleton else None, created_at=record.created_at,
        )


class CharacterPage(BaseModel):
    characters: list[CharacterOut]
    total: int
    limit: int
    offset: int
    next_offset: int | None = None


class PreprocessingOut(BaseModel):
    state: PreprocessingState
    error: ErrorInfo | None = None


class HairstyleOut(BaseModel):
    id: str
    source_character_id: str
    strands: int
    particles: int
    sha256: str = Field(description="SHA-256 of the hair file.")
    format: HairFormat
    units: str = Field(description="the hair file's units: given, recorded by a .npz, or auto (inferred)")
    prim: str | None = Field(None, description="the one curves prim or object read from a USD or Alembic file")
    options: dict
    preprocessing: PreprocessingOut
    created_at: float

    @classmethod
    def of(cls, record: HairstyleRecord, preprocessing: PreprocessingOut) -> HairstyleOut:
        return cls(
            id=record.id, source_character_id=record.source_character_id, strands=record.strands,
            particles=record.particles, sha256=record.hair.sha256, format=record.format, units=record.units,
            prim=record.prim, options=record.options.model_dump(), preprocessing=preprocessing, created_at=record.created_at,
        )


class HairstylePage(BaseModel):
    hairstyles: list[HairstyleOut]
    total: int
    limit: int
    offset: int
    next_offset: int | None = None


def ranged(name: str, default=None):
    """A ``Field`` whose bounds and description come from the solver's range of option ``name``
    (:data:`hairport.solver_options.OPTION_RANGES`): values outside it are 422 at the door."""
    spec = solver_options.OPTION_RANGES[name]
    units = f" ({spec.units})" if spec.units else ""
    return Field(default, ge=spec.minimum, le=spec.maximum, allow_inf_nan=False,
                 description=f"{spec.description}{units}; {spec.text()}")


class RetargetOptionsIn(BaseModel):
    """Solver options (Table 1, meters). ``guides`` and ``k`` default to the hairstyle's; other
    values preprocess the hairstyle again (once per combination, cached)."""

    model_config = ConfigDict(extra="forbid")

    method: str = Field(_RETARGET.method, description=(
        "the paper's solvers (multiscale, global) or a naive baseline; a baseline may carry the suffix +pushout"),
        json_schema_extra={"examples": list(solver_options.METHODS)})
    guides: int | None = ranged("guides")
    k: int | None = ranged("k")
    alpha: float = ranged("alpha", _RETARGET.alpha)
    beta: float = ranged("beta", _RETARGET.beta)
    spacing: float = ranged("spacing", _RETARGET.spacing)
    eps_c: float = ranged("eps_c", _RETARGET.eps_c)
    eps_s: float = ranged("eps_s", _RETARGET.eps_s)
    carry: float = ranged("carry", _RETARGET.carry)
    max_iterations: int = ranged("max_iterations", _RETARGET.max_iterations)
    step_tolerance: float = ranged("step_tolerance", _RETARGET.step_tolerance)
    energy_tolerance: float = ranged("energy_tolerance", _RETARGET.energy_tolerance)
    qp_backend: Literal[solver_options.QP_BACKENDS] = _RETARGET.qp_backend
    wrap: Literal[solver_options.WRAP_MODES] = Field(_RETARGET.wrap, description=(
        f"a target whose mesh topology (vertex count, faces) is not the source's: {_WRAP_AUTO} wraps the source "
        f"body onto it first; {_WRAP_ALWAYS} wraps a target of the source's topology too; {_WRAP_OFF} fails the job "
        "with topology_mismatch"))


class HairlineCurveIn(BaseModel):
    """A drawn front hairline, from one ear to the other (``hairport hairline`` writes the
    current one to start from)."""

    model_config = ConfigDict(extra="forbid")
    units: Units = "m"
    points: list[list[float]] = Field(min_length=3, max_length=MAX_CURVE_POINTS,
                                      description="[x, y, z] points on the target's head")
    turning_points: list[int] = Field(default_factory=list, max_length=MAX_CURVE_POINTS,
                                      description="indices of the corners matched to the hairline's, in order")


class HairlineIn(BaseModel):
    """A hairline edit (paper Sec. 6): a preset or a drawn curve, exactly one."""

    model_config = ConfigDict(extra="forbid")
    preset: HairlinePresetName | None = None
    amount: float = Field(_HAIRLINE.amount, ge=0.0, le=1.0, description="strength of the preset (0: no change)")
    curve: HairlineCurveIn | None = None
    method: Literal[solver_options.RELOCATION_METHODS] = Field(
        _HAIRLINE.method, description="how the roots follow: the embedded membrane, or a Sec. 7.5 baseline")
    parameterization: Literal[solver_options.PARAMETERIZATIONS] = _HAIRLINE.parameterization


LandmarkName = Annotated[str, StringConstraints(min_length=1, max_length=solver_options.MAX_LANDMARK_NAME_CHARS)]
LandmarkPoint = Annotated[list[Annotated[float, Field(allow_inf_nan=False)]], Field(min_length=3, max_length=3)]
LandmarkSide = Annotated[dict[LandmarkName, LandmarkPoint], Field(min_length=1, max_length=solver_options.MAX_LANDMARKS)]


class LandmarksIn(BaseModel):
    """The same named points on the source body and on the target (crown, nose tip, chin, ear tops, nape), each
    in its own file's coordinates (units and axes), to help the wrap of a target of another topology."""

    model_config = ConfigDict(extra="forbid")
    source: LandmarkSide = Field(description="points on the hairstyle's source body: {name: [x, y, z]}")
    target: LandmarkSide = Field(description="the same names on the target character: {name: [x, y, z]}")


FrameRangeText = Annotated[str, StringConstraints(min_length=3, max_length=64)]


class SequenceIn(BaseModel):
    """Retarget onto a sequence of bodies, frame by frame, each frame solved from the one before: one job and one
    animated result per sequence. Its frames take ``options.spacing`` 3 unless the request names one (it keeps
    strands from stretching in one frame and springing back in the next)."""

    model_config = ConfigDict(extra="forbid")
    frames_from: FramesFrom = Field(FROM_ANIMATION, description=(
        f"{FROM_ANIMATION}: each target character is an animated file (a USD stage with time-sampled mesh points, a "
        f"glTF with morph targets, an Alembic animated mesh) and its job's frames are its own; {FROM_CHARACTERS}: "
        "the target characters, in order, are the frames of one sequence (one job; the same mesh topology)"))
    frames: FrameRangeText | None = Field(None, description=(
        "START:END[:STEP], both ends included: the time codes of a USD stage, frames at 24 a second of a glTF "
        "animation or an Alembic mesh, rows of morph_weights, indices of the characters. Needed for an animation "
        "unless morph_weights are given; default: every row or character"), json_schema_extra={"examples": ["0:48"]})
    morph_weights: list[Annotated[list[Annotated[float, Field(allow_inf_nan=False)]], Field(min_length=1)]] | None = (
        Field(None, min_length=1, max_length=solver_sequence.MAX_FRAMES, description=(
            "one glTF target's morph-target weights, one list per frame and one number per morph target, instead "
            "of the file's animation")))
    warm_start: bool = Field(True, description="solve each frame from the previous frame's result moved with the "
                                               "body (false: every frame cold, on its own)")
    temporal: float = ranged("temporal", _SEQUENCE.temporal)


class SequenceOut(SequenceIn):
    """A sequence job's sequence, as requested, with the characters of its frames."""

    character_ids: list[str] = Field(default_factory=list, description=(
        f"frames_from {FROM_CHARACTERS}: the characters of the frames, in order (the job's target is the first)"))


class RetargetIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    hairstyle_id: str
    target_character_ids: list[str] = Field(min_length=1)
    options: RetargetOptionsIn = Field(default_factory=RetargetOptionsIn)
    hairline: HairlineIn | None = None
    landmarks: LandmarksIn | None = Field(None, description=(
        "help the wrap of a target of another topology (one target per request: the points are on it)"))
    sequence: SequenceIn | None = Field(None, description="retarget onto a sequence of bodies (morph sweeps, animated "
                                                          "characters): one animated result per sequence")
    output_format: HairFormat | None = Field(None, description=(
        f"the result's hair format (default {DEFAULT_OUTPUT_FORMAT}, and {DEFAULT_SEQUENCE_FORMAT} for a sequence, "
        f"whose result is one animated file: {listed(solver_sequence.ANIMATED_FORMATS)})"))
    flag_guides: bool = Field(False, description=f"write the guides the solve used as the per-strand attribute "
                                                 f"{solver_options.GUIDE_FLAG} (1 guide, 0 other: Unreal's convention) in "
                                                 "formats with attributes")


#: the strand layers a job draws: its result, and the groom on its source character
StrandLayer = Literal["result", "source"]
#: the bodies a job draws (wrapped: the source body wrapped onto a target of another topology)
BodyLayer = Literal["target", "source", "wrapped"]
DISPLAY_DESCRIPTION = (
    "`application/vnd.hairport.display`: the ASCII magic `HPD1`, a little-endian uint32 header length, a JSON "
    "header (`arrays`: name, dtype, shape, offset from the end of the header), then the arrays, 8-byte aligned. "
    "Strands: `positions` (M, 3) float32 meters in hairport's frame (+Y up, face toward +Z), `starts` (K+1,) "
    "uint32, `inside` (M,) uint8 (1: inside the target body), `crossing` (M,) uint8 (1: the drawn segment from "
    "this vertex spans one that passes through the target body between two particles outside it; the header's "
    "`crossing` counts them), `color` (M, 3) uint8 when the groom has colours. "
    "Bodies: `vertices` (V, 3) float32, `faces` (F, 3) uint32, and the header's `up` vector.")


#: the OpenAPI ``responses`` entry of a display payload
DISPLAY_RESPONSE = {200: {"description": DISPLAY_DESCRIPTION, "content": {
    display.MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}}}}}


class HairlineOut(BaseModel):
    """A job target's front hairline: draw a new one from it and send it as ``hairline.curve`` (in the groom's
    axes: ``groom_rotation`` R maps them to hairport's, so a point p drawn here is sent as R^T p)."""

    units: Literal["m"] = "m"
    points: list[list[float]] = Field(description="the current hairline, ear to ear, hairport's frame (meters)")
    turning_points: list[int] = Field(description="indices of its corners (the ends included)")
    presets: dict[str, list[list[float]]] = Field(description="each preset's edit of it at amount 1")
    groom_rotation: list[list[float]] = Field(description="R with hairport's frame = R @ the groom's axes")
    groom_units: str = Field(description="the groom file's units")


class ChunkOut(BaseModel):
    """One chunk of a job's multi-scale fine level, solved by whichever worker took it."""

    index: int
    first_strand: int = Field(description="first strand of the chunk, counted among the strands that are not guides")
    stop_strand: int = Field(description="one past its last strand")
    particles: int
    state: ChunkState
    worker: str | None = Field(None, description="the worker running (or that ran) the chunk")
    attempts: int = Field(0, description="runs so far: a chunk whose worker died runs again")
    progress: float = 0.0
    seconds: float | None = Field(None, description="from its start to its points saved")
    solve_seconds: float | None = Field(None, description="its solve alone (the rest: loading and building its problem)")
    error: ErrorInfo | None = None


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
    hairline: dict | None = Field(None, description="the hairline edit asked for (a preset or a drawn curve)")
    landmarks: dict | None = Field(None, description="the landmarks given to help the wrap")
    flag_guides: bool = False
    cancel_requested: bool = Field(False, description="the job was asked to cancel (DELETE): a queued one is cancelled "
                                                      "at once, a running one stops at its solver's next iteration")
    attempts: int = Field(0, description="starts so far: a job whose worker died runs again, up to "
                                         "HAIRPORT_MAX_ATTEMPTS starts (then it fails with worker_lost)")
    worker: str | None = Field(None, description="the worker running (or last running) the job")
    heartbeat_at: float | None = Field(None, description="when the worker running the job last said it was alive")
    stale_at: float | None = Field(None, description="when the job was last found with a silent worker (state stale, "
                                                     "then queued again)")
    created_at: float
    started_at: float | None = None
    finished_at: float | None = None
    timings: dict | None = None
    metrics: dict | None = None
    error: ErrorInfo | None = None
    chunks: list[ChunkOut] | None = Field(None, description=(
        "the chunks of the multi-scale fine level when it ran over several workers (none: in the job's own run)"))
    sequence: SequenceOut | None = Field(None, description="a job onto a sequence of bodies: the request's sequence")
    frames: int | None = Field(None, description="a sequence job's frame count, once its frames are read")
    frames_done: int = Field(0, description="a sequence job's frames solved so far (its stage names the frame running)")
    links: dict[str, str] = Field(default_factory=dict)

    @classmethod
    def of(cls, record: JobRecord) -> JobOut:
        base = f"/v1/jobs/{record.id}"
        links = {"self": base}
        if record.state == SUCCEEDED:
            links.update(result=f"{base}/result", preview=f"{base}/preview.png", report=f"{base}/report")
        chunks = None if record.fine is None else [
            ChunkOut(**chunk.model_dump(include=_CHUNK_OUT_FIELDS)) for chunk in record.fine.chunks]
        sequence = None if record.sequence is None else SequenceOut(**record.sequence.model_dump())
        return cls(**{name: getattr(record, name) for name in _JOB_OUT_FIELDS}, chunks=chunks, sequence=sequence,
                   links=links)


#: the fields a JobOut copies from its record (read once: pydantic's class-level ``model_fields`` is slow, and a
#: listing builds 50 JobOuts per request)
_JOB_OUT_FIELDS = tuple(name for name in JobOut.model_fields if name not in ("links", "chunks", "sequence"))
_CHUNK_OUT_FIELDS = set(ChunkOut.model_fields)


class JobsCreated(BaseModel):
    jobs: list[JobOut]


class JobPage(BaseModel):
    jobs: list[JobOut]
    total: int
    limit: int
    offset: int
    next_offset: int | None = None


class BatchItemIn(BaseModel):
    """Options of one pair of a batch, in place of the batch's (a hairline given here, even null, replaces the
    batch's)."""

    model_config = ConfigDict(extra="forbid")
    hairstyle_id: str
    target_character_id: str
    options: RetargetOptionsIn | None = None
    hairline: HairlineIn | None = None


class BatchIn(BaseModel):
    """Every hairstyle onto every target character: one job per pair."""

    model_config = ConfigDict(extra="forbid")
    hairstyle_ids: list[str] = Field(min_length=1, json_schema_extra={"uniqueItems": True})
    target_character_ids: list[str] = Field(min_length=1, json_schema_extra={"uniqueItems": True})
    options: RetargetOptionsIn = Field(default_factory=RetargetOptionsIn)
    hairline: HairlineIn | None = None
    items: list[BatchItemIn] = Field(default_factory=list, description="per-pair options replacing the batch's")
    sequence: SequenceIn | None = Field(None, description=(
        f"every target is an animated character (frames_from {FROM_ANIMATION}): each pair's job retargets onto its "
        "frames"))
    output_format: HairFormat | None = Field(None, description=(
        f"the results' hair format (default {DEFAULT_OUTPUT_FORMAT}, {DEFAULT_SEQUENCE_FORMAT} with a sequence)"))
    flag_guides: bool = Field(False, description=f"write the guides as the attribute {solver_options.GUIDE_FLAG}")


class BatchJobOut(BaseModel):
    id: str
    hairstyle_id: str
    target_character_id: str
    state: JobState
    progress: float
    error: ErrorInfo | None = None
    links: dict[str, str]


class BatchSummary(BaseModel):
    """A batch without its jobs (a listing's item; ``GET /v1/batches/{id}`` adds them)."""

    id: str
    state: BatchState = Field(description=(
        "queued: no job started; running: some job has not ended; done: every job ended (see counts)"))
    counts: dict[str, int] = Field(description="jobs in each state")
    progress: float = Field(description="mean progress of the jobs (an ended job counts 1)")
    created_at: float
    finished_at: float | None = Field(None, description="when its last job ended, once every job has")
    hairstyle_ids: list[str]
    target_character_ids: list[str]
    output_format: HairFormat
    links: dict[str, str]


class BatchOut(BatchSummary):
    """A batch and its jobs."""

    jobs: list[BatchJobOut] = Field(description="one per pair, hairstyle by hairstyle, targets in order")


class BatchPage(BaseModel):
    batches: list[BatchSummary] = Field(description=(
        "newest first, without their jobs (a batch's own page lists them): a page costs the same whatever the "
        "batches' sizes"))
    total: int
    limit: int
    offset: int
    next_offset: int | None = None


class Problem(BaseModel):
    """An error (RFC 9457 problem details, ``application/problem+json``) with a stable ``code``."""

    type: str = Field(description="a URI naming the kind of error: the problem base followed by the code")
    title: str = Field(description="a short human summary of the kind of error")
    status: int = Field(description="the HTTP status code")
    detail: str = Field(description="what went wrong in this request, for people")
    code: str = Field(description="stable machine-readable code; each response's description lists the known "
                                  "codes of its status")
    request_id: str | None = Field(None, description="`internal` (500) only: the id the server logged the error "
                                                     "and its traceback under (also the `X-Request-ID` header)")


#: media type of a result file per hair format: the result route answers with it and the contract lists it
#: (OBJ and USD's text layers have registered types; the other formats have none and are plain binary files)
RESULT_MEDIA_TYPES: dict[str, str] = {name: "application/octet-stream" for name in solver.HAIR_FORMATS} | {
    "obj": "model/obj", "usda": "model/vnd.usda"}


def result_content() -> dict:
    """The OpenAPI ``content`` of a result: each media type of :data:`RESULT_MEDIA_TYPES`, once."""
    return {media_type: {"schema": {"type": "string", "format": "binary"}}
            for media_type in dict.fromkeys(RESULT_MEDIA_TYPES.values())}


RESULT_DESCRIPTION = "The result file, by `format`: " + ", ".join(
    f"{name} `{media_type}`" for name, media_type in RESULT_MEDIA_TYPES.items()) + "."


#: the values a form's units field takes (``auto``: the file's, else inferred)
UNITS_CHOICES = (solver.AUTO, *solver.UNITS)
#: the values a form's axis field takes (``auto``: inferred; case and surrounding spaces are ignored)
AXIS_FORM_CHOICES = (solver.AUTO, *solver.AXIS_CHOICES)
UNITS_ENUM = {"enum": list(UNITS_CHOICES)}
AXIS_ENUM = {"enum": list(AXIS_FORM_CHOICES)}
