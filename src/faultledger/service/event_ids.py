"""Event ids: time-ordered UUIDs (version 7, RFC 9562) without a system call per report.

Version 7 rather than 4 because of the log's unique index on ``event_id``: random ids land
on a random page of that index each, so a group commit of eight reports wrote eight of its
pages into the WAL; ids that grow with time go to its last page, like ``seq`` does
(docs/performance.md). An id still says nothing about its record that the record does not
(it carries the time it was made, to the millisecond).

``uuid.uuid4()`` reads 16 bytes from the kernel for every id and builds a ``UUID`` object to
print it (~2.6 µs). An event id is unique, not secret, so its random part comes from one
Mersenne Twister per process, seeded with 256 bits from the kernel and seeded anew in a
forked child (which would otherwise repeat its parent's ids): 74 random bits per
millisecond and process, as RFC 9562 lays out.
"""

from __future__ import annotations

import os
import random
import time

_random = random.Random()


def _seed() -> None:
    _random.seed(os.urandom(32))


_seed()
os.register_at_fork(after_in_child=_seed)

_VERSION_7 = 0x7 << 76
_VARIANT = 0b10 << 62
_RAND_B = (1 << 62) - 1


def new_event_id() -> str:
    """A fresh UUIDv7, lowercase and hyphenated (the spelling the log stores)."""
    millis = time.time_ns() // 1_000_000 & 0xFFFF_FFFF_FFFF
    rand = _random.getrandbits(74)
    digits = "%032x" % (millis << 80 | _VERSION_7 | (rand >> 62) << 64 | _VARIANT
                        | rand & _RAND_B)
    return f"{digits[:8]}-{digits[8:12]}-{digits[12:16]}-{digits[16:20]}-{digits[20:]}"
