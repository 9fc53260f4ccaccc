"""`faultledger sync` (push this robot's log to a fleet central) and the central half of
`verify --central` (cli/audit.py). The push itself is faultledger.fleet's; this module
translates options and shows progress. docs/fleet.md, "Robot side"."""

from __future__ import annotations

import logging
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path
from types import FrameType
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TaskID, TextColumn
from rich.text import Text

from faultledger.cli import render
from faultledger.cli.options import ConfigOption, DbOption, fail, opened, prepare, settings_for
from faultledger.cli.safe_text import printable
from faultledger.errors import FaultLedgerError
from faultledger.fleet.check import CentralCheck, check_against_central
from faultledger.fleet.client import CentralClient, CentralError, check_central_url, read_token
from faultledger.fleet.push import (
    NoIdentityError,
    Pusher,
    PusherThread,
    RobotLog,
    RobotLogError,
    Status,
    Stopped,
)
from faultledger.service.config import Settings
from faultledger.service.ledger import FaultLedger
from faultledger.service.results import VerifyReport

CentralOption = Annotated[str | None, typer.Option(
    "--central", metavar="URL",
    help="The fleet central's base URL, e.g. https://central.example:8080 (default: the "
    "config's fleet.central).")]
TokenFileOption = Annotated[Path | None, typer.Option(
    "--token-file", metavar="FILE",
    help="File holding this robot's token, as `faultledger token create --role robot --name "
    "ROBOT_ID` printed it on the central (default: the config's fleet.token_file).")]
PLAIN_EVERY_SEC = 1.0
"""Not a terminal: a progress line at most this often while pushing."""
STOP_WAIT_SEC = 5.0
"""`sync --follow` after SIGTERM/SIGINT: how long a request in flight may take to finish."""


def register(app: typer.Typer) -> None:
    app.command("sync")(sync)


def token_path(token_file: Path | None, settings: Settings) -> Path | None:
    """``--token-file``, else the config's ``fleet.token_file``."""
    return token_file or (settings.fleet.token_file if settings.fleet is not None else None)


def central_inputs(central: str | None, token_file: Path | None,
                   settings: Settings) -> tuple[str, str]:
    """The central's URL and the token, from the options or the config's ``fleet:``; a
    missing or bad one is exit 2 in one line."""
    fleet = settings.fleet
    url = central or (fleet.central if fleet is not None else None)
    path = token_path(token_file, settings)
    if url is None:
        fail("no central: give --central URL (or fleet.central in the config)")
    if path is None:
        fail("no token: give --token-file FILE (or fleet.token_file in the config)")
    try:
        return check_central_url(url), read_token(path)
    except FaultLedgerError as error:
        fail(str(error))


def sync(
    central: CentralOption = None,
    token_file: TokenFileOption = None,
    follow: Annotated[bool, typer.Option(
        "--follow", help="Keep pushing each new record (within a second) until SIGTERM or "
        "Ctrl-C; wait for a central that is away.")] = False,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Push every record the fleet central lacks, in seq order.

    The robot's log is only read. Exit 0 once the central holds the whole log; 1 when it
    refuses a batch (naming the seq), refuses the token or cannot be reached. docs/fleet.md.
    """
    settings = settings_for(config)
    url, token = central_inputs(central, token_file, settings)
    setup = prepare(db, config)
    with opened(setup) as ledger, CentralClient(url, token) as client:
        out = Console(highlight=False, soft_wrap=True)
        reporter: RichReporter | PlainReporter = (
            RichReporter(out) if out.is_terminal else PlainReporter())
        pusher = Pusher(RobotLog(ledger), client, reporter,
                        token_file=token_path(token_file, settings))
        code = _follow(pusher, reporter) if follow else _once(pusher, reporter, ledger)
    raise typer.Exit(code)


def _once(pusher: Pusher, reporter: RichReporter | PlainReporter, ledger: FaultLedger) -> int:
    try:
        try:
            status = pusher.sync()
        finally:
            reporter.close()
    except NoIdentityError as error:
        if pusher.log.head() == 0:
            render.say(f"nothing to push: the log {render.describe_url(ledger.url)} is empty")
            return 0
        fail(str(error), 1)
    except (CentralError, RobotLogError, Stopped) as error:
        fail(f"{error}{_where(pusher)}", 1)
    except KeyboardInterrupt:
        fail(f"interrupted{_where(pusher)}; sync again to push the rest", 130)
    render.say(_done(status))
    return 0


def _follow(pusher: Pusher, reporter: RichReporter | PlainReporter) -> int:
    """The pusher on its own thread; this one waits for SIGTERM/SIGINT, then gives a request
    in flight a few seconds (the central ignores a batch sent again, so none is lost)."""
    stopped = threading.Event()
    caught: list[str] = []

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        caught.append(signal.Signals(signum).name)
        stopped.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    worker = PusherThread(pusher)
    worker.start()
    while not stopped.wait(0.5):
        pass
    worker.stop(STOP_WAIT_SEC)
    reporter.close()
    render.say(f"stopped ({caught[0] if caught else 'signal'})"
               f"{_where(pusher) or ': the central was not reached'}")
    return 0


def _where(pusher: Pusher) -> str:
    """Where the central stands, for the last line of a run."""
    if pusher.central_seq is None:
        return ""
    head = max(pusher.head_seq, pusher.central_seq)
    return (f"; the central holds seq {pusher.central_seq} of {head} "
            f"({pusher.pushed} records pushed by this run)")


def _done(status: Status) -> str:
    who = (f"robot {status.identity.robot_id}, ledger_id {status.identity.ledger_id}")
    if status.pushed == 0:
        pushed = "nothing to push, it held them all"
    else:
        seconds = max(status.elapsed, 1e-6)
        pushed = (f"pushed {status.pushed} records in {seconds:.1f} s "
                  f"({status.pushed / seconds:,.0f} records/s)")
    return (f"caught up: {status.central} holds seq {status.central_seq} of {who}; {pushed}"
            + (f"; {status.ignored} it already held" if status.ignored else ""))


def age(seconds: float) -> str:
    """12 s, 4 min, 3 h, 2 d: how old the newest record at the central is."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.0f} h"
    return f"{seconds / 86400:.0f} d"


def progress_text(status: Status) -> str:
    rate = f", {status.rate:,.0f} records/s" if status.rate else ""
    lag = (f"lag {status.behind} records, {age(status.lag_seconds)}" if not status.caught_up
           else "caught up")
    return (f"central at seq {status.central_seq} of {status.head_seq} "
            f"({status.pushed} pushed{rate}); {lag}")


class PlainReporter:
    """Not a terminal (a pipe, a log file, systemd): a line at most once a second while
    pushing, one when caught up; events on stderr. Idle contacts print nothing."""

    def __init__(self) -> None:
        self._said = 0.0
        self._pushing = False

    def progress(self, status: Status) -> None:
        now = time.monotonic()
        if status.caught_up:
            if self._pushing:
                print(printable(progress_text(status)), flush=True)
            self._pushing = False
            return
        if not self._pushing or now - self._said >= PLAIN_EVERY_SEC:
            print(printable(progress_text(status)), flush=True)
            self._said = now
        self._pushing = True

    def event(self, level: int, text: str) -> None:
        label = {logging.ERROR: "error:", logging.WARNING: "warning:"}.get(level, "note:")
        render.complain(label, text)

    def close(self) -> None:
        """Nothing to tidy up."""


class RichReporter:
    """A terminal: one live progress bar (records, rate, lag); events printed above it."""

    def __init__(self, out: Console) -> None:
        self.out = out
        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(bar_width=None),
            TextColumn("{task.fields[counts]}"), TextColumn("{task.fields[rate]}"),
            TextColumn("{task.fields[lag]}"), console=out, transient=True)
        self._task: TaskID | None = None
        self._lock = threading.Lock()

    def progress(self, status: Status) -> None:
        fields: dict[str, Any] = {
            "counts": f"{status.central_seq}/{status.head_seq}",
            "rate": f"{status.rate:,.0f} rec/s" if status.rate else "",
            "lag": "caught up" if status.caught_up else
            f"lag {status.behind} rec, {age(status.lag_seconds)}"}
        total = max(1, status.head_seq - status.start_seq)
        done = status.central_seq - status.start_seq
        with self._lock:
            if self._task is None:
                self._progress.start()
                self._task = self._progress.add_task("sync", total=total, completed=done,
                                                     **fields)
            else:
                self._progress.update(self._task, total=total, completed=done, **fields)

    def event(self, level: int, text: str) -> None:
        label = {logging.ERROR: "error:", logging.WARNING: "warning:"}.get(level, "note:")
        style = "bold red" if level >= logging.WARNING else "bold yellow"
        with self._lock:  # above the bar while it runs
            self._progress.console.print(Text.assemble((label, style), " ", printable(text)))

    def close(self) -> None:
        with self._lock:
            if self._task is not None:
                self._progress.stop()
                self._task = None


# -- verify --central ------------------------------------------------------------------------
def check_central(ledger: FaultLedger, central: str | None, token_file: Path | None,
                  settings: Settings) -> CentralCheck:
    """Compare the central's copy of this log with it; a central that cannot be asked is
    a failed verify (exit 1) naming the cause, never a pass."""
    url, token = central_inputs(central, token_file, settings)
    try:
        with CentralClient(url, token) as client:
            return check_against_central(RobotLog(ledger), client)
    except NoIdentityError as error:
        render.complain("verify FAILED:", f"nothing to compare with the central: {error}")
    except (CentralError, RobotLogError) as error:
        render.complain("verify FAILED:", f"cannot compare with the central: {error}")
    raise typer.Exit(1)


def with_central(report: VerifyReport, check: CentralCheck) -> VerifyReport:
    """``verify``'s report with the central's finding (like ``with_anchors``): the earliest
    first bad seq, the central's problem after the log's own."""
    if check.ok or check.problem is None:
        return report
    firsts = [s for s in (report.first_bad_seq, check.first_bad_seq) if s is not None]
    return replace(report, ok=False, first_bad_seq=min(firsts) if firsts else None,
                   problems=[*report.problems, f"central {check.central}: {check.problem}"])


def central_line(check: CentralCheck) -> str:
    """The OK line of `verify --central`."""
    held = ("the central holds no record of this log yet (sync pushes them)"
            if check.central_seq == 0 else
            f"its {check.compared} records of this log (seq 1..{check.central_seq}) are in "
            "this log, unchanged")
    waiting = (f"; {check.not_pushed} newer records not pushed yet" if check.not_pushed else "")
    return f"central {check.central}: {held}{waiting}{others_note(check)}"


def others_note(check: CentralCheck) -> str:
    """The robot's other logs at the central (a replaced database), or nothing."""
    if not check.other_logs:
        return ""
    logs = ", ".join(f"ledger_id {log.ledger_id} (seq 1..{log.last_seq}, last pushed "
                     f"{log.last_pushed_at})" for log in check.other_logs)
    count = len(check.other_logs)
    return (f"; the central also holds {count} other log{'s' if count > 1 else ''} of robot "
            f"{check.identity.robot_id}, not in this database (it was replaced since): {logs}")


def central_json(check: CentralCheck) -> dict[str, Any]:
    return {"url": check.central, "ok": check.ok, "compared": check.compared,
            "central_seq": check.central_seq, "head_seq": check.head_seq,
            "not_pushed": check.not_pushed, "first_bad_seq": check.first_bad_seq,
            "problem": check.problem,
            "other_logs": [{"ledger_id": log.ledger_id, "last_seq": log.last_seq,
                            "last_pushed_at": log.last_pushed_at} for log in check.other_logs]}
