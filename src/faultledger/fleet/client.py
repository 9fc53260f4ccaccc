"""The central's fleet API as a robot sees it (docs/fleet.md, "The push protocol"): push a
batch, page through the (seq, hash) pairs it holds. Every answer other than success is an
exception that says what happened and whether waiting helps (``transient``), so the push
loop decides without parsing text."""

from __future__ import annotations

import email.utils
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import httpx

from faultledger.domain.text import printable
from faultledger.errors import ConfigError, FaultLedgerError, Reason
from faultledger.service.tokens import PREFIX

RECORDS_PATH = "api/v1/fleet/records"
"""POST: push a batch; GET: the (seq, hash) pairs the central holds. Relative to the central's
URL, so a central behind a proxy path (https://host/faultledger/) works."""
ROBOTS_PATH = "api/v1/fleet/robots"
"""GET: the robot logs the central holds (a robot's token: its own)."""
CONNECT_TIMEOUT_SEC = 5.0
ANSWER_TIMEOUT_SEC = 30.0
"""How long the central may take to answer a batch (it checks and stores up to 1,000
records); a batch sent again after a lost answer is ignored by the central, never doubled."""
MAX_TOKEN_FILE_BYTES = 64 * 1024
MAX_RETRY_AFTER_SEC = 3600.0


class CentralError(FaultLedgerError):
    """An answer of the central other than success, or none at all."""

    transient = False
    """Waiting and sending the same batch again may succeed (the central is away or busy)."""
    retry_after: float | None = None
    """The central's Retry-After, in seconds, when it gave one."""


class CentralUnreachable(CentralError):
    """No answer: connection refused, DNS, a timeout, a broken connection."""

    reason = Reason.UNAVAILABLE
    transient = True


class CentralUnavailable(CentralError):
    """5xx: the central is there but cannot take the batch now (503 busy, 502 from a proxy)."""

    reason = Reason.UNAVAILABLE
    transient = True

    def __init__(self, message: str, status: int, retry_after: float | None) -> None:
        super().__init__(message)
        self.status = status
        self.retry_after = retry_after


class TokenRefused(CentralError):
    """401 (unknown, revoked or expired token) or 403 (a token for another robot, or a role
    that may not push)."""

    reason = Reason.FORBIDDEN

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


class BatchRefused(CentralError):
    """The central refused the batch and stored none of it: a record it holds differs
    (409 record-differs), a hash or prev_hash does not check (422 broken-chain), the log is
    held for another robot (409 robot-differs), or the body itself (400)."""

    def __init__(self, message: str, status: int, error: str, seq: int | None) -> None:
        super().__init__(message)
        self.status = status
        self.error = error
        self.seq = seq


class ChainGap(CentralError):
    """409 chain-gap: the batch starts after the central's last seq + 1; push from there."""

    def __init__(self, message: str, last_seq: int) -> None:
        super().__init__(message)
        self.last_seq = last_seq


class UnknownLedger(CentralError):
    """404 unknown-ledger: the central holds no record of this log yet."""

    reason = Reason.NOT_FOUND


class BatchTooLarge(CentralError):
    """413: the body is over the central's limit (http.max_body_bytes); send fewer records."""


class CentralAnswerError(CentralError):
    """An answer that is not the protocol's (no fleet API there: an older faultledger or
    another server; a body that is not the documented JSON)."""


@dataclass(frozen=True, slots=True)
class PushAnswer:
    """Where the central stands for one log after a batch (docs/fleet.md)."""

    last_seq: int
    last_hash: str
    stored: int
    ignored: int


@dataclass(frozen=True, slots=True)
class RecordsPage:
    """One page of ``GET /api/v1/fleet/records``: (seq, hash) in seq order, and the last seq
    the central holds for the log."""

    items: list[tuple[int, str]]
    last_seq: int


@dataclass(frozen=True, slots=True)
class HeldLog:
    """One robot log as ``GET /api/v1/fleet/robots`` lists it."""

    robot_id: str
    ledger_id: str
    last_seq: int
    last_pushed_at: str


def check_central_url(text: str) -> str:
    """The central's base URL (ending in ``/``); anything but an http(s) URL with a host is a
    ConfigError naming what is wrong."""
    parts = urlsplit(text.strip())
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ConfigError(f"central URL {printable(text)!r} must be http://HOST[:PORT][/PATH] "
                          "or https://…")
    if parts.query or parts.fragment:
        raise ConfigError(f"central URL {printable(text)!r} must not have a query or fragment")
    try:
        parts.port  # noqa: B018 - raises on a port outside 0..65535
    except ValueError:
        raise ConfigError(f"central URL {printable(text)!r} has an invalid port") from None
    path = parts.path if parts.path.endswith("/") else parts.path + "/"
    return urlunsplit((parts.scheme, parts.netloc, path, "", ""))


def shown_url(url: str) -> str:
    """The URL as messages name it: without any user:password."""
    parts = urlsplit(url)
    host = parts.netloc.rpartition("@")[2]
    return urlunsplit((parts.scheme, host, parts.path, "", ""))


def read_token(path: Path) -> str:
    """The bearer token in ``path``: what ``faultledger token create`` printed (one line,
    ``flt_…``); comment lines (``#``) and blank lines are skipped. The central's own token file
    (hashes only) is refused with a message saying which file is meant."""
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_TOKEN_FILE_BYTES + 1)
    except OSError as error:
        raise ConfigError(f"cannot read token file {path}: {error.strerror or error}") from None
    if len(raw) > MAX_TOKEN_FILE_BYTES:
        raise ConfigError(f"token file {path} is larger than {MAX_TOKEN_FILE_BYTES // 1024} KiB;"
                          " it should hold one token (faultledger token create prints it)")
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        raise ConfigError(f"token file {path} is not a token: a token is ASCII "
                          f"({PREFIX}…, as faultledger token create prints it)") from None
    lines = [line.strip() for line in text.splitlines()]
    lines = [line for line in lines if line and not line.startswith("#")]
    if any(line.startswith(("tokens:", "- name:", "sha256:")) for line in lines):
        raise ConfigError(f"token file {path} is a server's token file (names and SHA-256 "
                          "hashes, no token): give the file holding the token itself, as "
                          "`faultledger token create --role robot --name ROBOT` printed it")
    if not lines:
        raise ConfigError(f"token file {path} is empty: put the token `faultledger token "
                          "create --role robot --name ROBOT` printed on the central in it")
    if len(lines) > 1 or any(char.isspace() for char in lines[0]):
        raise ConfigError(f"token file {path} must hold one token on one line "
                          f"({PREFIX}…), found {len(lines)} lines")
    return lines[0]


def retry_after_seconds(value: str | None, now: float | None = None) -> float | None:
    """A Retry-After header in seconds (delta-seconds or an HTTP date); None when absent or
    unreadable. Capped at an hour, so a wrong header cannot park the pusher for days."""
    if value is None:
        return None
    text = value.strip()
    if text.isascii() and text.isdigit():
        return min(float(text), MAX_RETRY_AFTER_SEC)
    try:
        moment = email.utils.parsedate_to_datetime(text)
    except (TypeError, ValueError, IndexError):
        return None
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    current = datetime.now(UTC).timestamp() if now is None else now
    delta = moment.timestamp() - current
    return None if math.isnan(delta) else min(max(delta, 0.0), MAX_RETRY_AFTER_SEC)


class CentralClient:
    """One central, one token: a keep-alive HTTP connection reused for every batch."""

    def __init__(self, url: str, token: str, *, timeout: float = ANSWER_TIMEOUT_SEC,
                 transport: httpx.BaseTransport | None = None) -> None:
        self.url = check_central_url(url)
        self.shown = shown_url(self.url)
        self._http = httpx.Client(
            base_url=self.url, transport=transport, follow_redirects=False,
            timeout=httpx.Timeout(timeout, connect=CONNECT_TIMEOUT_SEC),
            headers={"authorization": f"Bearer {token}", "user-agent": "faultledger-sync"})

    def set_token(self, token: str) -> None:
        """Use another token from the next request on (the token file was replaced)."""
        self._http.headers["authorization"] = f"Bearer {token}"

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> CentralClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def push(self, robot_id: str, ledger_id: str, head_seq: int,
             records: Sequence[str] = ()) -> PushAnswer:
        """POST one batch (docs/fleet.md): ``records`` are JSON objects already encoded
        (``push.record_json``), so the batch is sized and encoded once. An empty batch asks
        where the central stands."""
        head = json.dumps({"robot_id": robot_id, "ledger_id": ledger_id, "head_seq": head_seq},
                          separators=(",", ":"))
        content = (head[:-1] + ',"records":[' + ",".join(records) + "]}").encode()
        answer = self._send("POST", RECORDS_PATH, content=content,
                            headers={"content-type": "application/json"})
        data = self._json(answer)
        try:
            return PushAnswer(int(data["last_seq"]), str(data.get("last_hash") or ""),
                              int(data.get("stored", 0)), int(data.get("ignored", 0)))
        except (KeyError, TypeError, ValueError):
            raise CentralAnswerError(f"the central {self.shown} answered the batch without a "
                                     f"last_seq: {_clip(answer.text)}") from None

    def records(self, ledger_id: str, after_seq: int, limit: int) -> RecordsPage:
        """One page of the (seq, hash) pairs the central holds for ``ledger_id``."""
        answer = self._send("GET", RECORDS_PATH, params={
            "ledger_id": ledger_id, "after_seq": after_seq, "limit": limit})
        data = self._json(answer)
        try:
            items = [(int(item["seq"]), str(item["hash"])) for item in data["items"]]
            return RecordsPage(items, int(data.get("last_seq") or 0))
        except (KeyError, TypeError, ValueError):
            raise CentralAnswerError(f"the central {self.shown} answered GET {RECORDS_PATH} "
                                     f"without items of seq and hash: {_clip(answer.text)}"
                                     ) from None

    def robots(self) -> list[HeldLog]:
        """The robot logs the central holds (a robot's token: only that robot's)."""
        answer = self._send("GET", ROBOTS_PATH)
        data = self._json(answer)
        try:
            return [HeldLog(str(item["robot_id"]), str(item["ledger_id"]),
                            int(item["last_seq"]), str(item["last_pushed_at"]))
                    for item in data["items"]]
        except (KeyError, TypeError, ValueError):
            raise CentralAnswerError(f"the central {self.shown} answered GET {ROBOTS_PATH} "
                                     f"without robot logs: {_clip(answer.text)}") from None

    def _send(self, method: str, path: str, **options: Any) -> httpx.Response:
        try:
            answer = self._http.request(method, path, **options)
        except httpx.TimeoutException as error:
            raise CentralUnreachable(f"the central {self.shown} did not answer in time "
                                     f"({type(error).__name__})") from None
        except httpx.TransportError as error:
            raise CentralUnreachable(f"cannot reach the central {self.shown}: "
                                     f"{_cause(error)}") from None
        if answer.status_code < 300:
            return answer
        raise self._refusal(answer)

    def _refusal(self, answer: httpx.Response) -> CentralError:
        status = answer.status_code
        data = _body(answer)
        error = str(data.get("error") or data.get("reason") or "")
        said = (printable(str(data.get("message") or "")) or _clip(answer.text)
                or answer.reason_phrase)
        what = f"{status} {error}".rstrip() + f": {said}"
        seq = _int(data.get("seq"))
        if status in (401, 403):
            return TokenRefused(f"the central {self.shown} refused the token ({what})", status)
        if status == 409 and error == "chain-gap":
            last = _int(data.get("last_seq"))
            if last is not None:
                return ChainGap(f"the central {self.shown} holds this log up to seq {last} "
                                f"({what})", last)
        if status == 413:
            return BatchTooLarge(f"the central {self.shown} refused the batch as too large "
                                 f"({what})")
        if status >= 500:
            return CentralUnavailable(f"the central {self.shown} cannot take records now "
                                      f"({what})", status,
                                      retry_after_seconds(answer.headers.get("retry-after")))
        if status in (400, 409, 422) and data:
            where = f" at seq {seq}" if seq is not None else ""
            return BatchRefused(f"the central {self.shown} refused the batch{where} ({what})",
                                status, error, seq)
        if status == 404 and error == "unknown-ledger":
            return UnknownLedger(f"the central {self.shown} holds no record of this log "
                                 f"({what})")
        if status == 404:
            return CentralAnswerError(f"the central {self.shown} has no fleet API ({what}): "
                                      "is it a faultledger central of this version, and is "
                                      "the URL its base URL?")
        return CentralAnswerError(f"the central {self.shown} answered {what}")

    def _json(self, answer: httpx.Response) -> dict[str, Any]:
        data = _body(answer)
        if not data:
            raise CentralAnswerError(f"the central {self.shown} answered {answer.status_code} "
                                     f"without a JSON object: {_clip(answer.text)}")
        return data


def _body(answer: httpx.Response) -> dict[str, Any]:
    try:
        data = answer.json()
    except ValueError:
        return {}
    return data if isinstance(data, dict) else {}


def _int(value: object) -> int | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, str) and value.isascii() and value.isdigit():
        return int(value)
    return None


def _clip(text: str, size: int = 200) -> str:
    shown = printable(" ".join(text.split()))
    return shown if len(shown) <= size else shown[:size] + "…"


def _cause(error: httpx.TransportError) -> str:
    """The innermost reason of a transport error (``[Errno 111] Connection refused``)."""
    cause: BaseException = error
    while cause.__cause__ is not None or cause.__context__ is not None:
        cause = cause.__cause__ or cause.__context__  # type: ignore[assignment]
    text = str(cause) or str(error) or type(error).__name__
    if isinstance(cause, OSError) and cause.strerror:
        text = cause.strerror.lower()
    return printable(text)
