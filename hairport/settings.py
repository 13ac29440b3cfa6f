"""The one settings object of hairport (environment variables with the prefix ``HAIRPORT_``)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


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


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
