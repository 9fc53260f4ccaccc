"""Event ids made without a system call (service/event_ids.py) are still UUID4s, in the one
spelling the log stores, and a forked child does not repeat its parent's."""

from __future__ import annotations

import os
import uuid

from faultledger.service.event_ids import new_event_id


def test_ids_are_distinct_version_4_uuids_in_canonical_spelling() -> None:
    ids = [new_event_id() for _ in range(20_000)]
    assert len(set(ids)) == len(ids)
    for event_id in ids[:2_000]:
        parsed = uuid.UUID(event_id)
        assert parsed.version == 4 and parsed.variant == uuid.RFC_4122
        assert str(parsed) == event_id


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
