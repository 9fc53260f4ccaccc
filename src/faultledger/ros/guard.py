"""No ROS callback of ours ends the process, and no log line grows with its input.

rclpy re-raises an exception escaping a callback out of ``spin_once``, which ends the process
that spins. Every callback we hand rclpy goes through one of these wrappers:

* ``guard_service``: a service callback; an exception becomes a failed answer
  (``accepted``/``success`` false, ``message``/``error_message`` saying why) and one log line;
* ``guard_callback``: a subscription, timer or event callback; an exception becomes one log
  line (at most one per ``every_sec`` per callback, with a count of those held back).

``clip`` is how any value from outside appears in a log line or an answer: control characters
escaped, at most ``limit`` characters, then ``…(+N chars)``.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol, TypeVar

from faultledger.domain.text import printable
from faultledger.errors import FaultLedgerError

FIELD_LIMIT = 200
"""Characters of one request field quoted in a log line."""
MESSAGE_LIMIT = 400
"""Characters of an error message in a log line or a failed answer."""
CALLBACK_LOG_EVERY_SEC = 5.0
"""A failing subscription or timer callback logs at most once per this many seconds."""

_Response = TypeVar("_Response")


class Logger(Protocol):
    """What we use of rclpy's RcutilsLogger."""

    def warning(self, message: str, **kwargs: Any) -> bool: ...

    def error(self, message: str, **kwargs: Any) -> bool: ...


def clip(value: object, limit: int = FIELD_LIMIT) -> str:
    """``value`` on one line for a log line or a message: a string as it is, anything else as
    its repr; control, format and separator characters escaped (``safe_text.printable``); at
    most ``limit`` characters, the rest counted: ``AAAA…(+999996 chars)``. Never expensive:
    only the head of a huge string is looked at."""
    text = value if isinstance(value, str) else repr(value)
    head = printable(text[:limit])
    if len(head) > limit:  # escapes made it longer: keep whole escapes only
        pieces, used, taken = [], 0, 0
        for char in text[:limit]:
            piece = printable(char)
            if used + len(piece) > limit:
                break
            pieces.append(piece)
            used += len(piece)
            taken += 1
        head, rest = "".join(pieces), len(text) - taken
    else:
        rest = len(text) - min(len(text), limit)
    return head if rest <= 0 else f"{head}…(+{rest} chars)"


def error_text(error: BaseException) -> str:
    """What a failed answer says: the ledger's own message for input it refused (an
    InvalidInputError and the like), else ``internal error: Type: message``; clipped."""
    if isinstance(error, FaultLedgerError):
        return clip(str(error), MESSAGE_LIMIT)
    return clip(f"internal error: {type(error).__name__}: {error}", MESSAGE_LIMIT)


def origin(error: BaseException) -> str:
    """``file.py:line`` where ``error`` was raised (the innermost frame), for the log line."""
    tb = error.__traceback__
    if tb is None:
        return "?"
    while tb.tb_next is not None:
        tb = tb.tb_next
    return f"{Path(tb.tb_frame.f_code.co_filename).name}:{tb.tb_lineno}"


def log_failure(logger: Logger, name: str, error: BaseException, note: str = "") -> None:
    """One line: refused input at WARN, anything else at ERROR with where it was raised."""
    if isinstance(error, FaultLedgerError):
        logger.warning(f"{name}: refused: {error_text(error)}{note}")
    else:
        logger.error(f"{name}: {error_text(error)} (at {origin(error)}){note}")


def fail(response: _Response, text: str) -> _Response:
    """Mark a service response failed, with ``text`` where the type has room for it."""
    for flag in ("accepted", "success"):
        if hasattr(response, flag):
            setattr(response, flag, False)
    for field in ("message", "error_message"):
        if hasattr(response, field):
            setattr(response, field, text)
    return response


def guard_service(callback: Callable[[Any, Any], Any], logger: Logger, name: str
                  ) -> Callable[[Any, Any], Any]:
    """``callback(request, response)`` that never raises: on an exception it answers a fresh
    response of the same type marked failed (``fail``) and logs one line."""

    @functools.wraps(callback)
    def guarded(request: Any, response: Any) -> Any:
        try:
            return callback(request, response)
        except Exception as error:
            log_failure(logger, name, error)
            return fail(type(response)(), error_text(error))

    return guarded


def guard_callback(callback: Callable[..., Any], logger: Logger, name: str,
                   every_sec: float = CALLBACK_LOG_EVERY_SEC) -> Callable[..., None]:
    """``callback(*args)`` (subscription, timer, event, ledger notification) that never
    raises: an exception is logged (one line, at most one per ``every_sec``, with how many
    were held back since the last) and the call returns None."""
    lock = threading.Lock()
    state = {"last": -float("inf"), "held": 0}

    @functools.wraps(callback)
    def guarded(*args: Any) -> None:
        try:
            callback(*args)
        except Exception as error:
            now = time.monotonic()
            with lock:
                if now - state["last"] < every_sec:
                    state["held"] += 1
                    return
                held, state["held"], state["last"] = state["held"], 0, now
            note = f" ({held} more failures since the last line)" if held else ""
            log_failure(logger, name, error, note)

    return guarded
