"""Text from outside reaches a person literally: never as rich markup, never as a terminal
control sequence, never as HTML (docs/architecture.md, "What a person sees").

Hostile descriptions, source ids, actors, reasons and policy prefixes are stored through the
real API in a real SQLite file; the real CLI runs in a subprocess (piped, and under a real
pseudo-terminal at 80 columns) and its output is read as a person would see it.
"""

from __future__ import annotations

import fcntl
import io
import json
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from rich.console import Console
from rich.table import Table

from faultledger import FaultLedger, Policy
from faultledger.cli.render import complain
from faultledger.cli.safe_text import cell, printable
from faultledger.domain.policy import SourceOverride
from faultledger.reports import shift_html

OSC8 = "\x1b]8;;http://x\x1b\\click\x1b]8;;\x1b\\"
"""An OSC-8 hyperlink: ``click`` linking to http://x in a terminal that honours it."""
HOSTILE = {
    "MARKUP_CLOSE": "[/]",
    "MARKUP_STYLE": "[bold red]x[/]",
    "CLEAR_SCREEN": "\x1b[2J",
    "HYPERLINK": OSC8,
    "CARRIAGE_RETURN": "ok\rFAKE",
    "BIDI_OVERRIDE": "abc\u202edef",
    "NEWLINE": "one\ntwo",
    "C1_CSI": "\x9b31m red",
    "LINE_SEPARATOR": "a\u2028b\u2029c",
    "BELL_DEL": "\x07\x7f",
}
"""Fault code -> hostile text (its description; its source is "/x" + the text)."""
LONG_CODE = "LONG_DESCRIPTION"
LONG = (("[/]\x1b[2J" + "x" * 100 + "\n") * 40)[:4096]
"""4096 characters, the longest description the ledger takes."""
assert len(LONG) == 4096
CLEARED = "MARKUP_CLOSE"
"""Cleared with a hostile actor and reason."""
ACTOR = "[red]op[/]\x1b[31m\u202e"
REASON = "[/] done\r\nnext \x1b]8;;http://x\x1b\\y\x1b]8;;\x1b\\"
PREFIX = "/x[/]\x1b[2J"
"""A policy override prefix (recorded in the log as policy JSON)."""
T0 = datetime(2026, 11, 21, 7, 0, tzinfo=UTC)
"""Inside 2026-11-21/morning of the default calendar (06:00-14:00 UTC)."""
SHIFT, AS_OF = "2026-11-21/morning", "2026-11-21T20:00:00+00:00"

BOX = "┏┓┗┛┃━┡┩╇┯┷│─├┤┼└┘┌┐┬┴╭╮╰╯"
SGR = re.compile(r"\x1b\[[0-9;]*m")
"""rich's own colour codes on a terminal: the only escape sequences allowed there."""
UNSAFE_BYTE = re.compile(rb"[\x00-\x09\x0b-\x1f\x7f]|\xc2[\x80-\x9f]|\xe2\x80[\xa8-\xae]"
                         rb"|\xe2\x81[\xa6-\xa9]")
"""Any C0 control but LF, DEL, C1, U+2028-U+202E and U+2066-U+2069, as UTF-8 bytes."""


def url_of(path: Path) -> str:
    return f"sqlite:///{path}"


@pytest.fixture(scope="module")
def hostile_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("hostile") / "faults.db"
    policy = Policy(overrides={PREFIX: SourceOverride(healing_enabled=True)})
    with FaultLedger.open(url_of(path), policy=policy) as ledger:
        for i, (code, text) in enumerate(HOSTILE.items()):
            result = ledger.report(code, "FAILED", severity=1, description=text,
                                   source_id="/x" + text, at=T0 + timedelta(minutes=i))
            assert result.accepted, result.message
        result = ledger.report(LONG_CODE, "FAILED", severity=2, description=LONG,
                               source_id="/long", at=T0 + timedelta(minutes=30))
        assert result.accepted, result.message
        cleared = ledger.clear(CLEARED, actor=ACTOR, reason=REASON,
                               at=T0 + timedelta(hours=1))
        assert cleared.success, cleared.message
    return path


def cli(*args: str, db: Path | None = None) -> subprocess.CompletedProcess[bytes]:
    """The real CLI in a subprocess, stdout piped (not a terminal)."""
    extra = ["--db", url_of(db)] if db is not None else []
    return subprocess.run([sys.executable, "-m", "faultledger.cli.main", *args, *extra],
                          capture_output=True, timeout=120, env=_env())


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("COLUMNS", "LINES", "NO_COLOR", "FORCE_COLOR", "FAULTLEDGER_DEBUG")}
    env["TERM"] = "xterm-256color"
    return env


def assert_clean(done: subprocess.CompletedProcess[bytes]) -> str:
    """Exit 0, no traceback, and not one control byte but LF in stdout."""
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    assert b"Traceback" not in done.stderr
    bad = UNSAFE_BYTE.search(done.stdout)
    assert bad is None, f"control byte {bad.group()!r} at {bad.start()}"
    return done.stdout.decode("utf-8")


@dataclass
class Row:
    cells: list[str]
    lines: int


def table_rows(output: str, title: str) -> list[Row]:
    """The data rows of the rich table printed under ``title``: each cell's text rejoined
    across the lines it was folded onto (a row's first cell is never empty)."""
    lines = output.splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip().startswith(title))
    rows: list[Row] = []
    body = False
    for line in lines[start + 1:]:
        if line.startswith(("┡", "├")):
            body = True
            continue
        if line.startswith("└"):
            return rows
        assert line.startswith(("┏", "┃", "│")) and line.rstrip().endswith(("┓", "┃", "│")), \
            f"a line broke out of the table: {line!r}"
        if not body or not line.startswith("│"):
            continue
        parts = [part.strip() for part in line.rstrip()[1:-1].split("│")]
        if parts[0] or not rows:
            rows.append(Row(parts, 1))
        else:
            last = rows[-1]
            last.cells = [a + (" " if a and b else "") + b
                          for a, b in zip(last.cells, parts, strict=True)]
            last.lines += 1
    raise AssertionError(f"table {title!r} not closed")


def column_text(output: str, title: str, column: int) -> str:
    """All of one column of a table, top to bottom, without whitespace: where rows begin
    cannot be told once even the first column is folded (a narrow terminal)."""
    rows = table_rows(output, title)
    return "".join(squeeze(row.cells[column]) for row in rows)


def squeeze(text: str) -> str:
    """Folding and wrapping change only where spaces and line breaks fall."""
    return re.sub(r"\s+", "", text)


def shown_as(row: Row, column: int, expected: str) -> None:
    assert squeeze(row.cells[column]) == squeeze(printable(expected)), row.cells[column]


# -- printable / cell --------------------------------------------------------------------------
@pytest.mark.parametrize(("raw", "shown"), [
    ("\x1b[2J", "\\x1b[2J"),
    ("a\nb\rc\td", "a\\nb\\rc\\td"),
    ("\x00\x01\x1f\x7f", "\\x00\\x01\\x1f\\x7f"),
    ("\x80\x85\x9b\x9f", "\\x80\\x85\\x9b\\x9f"),
    ("\u202a\u202b\u202c\u202d\u202e", "\\u202a\\u202b\\u202c\\u202d\\u202e"),
    ("\u2066\u2067\u2068\u2069", "\\u2066\\u2067\\u2068\\u2069"),
    ("\u2028\u2029", "\\u2028\\u2029"),
    ("zero\u200bwidth\u200f\ufeff", "zero\\u200bwidth\\u200f\\ufeff"),
    ("tag\U000e0041", "tag\\U000e0041"),
    (OSC8, "\\x1b]8;;http://x\\x1b\\click\\x1b]8;;\\x1b\\"),
])
def test_printable_escapes_every_control_format_and_separator_character(
    raw: str, shown: str
) -> None:
    assert printable(raw) == shown
    assert printable(raw).isprintable()


@pytest.mark.parametrize("text", [
    "", "MOTOR_OVERHEAT 92 °C", "[/] [bold]x[/bold] :smile:", r"C:\path\x1b", "温度 ⚠ 🔥",
    "ünïcödé — ok", "tab-free text with  two spaces",
])
def test_printable_leaves_ordinary_text_as_it_is(text: str) -> None:
    assert printable(text) == text


def test_cell_is_never_markup_and_shows_the_text_literally() -> None:
    out = io.StringIO()
    console = Console(file=out, width=200, force_terminal=True, color_system="truecolor")
    table = Table()
    table.add_column("value")
    for text in [*HOSTILE.values(), ACTOR, REASON]:
        table.add_row(cell(text, "bold"))
    console.print(table)
    seen = SGR.sub("", out.getvalue())
    assert "\x1b" not in seen and "\r" not in seen
    for text in [*HOSTILE.values(), ACTOR, REASON]:
        assert printable(text) in seen


def test_complain_quotes_input_on_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    complain("error:", f"bad value {REASON}{OSC8}[/]")
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "\x1b" not in err
    assert err == f"error: bad value {printable(REASON)}{printable(OSC8)}[/]\n"


# -- the CLI, piped ----------------------------------------------------------------------------
def test_list_shows_every_hostile_fault_on_its_own_rows(hostile_db: Path) -> None:
    out = assert_clean(cli("list", "--all", db=hostile_db))
    rows = {row.cells[0]: row for row in table_rows(out, "faults in")}
    assert set(rows) == {*HOSTILE, LONG_CODE}
    for code, text in HOSTILE.items():
        shown_as(rows[code], 8, text)  # (column 3: who acknowledged)
        shown_as(rows[code], 7, "/x" + text)
        assert rows[code].lines <= 3
    shown_as(rows[LONG_CODE], 8, LONG)
    assert "[bold red]x[/]" in out and "\\x1b[2J" in out and "\\u202e" in out


def test_show_lists_the_fault_and_its_transitions_literally(hostile_db: Path) -> None:
    out = assert_clean(cli("show", CLEARED, db=hostile_db))
    [fault] = table_rows(out, f"fault {CLEARED}")
    shown_as(fault, 8, HOSTILE[CLEARED])
    moves = table_rows(out, "status transitions")
    assert [m.cells[3] for m in moves] == ["CONFIRMED", "CLEARED"]
    shown_as(moves[0], 5, "/x" + HOSTILE[CLEARED])
    shown_as(moves[1], 5, ACTOR)


def test_history_shows_reports_clears_and_policy_literally(hostile_db: Path) -> None:
    out = assert_clean(cli("history", db=hostile_db))
    rows = table_rows(out, "fault log")
    kinds = [r.cells[2] for r in rows]
    assert kinds.count("fault_reported") == len(HOSTILE) + 1
    assert "policy_changed" in kinds
    policy = rows[kinds.index("policy_changed")]
    assert squeeze(printable('"' + PREFIX.replace("\x1b", "\\u001b") + '"')) \
        in squeeze(policy.cells[5])
    [clear] = [r for r in rows if r.cells[2] == "fault_cleared"]
    shown_as(clear, 4, ACTOR)
    assert squeeze(clear.cells[5]) == squeeze(printable(f"cleared by {ACTOR}: {REASON}"))
    by_source = {squeeze(r.cells[4]): r for r in rows if r.cells[2] == "fault_reported"}
    for text in HOSTILE.values():
        row = by_source[squeeze(printable("/x" + text))]
        assert squeeze(printable(repr(text))) in squeeze(row.cells[5])


def test_history_export_keeps_the_exact_text(hostile_db: Path) -> None:
    done = cli("history", "--kind", "fault_cleared", "--format", "jsonl", db=hostile_db)
    assert done.returncode == 0
    [record] = [json.loads(line) for line in done.stdout.decode().splitlines()]
    assert record["source_id"] == ACTOR and record["payload"]["reason"] == REASON


def test_stats_grouped_by_source_shows_sources_literally(hostile_db: Path) -> None:
    out = assert_clean(cli("stats", "--by", "day", "--group-by", "source",
                           "--since", "2026-11-21T00:00Z", "--until", "2026-11-22T00:00Z",
                           "--as-of", AS_OF, db=hostile_db))
    rows = table_rows(out, "statistics by day")
    sources = {squeeze(r.cells[2]) for r in rows}
    for text in HOSTILE.values():
        assert squeeze(printable("/x" + text)) in sources


def test_report_shift_shows_sources_literally(hostile_db: Path) -> None:
    out = assert_clean(cli("report-shift", SHIFT, "--as-of", AS_OF, db=hostile_db))
    rows = table_rows(out, "longest downtimes")
    sources = {squeeze(r.cells[1]) for r in rows}
    for code, text in HOSTILE.items():  # the top 10: all but the cleared (shortest) episode
        if code != CLEARED:
            assert squeeze(printable("/x" + text)) in sources


def test_error_lines_quote_hostile_input_escaped(hostile_db: Path) -> None:
    done = cli("show", "NOPE\x1b[2J[/]\u202e", db=hostile_db)
    assert done.returncode == 1 and b"Traceback" not in done.stderr
    assert UNSAFE_BYTE.search(done.stderr) is None
    assert done.stderr.decode().count("\n") == 1
    done = cli("history", "--output", str(hostile_db.parent / "[red]\x1b[2J.jsonl"),
               "--format", "jsonl", db=hostile_db)
    assert done.returncode == 0, done.stderr
    assert UNSAFE_BYTE.search(done.stderr) is None and b"[red]\\x1b[2J.jsonl" in done.stderr


def test_demo_on_a_hostile_path_is_clean(tmp_path: Path) -> None:
    directory = tmp_path / "[red]\x1b[2J"
    directory.mkdir()
    out = assert_clean(cli("demo", db=directory / "demo.db"))
    assert "%5Bred%5D%1B%5B2J" in out and "verify: OK" in out  # the URL, percent-encoded


# -- the CLI on a real terminal ----------------------------------------------------------------
def run_in_terminal(*args: str, columns: int = 80) -> tuple[int, bytes]:
    """Run the CLI with a pseudo-terminal of ``columns`` columns as its stdout and stderr;
    returns the exit code and every byte the terminal received."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    try:
        child = subprocess.Popen([sys.executable, "-m", "faultledger.cli.main", *args],
                                 stdin=slave, stdout=slave, stderr=slave, env=_env(),
                                 close_fds=True)
    finally:
        os.close(slave)
    received = bytearray()
    try:
        while True:
            ready, _, _ = select.select([master], [], [], 60)
            if not ready:
                child.kill()
                raise AssertionError("the CLI printed nothing for 60 s")
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            received += chunk
    finally:
        os.close(master)
    return child.wait(timeout=60), bytes(received)


@pytest.mark.parametrize("command", [("list", "--all"), ("history",), ("show", CLEARED)])
def test_on_an_80_column_terminal_only_rich_colours_reach_it(
    hostile_db: Path, command: tuple[str, ...]
) -> None:
    code, raw = run_in_terminal(*command, "--db", url_of(hostile_db))
    text = raw.decode("utf-8").replace("\r\n", "\n")
    assert code == 0, text
    assert "Traceback" not in text
    assert SGR.search(text), "rich should colour a terminal"
    plain = SGR.sub("", text)
    bad = UNSAFE_BYTE.search(plain.encode("utf-8"))
    assert bad is None, f"control byte {bad.group()!r} reached the terminal"
    assert max(len(line) for line in plain.splitlines()) <= 80
    if command[0] == "list":  # codes are never split; descriptions do not fit in 80 columns
        codes = column_text(plain, "faults in", 0)
        assert "description" not in plain
        code, raw = run_in_terminal(*command, "--db", url_of(hostile_db), columns=200)
        wide = SGR.sub("", raw.decode("utf-8").replace("\r\n", "\n"))
        assert code == 0, wide
        assert UNSAFE_BYTE.search(wide.encode("utf-8")) is None
        descriptions = column_text(wide, "faults in", 7)
        for code_, hostile in HOSTILE.items():
            assert code_ in codes
            assert squeeze(printable(hostile)) in descriptions


# -- HTML --------------------------------------------------------------------------------------
HTML_HOSTILE = '<script>alert(1)</script>"onmouseover=alert(2) x=\'[/]\x1b]8;;http://x\x1b\\'


def assert_html_safe(page: str) -> None:
    assert "<script" not in page
    assert '"onmouseover' not in page and "'[/]" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;&#34;onmouseover=alert(2) x=&#39;[/]" \
           "\\x1b]8;;http://x\\x1b\\" in page
    bad = UNSAFE_BYTE.search(page.encode("utf-8"))
    assert bad is None, f"control byte {bad.group()!r} in the HTML"


def test_report_shift_html_escapes_sources_and_descriptions(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url_of(path)) as ledger:
        for i, code in enumerate(["SCRIPT_A", "SCRIPT_B"]):
            result = ledger.report(code, "FAILED", severity=3, description=HTML_HOSTILE,
                                   source_id="/s" + HTML_HOSTILE,
                                   at=T0 + timedelta(minutes=i))
            assert result.accepted, result.message
    target = tmp_path / "report.html"
    done = cli("report-shift", SHIFT, "--as-of", AS_OF, "--html", str(target), db=path)
    assert_clean(done)
    page = target.read_text(encoding="utf-8")
    downtimes = page[page.index("<h2>Longest downtimes</h2>"):page.index("<h2>Per hour</h2>")]
    assert downtimes.count("/s&lt;script&gt;") == 2
    assert_html_safe(page)


def _hostile_context(value: str) -> dict[str, Any]:
    table = {"headers": [{"text": value, "cls": value}],
             "rows": [[{"text": value, "cls": value}, {"text": value, "cls": ""}]]}
    return {"shift_id": value, "span_text": value, "length_text": value, "previous_id": value,
            "in_progress_until": value, "notes": [value], "dst_change": True, "top": value,
            "timezone": value, "shift_name": value, "estop_codes": value,
            "as_of": value, "figures": table, "offenders": table, "downtimes": table,
            "hours": table, "offenders_png": value, "hours_png": value, "headline": value,
            "glossary": [{"term": value, "meaning": value}]}


def test_every_slot_of_the_html_template_is_escaped_attributes_too() -> None:
    """Every value the template shows, including class and alt attributes and the image
    data, given the hostile text: nothing comes out raw."""
    template = shift_html._environment().get_template(shift_html.TEMPLATE)
    page = template.render(_hostile_context(HTML_HOSTILE))
    assert_html_safe(page)
    escaped = "&lt;script&gt;alert(1)&lt;/script&gt;&#34;onmouseover=alert(2)"
    assert f'class="{escaped}' in page and f'alt="top offenders of {escaped}' in page
    assert page.count(escaped) >= 20



# -- faultledger nodes -------------------------------------------------------------------------
def test_nodes_view_rows_show_publisher_text_literally() -> None:
    """Node names, package, type and messages come from any publisher on /nodemon/state."""
    nodes_view = pytest.importorskip("faultledger.cli.nodes_view")  # needs rclpy
    from faultledger.ros.bridges.node_state import node_state_type

    pytest.importorskip("nodemon_msgs.msg")  # built by `make interfaces`
    node_state = node_state_type()
    view = nodes_view.NodesView()
    texts = list(HOSTILE.values())
    for i, text in enumerate(texts):
        message = node_state()
        message.nodename, message.package, message.nodetype = f"/n{i}{text}", text, text
        message.state = 2
        message.human_message, message.machine_message = text, REASON
        view.on_state(message)
    rows = view.rows(now=0.0)
    assert len(rows) == len(texts)
    by_name = {row[0].plain: row for row in rows}
    for i, text in enumerate(texts):
        row = by_name[printable(f"/n{i}{text}")]
        assert [c.plain for c in row[1:3]] == [printable(text)] * 2
        assert row[5].plain == printable(f"{text} [{REASON}]")
        assert not row[0].spans  # a Text with the name as content, no markup parsed
    out = io.StringIO()
    Console(file=out, width=200, force_terminal=True, color_system="truecolor").print(
        view.table(now=0.0))
    plain = SGR.sub("", out.getvalue())
    assert UNSAFE_BYTE.search(plain.encode("utf-8")) is None
    shown = table_rows(plain, "nodes on /nodemon/state")  # no line broke out of the table
    assert sorted(row.cells[0] for row in shown) == sorted(by_name)  # one row per node
    for row in shown:
        assert squeeze(row.cells[5]) == squeeze(by_name[row.cells[0]][5].plain)
