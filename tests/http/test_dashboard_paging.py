"""Issue 17 in headless Chromium: the fault detail and the History tab show the newest records
first and page backwards ("Older records") with a count of how many are shown; severities are
coloured; every time is in the shift calendar's zone (not the browser's), named on the page.
Screenshots land in test-artifacts/screenshots/ (look at them)."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from faultledger import FaultLedger
from tests.cli_stats_scenario import CALENDAR_YAML as SHIFTS
from tests.http.conftest import SHOTS, Server, needs_browser, start_server, write_config

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

pytestmark = needs_browser

CODE = "LIDAR_FRONT_TIMEOUT"
T0 = datetime(2026, 11, 20, 12, 0, tzinfo=UTC)  # 13:00 in Berlin (CET), 07:00 in New York
REPORTS = 300
OTHERS = {"BATTERY_LOW": 1, "CAMERA_DROPPED_FRAMES": 0, "DRIVE_OVERCURRENT": 2,
          "HW_BASE_EMERGENCY_STOP": 3}


def wait(browser: WebDriver, condition: object, timeout: float = 10) -> None:
    WebDriverWait(browser, timeout, poll_frequency=0.05).until(condition)  # type: ignore[arg-type]


def seed(db: Path) -> None:
    """300 FAILED reports of one code, one every 5 minutes (the last one almost a day after
    the first), and one fault of every other severity."""
    with FaultLedger.open(f"sqlite:///{db}", background=False) as ledger:
        for i in range(REPORTS):
            assert ledger.report(CODE, "FAILED", i % 4, "front lidar timed out", "/lidar/front",
                                 at=T0 + timedelta(minutes=5 * i)).accepted
        for n, (code, severity) in enumerate(OTHERS.items()):
            assert ledger.report(code, "FAILED", severity, f"a {code.lower()} fault", "/robot",
                                 at=T0 + timedelta(hours=1, minutes=n)).accepted


@pytest.fixture
def server(tmp_path: Path) -> Iterator[Server]:
    db = tmp_path / "faults.db"
    seed(db)
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text(SHIFTS, encoding="utf-8")
    running = start_server(db, config=write_config(tmp_path / "config.yaml",
                                                   extra={"shifts": str(shifts)}))
    yield running
    running.stop()


@pytest.fixture
def new_york(browser: WebDriver) -> Iterator[WebDriver]:
    """The browser believes it is in New York: the page must not show that zone."""
    browser.execute_cdp_cmd("Emulation.setTimezoneOverride", {"timezoneId": "America/New_York"})
    try:
        yield browser
    finally:
        browser.execute_cdp_cmd("Emulation.setTimezoneOverride", {"timezoneId": ""})
        browser.set_window_size(1366, 900)


def seqs(browser: WebDriver, table: str) -> list[int]:
    found = browser.execute_script(
        "return [...document.querySelectorAll(`#${arguments[0]} tbody tr`)]"
        ".map(tr => Number(tr.dataset.seq))", table)
    return [int(seq) for seq in found]


def text(browser: WebDriver, element_id: str) -> str:
    return str(browser.find_element(By.ID, element_id).text)


def api(server: Server, **params: Any) -> dict[str, Any]:
    answer: dict[str, Any] = server.client.get("/api/v1/history", params=params).json()
    return answer


def test_the_detail_shows_the_newest_records_first_and_pages_backwards(
        new_york: WebDriver, server: Server) -> None:
    browser = new_york
    mine = [r["seq"] for r in api(server, code=CODE, limit=10_000)["items"]][::-1]
    assert len(mine) == REPORTS  # newest first
    browser.get(server.url)
    wait(browser, lambda b: b.find_element(By.ID, "connection").text == "live")
    assert browser.execute_script(
        "return Intl.DateTimeFormat().resolvedOptions().timeZone") == "America/New_York"

    # Severity colours: one colour per level, the label kept as text.
    badges = browser.execute_script(
        "return Object.fromEntries([...document.querySelectorAll('#fault-table .severity')]"
        ".map(b => [b.textContent, getComputedStyle(b).backgroundColor]))")
    assert set(badges) == {"INFO", "WARN", "ERROR", "CRITICAL"}
    assert len(set(badges.values())) == 4
    # Times in the calendar's zone: the last report at 2026-11-21 12:55 UTC is 13:55 in Berlin.
    lidar = browser.find_element(By.CSS_SELECTOR, f"tr[data-code='{CODE}']")
    assert "2026-11-21 13:55:00" in lidar.text
    assert "Europe/Berlin" in text(browser, "fault-table")  # the column names the zone
    assert "all times in Europe/Berlin" in browser.find_element(By.TAG_NAME, "footer").text
    browser.save_screenshot(str(SHOTS / "issue17-faults-severity.png"))

    lidar.click()
    wait(browser, lambda b: len(seqs(b, "detail-history")) == 50)
    assert seqs(browser, "detail-history") == mine[:50]  # the first row is the newest seq
    assert text(browser, "detail-count") == "50 newest of 300 records"
    fields = text(browser, "detail-fields")
    assert "first occurred ever\n2026-11-20 13:00:00 CET" in fields
    assert "episode\n1, since 2026-11-20 13:00:00 CET" in fields
    assert "last occurred\n2026-11-21 13:55:00 CET" in fields
    first_row = browser.find_element(By.CSS_SELECTOR, "#detail-history tbody tr").text
    assert first_row.startswith(f"{mine[0]} 2026-11-21 13:55:00 FAILED")
    browser.save_screenshot(str(SHOTS / "issue17-detail-newest.png"))

    browser.find_element(By.ID, "detail-older").click()
    wait(browser, lambda b: len(seqs(b, "detail-history")) == 100)
    assert seqs(browser, "detail-history") == mine[:100]  # no gap, no repeat
    assert text(browser, "detail-count") == "100 newest of 300 records"
    browser.execute_script("document.querySelector('#detail-history tbody tr:nth-child(45)')"
                           ".scrollIntoView()")
    browser.save_screenshot(str(SHOTS / "issue17-detail-older.png"))

    # A new report of the selected fault goes on top at once; the pages below stay.
    answer = server.client.post("/api/v1/reports", json={
        "fault_code": CODE, "event_type": "FAILED", "severity": 2, "source_id": "/lidar/front"})
    newest = answer.json()["seq"]
    wait(browser, lambda b: seqs(b, "detail-history")[:1] == [newest], timeout=5)
    assert seqs(browser, "detail-history") == [newest, *mine[:100]]
    wait(browser, lambda b: text(b, "detail-count") == "101 newest of 301 records")

    for _ in range(4):
        shown = len(seqs(browser, "detail-history"))
        browser.find_element(By.ID, "detail-older").click()
        wait(browser, lambda b, shown=shown: len(seqs(b, "detail-history")) > shown)
    assert seqs(browser, "detail-history") == [newest, *mine]
    assert text(browser, "detail-count") == "all 301 records"
    assert not browser.find_element(By.ID, "detail-older").is_displayed()


def test_the_history_tab_opens_at_the_newest_record(new_york: WebDriver,
                                                    server: Server) -> None:
    browser = new_york
    everything = [r["seq"] for r in api(server, limit=10_000)["items"]][::-1]
    browser.get(server.url)
    wait(browser, lambda b: b.find_element(By.ID, "connection").text == "live")
    browser.find_element(By.CSS_SELECTOR, "button[data-view='history']").click()
    wait(browser, lambda b: len(seqs(b, "history-table")) == 100)
    assert seqs(browser, "history-table") == everything[:100]
    assert text(browser, "history-count") == f"100 newest of {len(everything)} records"
    newest = browser.find_element(By.CSS_SELECTOR, "#history-table tbody tr").text
    assert "2026-11-20 14:03:00" in newest  # the last other fault: T0 + 1 h 3 min, in Berlin
    browser.save_screenshot(str(SHOTS / "issue17-history.png"))
    browser.find_element(By.ID, "history-older").click()
    wait(browser, lambda b: len(seqs(b, "history-table")) == 200)
    assert seqs(browser, "history-table") == everything[:200]
    assert text(browser, "history-count") == f"200 newest of {len(everything)} records"
    browser.save_screenshot(str(SHOTS / "issue17-history-older.png"))

    # A search pages the same way, and says how many match.
    browser.find_element(By.ID, "history-code").send_keys("DRIVE_*")
    browser.find_element(By.CSS_SELECTOR, "#history-form button[type='submit']").click()
    wait(browser, lambda b: text(b, "history-count") == "1 record")
    assert not browser.find_element(By.ID, "history-older").is_displayed()
    row = browser.find_element(By.CSS_SELECTOR, "#history-table tbody tr").text
    assert "DRIVE_OVERCURRENT" in row and "ERROR" in row
