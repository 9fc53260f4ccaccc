"""The YAML configuration file, validated with pydantic into clear, located error messages."""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from faultledger.domain.policy import Policy
from faultledger.domain.shifts import ShiftCalendar
from faultledger.errors import ConfigError

DEFAULT_DATABASE_URL = "sqlite:///var/faultledger.db"
M = TypeVar("M", bound=BaseModel)


class DatabaseSettings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    url: str = DEFAULT_DATABASE_URL
    max_batch: int = Field(default=512, ge=1, le=100_000)
    """Most reports one group commit may carry."""


class Settings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    database: DatabaseSettings = Field(default_factory=DatabaseSettings)
    policy: Policy = Field(default_factory=Policy)
    bridges: dict[str, dict[str, Any]] = Field(default_factory=dict)
    """Bridges `faultledger serve` runs: name → {enabled, config: FILE, inline settings}.
    Validated by the ROS adapter when it starts them (the core does not import ROS)."""
    shifts: Path | None = None
    """Shift calendar YAML (see config/shifts.yaml) for statistics, relative to the working
    directory; None: the built-in default calendar (UTC, three 8-hour shifts)."""


def load_settings(path: Path | None) -> Settings:
    """Settings from a YAML file, or the built-in defaults when no file is given."""
    if path is None:
        return Settings()
    return _load(path, Settings, "config file")


def load_shift_calendar(path: Path) -> ShiftCalendar:
    """``config/shifts.yaml``: refused as a whole, with located messages, when invalid."""
    return _load(path, ShiftCalendar, "shift calendar")


def _load(path: Path, model: type[M], what: str) -> M:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise ConfigError(f"cannot read {what} {path}: {error}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"{what} {path} is not valid YAML: {error}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{what} {path} must contain a mapping at the top level")
    try:
        return model.model_validate(data)
    except ValidationError as error:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc']) or '(top)'}: {e['msg']}"
            for e in error.errors()
        )
        raise ConfigError(f"{what} {path} is invalid: {problems}") from None
