"""`faultledger report-shift`: the end-of-shift summary against the previous instance of the
same shift, its top offenders, longest downtimes and hours; the HTML file and the PNG charts.

Expected figures come from ``FaultLedger.stats`` on the same scripted scenario (and the
script itself), never from constants typed here. No browser test: the project has no browser
test infrastructure (no Chromium/Playwright), so the HTML is checked as text.
"""

from __future__ import annotations

import base64
import re
import struct
from datetime import timedelta
from pathlib import Path

import pytest

from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import StatsRow
from faultledger.errors import InvalidInputError
from faultledger.reports.shift import duration, last_completed
from tests.cli_stats_scenario import (
    ARM1,
    AS_OF,
    AS_OF_TEXT,
    GLOB,
    LIDAR,
    MOTOR,
    NIGHT,
    PREVIOUS_NIGHT,
    Scenario,
    assert_clean_error,
    berlin,
    build,
    invoke,
    presses,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
NIGHT_START, NIGHT_END = berlin(21, 22, 0), berlin(22, 6, 0)


@pytest.fixture
def scenario(tmp_path: Path) -> Scenario:
    return build(tmp_path)


def shift_row(scenario: Scenario, shift_id: str) -> StatsRow:
    with scenario.ledger() as ledger:
        [row] = ledger.stats("shift", shift_id, shift_id, calendar=scenario.calendar,
                             as_of=AS_OF)
    return row


def table(output: str, title: str) -> list[list[str]]:
    """Data rows of the rich table printed under ``title``."""
    lines = output.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(title))
    rows: list[list[str]] = []
    for line in lines[start + 1:]:
        if line.startswith("└"):
            return rows
        if line.startswith("│"):
            rows.append([cell.strip() for cell in line.split("│")[1:-1]])
    raise AssertionError(f"table {title!r} not closed")


def report(scenario: Scenario, *args: str) -> str:
    result = invoke("report-shift", *scenario.cli(*args))
    assert result.exit_code == 0, result.stderr
    return result.stdout


def test_the_header_names_the_shift_its_local_times_and_the_comparison(
    scenario: Scenario
) -> None:
    out = report(scenario, NIGHT, "--as-of", AS_OF_TEXT)
    assert out.splitlines()[:3] == [
        f"Shift report {NIGHT}",
        "Sat 2026-11-21 22:00 – Sun 2026-11-22 06:00 Europe/Berlin, 8h",
        f"compared with {PREVIOUS_NIGHT}",
    ]
    assert "in progress" not in out


def test_key_counts_are_compared_with_the_previous_night(scenario: Scenario) -> None:
    out = report(scenario, NIGHT, "--as-of", AS_OF_TEXT)
    this, before = shift_row(scenario, NIGHT), shift_row(scenario, PREVIOUS_NIGHT)
    # The scenario: every press is one activation; the nights differ.
    assert this.activations == presses(NIGHT_START, NIGHT_END)
    assert before.activations == presses(NIGHT_START - timedelta(days=1),
                                         NIGHT_END - timedelta(days=1))
    assert this.activations != before.activations
    figures = {row[0]: row[1:] for row in table(out, "key figures")}
    assert this.estops == presses(NIGHT_START, NIGHT_END, GLOB) > 0
    assert this.estops < this.activations  # the lidar and the motor are no e-stops
    for label, name in (("failed reports", "failed_reports"), ("e-stops", "estops"),
                        ("activations (all faults)", "activations"),
                        ("confirmations", "confirmations"), ("heals", "heals")):
        now, then = getattr(this, name), getattr(before, name)
        assert figures[label] == [str(now), str(then), f"{now - then:+d}",
                                  f"{(now - then) / then * 100:+.1f} %"], label
    assert figures["clears"] == ["0", "0", "±0", "-"]
    assert figures["fault time CONFIRMED (sum)"][:2] == [duration(this.active_seconds),
                                          duration(before.active_seconds)]
    assert figures["MTTR"][:2] == [duration(this.mttr_seconds), duration(before.mttr_seconds)]
    assert this.mttr_seconds is not None and before.mttr_seconds is not None
    mttr_change = (this.mttr_seconds - before.mttr_seconds) / before.mttr_seconds * 100
    assert figures["MTTR"][3] == f"{mttr_change:+.1f} %"
    assert figures["MTBF"][:2] == [duration(this.mtbf_seconds), duration(before.mtbf_seconds)]
    assert list(figures) == ["e-stops", "aborted goals", "activations (all faults)",
                             "failed reports", "confirmations", "heals", "clears",
                             "fault time CONFIRMED (sum)", "MTTR", "MTBF", "time in flood",
                             "chattering codes", "stale codes", "acknowledgements", "MTTA",
                             "time shelved (sum)"]


def test_top_offenders_are_ranked_by_activations(scenario: Scenario) -> None:
    out = report(scenario, NIGHT, "--as-of", AS_OF_TEXT)
    with scenario.ledger() as ledger:
        by_code = ledger.stats("shift", NIGHT, NIGHT, group_by=["code"],
                               calendar=scenario.calendar, as_of=AS_OF)
    ranked = sorted(by_code, key=lambda r: (-r.activations, -r.confirmations,
                                            str(r.group["code"])))
    offenders = table(out, "top 10 offenders")
    assert [row[1] for row in offenders] == [str(r.group["code"]) for r in ranked]
    assert offenders[0][:4] == ["1", ARM1, str(presses(NIGHT_START, NIGHT_END, ARM1)),
                                str(ranked[0].confirmations)]


def test_longest_downtimes_put_the_most_time_inside_the_shift_first(
    scenario: Scenario
) -> None:
    out = report(scenario, NIGHT, "--as-of", AS_OF_TEXT)
    downtimes = table(out, "longest downtimes")
    assert downtimes[0][:5] == [LIDAR, "/sensors/lidar", "ERROR", "2026-11-21 23:00:00",
                                "2026-11-22 01:00:00"]
    # The motor is still CONFIRMED: 30 minutes of it fall into the night.
    assert downtimes[1][0] == MOTOR
    assert downtimes[1][4:] == ["still CONFIRMED", duration(1800),
                                duration((AS_OF - berlin(22, 5, 30)).total_seconds())]
    assert [row[0] for row in downtimes].count(ARM1) == presses(NIGHT_START, NIGHT_END, ARM1)


def test_downtimes_service_crops_to_the_range_and_ends_open_episodes_at_as_of(
    scenario: Scenario
) -> None:
    with scenario.ledger() as ledger:
        found = ledger.downtimes(NIGHT_START, NIGHT_END, as_of=AS_OF)
        top2 = ledger.downtimes(NIGHT_START, NIGHT_END, 2, as_of=AS_OF)
        with pytest.raises(InvalidInputError, match="before"):
            ledger.downtimes(NIGHT_END, NIGHT_START)
    assert top2 == found[:2]
    lidar, motor = found[0], found[1]
    assert (lidar.fault_code, lidar.seconds, lidar.seconds_in_range) == (LIDAR, 7200, 7200)
    assert (lidar.start, lidar.end) == (berlin(21, 23, 0), berlin(22, 1, 0))
    assert (motor.fault_code, motor.end, motor.seconds_in_range) == (MOTOR, None, 1800)
    assert motor.seconds == (AS_OF - berlin(22, 5, 30)).total_seconds()
    assert all(NIGHT_START - timedelta(hours=1) < d.start < NIGHT_END for d in found)
    assert [d.seconds_in_range for d in found] == sorted(
        (d.seconds_in_range for d in found), reverse=True)


def test_the_hours_chart_has_one_row_per_local_hour(scenario: Scenario) -> None:
    out = report(scenario, NIGHT, "--as-of", AS_OF_TEXT)
    hours = table(out, "per hour")
    assert [row[0] for row in hours] == ["22:00", "23:00", "00:00", "01:00", "02:00",
                                         "03:00", "04:00", "05:00"]
    with scenario.ledger() as ledger:
        rows = ledger.stats("hour", NIGHT, NIGHT, calendar=scenario.calendar, as_of=AS_OF)
    # hour, e-stops, bar, aborted goals, bar, activations, bar, confirmations (as the HTML)
    assert [(row[1], row[3], row[5], row[7]) for row in hours] == [
        (str(r.estops), str(r.aborted_goals), str(r.activations), str(r.confirmations))
        for r in rows]


def test_default_shift_is_the_last_completed_one(scenario: Scenario) -> None:
    out = report(scenario, "--as-of", "2026-11-22T07:30")  # the morning is running
    assert out.splitlines()[0] == f"Shift report {NIGHT}"


def test_a_running_shift_is_marked_in_progress(scenario: Scenario) -> None:
    out = report(scenario, "2026-11-22/morning", "--as-of", "2026-11-22T07:30")
    assert "in progress: figures up to 2026-11-22 07:30:00" in out


def test_last_completed_skips_unscheduled_time() -> None:
    weekdays = ShiftCalendar.model_validate({
        "timezone": "Europe/Berlin",
        "shifts": [{"name": "day", "start": "08:00", "end": "16:00",
                    "weekdays": ["mon", "tue", "wed", "thu", "fri"]}]})
    sunday_noon = berlin(22, 12, 0)
    assert last_completed(weekdays, sunday_noon).id == "2026-11-20/day"
    assert last_completed(weekdays, berlin(23, 9, 0)).id == "2026-11-20/day"  # Monday's runs
    assert last_completed(weekdays, berlin(23, 16, 0)).id == "2026-11-23/day"


def test_a_dst_night_shows_its_real_and_nominal_length(scenario: Scenario) -> None:
    out = report(scenario, "2026-10-24/night", "--as-of", AS_OF_TEXT)
    assert out.splitlines()[1] == ("Sat 2026-10-24 22:00 – Sun 2026-10-25 06:00 Europe/Berlin, "
                                   "9h (nominal 8h: daylight saving time change)")
    hours = [row[0] for row in table(out, "per hour")]
    assert len(hours) == 9
    assert hours[4:6] == ["02:00 CEST", "02:00 CET"]


def test_a_shift_without_previous_instance_says_so(scenario: Scenario, tmp_path: Path) -> None:
    shifts = tmp_path / "new.yaml"
    shifts.write_text(
        "timezone: Europe/Berlin\nshifts:\n  - {name: day, start: '08:00', end: '16:00'}\n"
        "versions:\n  - effective: 2026-11-21\n    shifts:\n"
        "      - {name: night, start: '22:00', end: '06:00'}\n", encoding="utf-8")
    result = invoke("report-shift", NIGHT, "--db", scenario.url, "--shifts", str(shifts),
                    "--as-of", AS_OF_TEXT)
    assert result.exit_code == 0, result.stderr
    assert "compared with no previous night shift" in result.stdout
    figures = {row[0]: row[1:] for row in table(result.stdout, "key figures")}
    assert figures["activations (all faults)"] == [
        str(shift_row(scenario, NIGHT).activations), "-", "-", "-"]


def test_html_is_one_self_contained_file(scenario: Scenario, tmp_path: Path) -> None:
    target = tmp_path / "night.html"
    out = report(scenario, NIGHT, "--as-of", AS_OF_TEXT, "--html", str(target))
    assert f"wrote {target}" in out
    page = target.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>")
    assert f"<h1>Shift report {NIGHT}</h1>" in page
    assert "<style>" in page
    assert not re.search(r"""(src|href)=["']?(https?:|//|file:)""", page)
    images = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(images) == 2
    for data in images:
        assert base64.b64decode(data).startswith(PNG_SIGNATURE)
    first_offender = page.index("<h2>Top 10 offenders</h2>")
    assert ARM1 in page[first_offender:page.index("<h2>Longest downtimes</h2>")]
    assert LIDAR in page[page.index("<h2>Longest downtimes</h2>"):]
    this, before = shift_row(scenario, NIGHT), shift_row(scenario, PREVIOUS_NIGHT)
    change = this.activations - before.activations
    assert (f"<td>{this.activations}</td><td>{before.activations}</td>"
            f'<td class="worse">{change:+d}</td>') in page


def test_png_holds_the_charts(scenario: Scenario, tmp_path: Path) -> None:
    target = tmp_path / "night.png"
    out = report(scenario, NIGHT, "--as-of", AS_OF_TEXT, "--png", str(target))
    assert f"wrote {target}" in out
    data = target.read_bytes()
    assert data.startswith(PNG_SIGNATURE)
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert width >= 800 and height >= 500
    assert len(data) > 20_000  # drawn bars, labels and text, not an empty canvas


def test_html_and_png_together(scenario: Scenario, tmp_path: Path) -> None:
    html, png = tmp_path / "r.html", tmp_path / "r.png"
    report(scenario, NIGHT, "--as-of", AS_OF_TEXT, "--html", str(html), "--png", str(png))
    assert html.stat().st_size > 20_000 and png.read_bytes().startswith(PNG_SIGNATURE)


@pytest.mark.parametrize(("shift_id", "words"), [
    ("2026-11-21", ["shift id must look like 2026-11-21/night"]),
    ("2026-11-21/lunch", ["no shift 'lunch' starts on 2026-11-21"]),
    ("2099-01-01/night", ["has not started yet"]),
])
def test_bad_shift_ids_are_one_clear_line(
    scenario: Scenario, shift_id: str, words: list[str]
) -> None:
    result = invoke("report-shift", shift_id, *scenario.cli("--as-of", AS_OF_TEXT))
    assert_clean_error(result, *words)
    assert result.exit_code == 2


def test_an_unwritable_html_path_is_a_clear_error(scenario: Scenario, tmp_path: Path) -> None:
    target = tmp_path / "no" / "such" / "dir" / "r.html"
    result = invoke("report-shift", NIGHT,
                    *scenario.cli("--as-of", AS_OF_TEXT, "--html", str(target)))
    assert result.exit_code == 2
    assert "Traceback" not in result.stderr
    assert f"cannot write {target}" in result.stderr


def test_the_headline_calls_only_e_stop_codes_e_stops_with_plurals_right(
    tmp_path: Path
) -> None:
    """The user's afternoon: one camera fault and nothing else is 0 e-stops and 1 activation,
    never "1 activations (e-stop presses…)"."""
    from datetime import UTC, datetime

    from faultledger import FaultLedger
    from faultledger.reports.shift import build_report

    calendar = ShiftCalendar.model_validate({"timezone": "UTC", "shifts": [
        {"name": "morning", "start": "06:00", "end": "14:00"},
        {"name": "afternoon", "start": "14:00", "end": "22:00"},
        {"name": "night", "start": "22:00", "end": "06:00"}]})
    with FaultLedger.open(f"sqlite:///{tmp_path / 'a.db'}", background=False,
                          calendar=calendar) as ledger:
        assert ledger.report("CAMERA_DROPPED_FRAMES", "FAILED", 1, "", "/camera",
                             at=datetime(2026, 11, 25, 15, 0, tzinfo=UTC)).accepted
        report = build_report(ledger, calendar, "2026-11-25/afternoon",
                              datetime(2026, 11, 26, 3, 0, tzinfo=UTC))
        assert report.headline == ("0 e-stops, 0 aborted goals; 1 activation of all faults "
                                   "from 1 failed report, 1 confirmation")
        assert report.previous is not None and report.previous.id == "2026-11-24/afternoon"
        for at in (datetime(2026, 11, 25, 16, 0, tzinfo=UTC),
                   datetime(2026, 11, 25, 17, 0, tzinfo=UTC)):
            assert ledger.report("HW_ARM_EMERGENCY_STOP", "FAILED", 3, "", "/arm",
                                 at=at).accepted
            assert ledger.report("HW_ARM_EMERGENCY_STOP", "PASSED", 0, "", "/arm",
                                 at=at + timedelta(seconds=5)).accepted
        report = build_report(ledger, calendar, "2026-11-25/afternoon",
                              datetime(2026, 11, 26, 3, 0, tzinfo=UTC))
        assert report.headline.startswith("2 e-stops, 0 aborted goals; 3 activations")
