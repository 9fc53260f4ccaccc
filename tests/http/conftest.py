"""A real HTTP server per test: `faultledger http` in a subprocess on a loopback port.

``http_server(config=..., db=...)`` starts one and returns a ``Server`` with its base URL, an
``httpx.Client`` and the database file; every server still running at the end is stopped.
``browser`` is one headless Chromium (Debian's chromium + chromium-driver) for the session;
tests that use it are marked ``needs_browser`` and save screenshots in ``SHOTS``.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

CHROMIUM = shutil.which("chromium")
DRIVER = shutil.which("chromedriver")
SHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "screenshots"
"""Screenshots for a person to look at (git ignores test-artifacts/; never the user's var/)."""
needs_browser = pytest.mark.skipif(CHROMIUM is None or DRIVER is None,
                                   reason="needs Debian's chromium and chromium-driver")

READY = re.compile(r"faultledger http ready.*?: (http://[0-9.:\[\]]+/)")


@dataclass
class Server:
    url: str
    db: Path
    process: subprocess.Popen[str]
    client: httpx.Client
    log: Path

    def output(self) -> str:
        return self.log.read_text()

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
        self.client.close()
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode


def write_config(path: Path, http: dict[str, object] | None = None,
                 extra: dict[str, object] | None = None) -> Path:
    data: dict[str, object] = {"http": {"tokens_file": None, **(http or {})}}
    data.update(extra or {})
    path.write_text(yaml.safe_dump(data))
    return path


def start_server(db: Path, *args: str, config: Path | None = None,
                 env: dict[str, str] | None = None, timeout: float = 30.0) -> Server:
    """Output goes to a file beside the database (a pipe nobody reads could fill up and
    stall the server); the ready line gives the port the kernel chose."""
    command = [sys.executable, "-m", "faultledger.cli.main", "http", "--db", str(db),
               "--listen", "127.0.0.1:0", *args]
    if config is not None:
        command += ["--config", str(config)]
    log = db.with_name(f"{db.stem}-http-{time.monotonic_ns()}.log")
    with log.open("w") as out:
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, text=True,
                                   env={**os.environ, **(env or {})})
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = log.read_text()
        found = READY.search(text)
        if found:
            url = found.group(1)
            return Server(url, db, process, httpx.Client(base_url=url, timeout=10.0), log)
        if process.poll() is not None:
            break
        time.sleep(0.05)
    process.kill()
    process.wait()
    raise AssertionError("faultledger http did not start:\n" + log.read_text())


@pytest.fixture
def http_server(tmp_path: Path) -> Iterator[Callable[..., Server]]:
    started: list[Server] = []

    def _start(*args: str, config: Path | None = None, db: Path | None = None,
               env: dict[str, str] | None = None) -> Server:
        server = start_server(db or tmp_path / "faults.db", *args, config=config, env=env)
        started.append(server)
        return server

    yield _start
    for server in started:
        server.stop()


@pytest.fixture(scope="session")
def browser() -> Iterator[Any]:
    """One headless Chromium for the whole session (a selenium WebDriver)."""
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    if CHROMIUM is None or DRIVER is None:
        pytest.skip("needs Debian's chromium and chromium-driver")
    options = Options()
    options.binary_location = CHROMIUM
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-dev-shm-usage", "--window-size=1366,900"):
        options.add_argument(argument)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    SHOTS.mkdir(parents=True, exist_ok=True)
    yield driver
    driver.quit()
