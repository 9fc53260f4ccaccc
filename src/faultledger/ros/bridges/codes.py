"""Fault codes of the bridges: one rule for every bridge (no rclpy).

A bridge names a fault ``<prefix><NAME>_<SUFFIX>``: the prefix is configuration (used as
given), the suffix says what happened (``ABORTED``, ``EMERGENCY_STOP``, ``HEARTBEAT_LOST``) and
``<NAME>`` is made from what the bridge watches (an action, a diagnostic status, a hardware and
a device id, a node), in upper snake case:

* accents are dropped (NFKD, then only ASCII is kept: ``é`` → ``E``, ``日本`` → nothing);
* camelCase is split (``moveGroup`` → ``MOVE_GROUP``, ``GPSStatus`` → ``GPS_STATUS``), as the
  diagnostics bridge always did (a drop-in for ros2_medkit's diagnostic_bridge);
* every run of other characters than ``A-Z a-z 0-9`` becomes one ``_``, and leading or
  trailing ``_`` are removed.

Several names (hardware id, device id) are joined with ``_``. A code is at most
``MAX_CODE_LENGTH`` (128) characters. When it would be longer, or when a name is empty after
cleaning (``/``, ``日本``), ``<NAME>`` is cut and followed by ``_`` and the first
``HASH_LENGTH`` (8) upper-case hex digits of the SHA-256 of the *original* names (UTF-8 with
surrogatepass; several names joined by NUL), always before the suffix: the suffix survives,
and two long names sharing their beginning still get different codes.
"""

from __future__ import annotations

import hashlib
import re
import unicodedata

from faultledger.domain.validation import MAX_FAULT_CODE_LENGTH

MAX_CODE_LENGTH = MAX_FAULT_CODE_LENGTH
"""128: the longest fault code the ledger accepts."""
HASH_LENGTH = 8
"""Hex digits of SHA-256 in a cut (or empty) name."""

UPPER_SNAKE = re.compile(r"[A-Z0-9]+(?:_[A-Z0-9]+)*")
"""What ``upper_snake`` yields (non-empty), and what a code made of upper-snake parts is."""

_CAMEL = re.compile(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])")
_NON_ALNUM = re.compile(r"[^A-Za-z0-9]+")


def upper_snake(text: str) -> str:
    """``/robot1/arm/followJointTrajectory`` → ``ROBOT1_ARM_FOLLOW_JOINT_TRAJECTORY``,
    ``Température moteur`` → ``TEMPERATURE_MOTEUR``; ``""`` when no letter or digit is left."""
    ascii_text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    return _NON_ALNUM.sub("_", _CAMEL.sub("_", ascii_text)).strip("_").upper()


def name_hash(*names: str) -> str:
    """The first ``HASH_LENGTH`` upper-case hex digits of the SHA-256 of the names (joined by
    NUL, encoded UTF-8 with surrogatepass)."""
    text = "\x00".join(names).encode("utf-8", "surrogatepass")
    return hashlib.sha256(text).hexdigest()[:HASH_LENGTH].upper()


def fault_code(*names: str, prefix: str = "", suffix: str = "") -> str:
    """``<prefix><NAME>_<suffix>`` (module docstring), at most ``MAX_CODE_LENGTH`` characters.

    ``prefix`` is used as given, separator included (``"ACTION_"``, ``"NODE_"``, a diagnostics
    ``code_prefix`` such as ``"robot1."``); ``suffix`` follows after ``_`` (none when empty).
    Neither is ever cut. Raises ValueError when prefix and suffix leave no room for the hash.
    """
    parts = [upper_snake(name) for name in names]
    name = "_".join(part for part in parts if part)
    tail = f"_{suffix}" if suffix else ""
    code = f"{prefix}{name}{tail}"
    if name and all(parts) and len(code) <= MAX_CODE_LENGTH:
        return code
    room = MAX_CODE_LENGTH - len(prefix) - len(tail) - HASH_LENGTH
    if room < 0:
        raise ValueError(f"prefix {prefix!r} and suffix {suffix!r} leave no room for a code")
    head = name[: max(room - 1, 0)].rstrip("_")  # room - 1: the "_" before the hash
    return f"{prefix}{head}_{name_hash(*names)}{tail}" if head else \
        f"{prefix}{name_hash(*names)}{tail}"
