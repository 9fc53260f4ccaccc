"""Event ids made without a system call (service/event_ids.py) are UUIDv7s in the one spelling
the log stores, growing with time (so they append to the event_id index, like seq), and a
forked child does not repeat its parent's."""

from __future__ import annotations

import os
import time
import uuid

from faultledger.service.event_ids import new_event_id


def test_ids_are_distinct_version_7_uuids_in_canonical_spelling() -> None:
    before_ms = time.time_ns() // 1_000_000
    ids = [new_event_id() for _ in range(20_000)]
    after_ms = time.time_ns() // 1_000_000
    assert len(set(ids)) == len(ids)
    for event_id in ids[:2_000]:
        parsed = uuid.UUID(event_id)
        assert parsed.version == 7 and parsed.variant == uuid.RFC_4122
        assert str(parsed) == event_id
        assert before_ms <= parsed.int >> 80 <= after_ms  # RFC 9562: unix milliseconds


def test_ids_made_in_later_milliseconds_sort_after_earlier_ones() -> None:
    first = new_event_id()
    time.sleep(0.002)
    assert all(later > first for later in (new_event_id() for _ in range(100)))


def test_a_forked_child_draws_other_ids_than_its_parent() -> None:
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: its next ids, to the parent
        os.close(read)
        os.write(write, ",".join(new_event_id() for _ in range(10)).encode())
        os._exit(0)
    os.close(write)
    with os.fdopen(read) as pipe:
        child = pipe.read().split(",")
    os.waitpid(pid, 0)
    parent = [new_event_id() for _ in range(10)]
    assert len(child) == 10
    assert not set(child) & set(parent)
