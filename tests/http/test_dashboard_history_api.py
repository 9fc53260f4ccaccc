"""GET /api/v1/history paged backwards (``order=desc`` + ``before_seq``, answering
``next_before_seq``) and its ``total``: what the dashboard's fault detail and History tab
read (issue 17). ``after_seq`` paging and the exports stay as they were."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.http.conftest import Server, start_server

CODES = ("PAGE_A", "PAGE_B", "PAGE_C")
TOTAL = 302
"""The log's identity (seq 1), the policy (seq 2) and the 300 reports."""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """302 records: seq 1 is the log's identity, seq 2 the policy, then reports of A, B, C in
    turn (A at seq 3, 6, …; every sixth report a PASSED)."""
    running = start_server(tmp_path_factory.mktemp("history") / "faults.db")
    reports = [{"fault_code": CODES[i % 3], "event_type": "PASSED" if i % 6 == 5 else "FAILED",
                "severity": 1, "source_id": f"/src/{i % 2}"} for i in range(300)]
    answer = running.client.post("/api/v1/reports", json=reports).json()
    assert all(r["accepted"] for r in answer["results"])
    yield running
    running.stop()


def get(server: Server, **params: Any) -> dict[str, Any]:
    answer = server.client.get("/api/v1/history", params=params)
    assert answer.status_code == 200, answer.text
    body: dict[str, Any] = answer.json()
    return body


def all_seqs(server: Server, **params: Any) -> list[int]:
    """Every seq the filters select, oldest first, in one ascending page."""
    return [r["seq"] for r in get(server, limit=10_000, **params)["items"]]


def pages_backwards(server: Server, size: int, **params: Any) -> list[list[int]]:
    pages: list[list[int]] = []
    before: int | None = None
    while True:
        cursor = {} if before is None else {"before_seq": before}
        page = get(server, order="desc", limit=size, **params, **cursor)
        assert "next_after_seq" not in page
        pages.append([r["seq"] for r in page["items"]])
        before = page["next_before_seq"]
        if before is None:
            return pages
        assert before == pages[-1][-1]


def test_the_newest_page_first_then_older_ones_without_gap_or_repeat(server: Server) -> None:
    everything = all_seqs(server)
    assert everything == list(range(1, TOTAL + 1))
    first = get(server, order="desc", limit=50)
    assert [r["seq"] for r in first["items"]] == list(range(TOTAL, TOTAL - 50, -1))
    assert first["next_before_seq"] == TOTAL - 49
    second = get(server, order="desc", limit=50, before_seq=TOTAL - 49)
    assert [r["seq"] for r in second["items"]] == list(range(TOTAL - 50, TOTAL - 100, -1))
    pages = pages_backwards(server, 50)
    assert [len(p) for p in pages] == [50, 50, 50, 50, 50, 50, 2]
    assert [seq for page in pages for seq in page] == everything[::-1]


def test_a_page_that_ends_exactly_at_the_oldest_record_says_there_is_no_more(
        server: Server) -> None:
    page = get(server, order="desc", limit=1, before_seq=2)
    assert [r["seq"] for r in page["items"]] == [1]
    assert page["next_before_seq"] is None
    assert get(server, order="desc", before_seq=1) == {"items": [], "next_before_seq": None}


@pytest.mark.parametrize("filters", [
    {"code": "PAGE_A"},
    {"code": ["PAGE_B", "PAGE_C"]},
    {"code": "PAGE_*", "kind": "fault_reported", "source": "/src/1"},
    {"from_seq": 40, "to_seq": 170},
    {"code": "PAGE_C", "to_seq": 200},
], ids=["one-code", "two-codes", "glob-kind-source", "seq-range", "code-and-to-seq"])
def test_filters_hold_on_every_page_and_total_counts_them(server: Server,
                                                          filters: dict[str, Any]) -> None:
    expected = all_seqs(server, **filters)
    assert expected  # the filter selects something
    pages = pages_backwards(server, 7, **filters)
    assert [seq for page in pages for seq in page] == expected[::-1]
    assert all(len(page) == 7 for page in pages[:-1])
    for before in (None, expected[len(expected) // 2]):
        cursor = {} if before is None else {"before_seq": before}
        page = get(server, order="desc", limit=5, total="true", **filters, **cursor)
        assert page["total"] == len(expected)  # the filters' count, whatever the page


def test_one_code_of_300_reports(server: Server) -> None:
    """The fault detail's question: the 100 reports of one code, newest first, with the count."""
    a_seqs = [3 + 3 * i for i in range(100)]
    page = get(server, code="PAGE_A", order="desc", limit=50, total="true")
    assert [r["seq"] for r in page["items"]] == a_seqs[::-1][:50]
    assert {r["fault_code"] for r in page["items"]} == {"PAGE_A"}
    assert page["total"] == 100
    older = get(server, code="PAGE_A", order="desc", limit=50, before_seq=page["next_before_seq"])
    assert [r["seq"] for r in older["items"]] == a_seqs[::-1][50:]
    assert older["next_before_seq"] is None


def test_ascending_paging_is_unchanged_and_may_be_bounded_by_before_seq(server: Server) -> None:
    first = get(server, limit=2)
    assert [r["seq"] for r in first["items"]] == [1, 2]
    assert first == {"items": first["items"], "next_after_seq": 2}
    rest = get(server, after_seq=2, limit=10_000)
    assert [r["seq"] for r in rest["items"]] == list(range(3, TOTAL + 1))
    assert rest["next_after_seq"] is None
    window = get(server, after_seq=10, before_seq=15, total="true")
    assert [r["seq"] for r in window["items"]] == [11, 12, 13, 14]
    assert window["total"] == TOTAL  # the filters' count, not the page's
    assert get(server, code="NO_SUCH_CODE", total="true") == {
        "items": [], "next_after_seq": None, "total": 0}


def test_exports_stay_in_seq_order_and_refuse_desc(server: Server) -> None:
    csv = server.client.get("/api/v1/history", params={"format": "csv", "code": "PAGE_B"})
    seqs = [int(line.split(",", 1)[0]) for line in csv.text.splitlines()[1:]]
    assert seqs == all_seqs(server, code="PAGE_B")
    for params in ({"format": "csv", "order": "desc"}, {"format": "jsonl", "total": "true"}):
        refused = server.client.get("/api/v1/history", params=params)
        assert refused.status_code == 400
        assert refused.json()["reason"] == "invalid"
        assert "JSON pages" in refused.json()["message"]
    for bad in ({"order": "newest"}, {"before_seq": "0"}):
        assert server.client.get("/api/v1/history", params=bad).status_code == 400
