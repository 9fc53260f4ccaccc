"""FaultReporter against the real fault manager: each side its own process, no fakes (SPEC §8).

Run as a script, this file is the reporter process: it reads JSON batches of reports from stdin,
prints ``reported <results>`` after making them and ``delivered`` once the manager has answered
them all, spinning with ``spin_once`` in between (never a repeated spin_until_future_complete).
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from faultledger import Fault, FaultLedger
from faultledger.domain.events import FaultReported

ERROR, WARN, CRITICAL = 2, 1, 3
SOURCE = "/test/reporter"
DISCOVERY_SEC = 20.0


if __name__ != "__main__":  # the tests; run as a script this file is the reporter process
    from tests.ros.processes import LineProcess

    class Proc(LineProcess):
        def __init__(self, args: list[str], log: Path) -> None:
            super().__init__(args, log, timeout=DISCOVERY_SEC)

        def send(self, batch: list[list[object]]) -> list[bool]:
            """Have the reporter process make these reports; returns what report() returned."""
            results: list[bool] = json.loads(self.ask(batch, "reported ", 10.0).split(" ", 1)[1])
            return results


@contextmanager
def manager(url: str, log: Path) -> Iterator[Proc]:
    """`faultledger serve` on ``url``, ready to serve; stopped with SIGTERM on exit."""
    proc = Proc([sys.executable, "-m", "faultledger.cli.main", "serve", "--db", url], log)
    try:
        proc.expect("fault_manager ready")
        yield proc
    finally:
        proc.stop()


@contextmanager
def reporter(tmp_path: Path, *ros_args: str, timeout_sec: float = 5.0) -> Iterator[Proc]:
    """A reporter process (this file as a script); ``ros_args`` go after ``--ros-args``."""
    args = [sys.executable, __file__, str(timeout_sec)]
    if ros_args:
        args += ["--ros-args", *ros_args]
    proc = Proc(args, tmp_path / f"reporter-{time.monotonic_ns()}.log")
    try:
        yield proc
    finally:
        assert proc.popen.stdin is not None
        proc.popen.stdin.close()  # EOF: the script exits
        proc.popen.wait(timeout=10)


def stored(url: str, code: str) -> tuple[Fault | None, list[FaultReported]]:
    """The fault and its reports as the ledger holds them (read after the manager stopped)."""
    ledger = FaultLedger.open(url)
    try:
        reports = [r.event for r in ledger.history(code=code)
                   if isinstance(r.event, FaultReported)]
        return ledger.get_fault(code), reports
    finally:
        ledger.close()


def test_an_error_report_reaches_the_ledger(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'faults.db'}"
    with manager(url, tmp_path / "manager.log"), reporter(tmp_path) as rep:
        assert rep.send([["failed", "MOTOR_OVERHEAT", ERROR, "winding at 140 C"]]) == [True]
        rep.expect("delivered")
    fault, reports = stored(url, "MOTOR_OVERHEAT")
    assert fault is not None
    assert (fault.severity, fault.description) == (ERROR, "winding at 140 C")
    assert fault.reporting_sources == (SOURCE,)
    assert len(reports) == 1


def test_warnings_below_the_threshold_stay_local(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'faults.db'}"
    with manager(url, tmp_path / "manager.log"):
        with reporter(tmp_path) as rep:
            warn = ["failed", "LIDAR_NOISE", WARN, ""]
            other = ["failed", "ODOM_DRIFT", WARN, ""]
            assert rep.send([warn, other, warn, other, ["passed", "LIDAR_NOISE"]]) == \
                [False, False, False, False, False]
            assert rep.send([warn, warn]) == [True, True]  # third and later in the window
            rep.expect("delivered")
        # A bad parameter is normalised with a warning naming it: threshold 0 becomes 1.
        with reporter(tmp_path, "-p", "fault_reporter.local_filtering.default_threshold:=0") as rep:
            assert rep.send([["failed", "CAMERA_DROP", WARN, ""]]) == [True]
            rep.expect("delivered")
        assert "fault_reporter.local_filtering.default_threshold=0" in rep.log.read_text()
    assert len(stored(url, "LIDAR_NOISE")[1]) == 2
    assert stored(url, "ODOM_DRIFT") == (None, [])
    assert len(stored(url, "CAMERA_DROP")[1]) == 1


def test_a_report_made_while_the_manager_is_down_is_delivered_once_it_is_up(
        tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'faults.db'}"
    with reporter(tmp_path) as rep:
        assert rep.send([["failed", "BATTERY_LOW", CRITICAL, "12 %"]]) == [True]
        time.sleep(1.0)  # several flush ticks find no service
        assert rep.lines.empty()
        with manager(url, tmp_path / "manager.log"):
            rep.expect("delivered")
    fault, reports = stored(url, "BATTERY_LOW")
    assert fault is not None and fault.status == "CONFIRMED"
    assert len(reports) == 1


def test_a_report_lost_with_a_killed_manager_is_resent_to_the_next(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'faults.db'}"
    with reporter(tmp_path, timeout_sec=2.0) as rep:
        with manager(url, tmp_path / "manager1.log") as first:
            assert rep.send([["failed", "ARM_STALL", ERROR, "before"]]) == [True]
            rep.expect("delivered")
            first.stop(signal.SIGKILL)
            # The dead manager stays in the DDS graph until its lease runs out, so this request
            # is sent to nobody and only the response timeout brings it back to the queue.
            assert rep.send([["failed", "GRIPPER_SLIP", ERROR, "after the kill"]]) == [True]
            time.sleep(0.5)
        with manager(url, tmp_path / "manager2.log"):
            rep.expect("delivered")
    assert "unanswered after 2.0 s" in rep.log.read_text()
    assert len(stored(url, "GRIPPER_SLIP")[1]) == 1


def _reporter_process() -> int:
    """The reporter side: one node, one FaultReporter, batches from stdin."""
    import select

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from faultledger.ros.reporter import FaultReporter

    context = Context()
    rclpy.init(args=sys.argv, context=context)
    node = rclpy.create_node(f"test_reporter_{os.getpid()}", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    faults = FaultReporter(node, SOURCE, response_timeout_sec=float(sys.argv[1]))
    waiting = False
    try:
        while True:
            executor.spin_once(timeout_sec=0.02)
            if waiting and faults.pending == 0:
                print("delivered", flush=True)
                waiting = False
            if select.select([sys.stdin], [], [], 0)[0]:
                line = sys.stdin.readline()
                if not line:
                    return 0
                results = []
                for kind, code, *rest in json.loads(line):  # [kind, code, severity?, text?]
                    results.append(faults.report(code, rest[0], rest[1]) if kind == "failed"
                                   else faults.report_passed(code))
                print("reported", json.dumps(results), flush=True)
                waiting = True
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


if __name__ == "__main__":
    sys.exit(_reporter_process())
