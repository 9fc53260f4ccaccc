"""One POST of one alert to a rule's receiver, and what its answer means for the delivery:
delivered (2xx), tried again later (no answer, 408, 429, 5xx) or failed for good (any other
status: the receiver refuses this body, and sending it again would not change that)."""

from __future__ import annotations

import email.utils
import json
import math
import time
from typing import Any, NamedTuple

import httpx

from faultledger.domain import alert_bodies
from faultledger.domain.alerts import Alert
from faultledger.domain.text import printable
from faultledger.service.config import AlertReceiver
from faultledger.version import version

CONNECT_TIMEOUT_SEC = 5.0
ANSWER_TIMEOUT_SEC = 10.0
"""How long a receiver may take to answer; then the attempt counts as failed (tried again)."""
MAX_RETRY_AFTER_SEC = 300.0
RETRIED_STATUSES = frozenset({408, 429})


class Outcome(NamedTuple):
    delivered: bool
    final: bool = False
    """Failed for good (not tried again)."""
    error: str = ""
    retry_after: float | None = None


def body(receiver: AlertReceiver, alert: Alert) -> dict[str, Any]:
    if receiver.type == "slack":
        return alert_bodies.slack(alert)
    if receiver.type == "pagerduty":
        assert receiver.routing_key is not None  # the config requires it
        return alert_bodies.pagerduty(alert, receiver.routing_key)
    return alert_bodies.webhook(alert)


class Receiver:
    """A rule's receiver over one HTTP client (kept-alive connections). No proxy from the
    environment: an alert goes where the config says, and nowhere else."""

    def __init__(self, settings: AlertReceiver,
                 transport: httpx.BaseTransport | None = None) -> None:
        self.settings = settings
        self._http = httpx.Client(
            timeout=httpx.Timeout(ANSWER_TIMEOUT_SEC, connect=CONNECT_TIMEOUT_SEC),
            trust_env=False, follow_redirects=False, transport=transport,
            headers={"User-Agent": f"faultledger/{version()}"})

    @property
    def shown(self) -> str:
        return f"{self.settings.type} {self.settings.url}"

    def send(self, alert: Alert) -> Outcome:
        content = json.dumps(body(self.settings, alert), ensure_ascii=False,
                             separators=(",", ":")).encode()
        try:
            answer = self._http.post(self.settings.url, content=content, headers={
                "Content-Type": "application/json", "Idempotency-Key": alert.key})
        except httpx.TimeoutException:
            return Outcome(False, error=f"no answer within {ANSWER_TIMEOUT_SEC:g} s")
        except httpx.TransportError as error:
            return Outcome(False, error=f"cannot reach the receiver: {_cause(error)}")
        status = answer.status_code
        if 200 <= status < 300:
            return Outcome(True)
        text = printable(answer.text[:200].strip()) if answer.content else ""
        said = f"HTTP {status} {answer.reason_phrase}" + (f": {text}" if text else "")
        if status in RETRIED_STATUSES or status >= 500:
            return Outcome(False, error=said,
                           retry_after=_retry_after(answer.headers.get("Retry-After")))
        return Outcome(False, final=True, error=said)

    def close(self) -> None:
        self._http.close()


def _retry_after(value: str | None) -> float | None:
    """Seconds from a Retry-After header (seconds or an HTTP date), at most 300 s."""
    if not value:
        return None
    try:
        seconds = float(value)
    except ValueError:
        try:
            moment = email.utils.parsedate_to_datetime(value)
        except (TypeError, ValueError):
            return None
        seconds = moment.timestamp() - time.time()
    if not math.isfinite(seconds):
        return None
    return min(MAX_RETRY_AFTER_SEC, max(0.0, seconds))


def _cause(error: httpx.TransportError) -> str:
    """The innermost reason (connection refused, name not known), on one line."""
    found: BaseException = error
    while found.__cause__ is not None or found.__context__ is not None:
        found = found.__cause__ or found.__context__  # type: ignore[assignment]
    return printable(str(found) or type(found).__name__)[:200]
