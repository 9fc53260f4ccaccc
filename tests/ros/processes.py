"""Child processes for the ROS tests: commands on stdin, stdout lines on a queue (so a read
times out instead of blocking), stderr in a log file the failure messages quote."""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import threading
import time
from pathlib import Path


class LineProcess:
    """One child process; ``timeout`` is how long ``expect`` waits unless told otherwise."""

    close_stdin_on_stop = False
    """Whether ``stop`` closes stdin first (ends the publisher scripts on EOF)."""
    stop_wait_sec = 10.0

    def __init__(self, args: list[str], log: Path, *, timeout: float = 30.0,
                 env: dict[str, str] | None = None) -> None:
        """``env``: the child's whole environment (None: this process's)."""
        self.log = log
        self.timeout = timeout
        with log.open("w") as err:
            self.popen = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                          stderr=err, text=True, env=env)
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.put(line.rstrip("\n"))

    def expect(self, prefix: str, timeout: float | None = None) -> str:
        """The next stdout line starting with ``prefix`` (earlier lines are skipped)."""
        wait = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + wait
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            if line.startswith(prefix):
                return line
        raise AssertionError(f"{self.log.name}: no line {prefix!r} within {wait} s; "
                             f"stderr:\n{self.stderr()[-4000:]}")

    def write(self, line: str) -> None:
        assert self.popen.stdin is not None
        self.popen.stdin.write(line + "\n")
        self.popen.stdin.flush()

    def ask(self, command: object, answer: str, timeout: float | None = None) -> str:
        """Send ``command`` as one JSON line and return the answer line."""
        self.write(json.dumps(command))
        return self.expect(answer, timeout)

    def stderr(self) -> str:
        return self.log.read_text(encoding="utf-8", errors="replace")

    def stop(self, sig: int | None = signal.SIGTERM) -> int:
        """Send ``sig`` (None: none) while running, wait, kill if stuck; the exit code."""
        if self.close_stdin_on_stop and self.popen.stdin is not None:
            self.popen.stdin.close()
        if sig is not None and self.popen.poll() is None:
            self.popen.send_signal(sig)
        try:
            self.popen.wait(timeout=self.stop_wait_sec)
        except subprocess.TimeoutExpired:
            self.popen.kill()
        return self.popen.wait()
