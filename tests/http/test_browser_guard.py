"""What a browser page may make the server do (docs/http.md, "Browsers: hosts, origins,
framing"): only configured host names are answered (DNS rebinding), a change from another
origin is refused, and every answer carries a CSP, X-Frame-Options and friends. Real
servers, httpx and headless Chromium: a page on a second loopback port, and a page served as
``http://evil.test:PORT`` through a local proxy (a name rebound to 127.0.0.1), try to read,
report and clear; the dashboard, Swagger UI and the shift report run under their CSP without
a single violation."""

from __future__ import annotations

import base64
import hashlib
import http.client
import re
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest

from faultledger import FaultLedger, ReportRequest
from tests.http.conftest import (
    CHROMIUM,
    DRIVER,
    SHOTS,
    Server,
    needs_browser,
    start_server,
    write_config,
)


def seeded(tmp_path: Path, **http: object) -> Server:
    db = tmp_path / "f.db"
    with FaultLedger.open(f"sqlite:///{db}") as ledger:
        ledger.report_many([ReportRequest("GUARD_MOTOR", "FAILED", 3, "overheat", "/arm"),
                            ReportRequest("GUARD_LIDAR", "FAILED", 2, "dirty", "/base")])
    return start_server(db, config=write_config(tmp_path / "c.yaml", http=http))


def port_of(server: Server) -> int:
    return int(server.url.rstrip("/").rsplit(":", 1)[1])


def untouched(server: Server) -> None:
    """Both faults still CONFIRMED, nothing else reported."""
    faults = {i["fault_code"]: i["status"]
              for i in server.client.get("/api/v1/faults?status=all").json()["items"]}
    assert faults == {"GUARD_MOTOR": "CONFIRMED", "GUARD_LIDAR": "CONFIRMED"}, faults


def test_only_configured_host_names_are_answered(tmp_path: Path) -> None:
    server = seeded(tmp_path, allowed_hosts=["robot7.example", "cell.example:8443"])
    try:
        port = port_of(server)
        client = server.client
        for host in ("attacker.example", f"evil.test:{port}", f"127.0.0.1:{port + 1}",
                     f"cell.example:{port}", f"localhost:{port}x", ""):
            refused = client.get("/api/v1/faults", headers={"Host": host})
            assert refused.status_code == 400, host
            assert refused.json()["reason"] == "invalid"
            assert refused.json()["error_code"] == "invalid-host"
            assert "(http.allowed_hosts)" in refused.json()["message"]
        refused = client.delete("/api/v1/faults?status=all", headers={"Host": f"evil.test:{port}"})
        assert refused.status_code == 400
        for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"LOCALHOST:{port}",
                     f"[::1]:{port}", "robot7.example", f"robot7.example:{port}",
                     "cell.example:8443"):
            assert client.get("/api/v1/faults", headers={"Host": host}).status_code == 200, host
        untouched(server)
    finally:
        server.stop()
    anything = seeded(tmp_path / "any", allowed_hosts=["*"])
    try:
        answer = anything.client.get("/health", headers={"Host": "whatever.example"})
        assert answer.status_code == 200
    finally:
        anything.stop()


def test_a_change_from_another_origin_is_refused(tmp_path: Path) -> None:
    server = seeded(tmp_path, cors_origins=["http://ops.example"])
    try:
        client, own = server.client, server.url.rstrip("/")
        for origin in ("http://127.0.0.1:9", "null", "http://evil.test"):
            cleared = client.delete("/api/v1/faults/GUARD_MOTOR", headers={"Origin": origin})
            assert cleared.status_code == 403, origin
            assert cleared.json()["error_code"] == "forbidden-origin"
            posted = client.post("/api/v1/reports", headers={"Origin": origin},
                                 json={"fault_code": "XORIGIN", "event_type": "FAILED"})
            assert posted.status_code == 403
        untouched(server)
        # Reads are not changes: CORS decides whether a page may see them.
        assert client.get("/api/v1/faults", headers={"Origin": "http://evil.test"}
                          ).status_code == 200
        posted = client.post("/api/v1/reports", headers={"Origin": "http://ops.example"},
                             json={"fault_code": "FROM_OPS", "event_type": "FAILED"})
        assert posted.status_code == 200 and posted.json()["accepted"]
        assert client.delete("/api/v1/faults/GUARD_MOTOR", headers={"Origin": own}
                             ).status_code == 204
        assert client.delete("/api/v1/faults/GUARD_LIDAR").status_code == 204  # no Origin
    finally:
        server.stop()


def test_every_answer_forbids_framing_and_pages_carry_a_csp(tmp_path: Path) -> None:
    server = seeded(tmp_path)
    try:
        client = server.client
        common = {"x-frame-options": "DENY", "x-content-type-options": "nosniff",
                  "referrer-policy": "no-referrer"}
        for path in ("/", "/docs", "/api/v1/faults", "/static/dashboard.js", "/health",
                     "/api/v1/nothing", "/api/v1/shift-report"):
            answer = client.get(path)
            for name, value in common.items():
                assert answer.headers[name] == value, (path, name)
            policy = answer.headers["content-security-policy"]
            assert "frame-ancestors 'none'" in policy, path
            assert "unsafe-inline" not in policy and "unsafe-eval" not in policy, path
            if answer.headers["content-type"].startswith("text/html"):
                assert policy.startswith("default-src 'self'"), path
            else:
                assert policy == "default-src 'none'; frame-ancestors 'none'", path
        dashboard = client.get("/").headers["content-security-policy"]
        assert "script-src 'self';" in dashboard  # no inline script at all
        docs = client.get("/docs")
        inline = re.search(r"<script>(.*?)</script>", docs.text, re.S)
        assert inline is not None
        digest = base64.b64encode(hashlib.sha256(inline.group(1).encode()).digest()).decode()
        assert f"script-src 'self' 'sha256-{digest}'" in docs.headers["content-security-policy"]
    finally:
        server.stop()


# -- in Chromium -------------------------------------------------------------------------------
@contextmanager
def serving(handler: type[BaseHTTPRequestHandler]) -> Iterator[int]:
    """A tiny HTTP server on 127.0.0.1 (another origin than faultledger's); yields its
    port."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


ATTACK = """<!DOCTYPE html><html><head><title>win a prize</title></head><body>
<iframe id="framed" name="framed" src="{api}/" width="600" height="300"></iframe>
<form id="form" method="POST" action="{api}/api/v1/reports" enctype="text/plain"
      target="sink"><input name='{{"fault_code":"XFORM","event_type":"FAILED","x":"'
      value='"}}'></form><iframe name="sink"></iframe>
<script>
window.results = {{}};
async function attempt(name, url, init) {{
  try {{ const r = await fetch(url, init); window.results[name] = r.status; }}
  catch (e) {{ window.results[name] = "blocked"; }}
}}
(async () => {{
  const report = JSON.stringify({{fault_code: "XORIGIN", event_type: "FAILED"}});
  await attempt("read", "{api}/api/v1/faults?status=all", {{}});
  await attempt("report", "{api}/api/v1/reports",
                {{method: "POST", mode: "{mode}", headers: {{"Content-Type": "{kind}"}},
                  body: report}});
  await attempt("clear", "{api}/api/v1/faults?status=all", {{method: "DELETE"}});
  await attempt("clear_one", "{api}/api/v1/faults/GUARD_MOTOR", {{method: "DELETE"}});
  document.getElementById("form").submit();
  setTimeout(() => {{ document.title = "done"; }}, 1000);
}})();
</script></body></html>"""


def attack_page(api: str, *, same_origin: bool) -> bytes:
    return ATTACK.format(api=api, mode="same-origin" if same_origin else "no-cors",
                         kind="application/json" if same_origin else "text/plain").encode()


def wait_title(browser: Any, title: str, timeout: float = 15) -> None:
    deadline = time.monotonic() + timeout
    while browser.title != title and time.monotonic() < deadline:
        time.sleep(0.1)
    assert browser.title == title


@needs_browser
def test_a_page_from_another_origin_cannot_change_anything(tmp_path: Path, browser: Any
                                                           ) -> None:
    from selenium.webdriver.common.by import By

    server = seeded(tmp_path)
    api = server.url.rstrip("/")
    page = attack_page(api, same_origin=False)

    class Attacker(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(page)

        def log_message(self, *_: Any) -> None:
            pass

    try:
        with serving(Attacker) as port:
            browser.get(f"http://127.0.0.1:{port}/")
            wait_title(browser, "done")
            results = browser.execute_script("return window.results")
            assert results["read"] == "blocked"  # CORS closed: the page cannot read
            assert results["clear"] == "blocked" and results["clear_one"] == "blocked"
            browser.save_screenshot(str(SHOTS / "guard-cross-origin.png"))
            # The dashboard refused to render in the attacker's frame (X-Frame-Options).
            browser.switch_to.frame(browser.find_element(By.ID, "framed"))
            try:
                assert browser.find_elements(By.ID, "fault-table") == []
            finally:
                browser.switch_to.default_content()
        untouched(server)
    finally:
        server.stop()


class RebindingProxy(BaseHTTPRequestHandler):
    """An HTTP proxy for Chromium: ``http://evil.test:PORT/attack.html`` is the attacker's
    page; every other request to evil.test goes to 127.0.0.1:PORT unchanged, with its
    ``Host: evil.test:PORT``, as after a DNS rebinding."""

    page = b""

    def _forward(self) -> None:
        target = urlsplit(self.path)
        if target.path == "/attack.html":
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(self.page)))
            self.end_headers()
            self.wfile.write(self.page)
            return
        length = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(length) if length else None
        upstream = http.client.HTTPConnection("127.0.0.1", target.port or 80, timeout=10)
        headers = {k: v for k, v in self.headers.items()
                   if k.lower() not in ("proxy-connection", "connection")}
        upstream.request(self.command, target.path + (f"?{target.query}" if target.query
                                                      else ""), body, headers)
        answer = upstream.getresponse()
        data = answer.read()
        self.send_response(answer.status)
        for name, value in answer.getheaders():
            if name.lower() not in ("transfer-encoding", "connection", "content-length"):
                self.send_header(name, value)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)
        upstream.close()

    do_GET = do_POST = do_DELETE = do_OPTIONS = _forward

    def log_message(self, *_: Any) -> None:
        pass


@pytest.mark.skipif(CHROMIUM is None or DRIVER is None,
                    reason="needs Debian's chromium and chromium-driver")
def test_dns_rebinding_a_page_under_another_name_is_refused(tmp_path: Path) -> None:
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    server = seeded(tmp_path)
    port = port_of(server)
    RebindingProxy.page = attack_page(f"http://evil.test:{port}", same_origin=True)
    with serving(RebindingProxy) as proxy:
        options = Options()
        assert CHROMIUM is not None and DRIVER is not None
        options.binary_location = CHROMIUM
        for argument in ("--headless=new", "--no-sandbox", "--disable-gpu",
                         "--disable-dev-shm-usage", "--window-size=1000,700",
                         f"--proxy-server=http://127.0.0.1:{proxy}"):
            options.add_argument(argument)
        driver = webdriver.Chrome(service=Service(DRIVER), options=options)
        try:
            driver.get(f"http://evil.test:{port}/attack.html")
            wait_title(driver, "done")
            results = driver.execute_script("return window.results")
            # Same origin for the browser: it sends everything; the server refuses the name.
            assert results == {"read": 400, "report": 400, "clear": 400, "clear_one": 400}
            driver.get(f"http://evil.test:{port}/")
            assert "invalid-host" in driver.page_source
            driver.save_screenshot(str(SHOTS / "guard-dns-rebinding.png"))
        finally:
            driver.quit()
    untouched(server)
    server.stop()


CSP_WATCH = """window.__violations = [];
document.addEventListener('securitypolicyviolation', e => window.__violations.push(
  e.violatedDirective + ' ' + e.blockedURI));"""


@needs_browser
def test_the_pages_work_under_their_csp(tmp_path: Path, browser: Any) -> None:
    from selenium.webdriver.common.by import By

    server = seeded(tmp_path)
    watch = browser.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument",
                                    {"source": CSP_WATCH})
    try:
        browser.get(server.url)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not browser.find_elements(
                By.CSS_SELECTOR, "#fault-table tr[data-code='GUARD_MOTOR']"):
            time.sleep(0.1)
        assert browser.find_elements(By.CSS_SELECTOR, "#fault-table tr[data-code='GUARD_MOTOR']")
        browser.find_element(By.CSS_SELECTOR, "button.tab[data-view='stats']").click()
        time.sleep(1.5)
        browser.save_screenshot(str(SHOTS / "guard-dashboard-under-csp.png"))
        assert browser.execute_script("return window.__violations") == []
        browser.get(server.url + "docs")
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not browser.find_elements(
                By.CSS_SELECTOR, ".opblock"):
            time.sleep(0.1)
        assert browser.find_elements(By.CSS_SELECTOR, ".opblock"), "Swagger UI rendered"
        browser.save_screenshot(str(SHOTS / "guard-docs-under-csp.png"))
        assert browser.execute_script("return window.__violations") == []
        browser.get(server.url + "api/v1/shift-report")
        time.sleep(0.5)
        color = browser.execute_script("return getComputedStyle(document.body).color")
        images = browser.execute_script(
            "return [...document.images].map(i => i.naturalWidth > 0)")
        browser.save_screenshot(str(SHOTS / "guard-shift-report-under-csp.png"))
        assert browser.execute_script("return window.__violations") == []
        assert color == "rgb(29, 39, 51)"  # its inline style sheet (#1d2733) applied
        assert images and all(images)  # its data: charts drawn
    finally:
        browser.execute_cdp_cmd("Page.removeScriptToEvaluateOnNewDocument",
                                {"identifier": watch["identifier"]})
        server.stop()
