"""Service settings from the environment (prefix ``BODYSCAN_``), injected with :func:`get_settings`."""

from __future__ import annotations

import tomllib
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    """Every knob of the web service and the job workers.

    ``BODYSCAN_DATABASE_URL`` selects the database (e.g. ``postgresql://user:pw@host/bodyscan``);
    without it a SQLite file ``bodyscan.db`` in ``BODYSCAN_DATA_DIR`` is used.
    """

    model_config = SettingsConfigDict(env_prefix="BODYSCAN_", extra="ignore")

    database_url: str | None = Field(default=None, description="SQLAlchemy URL; SQLite file in data_dir if unset")
    data_dir: Path = Field(default=Path("data"), description="working data folder for the default SQLite file")
    max_upload_mb: float = Field(default=300.0, gt=0, description="largest accepted request body, MB")
    workers: int = Field(default=2, ge=0, le=64,
                         description="worker processes `bodyscan serve` starts; 0 = separate `bodyscan worker`s")
    job_lease_s: float = Field(default=60.0, gt=0, description="a running job without heartbeat this long is re-queued")
    heartbeat_s: float = Field(default=5.0, gt=0, description="how often a busy worker refreshes its lease")
    poll_s: float = Field(default=0.5, gt=0, description="idle worker poll interval")
    max_attempts: int = Field(default=3, ge=1, description="a job interrupted this often fails instead")
    snap_max_mm: float = Field(default=25.0, gt=0, description="farthest a pick may lie from the scan surface")
    path_step_mm: float = Field(default=2.0, gt=0, description="resampling step of picked polylines")
    log_level: str = Field(default="INFO")
    warm_up: bool = Field(default=True, description="a starting worker compiles the scan kernels at once "
                                                     "(about 40 s once, then 2-3 s from numba's cache), not "
                                                     "during the first scan job")

    @property
    def db_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'bodyscan.db').resolve()}"

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1024 * 1024)


@lru_cache
def get_settings() -> Settings:
    """Settings read once from the environment."""
    return Settings()


def software_version() -> str:
    """Installed bodyscan version, recorded with every measurement."""
    try:
        return version("bodyscan")
    except PackageNotFoundError:  # running from a source tree that is not installed
        pyproject = Path(__file__).resolve().parents[1] / "pyproject.toml"
        try:
            return tomllib.loads(pyproject.read_text())["project"]["version"]
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "0+unknown"
