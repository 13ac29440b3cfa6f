"""The one settings object of hairport (environment variables with the prefix ``HAIRPORT_``)."""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


def default_storage_dir() -> Path:
    """``$XDG_DATA_HOME/hairport`` (by default ``~/.local/share/hairport``): absolute, one per user."""
    data_home = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(data_home) / "hairport"


class Settings(BaseSettings):
    """Deployment and limit settings; solver parameters are per-request options, not settings."""

    model_config = SettingsConfigDict(env_prefix="HAIRPORT_", extra="ignore")

    cache_dir: Path = Field(default_factory=lambda: Path.home() / ".cache" / "hairport",
                            description="Downloaded assets, built characters and grooms.")
    max_strands: int = Field(5_000_000, description="Largest strand count a hair file may declare.")
    max_particles: int = Field(50_000_000, description="Largest particle count a hair file may declare.")
    max_vertices: int = Field(5_000_000, description="Largest vertex count a character mesh may have.")
    max_faces: int = Field(10_000_000, description="Largest face count a character mesh may have.")
    max_file_bytes: int = Field(4 * 1024**3, description="Largest input file read from disk (bytes).")
    memory_budget_bytes: int = Field(8 * 1024**3, description="Memory one job may use (bytes): inputs whose estimated need is larger are refused, and the worker child is limited to it.")
    worker_niceness: int = Field(10, ge=0, le=19, description="Scheduling niceness of the worker children that run jobs: on a host shared with the API, requests are served before the solver.")

    # service and worker
    redis_url: str = Field("redis://127.0.0.1:6379/0", description="Redis: Celery broker and readiness check.")
    storage_dir: Path = Field(default_factory=default_storage_dir, description=(
        "Uploads, artifacts, results and records (a volume shared by API and workers); made absolute at "
        "start-up. Default ~/.local/share/hairport (a laptop); a deployment sets it."))
    storage_url: str | None = Field(None, description=(
        "Where blobs live for every host: s3://bucket/prefix (AWS S3 or any S3-compatible server; credentials, "
        "region and endpoint from AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY, AWS_REGION, AWS_ENDPOINT_URL unless "
        "the s3_* settings give them) or a folder; storage_dir is then this host's cache. Unset: storage_dir "
        "holds everything."))
    database_url: str | None = Field(None, description=(
        "Where the records live: postgresql://user@host:port/name (every host shares it; the schema is made in "
        "an empty database, `hairport db upgrade` moves an older one) or unset (or sqlite:) for the storage "
        "folder's records and SQLite index (one host)."))
    s3_endpoint_url: str | None = Field(None, description="The S3 endpoint (over AWS_ENDPOINT_URL).")
    s3_region: str | None = Field(None, description="The S3 region (over AWS_REGION).")
    s3_access_key_id: str | None = Field(None, description="The S3 access key id (over AWS_ACCESS_KEY_ID).")
    s3_secret_access_key: SecretStr | None = Field(None, description="The S3 secret key (over AWS_SECRET_ACCESS_KEY).")
    api_keys: str = Field("", description="Comma-separated API keys; each key owns what it creates.")
    insecure_dev: bool = Field(False, description="Accept requests without a key (owner 'dev'); never in production.")
    max_upload_bytes: int = Field(512 * 1024**2, description="Largest accepted upload (bytes); larger gets 413.")
    retention_days: float = Field(30.0, description="Results, uploads and records older than this are purged.")
    orphan_grace_seconds: float = Field(3600.0, ge=60, description=(
        "A stored file no record refers to (an upload whose API process died before its record was written, the "
        "outputs of a run that lost its job) is removed once it was not saved or read for this long (s). It "
        "must be longer than an upload's validation, which happens between its file and its record (files of "
        "running jobs are kept whatever their age); the sweep runs hourly."))
    cors_origins: str = Field("", description="Comma-separated origins allowed by CORS ('*' for any).")
    task_time_limit: int = Field(3600, description="Hard time limit of one job (s); the worker child is killed.")
    task_soft_time_limit: int = Field(3300, description="Soft time limit of one job (s): the job fails cleanly.")
    visibility_timeout: int = Field(3900, description="Seconds before a job whose worker died is delivered again.")
    solver_workers: int = Field(1, ge=1, description=(
        "Processes a job's own run uses for the multi-scale fine level chunks it solves itself."))
    fine_chunk_particles: int = Field(250_000, ge=1, description=(
        "Particles per chunk of a job's multi-scale fine level sent to the fine queue; a fine level no larger "
        "than this is solved in the job's own run, without chunk tasks."))
    target_cache: bool = Field(True, description=(
        "Keep each target body's collision surface, and the source body wrapped onto each target of another "
        "topology, in the storage for every job and worker (false: every worker process builds the surface once "
        "per body, and every job wraps)."))
    max_fine_chunks: int = Field(32, ge=1, description=(
        "Most chunks one job's fine level is split into (larger chunks beyond that)."))
    max_targets_per_request: int = Field(64, description="Largest target_character_ids list of one retarget request.")
    max_batch_jobs: int = Field(256, ge=1, description="Most hairstyle x target pairs (jobs) of one batch.")
    max_attempts: int = Field(3, ge=1, description=(
        "Runs a job (or a preprocessing) may start: one whose worker died this many times fails with worker_lost."))
    heartbeat_seconds: float = Field(10.0, gt=0, description="A running job writes its heartbeat this often (s).")
    stale_after_seconds: float = Field(40.0, gt=0, description=(
        "A running job whose heartbeat is older than this (s) is marked stale and queued again."))
    sweep_seconds: float = Field(15.0, gt=0, description=(
        "How often workers and the API look for stale jobs and lost messages (s; one sweep per period "
        "for the whole deployment)."))
    lost_after_seconds: float = Field(60.0, gt=0, description=(
        "A job queued this long (s) whose message is in no queue of the broker is sent again."))
    enqueue_timeout_seconds: float = Field(3.0, gt=0, description=(
        "Longest wait for the broker when a request sends a task (s); past it the request is 503."))
    max_concurrent_validations: int = Field(2, ge=1, description=(
        "Uploads the API validates at once, each in a process of its own (started with the API, one core "
        "each while busy); more wait their turn."))
    validation_memory_bytes: int = Field(1024**3, ge=16 * 1024**2, description=(
        "Memory one upload's validation may allocate (bytes), beyond its process's own ~0.25 GB: the heap "
        "limit of that process; an upload needing more is refused (413 over_memory_budget)."))
    validation_wait_seconds: float = Field(30.0, ge=0, description=(
        "Longest wait of an upload for a free validation process (s); past it the request is 503 "
        "validation_busy with Retry-After."))
    validation_timeout_seconds: float = Field(120.0, gt=0, description=(
        "Longest validation of one upload (s); past it its process is stopped and the upload refused "
        "(413 too_large)."))

    def s3_overrides(self) -> dict:
        """The ``s3_*`` settings that are set, as :class:`hairport.storage.s3.S3Objects` takes them."""
        secret = None if self.s3_secret_access_key is None else self.s3_secret_access_key.get_secret_value()
        given = {"endpoint_url": self.s3_endpoint_url, "region": self.s3_region,
                 "access_key_id": self.s3_access_key_id, "secret_access_key": secret}
        # an empty value (a compose file's unset variable) gives nothing
        return {name: value for name, value in given.items() if value}

    @field_validator("storage_dir")
    @classmethod
    def _absolute_storage(cls, value: Path) -> Path:
        # resolved once, when the settings are read: a relative path would mean another folder in
        # every process started from another working directory
        return Path(value).expanduser().resolve()

    @property
    def api_key_list(self) -> list[str]:
        return [key.strip() for key in self.api_keys.split(",") if key.strip()]

    @property
    def cors_origin_list(self) -> list[str]:
        return [origin.strip() for origin in self.cors_origins.split(",") if origin.strip()]


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
