"""The YAML configuration file, validated with pydantic into clear, located error messages."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from faultledger.domain import alerts, validation
from faultledger.domain.policy import Policy
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import DEFAULT_ESTOP_CODES
from faultledger.errors import ConfigError

DEFAULT_DATABASE_URL = "sqlite:///var/faultledger.db"
DEFAULT_CONFIG = Path("config/faultledger.yaml")
"""The shipped configuration, found relative to the working directory when no --config /
FAULTLEDGER_CONFIG names one: `make run` serves with it, so every command run from the same
checkout then agrees with the server on the calendar, the e-stop codes and the token file."""
MAX_CONFIG_BYTES = 1024 * 1024
"""A configuration file larger than this is refused unread (a wrong path, /dev/zero)."""
M = TypeVar("M", bound=BaseModel)


class DatabaseSettings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    url: str = DEFAULT_DATABASE_URL
    max_batch: int = Field(default=512, ge=1, le=100_000)
    """Most reports one group commit may carry."""


class AnchorSettings(BaseModel):
    """Signed anchors of the log head (docs/operations.md, "Verify (tamper evidence)")."""

    model_config = ConfigDict(extra="forbid")

    key: Path | None = None
    """Ed25519 private key (PEM) `serve` signs anchors with; keep it outside the database."""
    public_key: Path | None = None
    """The trusted public key `verify` checks anchors with."""
    directory: Path | None = None
    """Where `serve` writes an anchor every ``interval_sec`` (with ``key``); never created."""
    interval_sec: float = Field(default=3600.0, gt=0)
    keep: int | None = Field(default=None, ge=1)
    """Newest anchor files `serve` keeps in ``directory``; None: all."""


HOST_PATTERN = (r"^(\*|[A-Za-z0-9]([A-Za-z0-9.-]{0,252})?(:\d{1,5})?"
                r"|\[[0-9A-Fa-f:.]{2,45}\](:\d{1,5})?)$")
"""An ``http.allowed_hosts`` entry: a name or address, optionally with a port, or ``*``."""
TOKEN_NAME_PATTERN = r"^[A-Za-z0-9_.@-]{1,64}$"
TOKEN_NAME_RULE = "1..64 characters: letters, digits, _ . @ -"


class TokenEntry(BaseModel):
    """One HTTP bearer token: only its SHA-256 is stored (``faultledger token create``)."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=64, pattern=TOKEN_NAME_PATTERN)
    """Who holds it: recorded as the actor of every change made with it."""
    role: Literal["viewer", "reporter", "operator", "admin", "robot"]
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")
    expires_at: datetime | None = None
    """When it stops working (UTC); None: never. A time without a zone is UTC."""
    created_at: datetime | None = None
    """When `token create` issued it (UTC); None for entries written before it was kept."""

    @field_validator("expires_at", "created_at")
    @classmethod
    def _utc(cls, value: datetime | None) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            return value.replace(tzinfo=UTC)
        return value.astimezone(UTC)


class HttpSettings(BaseModel):
    """The HTTP adapter (docs/http.md): `faultledger http` and `faultledger serve --http`."""

    model_config = ConfigDict(extra="forbid")

    listen: str = "127.0.0.1:8080"
    """[HOST:]PORT; the command line's --listen / --http wins."""
    tokens: list[TokenEntry] = Field(default_factory=list)
    tokens_file: Path | None = Path("var/http-tokens.yaml")
    """Where `faultledger token create` adds tokens; read at start when it exists, and again
    within a second or two whenever it changes (create, revoke)."""
    cors_origins: list[str] = Field(default_factory=list)
    """Origins allowed to call the API from a browser; empty: none (CORS closed)."""
    max_body_bytes: int = Field(default=1024 * 1024, ge=1024, le=64 * 1024 * 1024)
    max_reports_per_request: int = Field(default=1000, ge=1, le=100_000)
    stream_buffer: int = Field(default=10_000, ge=100, le=1_000_000)
    """Notifications kept for stream clients; a client further behind is disconnected and
    resumes from the log with Last-Event-ID."""
    # Limits (docs/http.md, "Limits"): what one client, or many, can make the server do.
    allowed_hosts: list[Annotated[str, Field(pattern=HOST_PATTERN)]] = Field(
        default_factory=list, max_length=256)
    """Host names answered besides the listen address, localhost, 127.0.0.1 and [::1] (a
    name alone: any port; ``name:port``: that port); ``*``: any Host. Others are refused 400
    (DNS rebinding)."""
    max_connections: int = Field(default=500, ge=8, le=100_000)
    """Open connections; a new one beyond this closes the oldest idle or slow one, or is
    refused 503 when every one is being answered. Capped below the open-files limit."""
    header_timeout_sec: float = Field(default=10.0, gt=0, le=3600)
    """A request's line and headers must arrive within this, from its first byte (a new
    connection: from its opening)."""
    body_timeout_sec: float = Field(default=30.0, gt=0, le=3600)
    """A request's body must arrive within this, from the end of its headers."""
    keep_alive_sec: int = Field(default=5, ge=1, le=3600)
    """An idle keep-alive connection is closed after this (uvicorn's timeout_keep_alive)."""
    send_timeout_sec: float = Field(default=30.0, gt=0, le=3600)
    """A connection whose client reads nothing of an answer for this long is closed."""
    max_header_bytes: int = Field(default=16 * 1024, ge=1024, le=1024 * 1024)
    """Request line plus headers; more is answered 400 (h11's max incomplete event size)."""
    heavy_reads: int = Field(default=1, ge=1, le=64)
    """Statistics, history, state-at and shift reports computed at once (threads of their
    own); more wait in a queue. One is fastest under Python's GIL (docs/performance.md)."""
    heavy_queue: int = Field(default=16, ge=0, le=10_000)
    """Heavy reads waiting for one of those; one more is answered 503 with Retry-After."""
    heavy_wait_sec: float = Field(default=10.0, gt=0, le=600)
    """How long a heavy read waits in the queue before it is answered 503 (Retry-After)."""
    max_stats_rows: int = Field(default=10_000, ge=10, le=60_000)
    """Rows one GET /api/v1/stats may answer: periods, or periods times groups."""
    max_stats_records: int = Field(default=100_000, ge=1000, le=100_000_000)
    """Facts, episodes and goal outcomes one GET /api/v1/stats may read (a query the
    per-minute sums cannot answer: with code or group_by)."""


class RobotLabels(BaseModel):
    """Where a robot works: what a central's statistics group by (``--group-by line``)."""

    model_config = ConfigDict(extra="forbid")

    line: str = Field(default="", max_length=128)
    site: str = Field(default="", max_length=128)


class FleetSettings(BaseModel):
    """A robot's push to a fleet central (docs/fleet.md, "Robot side"): with ``central`` and
    ``token_file``, `serve` and `http` keep the central caught up with the log on a thread of
    their own, like `sync --follow`. On the central, ``robots`` labels each robot with its
    line and site."""

    model_config = ConfigDict(extra="forbid")

    central: str | None = Field(default=None, pattern=r"^https?://[^\s/?#]+[^\s?#]*$",
                                max_length=2048)
    """The central's base URL (http://HOST:PORT or https://…, a path allowed)."""
    token_file: Path | None = None
    """The file holding this robot's token (what `token create --role robot` printed on the
    central); relative to the working directory."""
    robots: dict[str, RobotLabels] = Field(default_factory=dict)
    """On a central: robot_id → {line, site}."""

    @model_validator(mode="after")
    def _both_or_neither(self) -> FleetSettings:
        if (self.central is None) != (self.token_file is None):
            raise ValueError("fleet.central and fleet.token_file go together: the central to "
                             "push to and the robot token it accepts")
        for robot_id in self.robots:
            problem = validation.robot_id_error(robot_id)
            if problem:
                raise ValueError(f"fleet.robots: {problem}")
        return self

    def labels(self) -> dict[str, dict[str, str]]:
        return {robot: {"line": found.line, "site": found.site}
                for robot, found in self.robots.items()}


LOCATED = "located"
"""A pydantic error type whose message names its place itself (``alerts[2] 'oncall'…``)."""


class AlertReceiver(BaseModel):
    """Where a rule's alerts go (docs/alerts.md, "Receivers")."""

    model_config = ConfigDict(extra="forbid")

    type: Literal["webhook", "slack", "pagerduty"]
    url: str = Field(pattern=r"^https?://[^\s/?#]+[^\s#]*$", max_length=2048)
    """http:// or https://; PagerDuty's is https://events.pagerduty.com/v2/enqueue."""
    routing_key: str | None = Field(default=None, pattern=r"^[A-Za-z0-9_\-]{1,128}$")
    """PagerDuty's integration key: required for type pagerduty, refused for the others."""

    @model_validator(mode="after")
    def _routing_key(self) -> AlertReceiver:
        if self.type == "pagerduty" and self.routing_key is None:
            raise ValueError("a pagerduty receiver needs routing_key (the integration key of "
                             "the PagerDuty service)")
        if self.type != "pagerduty" and self.routing_key is not None:
            raise ValueError(f"routing_key is for pagerduty receivers only, not {self.type}")
        return self


class AlertRule(BaseModel):
    """One alert rule (docs/alerts.md): the events it sends, of which codes and severities,
    to which receiver."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    name: str
    on: list[str] = Field(min_length=1)
    codes: list[str] = Field(default_factory=lambda: ["*"], min_length=1,
                             max_length=alerts.MAX_GLOBS)
    """fnmatch globs (case-sensitive); a fault's code must match one."""
    min_severity: int = 0
    """0-3 or INFO/WARN/ERROR/CRITICAL: the fault's severity after the record must be at
    least this."""
    receiver: AlertReceiver
    sync_lag_seconds: float = Field(default=alerts.DEFAULT_SYNC_LAG_SECONDS, gt=0,
                                    le=30 * 86_400)
    """sync_lag: a robot log whose lag (docs/fleet.md, "Lag") passes this alerts once."""

    @model_validator(mode="before")
    @classmethod
    def _yaml_on(cls, data: Any) -> Any:
        """YAML 1.1 reads a bare ``on:`` key as the boolean true."""
        if isinstance(data, dict) and True in data and "on" not in data:
            data = {("on" if k is True else k): v for k, v in data.items()}
        return data

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        if alerts.RULE_NAME.fullmatch(value) is None:
            raise ValueError(f"must be {alerts.RULE_NAME_RULE}")
        return value

    @field_validator("on")
    @classmethod
    def _events(cls, value: list[str]) -> list[str]:
        for event in value:
            if event in alerts.NOT_ALERTS:
                raise ValueError(f"{event!r} is no alert event: {alerts.NOT_ALERTS[event]}")
            if event not in alerts.ALERT_EVENTS:
                raise ValueError(f"unknown event {validation.shown(event)} (events: "
                                 f"{', '.join(alerts.ALERT_EVENTS)})")
        return list(dict.fromkeys(value))

    @field_validator("codes")
    @classmethod
    def _codes(cls, value: list[str]) -> list[str]:
        for glob in value:
            problem = alerts.glob_error(glob)
            if problem:
                raise ValueError(problem)
        return value

    @field_validator("min_severity", mode="before")
    @classmethod
    def _severity(cls, value: object) -> int:
        return alerts.parse_severity(value)

    @model_validator(mode="after")
    def _receiver_events(self) -> AlertRule:
        if self.receiver.type == "pagerduty":
            missing = [e for e in self.on if e not in alerts.PAGERDUTY_ACTIONS]
            if missing:
                raise ValueError(f"on: {missing[0]} has no PagerDuty event action (PagerDuty "
                                 "takes trigger, acknowledge and resolve)")
        return self


def alert_rules(raw: object) -> list[AlertRule]:
    """The ``alerts`` list, each problem naming its rule: ``alerts[2] 'oncall': on: …``."""
    if not isinstance(raw, list):
        raise PydanticCustomError(LOCATED, "alerts must be a list of rules, got {got}",
                                  {"got": validation.shown(raw)})
    rules: list[AlertRule] = []
    seen: dict[str, int] = {}
    for index, item in enumerate(raw):
        name = item.get("name") if isinstance(item, dict) else None
        where = f"alerts[{index}]" + (f" {name!r}" if isinstance(name, str) else "")
        if not isinstance(item, dict):
            raise PydanticCustomError(LOCATED, "{where}: a rule must be a mapping, got {got}",
                                      {"where": where, "got": validation.shown(item)})
        try:
            rule = AlertRule.model_validate(item)
        except ValidationError as error:
            first = error.errors()[0]
            place = ".".join(str(p) for p in first["loc"])
            message = str(first["msg"]).removeprefix("Value error, ")
            raise PydanticCustomError(LOCATED, "{where}: {problem}", {
                "where": where, "problem": f"{place}: {message}" if place else message,
            }) from None
        if rule.name in seen:
            raise PydanticCustomError(LOCATED, "{where}: duplicate rule name (also "
                                      "alerts[{first}])", {"where": where,
                                                           "first": seen[rule.name]})
        seen[rule.name] = index
        rules.append(rule)
    return rules


class Settings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    robot_id: str | None = None
    """The robot a log this process writes records as its own (docs/configuration.md,
    "Robot identity"); None: the host name for a new identity, any recorded one is used."""
    database: DatabaseSettings = Field(default_factory=DatabaseSettings)
    policy: Policy = Field(default_factory=Policy)
    bridges: dict[str, dict[str, Any]] = Field(default_factory=dict)
    """Bridges `faultledger serve` runs: name → {enabled, config: FILE, inline settings}.
    Validated by the ROS adapter when it starts them (the core does not import ROS)."""
    shifts: Path | None = None
    """Shift calendar YAML (see config/shifts.yaml) for statistics, shift ids and the zone
    times are shown in, relative to the working directory; None: the built-in default
    calendar (UTC, three 8-hour shifts)."""
    estop_codes: list[Annotated[str, Field(min_length=1, max_length=256)]] = Field(
        default_factory=lambda: list(DEFAULT_ESTOP_CODES), min_length=1, max_length=256)
    """Globs (case-sensitive) of the codes that are emergency stops: their activations are
    the ``estops`` figure every statistics row, report and the dashboard headline."""
    anchors: AnchorSettings = Field(default_factory=AnchorSettings)
    http: HttpSettings = Field(default_factory=HttpSettings)
    fleet: FleetSettings | None = None
    """Push this robot's log to a central while serving; None: no push (docs/fleet.md)."""
    alerts: list[AlertRule] = Field(default_factory=list)
    """Alert rules the serving process delivers (docs/alerts.md)."""

    @field_validator("alerts", mode="before")
    @classmethod
    def _alerts(cls, value: object) -> list[AlertRule]:
        return alert_rules([] if value is None else value)

    @field_validator("robot_id")
    @classmethod
    def _robot_id(cls, value: str | None) -> str | None:
        problem = None if value is None else validation.robot_id_error(value)
        if problem is not None:
            raise ValueError(problem)
        return value


def config_path(given: Path | None) -> Path | None:
    """The configuration file a command uses: the one given, else ``DEFAULT_CONFIG`` when it
    exists in the working directory, else none (the built-in defaults)."""
    if given is not None:
        return given
    return DEFAULT_CONFIG if DEFAULT_CONFIG.is_file() else None


def load_settings(path: Path | None) -> Settings:
    """Settings from a YAML file, or the built-in defaults when no file is given."""
    if path is None:
        return Settings()
    return load_model(path, Settings, "config file")


def load_shift_calendar(path: Path) -> ShiftCalendar:
    """``config/shifts.yaml``: refused as a whole, with located messages, when invalid."""
    return load_model(path, ShiftCalendar, "shift calendar")


def load_model(path: Path, model: type[M], what: str) -> M:
    """A YAML file validated into ``model``; every problem is one ``ConfigError`` line."""
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_CONFIG_BYTES + 1)
        if len(raw) > MAX_CONFIG_BYTES:
            raise ConfigError(f"{what} {path} is larger than {MAX_CONFIG_BYTES // 1024} KiB; "
                              "is it the right file?")
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise ConfigError(f"cannot read {what} {path}: {error}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"{what} {path} is not valid YAML: {error}") from None
    except RecursionError:
        raise ConfigError(f"{what} {path} is nested too deeply") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{what} {path} must contain a mapping at the top level")
    try:
        return model.model_validate(data)
    except RecursionError:
        raise ConfigError(f"{what} {path} is nested too deeply") from None
    except ValidationError as error:
        found = error.errors()
        problems = "; ".join(
            e["msg"] if e["type"] == LOCATED
            else f"{'.'.join(str(p) for p in e['loc']) or '(top)'}: {e['msg']}"
            for e in found[:5]
        ) + (f"; and {len(found) - 5} more" if len(found) > 5 else "")
        raise ConfigError(f"{what} {path} is invalid: {problems}") from None
