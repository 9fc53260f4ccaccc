"""``GET /api/v1/shift-report?format=json``: the figures the dashboard shows are the report's
(one builder), e-stops come from the configured ``estop_codes``, and "previous shift" is the
previous instance of the same shift, as in `report-shift`."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

from faultledger import FaultLedger
from tests.cli_stats_scenario import CALENDAR_YAML as SHIFTS
from tests.http.conftest import start_server, write_config

AFTERNOON = "2026-11-25/afternoon"


def at(day: int, hour: int, minute: int = 0) -> datetime:
    """Berlin local time in November (UTC+1) as UTC."""
    return datetime(2026, 11, day, hour - 1, minute, tzinfo=UTC)


def seed(db: Path) -> None:
    """Afternoon of the 25th: one camera fault, two presses of the plant's own e-stop;
    the morning before (the preceding shift): five presses; the afternoon of the 24th
    (the previous afternoon): one press."""
    with FaultLedger.open(f"sqlite:///{db}", background=False) as ledger:
        presses = [at(24, 18)] + [at(25, 7, m) for m in range(0, 50, 10)] + [
            at(25, 16), at(25, 17)]
        assert ledger.report("CAMERA_DROPPED_FRAMES", "FAILED", 1, "", "/camera",
                             at=at(25, 15)).accepted
        for pressed in presses:
            for event_type, offset in (("FAILED", 0), ("PASSED", 5)):
                assert ledger.report("PLC_CELL3_ESTOP", event_type, 3, "", "/plc",
                                     at=pressed + timedelta(seconds=offset)).accepted


def test_the_json_report_headlines_configured_e_stops_against_the_previous_afternoon(
    tmp_path: Path
) -> None:
    db = tmp_path / "faults.db"
    seed(db)
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text(SHIFTS, encoding="utf-8")
    config = write_config(tmp_path / "config.yaml", extra={
        "shifts": str(shifts), "estop_codes": ["PLC_*_ESTOP"]})
    server = start_server(db, config=config)
    try:
        answer = server.client.get("/api/v1/shift-report", params={
            "shift": AFTERNOON, "format": "json", "as_of": "2026-11-26T03:00"})
        assert answer.status_code == 200, answer.text
        report = answer.json()
        assert report["shift"]["id"] == AFTERNOON
        assert report["timezone"] == "Europe/Berlin"
        assert report["previous"]["id"] == "2026-11-24/afternoon"  # not the morning
        assert report["estop_codes"] == ["PLC_*_ESTOP"]
        figures = {f["key"]: f for f in report["figures"]}
        assert [f["key"] for f in report["figures"]][:3] == ["estops", "aborted_goals",
                                                             "activations"]
        assert (figures["estops"]["value"], figures["estops"]["previous"]) == (2, 1)
        assert figures["estops"]["label"] == "e-stops"
        assert figures["estops"]["change_text"] == "+1"
        assert (figures["activations"]["value"], figures["activations"]["previous"]) == (3, 1)
        assert report["headline"] == ("2 e-stops, 0 aborted goals; 3 activations of all "
                                      "faults from 3 failed reports, 1 confirmation")
        stats = server.client.get("/api/v1/stats", params={
            "by": "shift", "since": "2026-11-25/morning", "until": AFTERNOON,
            "as_of": "2026-11-26T03:00"}).json()["items"]
        assert [(r["period"], r["estops"]) for r in stats] == [
            ("2026-11-25/morning", 5), (AFTERNOON, 2)]
        html = server.client.get("/api/v1/shift-report", params={"shift": AFTERNOON})
        assert "2 e-stops, 0 aborted goals" in html.text
        assert "Compared with the previous afternoon shift, 2026-11-24/afternoon" in html.text
        bad = server.client.get("/api/v1/shift-report", params={"format": "xml"})
        assert bad.status_code == 400
    finally:
        server.stop()
