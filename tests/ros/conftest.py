"""Fixtures for the ROS 2 tests: the fault manager as a real process, and rclpy test clients.

Every test here starts real DDS participants. They must never reach a real network, so this
directory refuses to run unless ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` is set, which
``scripts/in-netns`` does (it also gives the run a private network namespace with only ``lo``):

    scripts/in-netns .venv/bin/pytest -q tests/ros

Fixtures:

* ``manager``: factory ``manager(*extra_args, db=None) -> Manager`` that starts
  ``python -m faultledger.cli.main serve --db sqlite:///<tmp>/<file>.db [extra_args]`` in the
  test's tmp_path, waits (30 s at most) for its ``fault_manager ready`` stdout line and stops it
  with SIGTERM at teardown (SIGKILL when it does not exit). A ``Manager`` can be stopped
  (``stop(sig)``), killed (``kill()``) and started again on the same database (``start()``).
  ``shared_manager`` is the same factory shared by the tests of one class. Only one manager
  may run at a time on one DDS domain: they all serve the same names (each pytest-xdist
  worker has a domain of its own).
* ``client``: a fresh rclpy Context + Node + SingleThreadedExecutor (``RosClient``) with
  ``call(srv_type, name, request, timeout=10)`` and typed helpers for the fault manager's services;
  ``shared_client`` is one per test class.
* ``events``: an ``EventRecorder`` on ``client``'s node, subscribed to ``/fault_manager/events``
  (RELIABLE, VOLATILE, KEEP_LAST 100), collecting every message it receives.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, Protocol

import pytest
import rclpy
from builtin_interfaces.msg import Time
from faultledger_msgs.srv import GetHistory
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from ros2_medkit_msgs.msg import FaultEvent
from ros2_medkit_msgs.srv import (
    ClearFault,
    GetFault,
    ListFaults,
    ListFaultsForEntity,
    ReportFault,
)

WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")
"""``gw0``, ``gw1``, … under ``pytest -n``: each worker gets a DDS domain of its own (set here,
before any participant exists; the fault managers it starts inherit it), so the managers of
two workers, which serve the same names, never see each other (docs/testing.md)."""
if WORKER.startswith("gw"):
    os.environ["ROS_DOMAIN_ID"] = str(20 + int(WORKER[2:]))

# Importing rclpy starts no DDS participant (rclpy.init + a node would); no fixture runs
# before these guards.
LOCALHOST_ONLY = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST"
REFUSAL = (
    "tests/ros start ROS 2 (DDS) processes and must not reach a real network: run them as "
    "`scripts/in-netns .venv/bin/pytest -q tests/ros` (private network namespace, "
    "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST). ROS_AUTOMATIC_DISCOVERY_RANGE is "
    f"{os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')!r} here; refusing to run."
)


def pytest_sessionstart(session: pytest.Session) -> None:
    """Refuse before anything starts when this conftest is loaded at startup (pytest tests/ros)."""
    if not LOCALHOST_ONLY:
        pytest.exit(REFUSAL, returncode=4)


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config,
                                  items: list[pytest.Item]) -> None:
    """Refuse after collection when this directory was collected as part of a larger run."""
    if not LOCALHOST_ONLY:
        pytest.exit(REFUSAL, returncode=4)


READY_PREFIX = "fault_manager ready"
READY_TIMEOUT = 30.0
STOP_TIMEOUT = 15.0
NS = "/fault_manager"
EVENTS_TOPIC = f"{NS}/events"
FAILED = 0
PASSED = 1

SERVICE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10000,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE,
)
"""Test clients keep a deep queue: the default depth 10 drops requests in a burst."""

EVENTS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=100,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE,
)


# -- the fault manager process ---------------------------------------------------------------------
class Manager:
    """One fault manager (``faultledger serve``) on one database file, startable many times."""

    def __init__(self, directory: Path, db_path: Path, args: Sequence[str],
                 db_option: bool = True) -> None:
        self.directory = directory
        self.db_option = db_option
        self.db_path = db_path
        self.url = f"sqlite:///{db_path}"
        self.args: list[str] = list(args)
        self.proc: subprocess.Popen[str] | None = None
        self.ready_line = ""
        self.stdout_lines: list[str] = []
        self.stderr_path: Path = directory / f"{db_path.stem}-manager-0.stderr"
        self.exit_codes: list[int] = []
        self.starts = 0
        self._reader: threading.Thread | None = None

    def command(self) -> list[str]:
        db = ["--db", self.url] if self.db_option else []
        return [sys.executable, "-m", "faultledger.cli.main", "serve", *db, *self.args]

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stderr_text(self) -> str:
        try:
            return self.stderr_path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return ""

    def describe(self) -> str:
        """Diagnostics for assertion messages: the command, stdout seen and stderr's tail."""
        return (f"command: {' '.join(self.command())}\nstdout: {self.stdout_lines[-20:]}\n"
                f"stderr (tail):\n{self.stderr_text()[-4000:]}")

    def start(self, args: Sequence[str] | None = None) -> str:
        """Start (again) on the same database; returns the ready line. ``args`` replaces the
        extra arguments for this and later starts."""
        assert not self.running, "manager is already running"
        if args is not None:
            self.args = list(args)
        self.starts += 1
        self.stderr_path = self.directory / f"{self.db_path.stem}-manager-{self.starts}.stderr"
        self.stdout_lines = []
        self.ready_line = ""
        ready = threading.Event()
        with self.stderr_path.open("w", encoding="utf-8") as stderr:
            proc = subprocess.Popen(
                self.command(), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=stderr,
                text=True, cwd=self.directory,
            )
        self.proc = proc

        def read_stdout() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:  # keeps draining after ready so the pipe never fills
                self.stdout_lines.append(line.rstrip("\n"))
                if not ready.is_set() and line.startswith(READY_PREFIX):
                    self.ready_line = line.strip()
                    ready.set()
            ready.set()  # EOF: the process ended (or closed stdout)

        self._reader = threading.Thread(target=read_stdout, daemon=True, name="manager-stdout")
        self._reader.start()
        ready.wait(READY_TIMEOUT)
        if not self.ready_line:
            exited = proc.poll()
            if exited is None:
                self._force_kill()
                raise AssertionError(
                    f"fault manager printed no '{READY_PREFIX}' line within {READY_TIMEOUT} s\n"
                    + self.describe())
            raise AssertionError(f"fault manager exited with code {exited} before it was "
                                 f"ready\n{self.describe()}")
        return self.ready_line

    def stop(self, sig: int = signal.SIGTERM, timeout: float = STOP_TIMEOUT) -> int:
        """Send ``sig`` and wait for the exit; returns the exit code (-9 when it had to be
        killed after ``timeout``; the test then sees a code other than 0)."""
        proc = self.proc
        assert proc is not None, "manager was never started"
        if proc.poll() is None:
            proc.send_signal(sig)
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self._force_kill()
        return self._finish()

    def kill(self) -> int:
        """kill -9: no chance to clean up."""
        proc = self.proc
        assert proc is not None, "manager was never started"
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=STOP_TIMEOUT)
        return self._finish()

    def terminate(self) -> None:
        """Teardown: SIGTERM, SIGKILL when needed; never raises."""
        if self.running:
            with contextlib.suppress(Exception):
                self.stop()

    def _force_kill(self) -> None:
        assert self.proc is not None
        self.proc.kill()
        self.proc.wait(timeout=STOP_TIMEOUT)

    def _finish(self) -> int:
        assert self.proc is not None
        code = self.proc.returncode
        if self._reader is not None:
            self._reader.join(timeout=5)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self.exit_codes.append(code)
        return code


class ManagerFactory(Protocol):
    def __call__(self, *args: str, db: Path | None = None, start: bool = True,
                 db_option: bool = True) -> Manager: ...


@contextlib.contextmanager
def _managers(directory: Path) -> Iterator[ManagerFactory]:
    started: list[Manager] = []
    counter = itertools.count()

    def make(*args: str, db: Path | None = None, start: bool = True,
             db_option: bool = True) -> Manager:
        n = next(counter)
        path = db if db is not None else directory / ("faults.db" if n == 0 else f"faults-{n}.db")
        manager = Manager(directory, path, args, db_option)
        started.append(manager)
        if start:
            manager.start()
        return manager

    try:
        yield make
    finally:
        for manager in reversed(started):
            manager.terminate()


@pytest.fixture
def manager(tmp_path: Path) -> Iterator[ManagerFactory]:
    """``manager(*extra_args, db=None, start=True, db_option=True)``: a fault manager on a
    tmp_path database (``db_option=False``: no ``--db``; the test passes the database itself)."""
    with _managers(tmp_path) as make:
        yield make


@pytest.fixture(scope="class")
def shared_manager(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ManagerFactory]:
    """Same as ``manager`` but shared by the tests of one class (one directory).

    Only one fault manager may run at a time (they all serve ``/fault_manager``): keep tests
    that start their own outside the class, and never run this directory with pytest-xdist.
    """
    with _managers(tmp_path_factory.mktemp("manager")) as make:
        yield make


# -- rclpy clients ---------------------------------------------------------------------------------
def to_time(ns: int) -> Any:
    seconds, nanoseconds = divmod(ns, 1_000_000_000)
    return Time(sec=seconds, nanosec=nanoseconds)


def time_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class ServiceTimeout(AssertionError):
    """A service was not available, or a request was not answered, in time."""


_node_names = itertools.count()


class RosClient:
    """A test participant: its own Context, Node and SingleThreadedExecutor.

    Futures are waited for with ``spin_once`` loops, never with repeated
    ``spin_until_future_complete`` (rclpy 7.1.6 slows down call after call with that).
    """

    def __init__(self, name: str | None = None) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        node_name = name or f"pytest_client_{os.getpid()}_{next(_node_names)}"
        self.node: Any = Node(node_name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._clients: dict[str, Any] = {}

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.executor.remove_node(self.node)
        with contextlib.suppress(Exception):
            self.executor.shutdown(timeout_sec=1.0)
        with contextlib.suppress(Exception):
            self.node.destroy_node()
        with contextlib.suppress(Exception):
            rclpy.shutdown(context=self.context)

    # spinning
    def spin_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() >= deadline:
                return predicate()
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    # services
    def service_client(self, srv_type: Any, name: str) -> Any:
        client = self._clients.get(name)
        if client is None:
            client = self.node.create_client(srv_type, name, qos_profile=SERVICE_QOS)
            self._clients[name] = client
        return client

    def wait_for(self, srv_type: Any, name: str, timeout: float = 20.0) -> Any:
        client = self.service_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise ServiceTimeout(f"service {name} not available within {timeout} s")
        return client

    def call(self, srv_type: Any, name: str, request: Any, timeout: float = 10.0) -> Any:
        """One request, answered within ``timeout`` seconds (else ServiceTimeout)."""
        client = self.wait_for(srv_type, name, max(timeout, 20.0))
        future = client.call_async(request)
        if not self.spin_until(future.done, timeout):
            client.remove_pending_request(future)
            raise ServiceTimeout(f"{name}: no answer within {timeout} s to {request!r}")
        exception = future.exception()
        if exception is not None:
            raise exception
        return future.result()

    def call_all(self, srv_type: Any, name: str, requests: Iterable[Any],
                 timeout: float = 30.0) -> list[Any]:
        """Send every request back to back, then wait for all answers (None: unanswered)."""
        client = self.wait_for(srv_type, name)
        futures = [client.call_async(request) for request in requests]
        self.spin_until(lambda: all(f.done() for f in futures), timeout)
        answers: list[Any] = []
        for future in futures:
            if future.done():
                answers.append(future.result())
            else:
                client.remove_pending_request(future)
                answers.append(None)
        return answers

    def wait_until_answering(self, timeout: float = 30.0) -> None:
        """Block until the (re)started manager answers a harmless request.

        After a kill -9 the dead manager stays in the DDS graph until its lease expires, so
        ``wait_for_service`` succeeds at once and a request may go to the dead server only (a
        late-matched new server never sees it). Probe with short list_faults calls until one is
        answered: from then on requests and answers flow both ways with the new manager.
        """
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.call(ListFaults, f"{NS}/list_faults", ListFaults.Request(), timeout=2.0)
                return
            except ServiceTimeout:
                if time.monotonic() >= deadline:
                    raise

    # the fault manager's services
    def report(self, fault_code: str, event_type: int = FAILED, severity: int = 1,
               description: str = "", source_id: str = "/pytest") -> bool:
        request = ReportFault.Request(fault_code=fault_code, event_type=event_type,
                                      severity=severity, description=description,
                                      source_id=source_id)
        accepted: bool = self.call(ReportFault, f"{NS}/report_fault", request).accepted
        return accepted

    def get(self, fault_code: str) -> Any:
        return self.call(GetFault, f"{NS}/get_fault", GetFault.Request(fault_code=fault_code))

    def fault(self, fault_code: str) -> Any:
        """The fault message of a fault that must exist."""
        response = self.get(fault_code)
        assert response.success, f"get_fault({fault_code!r}): {response.error_message}"
        return response.fault

    def clear(self, fault_code: str) -> Any:
        return self.call(ClearFault, f"{NS}/clear_fault", ClearFault.Request(fault_code=fault_code))

    def list_faults(self, statuses: Sequence[str] = (), severity: int | None = None) -> list[Any]:
        request = ListFaults.Request(statuses=list(statuses),
                                     filter_by_severity=severity is not None,
                                     severity=severity or 0)
        faults: list[Any] = list(self.call(ListFaults, f"{NS}/list_faults", request).faults)
        return faults

    def for_entity(self, entity_id: str) -> Any:
        return self.call(ListFaultsForEntity, f"{NS}/list_faults_for_entity",
                         ListFaultsForEntity.Request(entity_id=entity_id))

    def history(self, fault_code: str = "", source_id: str = "", since_ns: int = 0,
                until_ns: int = 0, kinds: Sequence[str] = (), limit: int = 0) -> Any:
        request = GetHistory.Request(fault_code=fault_code, source_id=source_id,
                                     since=to_time(since_ns), until=to_time(until_ns),
                                     kinds=list(kinds), limit=limit)
        return self.call(GetHistory, f"{NS}/get_history", request)


@pytest.fixture
def client() -> Iterator[RosClient]:
    ros = RosClient()
    try:
        yield ros
    finally:
        ros.close()


@pytest.fixture(scope="class")
def shared_client() -> Iterator[RosClient]:
    ros = RosClient()
    try:
        yield ros
    finally:
        ros.close()


# -- the events topic ------------------------------------------------------------------------------
SYNC_PREFIX = "SYNC_"


class EventRecorder:
    """Collects every FaultEvent published on /fault_manager/events (RELIABLE, VOLATILE)."""

    _sync_codes = itertools.count()

    def __init__(self, ros: RosClient) -> None:
        self.ros = ros
        self.messages: list[Any] = []
        self.subscription = ros.node.create_subscription(
            FaultEvent, EVENTS_TOPIC, self.messages.append, EVENTS_QOS)

    def wait_for_count(self, count: int, timeout: float = 10.0) -> bool:
        return self.ros.spin_until(lambda: len(self.messages) >= count, timeout)

    def settle(self, seconds: float = 0.5) -> None:
        """Spin a little longer so that late (unexpected) events arrive too."""
        self.ros.spin_for(seconds)

    def wait_matched(self, timeout: float = 30.0) -> list[str]:
        """Make sure the manager's publisher has matched this subscription.

        A VOLATILE subscriber sees only what is published after the publisher has discovered
        it, and seeing the publisher from here does not prove the reverse. So: report a CRITICAL
        fault ``SYNC_<n>`` (born CONFIRMED, hence one ``fault_confirmed``) until its event arrives.
        Returns the sync codes used; ``scenario()`` leaves their events out.
        """
        if not self.ros.spin_until(lambda: self.ros.node.count_publishers(EVENTS_TOPIC) > 0,
                                   timeout):
            raise ServiceTimeout(f"no publisher on {EVENTS_TOPIC} within {timeout} s")
        deadline = time.monotonic() + timeout
        codes: list[str] = []
        while time.monotonic() < deadline:
            code = f"{SYNC_PREFIX}{os.getpid()}_{next(self._sync_codes)}"
            codes.append(code)
            assert self.ros.report(code, FAILED, severity=3, source_id="/pytest/sync")
            if self.ros.spin_until(
                    lambda: any(m.fault.fault_code in codes for m in self.messages), 3.0):
                return codes
        raise ServiceTimeout(f"{EVENTS_TOPIC}: none of the sync events {codes} arrived")

    def scenario(self) -> list[Any]:
        """Received events except those of the sync faults."""
        return [m for m in self.messages if not m.fault.fault_code.startswith(SYNC_PREFIX)]

    def of(self, fault_code: str) -> list[Any]:
        return [m for m in self.messages if m.fault.fault_code == fault_code]


@pytest.fixture
def events(client: RosClient) -> EventRecorder:
    """An EventRecorder on ``client``'s node, subscribed as soon as the fixture is requested."""
    return EventRecorder(client)
