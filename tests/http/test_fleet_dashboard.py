"""A fleet central's dashboard in headless Chromium (docs/http.md, "Dashboard", Fleet): the
Fleet view of two robots, one of them still syncing (its figures marked provisional, its lag
in hours), and the robot filter of the Faults view. Screenshots land in
test-artifacts/screenshots/fleet*.png (look at them)."""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime
from typing import Any
from zoneinfo import ZoneInfo

import pytest

from tests.http.conftest import SHOTS, needs_browser
from tests.http.fleet_scenario import ESTOP, OWN_FAULT, Fleet, start_fleet
from tests.http.test_browser_guard import CSP_WATCH

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402
from selenium.webdriver.support.ui import Select, WebDriverWait  # noqa: E402

pytestmark = needs_browser

BERLIN = ZoneInfo("Europe/Berlin")
LAPTOP = (1366, 900)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Fleet]:
    started = start_fleet(tmp_path_factory.mktemp("fleet-dashboard"))
    yield started
    started.server.stop()


def wait(browser: WebDriver, condition: object, timeout: float = 10) -> None:
    WebDriverWait(browser, timeout, poll_frequency=0.05).until(condition)  # type: ignore[arg-type]


FLEET_ROWS = """
return [...document.querySelectorAll('#fleet-table tbody tr')].map((tr) => ({
  robot: tr.dataset.robot,
  cells: [...tr.cells].map((td) => td.textContent),
  provisional: [...tr.cells].map((td) => td.classList.contains('provisional')),
  sync: tr.cells[8].className,
}));
"""


def fleet_rows(browser: WebDriver) -> dict[str, dict[str, Any]]:
    rows: list[dict[str, Any]] = browser.execute_script(FLEET_ROWS)
    return {row["robot"]: row for row in rows}


def open_central(browser: WebDriver, fleet: Fleet) -> None:
    browser.set_window_size(*LAPTOP)
    browser.get(fleet.server.url)
    wait(browser, lambda b: b.find_element(By.ID, "fleet-tab").is_displayed())


def berlin(iso: str) -> str:
    return f"{datetime.fromisoformat(iso).astimezone(BERLIN):%Y-%m-%d %H:%M:%S}"


def test_the_fleet_view_marks_the_figures_of_a_robot_still_syncing(browser: WebDriver,
                                                                  fleet: Fleet) -> None:
    watch = browser.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument",
                                    {"source": CSP_WATCH})
    try:
        open_central(browser, fleet)
        browser.find_element(By.CSS_SELECTOR, "button[data-view='fleet']").click()
        wait(browser, lambda b: b.find_element(By.ID, "view-fleet").get_attribute("data-shown"))
        assert browser.execute_script("return window.__violations") == []  # under the CSP
    finally:
        browser.execute_cdp_cmd("Page.removeScriptToEvaluateOnNewDocument",
                                {"identifier": watch["identifier"]})
    rows = fleet_rows(browser)
    assert list(rows) == ["robot-a", "robot-b"]
    # Robot, (line, site hidden: no labels), confirmed now, e-stops now/previous, aborted
    # goals now/previous, sync, last contact.
    a, b = rows["robot-a"], rows["robot-b"]
    assert a["cells"][3:8] == ["2", "2", "3", "1", "2"] and not any(a["provisional"])
    assert re.fullmatch(r"\d{1,2} s", a["cells"][8]) and "ok" in a["sync"]
    assert b["cells"][3:8] == ["1", "0*", "1*", "0*", "0*"]
    assert b["provisional"][4:8] == [True] * 4
    assert re.fullmatch(r"\d+ h \d+ min behind", b["cells"][8]) and "behind" in b["sync"]
    chains = {c["robot_id"]: c for c in
              fleet.server.client.get("/api/v1/fleet/robots").json()["items"]}
    for name, row in rows.items():  # in the calendar's zone, as every time on the page
        assert row["cells"][9] == berlin(chains[name]["last_pushed_at"])
    assert browser.find_element(By.ID, "fleet-legend").is_displayed()
    assert "still syncing: figures may grow" in browser.find_element(By.ID, "fleet-legend").text
    heads = [th.text for th in browser.find_elements(
        By.CSS_SELECTOR, "#fleet-table th.shift-current, #fleet-table th.shift-previous")]
    previous_label = f"{fleet.previous.name} {fleet.previous.production_day:%m-%d}"
    assert heads == [f"{fleet.current.name}, now", previous_label] * 2
    span = browser.find_element(By.ID, "fleet-span").text
    assert fleet.current.id in span and fleet.previous.id in span
    # No line or site labels (the config's fleet.robots): their columns are left out.
    assert not any(th.is_displayed()
                   for th in browser.find_elements(By.CSS_SELECTOR, "#fleet-table th.labels"))
    browser.save_screenshot(str(SHOTS / "fleet.png"))

    browser.set_window_size(800, 900)  # a tablet: the table scrolls, nothing overlaps
    wait(browser, lambda b: b.execute_script("return window.innerWidth") <= 800)
    browser.save_screenshot(str(SHOTS / "fleet-narrow.png"))
    browser.set_window_size(*LAPTOP)

    # A robot's row leads to its faults.
    browser.find_element(By.CSS_SELECTOR, "#fleet-table tr[data-robot='robot-b']").click()
    wait(browser, lambda b: b.find_element(By.ID, "view-faults").get_attribute("data-robot")
         == "robot-b")
    assert browser.find_element(By.ID, "robot-filter").get_attribute("value") == "robot-b"


FAULT_CODES = ("return [...document.querySelectorAll('#fault-table tbody tr')]"
               ".map(tr => tr.dataset.code)")


def test_the_robot_filter_shows_a_robots_faults_as_the_central_holds_them(
        browser: WebDriver, fleet: Fleet) -> None:
    open_central(browser, fleet)
    wait(browser, lambda b: b.execute_script(FAULT_CODES) == [OWN_FAULT])
    choose = Select(browser.find_element(By.ID, "robot-filter"))
    assert [o.get_attribute("value") for o in choose.options] == ["", "robot-a", "robot-b"]
    choose.select_by_value("robot-a")
    wait(browser, lambda b: b.find_element(By.ID, "view-faults").get_attribute("data-robot")
         == "robot-a")
    assert sorted(browser.execute_script(FAULT_CODES)) == ["LIDAR_TIMEOUT", "NAV_STUCK"]
    Select(browser.find_element(By.ID, "status-filter")).select_by_value("all")
    wait(browser, lambda b: ESTOP in b.execute_script(FAULT_CODES))
    note = browser.find_element(By.ID, "robot-note").text
    assert note.startswith("robot-a's faults as this central holds its log: in sync")
    assert "3 faults of robot-a" in browser.find_element(By.ID, "fault-count").text

    browser.find_element(By.CSS_SELECTOR, "#fault-table tr[data-code='NAV_STUCK']").click()
    wait(browser, lambda b: b.find_element(By.ID, "detail").is_displayed())
    fields = browser.find_element(By.ID, "detail-fields").text
    assert "robot-a" in fields and fleet.ledger_ids["robot-a"] in fields
    assert not browser.find_element(By.ID, "clear-form").is_displayed()
    assert not browser.find_element(By.ID, "detail-history-part").is_displayed()
    assert "clear it on the robot" in browser.find_element(By.ID, "detail-robot-note").text
    browser.save_screenshot(str(SHOTS / "fleet-robot-faults.png"))

    choose.select_by_value("robot-b")
    wait(browser, lambda b: b.find_element(By.ID, "view-faults").get_attribute("data-robot")
         == "robot-b")
    assert sorted(browser.execute_script(FAULT_CODES)) == ["GRIPPER_JAM", ESTOP]
    assert "behind" in browser.find_element(By.ID, "robot-note").text
    assert not browser.find_element(By.ID, "detail").is_displayed()

    choose.select_by_value("")  # back to the central's own log
    wait(browser, lambda b: b.execute_script(FAULT_CODES) == [OWN_FAULT])
    assert not browser.find_element(By.ID, "robot-note").is_displayed()
