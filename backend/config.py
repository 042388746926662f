"""Settings: one pydantic-settings class, every field read from ``DEXLABEL_<NAME>``.

The defaults are the embedded deployment: a SQLite file and a local frame folder under ./var,
the SQLite-backed job queue and an in-process consumer. Production points the same fields at
PostgreSQL, Redis and S3 (see docker-compose.yml).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

PLACEHOLDER_SECRETS = frozenset({"", "changeme", "change-me", "secret", "dev-secret-change-me"})
DEV_SECRET = "dev-secret-change-me"


class Settings(BaseSettings):
    """All runtime configuration of dexlabel."""

    model_config = SettingsConfigDict(env_prefix="DEXLABEL_", env_file=".env", extra="ignore")

    env: Literal["dev", "test", "prod"] = "dev"
    var_dir: Path = Path("var")
    database_url: str = ""
    redis_url: str | None = None
    storage_url: str = ""
    s3_endpoint_url: str | None = None
    s3_region: str = "us-east-1"
    public_url: str = "http://127.0.0.1:8000"
    secret_key: str = DEV_SECRET
    mano_dir: Path | None = None
    # The embedded deployment runs a queue consumer inside `dexlabel serve`; a scale-out
    # deployment turns it off and runs `dexlabel worker` processes instead.
    inprocess_worker: bool = True
    worker_threads: int = Field(default=2, ge=1, le=64)
    # Upper bound on frames served in one per-view bundle (a DexYCB clip has 72).
    max_bundle_frames: int = Field(default=2000, ge=1)

    @model_validator(mode="after")
    def _fill_defaults_and_check(self) -> Settings:
        if not self.database_url:
            self.database_url = f"sqlite:///{(self.var_dir / 'dexlabel.db').as_posix()}"
        if not self.storage_url:
            self.storage_url = (self.var_dir / "storage").as_posix()
        if self.env == "prod" and self.secret_key.strip().lower() in PLACEHOLDER_SECRETS:
            raise ValueError(
                "DEXLABEL_SECRET_KEY is a placeholder; set a long random value outside dev"
            )
        if self.env == "prod" and len(self.secret_key) < 32:
            raise ValueError("DEXLABEL_SECRET_KEY must be at least 32 characters outside dev")
        return self

    @property
    def queue_path(self) -> Path:
        """SQLite file of the embedded job queue (used when REDIS_URL is unset)."""
        return self.var_dir / "queue.db"

    @property
    def is_sqlite(self) -> bool:
        return self.database_url.startswith("sqlite")


@lru_cache
def get_settings() -> Settings:
    """The process-wide settings, read once from the environment."""
    return Settings()
