"""Issue 17 in headless Chromium: the statistics view is the server's end-of-shift report
(``GET /api/v1/shift-report?format=json``: e-stops of the configured codes first, "previous
shift" the previous instance of the same shift, named by its id) with charts of ``estops`` and
``aborted_goals`` per shift over 7 days whose labels never overlap. Screenshots land in
test-artifacts/screenshots/ (look at them)."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import date, datetime, time, timedelta
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo

import pytest

from faultledger import FaultLedger
from tests.cli_stats_scenario import CALENDAR_YAML as SHIFTS_YAML
from tests.http.conftest import SHOTS, Server, needs_browser, start_server, write_config

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

pytestmark = needs_browser

BERLIN = ZoneInfo("Europe/Berlin")
SHIFTS = {"morning": 6, "afternoon": 14, "night": 22}
DAY = datetime.now(BERLIN).date() - timedelta(days=1)
"""The production day of the shift looked at: yesterday, so every shift of it has started."""
CHOSEN = f"{DAY}/afternoon"
DAY_NUMBERS = {f"{DAY - timedelta(days=back):%d}" for back in range(8)}
PREVIOUS = f"{DAY - timedelta(days=1)}/afternoon"


def presses(day: int, shift: int) -> int:
    """E-stops in shift ``shift`` (0 morning … 2 night) of DAY - ``day``: 1 in the chosen
    afternoon, 2 in the previous afternoon, 3 in the morning between them."""
    return {(0, 1): 1, (1, 1): 2, (0, 0): 3}.get((day, shift), (day + shift) % 4)


def aborted(day: int, shift: int) -> int:
    return {(0, 1): 2, (1, 1): 0}.get((day, shift), (2 * day + shift) % 3)


def local(day: date, hour: int, minute: int) -> datetime:
    return datetime.combine(day, time(hour), tzinfo=BERLIN) + timedelta(minutes=minute)


def seed(db: Path) -> None:
    """Seven days (DAY-6 … DAY) of three shifts and the night before: e-stops on a plant code
    and the robot's e-stop, aborted navigation goals, and one other fault."""
    with FaultLedger.open(f"sqlite:///{db}", background=False) as ledger:
        for back in range(7, -1, -1):
            day = DAY - timedelta(days=back)
            for index, (name, hour) in enumerate(SHIFTS.items()):
                for n in range(presses(back, index)):
                    code = "PLC_CELL3_ESTOP" if n % 2 else "HW_BASE_EMERGENCY_STOP"
                    pressed = local(day, hour, 30 + 20 * n)
                    for event_type, offset in (("FAILED", 0), ("PASSED", 40)):
                        assert ledger.report(code, event_type, 3, "e-stop", "/plc",
                                             at=pressed + timedelta(seconds=offset)).accepted
                for n in range(aborted(back, index)):
                    assert ledger.record_goal_outcome(
                        "/navigate_to_pose", f"{day}-{name}-{n}", "ABORTED", "/bt_navigator",
                        at=local(day, hour, 45 + n)).accepted
        assert ledger.report("CAMERA_DROPPED_FRAMES", "FAILED", 1, "", "/camera",
                             at=local(DAY, 15, 10)).accepted


@pytest.fixture
def server(tmp_path: Path) -> Iterator[Server]:
    db = tmp_path / "faults.db"
    seed(db)
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text(SHIFTS_YAML, encoding="utf-8")
    running = start_server(db, config=write_config(tmp_path / "config.yaml", extra={
        "shifts": str(shifts), "estop_codes": ["HW_*_EMERGENCY_STOP", "PLC_*_ESTOP"]}))
    yield running
    running.stop()


def wait(browser: WebDriver, condition: object, timeout: float = 10) -> None:
    WebDriverWait(browser, timeout, poll_frequency=0.05).until(condition)  # type: ignore[arg-type]


CHART_BOXES = """
const root = `#${arguments[0]}`;
const all = (sel) => [...document.querySelectorAll(`${root} ${sel}`)];
const box = (t) => { const b = t.getBBox();
  return {text: t.textContent, x0: b.x, x1: b.x + b.width, y0: b.y, y1: b.y + b.height}; };
return {bars: all("rect.bar").length, titles: all("rect title").map(t => t.textContent),
        chosen: all("rect.chosen title").map(t => t.textContent),
        width: document.querySelector(`${root} svg`).getBoundingClientRect().width,
        texts: all("text").map(box)};
"""


def chart(browser: WebDriver, element_id: str) -> dict[str, Any]:
    found: dict[str, Any] = browser.execute_script(CHART_BOXES, element_id)
    return found


def shown(browser: WebDriver) -> str | None:
    """The shift the statistics view has finished drawing (None while it loads)."""
    found = browser.find_element(By.ID, "view-stats").get_attribute("data-shown")
    return None if found is None else str(found)


def overlapping(texts: list[dict[str, Any]]) -> list[tuple[str, str]]:
    """Pairs of chart labels whose boxes intersect."""
    return [(a["text"], b["text"]) for i, a in enumerate(texts) for b in texts[i + 1:]
            if a["x0"] < b["x1"] and b["x0"] < a["x1"] and a["y0"] < b["y1"] and b["y0"] < a["y1"]]


def test_the_statistics_view_is_the_shift_report_with_seven_days_of_charts(
        browser: WebDriver, server: Server) -> None:
    report = server.client.get("/api/v1/shift-report",
                               params={"shift": CHOSEN, "format": "json"}).json()
    assert report["previous"]["id"] == PREVIOUS
    try:
        browser.get(server.url)
        wait(browser, lambda b: b.find_element(By.ID, "connection").text == "live")
        browser.find_element(By.CSS_SELECTOR, "button[data-view='stats']").click()
        wait(browser, lambda b: shown(b) is not None)  # the last completed shift
        assert not browser.find_elements(By.ID, "stats-estop")  # no glob typed in the page
        browser.find_element(By.ID, "stats-shift").send_keys(CHOSEN)
        browser.find_element(By.CSS_SELECTOR, "#stats-form button[type='submit']").click()
        wait(browser, lambda b: shown(b) == CHOSEN)
        assert CHOSEN in browser.find_element(By.ID, "stats-title").text
        assert chart(browser, "chart-aborted")["bars"] == 21

        figures = browser.find_elements(By.CSS_SELECTOR, "#figures .figure")
        assert [f.get_attribute("data-key") for f in figures] == [
            f["key"] for f in report["figures"]]
        estops, goals = figures[0].text.split("\n"), figures[1].text.split("\n")
        assert estops == ["1", "e-stop", f"vs {PREVIOUS}: 2", "▼ -1 (-50.0 %)"]
        assert goals == ["2", "aborted goals", f"vs {PREVIOUS}: 0", "▲ +2 (new)"]
        tones = [f.find_element(By.CLASS_NAME, "change").get_attribute("class") or ""
                 for f in figures[:2]]
        assert "better" in tones[0] and "worse" in tones[1]  # fewer e-stops, more aborts
        hint = browser.find_element(By.ID, "estop-hint").text
        assert "HW_*_EMERGENCY_STOP, PLC_*_ESTOP" in hint
        span = browser.find_element(By.ID, "stats-span").text
        assert span == report["shift"]["span_text"] and span.endswith("Europe/Berlin")
        assert browser.find_element(By.ID, "stats-headline").text == report["headline"]
        offenders = [row.text for row in browser.find_elements(
            By.CSS_SELECTOR, "#offenders tbody tr")]
        # code, e-stops, activations, confirmations, failed reports, CONFIRMED time
        assert [row.split()[:5] for row in offenders] == [
            ["CAMERA_DROPPED_FRAMES", "0", "1", "1", "1"],
            ["HW_BASE_EMERGENCY_STOP", "1", "1", "0", "1"]]  # CONFIRMED since before

        # 7 days × 3 shifts up to the chosen one, from the stats rows' estops.
        expected = [presses(back, index) for back in range(7, -1, -1) for index in range(3)]
        expected = expected[2:-1]  # from the night of DAY-7 to the afternoon of DAY
        for width in (1366, 820, 560):
            browser.set_window_size(width, 1000)
            wait(browser, lambda b, w=width: abs(chart(b, "chart-estops")["width"]
                                                 - b.find_element(By.ID, "chart-estops").size[
                                                     "width"]) < 2)
            for element_id, chosen in (("chart-estops", f"{CHOSEN}: 1 e-stop"),
                                       ("chart-aborted", f"{CHOSEN}: 2 aborted goals")):
                drawn = chart(browser, element_id)
                assert drawn["bars"] == 21
                assert drawn["chosen"] == [chosen]
                assert overlapping(drawn["texts"]) == [], (width, element_id)
                # One label per production day where it fits (the longest form that does).
                days = [t["text"] for t in drawn["texts"] if t["y0"] > 150]
                assert len(days) >= 6, (width, days)
                assert all(label.split()[-1].split("-")[-1] in DAY_NUMBERS for label in days)
            titles = chart(browser, "chart-estops")["titles"]
            assert [int(t.split(": ")[1].split()[0]) for t in titles] == expected
            assert f"{PREVIOUS}: 2 e-stops" in titles
            browser.find_element(By.ID, "chart-estops").location_once_scrolled_into_view  # noqa: B018
            browser.save_screenshot(str(SHOTS / f"issue17-statistics-{width}.png"))
        browser.set_window_size(1366, 900)
        browser.execute_script("window.scrollTo(0, 0)")
        browser.save_screenshot(str(SHOTS / "issue17-statistics.png"))
    finally:
        browser.set_window_size(1366, 900)
