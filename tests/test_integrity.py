"""The chain hash's bytes (SPEC §3) are fixed for ever: every log ever written depends on them.
``record_hash`` writes the canonical list out by hand for speed; here it is held to the
definition, ``canonical_json`` of the list, for any text and any numbers."""

from __future__ import annotations

import hashlib
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from faultledger.domain.events import FaultCleared, FaultReported
from faultledger.domain.integrity import (
    GENESIS_HASH,
    canonical_json,
    parse_json,
    payload_json,
    record_hash,
)
from faultledger.domain.types import EventType

TEXT = st.text(st.characters(exclude_categories=["Cs"]), max_size=40)  # any UTF-8 text
NUMBER = st.integers(min_value=0, max_value=2**63 - 1)


def by_definition(prev: str, seq: int, event_id: str, kind: str, code: str | None,
                  source: str | None, payload: str, occurred: int, recorded: int,
                  version: int) -> str:
    digest = hashlib.sha256(prev.encode("ascii"))
    digest.update(canonical_json([seq, event_id, kind, code, source, occurred, recorded,
                                  version]).encode("utf-8"))
    digest.update(payload.encode("utf-8"))
    return digest.hexdigest()


@given(seq=NUMBER, event_id=TEXT, kind=TEXT, code=st.none() | TEXT, source=st.none() | TEXT,
       payload=TEXT, occurred=NUMBER, recorded=NUMBER, version=NUMBER)
def test_record_hash_is_the_canonical_json_definition(
        seq: int, event_id: str, kind: str, code: str | None, source: str | None,
        payload: str, occurred: int, recorded: int, version: int) -> None:
    args = (GENESIS_HASH, seq, event_id, kind, code, source, payload, occurred, recorded,
            version)
    assert record_hash(*args) == by_definition(*args)


def test_a_known_record_keeps_its_hash() -> None:
    """One record's hash as computed before the hand-written form (through the encoder): a
    change of bytes shows here even if the definition above were changed with it."""
    assert record_hash(GENESIS_HASH, 1, "e-1", "fault_reported", 'MOTOR_"HOT"\n\t', None,
                       '{"a":"ü"}', 10, 20, 1) == (
        "365ecde7bbe2c65e47b6295162dc03207b4478fc71653466078bc386d736c9ad")


@given(code=TEXT, kind=st.sampled_from(EventType), severity=st.integers(0, 3),
       description=TEXT, source=TEXT)
def test_a_reports_payload_is_the_canonical_json_of_its_payload(
        code: str, kind: EventType, severity: int, description: str, source: str) -> None:
    """``payload_json`` writes a fault report's payload out by hand (the ingest path); it is
    the encoder's canonical form of ``payload()``, byte for byte."""
    event = FaultReported(code, kind, severity, description, source)
    assert payload_json(event) == canonical_json(event.payload())


def test_other_records_payloads_go_through_the_encoder() -> None:
    cleared = FaultCleared('MOTOR_"HOT"', "operator\n", "ü")
    assert payload_json(cleared) == canonical_json(cleared.payload())
    assert payload_json(cleared) == '{"actor":"operator\\n","fault_code":"MOTOR_\\"HOT\\"",' \
        '"reason":"ü"}'


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
    | TEXT,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(TEXT, inner, max_size=4),
    max_leaves=12)


def _typed(value: object) -> object:
    """A value with the type of every part spelled out (1 == 1.0 == True in Python)."""
    if isinstance(value, dict):
        return ("dict", [(key, _typed(item)) for key, item in value.items()])
    if isinstance(value, list):
        return ("list", [_typed(item) for item in value])
    return (type(value).__name__, repr(value))


@given(value=JSON_VALUES)
def test_a_canonical_text_reads_as_json_reads_it(value: object) -> None:
    text = canonical_json(value)
    assert _typed(parse_json(text)) == _typed(json.loads(text))
    assert _typed(parse_json(text.encode())) == _typed(json.loads(text))


def test_what_the_fast_decoder_refuses_is_read_as_json_reads_it() -> None:
    for text in ('{"a":NaN}', '[Infinity,-Infinity]', '{"a":1e400}', '"\\ud800"',
                 '{"big":123456789012345678901234567890}'):
        assert _typed(parse_json(text)) == _typed(json.loads(text))


def test_text_that_is_not_json_is_refused_as_json_refuses_it() -> None:
    for text in ('{"a":', "", "[1,]", "{'a': 1}"):
        with pytest.raises(ValueError):
            parse_json(text)
