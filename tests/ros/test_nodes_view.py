"""``faultledger nodes`` on a real 80x30 terminal (tmux) against a real NodeStatePublisher
process: RUNNING, the last WARNING with its age, the summary line, a key changing the sort,
LOST once the publisher is killed; no line wider than 80 columns."""

from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from tests.ros.test_bridge_node_state import node_process, running

pytestmark = pytest.mark.skipif(shutil.which("tmux") is None, reason="needs tmux")
WIDTH = 80


@pytest.fixture
def terminal(tmp_path: Path) -> Iterator[Callable[..., str]]:
    """``run(*keys)``: sends keys to one tmux pane 80 columns wide; returns the screen."""
    socket = f"faultledger-test-{os.getpid()}-{time.monotonic_ns()}"
    tmux = ["tmux", "-L", socket, "-f", "/dev/null"]
    command = " ".join(shlex.quote(a) for a in [
        "env", f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}",
        sys.executable, "-m", "faultledger.cli.main", "nodes", "--timeout-sec", "2"])
    command += f" 2>{shlex.quote(str(tmp_path / 'nodes.stderr'))}"
    subprocess.run([*tmux, "new-session", "-d", "-x", str(WIDTH), "-y", "30", command],
                   check=True, timeout=10)

    def screen(*keys: str) -> str:
        for key in keys:
            subprocess.run([*tmux, "send-keys", "-t", "0", key], check=True, timeout=10)
        done = subprocess.run([*tmux, "capture-pane", "-p", "-t", "0"], capture_output=True,
                              text=True, timeout=10)
        return done.stdout

    try:
        yield screen
    finally:
        subprocess.run([*tmux, "kill-server"], capture_output=True, timeout=10)


def wait_screen(screen: Callable[..., str], check: Callable[[str], bool],
                timeout: float = 30.0) -> str:
    deadline = time.monotonic() + timeout
    shown = ""
    while time.monotonic() < deadline:
        shown = screen()
        assert all(len(line) <= WIDTH for line in shown.splitlines()), shown
        if check(shown):
            return shown
        time.sleep(0.3)
    raise AssertionError(f"screen never matched:\n{shown}")


def row(shown: str, name: str) -> str:
    return next((line for line in shown.splitlines() if name in line), "")


def test_nodes_view_on_a_terminal(tmp_path: Path, terminal: Callable[..., str]) -> None:
    shown = wait_screen(terminal, lambda s: "no NodeState on /nodemon/state yet" in s)
    assert "0 nodes" in shown
    with running(node_process(tmp_path, "camera_with_a_long_node_name", "/robot3")) as node:
        node.send("running")
        name = "/robot3/camera_with_a_long_node_name"
        wait_screen(terminal, lambda s: "RUNNING" in row(s, name))  # the view hears it now
        node.send("warning W_TEMP camera at 80 C")
        node.send("running")
        shown = wait_screen(terminal, lambda s: "RUNNING" in row(s, name)
                            and "WARNING" in row(s, name) and "ago" in row(s, name))
        assert "1 node: 1 RUNNING | /nodemon/state | since " in " ".join(shown.split())
        assert "sort name" in shown
        terminal("s")
        wait_screen(terminal, lambda s: "sort state" in s, 5.0)
        terminal("s")
        wait_screen(terminal, lambda s: "sort age" in s, 5.0)
        terminal("f", "c", "a", "m", "Enter")
        wait_screen(terminal, lambda s: "filter 'cam'" in " ".join(s.split()) and name in s, 5.0)
        node.stop(signal.SIGKILL)
    shown = wait_screen(terminal, lambda s: "LOST" in row(s, name), 15.0)
    assert "WARNING" in row(shown, name)  # the last non-RUNNING state stays
    assert "1 LOST" in shown
    terminal("q")
    wait_screen(terminal, lambda s: "q quit" not in s or "$" in s, 5.0)
