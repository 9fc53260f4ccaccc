"""Random event ids (UUID version 4) without a system call per report.

``uuid.uuid4()`` reads 16 bytes from the kernel for every id and builds a ``UUID`` object
to print it: ~2.6 µs, a noticeable share of a report's Python. An event id is unique, not
secret (it names a record; nobody has to be unable to guess the next one), so ids are drawn
from one Mersenne Twister per process, seeded with 256 bits from the kernel and seeded anew
in a forked child (which would otherwise repeat its parent's ids). Two processes' streams
never meet in practice: the chance of a collision is that of 122 random bits, as for
``uuid4``.
"""

from __future__ import annotations

import os
import random

_VERSION_4 = 0x4000 << 64 | 0x8000 << 48
"""The version (4) and variant (RFC 4122) bits."""
_KEEP = ~(0xF000 << 64 | 0xC000 << 48) & ((1 << 128) - 1)

_random = random.Random()


def _seed() -> None:
    _random.seed(os.urandom(32))


_seed()
os.register_at_fork(after_in_child=_seed)


def new_event_id() -> str:
    """A fresh UUID4, lowercase and hyphenated (the spelling the log stores)."""
    digits = "%032x" % (_random.getrandbits(128) & _KEEP | _VERSION_4)
    return f"{digits[:8]}-{digits[8:12]}-{digits[12:16]}-{digits[16:20]}-{digits[20:]}"
