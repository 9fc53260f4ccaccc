"""The audit commands: `history` (filters, CSV/JSON Lines export), `verify` (whole log or a
segment) and `state-at` (the fault table as of a seq or time). Registered by cli/main.py.

They only read: the database is never created, migrated or written. Bad input is one line on
stderr and exit 2; a failed check is exit 1.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from faultledger.cli import render
from faultledger.cli.fleet import (
    CentralOption,
    TokenFileOption,
    central_json,
    central_line,
    check_central,
    with_central,
)
from faultledger.cli.options import (
    TIME_HELP,
    ConfigOption,
    DbOption,
    JsonOption,
    RobotOption,
    ShiftsOption,
    WideOption,
    opened,
    parse_moment,
    parse_time,
    prepare,
)
from faultledger.cli.options import fail as _fail
from faultledger.cli.safe_text import cell
from faultledger.domain.clock import from_ns, iso_ns, to_ns
from faultledger.domain.events import KINDS
from faultledger.domain.fault import Fault
from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.integrity import GENESIS_HASH
from faultledger.domain.shifts import ShiftCalendar
from faultledger.errors import FaultLedgerError
from faultledger.fleet.check import CentralCheck
from faultledger.service.anchors import (
    AnchorCheck,
    load_public_key,
    newest_anchor,
    verify_anchors,
    with_anchors,
)
from faultledger.service.audit import export_history, seq_recorded_by, seqs_recorded_between
from faultledger.service.bootstrap import LedgerConfig
from faultledger.service.config import config_path, load_settings
from faultledger.service.exports import Tagged, Writer, write_csv, write_jsonl
from faultledger.service.fleet import Fleet
from faultledger.service.ledger import FaultLedger
from faultledger.service.output_files import OutputFileError, check_target, open_text_output
from faultledger.store.event_log import StoredRecord


class Format(StrEnum):
    """Output of `history`: a terminal table, or an export with every stored column."""

    table = "table"
    csv = "csv"
    jsonl = "jsonl"




def register(app: typer.Typer) -> None:
    """Add the audit commands to the `faultledger` app."""
    app.command("history")(history)
    app.command("verify")(verify)
    app.command("state-at")(state_at)


def history(
    code: Annotated[list[str] | None, typer.Option(
        "--code", metavar="GLOB", help="Fault code, or a case-sensitive glob such as "
        "'HW_*_EMERGENCY_STOP' (repeatable: any of them).")] = None,
    source: Annotated[str | None, typer.Option("--source", metavar="ID",
                                               help="Exact source id.")] = None,
    since: Annotated[str | None, typer.Option(
        "--since", metavar="TIME", help=f"occurred_at from (inclusive): {TIME_HELP}.")] = None,
    until: Annotated[str | None, typer.Option(
        "--until", metavar="TIME", help="occurred_at before (exclusive); like --since, a "
        "shift id means its end.")] = None,
    from_seq: Annotated[int | None, typer.Option(
        "--from-seq", min=1, metavar="SEQ", help="First seq (inclusive).")] = None,
    to_seq: Annotated[int | None, typer.Option(
        "--to-seq", min=1, metavar="SEQ", help="Last seq (inclusive).")] = None,
    kind: Annotated[list[str] | None, typer.Option(
        "--kind", metavar="KIND", help=f"Record kind (repeatable): {', '.join(KINDS)}.")
    ] = None,
    limit: Annotated[int | None, typer.Option("--limit", min=1, metavar="N",
                                              help="At most this many records.")] = None,
    fmt: Annotated[Format | None, typer.Option(
        "--format", metavar="FORMAT", help="table (default), csv or jsonl (JSON Lines).")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Same as --format jsonl.")] = False,
    as_csv: Annotated[bool, typer.Option("--csv", help="Same as --format csv.")] = False,
    output: Annotated[Path | None, typer.Option(
        "--output", "-o", metavar="FILE",
        help="Write the export to this file (default: stdout); an existing "
        "file is kept unless --force.")] = None,
    force: Annotated[bool, typer.Option(
        "--force", help="Replace an existing --output file.")] = False,
    wide: WideOption = False,
    robot: RobotOption = None,
    ledger_id: Annotated[str | None, typer.Option(
        "--ledger", metavar="ID",
        help="With --robot: only this log of the robot (its ledger_id).")] = None,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """The audit history: log records in seq order.

    The table shows times in the calendar's zone; CSV/JSON Lines carry every stored column
    and hash (times in ISO 8601 with their offset), so the chain can be recomputed from the
    export alone.
    """
    chosen = _output_format(fmt, as_json, as_csv)
    _check_seq_range(from_seq, to_seq)
    if output is not None and chosen is Format.table:
        _fail("--output writes an export: add --format csv or --format jsonl")
    if output is not None:
        try:
            check_target(output, force)  # before the query: refuse early, write nothing
        except OutputFileError as error:
            _fail(str(error))
    setup = prepare(db, config, shifts=shifts)
    filters: dict[str, Any] = {
        "codes": code or None, "source": source,
        "since": parse_time(since, "--since", setup.calendar),
        "until": parse_time(until, "--until", setup.calendar, upper=True),
        "kinds": kind or (), "limit": limit, "from_seq": from_seq, "to_seq": to_seq,
    }
    if ledger_id is not None and robot is None:
        _fail("--ledger needs --robot NAME (a fleet central's copy of that robot's log)")
    if robot is not None:
        _robot_history(setup, robot, ledger_id, filters, chosen, wide, output, force)
        return
    with opened(setup) as ledger:
        if chosen is Format.table:
            records = ledger.history(**filters)
            out = render.console(wide=wide)
            out.print(render.history_table(records, setup.calendar,
                                           render.fit_width(out, wide)))
            return
        rows = export_history(ledger, **filters)
        writer = write_csv if chosen is Format.csv else write_jsonl
        count = _export(rows, writer, ledger.identity, output, force)
    if output is not None:
        render.console(stderr=True).print(cell(f"wrote {count} records to {output}"))


def _robot_history(setup: LedgerConfig, robot: str, ledger_id: str | None,
                   filters: dict[str, Any], chosen: Format, wide: bool, output: Path | None,
                   force: bool) -> None:
    """``history --robot``: the robot's logs as a fleet central holds them, each exactly as
    the robot's own history gives it, log after log (a table per log)."""
    with opened(setup) as central, Fleet(central) as robot_logs:
        try:
            chains = robot_logs.chains_of(robot, ledger_id)
        except FaultLedgerError as error:
            _fail(str(error))
        if chosen is Format.table:
            out = render.console(wide=wide)
            for chain in chains:
                with robot_logs.log(chain) as ledger:
                    records = ledger.history(**filters)
                out.print(cell(f"robot {chain.robot_id}, log {chain.ledger_id}"))
                out.print(render.history_table(records, setup.calendar,
                                               render.fit_width(out, wide)))
            return
        rows = (Tagged(identity, row) for identity, row in robot_logs.history(
            robot, ledger_id, **filters))
        writer = write_csv if chosen is Format.csv else write_jsonl
        count = _export(rows, writer, None, output, force)
    if output is not None:
        render.console(stderr=True).print(cell(f"wrote {count} records to {output}"))


def verify(
    from_seq: Annotated[int | None, typer.Option(
        "--from-seq", min=1, metavar="SEQ",
        help="First seq of the segment (its predecessor's stored hash "
        "is the anchor).")] = None,
    to_seq: Annotated[int | None, typer.Option(
        "--to-seq", min=1, metavar="SEQ", help="Last seq of the segment (inclusive).")] = None,
    since: Annotated[str | None, typer.Option(
        "--since", metavar="TIME", help=f"Segment from the first record recorded at or after this: "
        f"{TIME_HELP}.")] = None,
    until: Annotated[str | None, typer.Option(
        "--until", metavar="TIME",
        help="Segment up to the last record recorded at or before this (the "
        "prefix `state-at` uses); a shift id means its end.")] = None,
    anchor_file: Annotated[list[Path] | None, typer.Option(
        "--anchor", metavar="FILE",
        help="Signed anchor file (repeatable; `faultledger anchor`): its record "
        "must be stored with the anchored hash, the chain intact up to it. Default: the newest "
        "in the config's anchors.directory when anchors.public_key is set too.")] = None,
    public_key: Annotated[Path | None, typer.Option(
        "--public-key", metavar="FILE",
        help="The trusted Ed25519 public key (PEM) anchors must be signed "
        "with (default: the config's anchors.public_key).")] = None,
    central: CentralOption = None,
    token_file: TokenFileOption = None,
    robot: RobotOption = None,
    as_json: JsonOption = False,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Check the hash chain and the projections (a full replay).

    For the whole log, also that the projections equal a full replay and SQLite's integrity
    check passes; with a range, only that segment, from the stored hash of the record before
    it. With anchors, also that the log still holds what they signed. With --central, also
    that every record a fleet central holds of this log is in it, unchanged.
    """
    if (since is not None or until is not None) and (from_seq is not None or to_seq is not None):
        _fail("give a seq range (--from-seq/--to-seq) or a time range (--since/--until), "
              "not both")
    _check_seq_range(from_seq, to_seq)
    anchor_paths, trusted = _anchor_inputs(anchor_file, public_key, config)
    if robot is not None:
        if (from_seq, to_seq, since, until, central) != (None,) * 5:
            _fail("--robot checks every log of the robot whole: no range, no --central")
        _verify_robot(prepare(db, config, shifts=shifts), robot, anchor_paths, trusted,
                      as_json)
        return
    matched: list[AnchorCheck] = []
    if token_file is not None and central is None:
        _fail("--token-file needs --central URL")
    settings = load_settings(config_path(config)) if central is not None else None
    witness: CentralCheck | None = None
    setup = prepare(db, config, shifts=shifts)
    first_time = parse_time(since, "--since", setup.calendar)
    last_time = parse_time(until, "--until", setup.calendar, upper=True)
    with opened(setup, verifying=True) as ledger:
        start, end = from_seq, to_seq
        if since is not None or until is not None:
            start, end = seqs_recorded_between(ledger, first_time, last_time)
        ranged = start is not None or end is not None
        report_ = ledger.verify(start, end) if ranged else ledger.verify()
        first = 1 if start is None else start
        anchor = _stored_hash(ledger, first - 1) if ranged else GENESIS_HASH
        if trusted is not None:
            anchored = verify_anchors(ledger, anchor_paths, trusted)
            report_, matched = with_anchors(report_, anchored), anchored.matched
        if settings is not None:
            witness = check_central(ledger, central, token_file, settings)
            report_ = with_central(report_, witness)
    if as_json:
        data: dict[str, Any] = {
            "ok": report_.ok, "records": report_.records, "head_seq": report_.head_seq,
            "head_hash": report_.head_hash, "first_bad_seq": report_.first_bad_seq,
            "problems": report_.problems,
            "robot_id": None if report_.identity is None else report_.identity.robot_id,
            "ledger_id": None if report_.identity is None else report_.identity.ledger_id}
        if ranged:
            data.update({"from_seq": first, "to_seq": end, "anchor_seq": first - 1,
                         "anchor_hash": anchor})
        if trusted is not None:
            data["anchors"] = [{"file": str(m.path), "seq": m.anchor.seq,
                                "hash": m.anchor.hash, "key_id": m.anchor.key_id,
                                "anchored_at": iso_ns(m.anchor.anchored_at_ns)}
                               for m in matched]
        if witness is not None:
            data["central"] = central_json(witness)
        typer.echo(json.dumps(data, indent=2))
    elif report_.ok and not ranged:
        render.say(f"OK: {report_.records} records, chain intact, projections "
                   f"equal a full replay; head seq {report_.head_seq} hash "
                   f"{report_.head_hash}")
    elif report_.ok:
        origin = ("the genesis hash" if first == 1
                  else f"the stored hash of record {first - 1} ({anchor})")
        render.say(f"OK: records {first}..{report_.head_seq} ({report_.records} "
                   f"records), chain intact from {origin}; seq {report_.head_seq} "
                   f"hash {report_.head_hash}")
    else:
        for problem in report_.problems:
            render.complain("FAILED:", problem)
        if report_.first_bad_seq is not None:
            typer.echo(f"first bad seq: {report_.first_bad_seq}")
    if not as_json:
        render.say(_identity_line(report_.identity))
    if report_.ok and not as_json:
        for m in matched:
            render.say(f"anchor {m.path}: seq {m.anchor.seq} hash {m.anchor.hash} "
                       f"(made {render.zoned(from_ns(m.anchor.anchored_at_ns), setup.calendar)}"
                       f", key "
                       f"{m.anchor.key_id}) matches")
        if witness is not None:
            render.say(central_line(witness))
    if not report_.ok:
        raise typer.Exit(1)


def _verify_robot(setup: LedgerConfig, robot: str, anchor_paths: list[Path],
                  trusted: Any, as_json: bool) -> None:
    """``verify --robot``: every log of the robot a fleet central holds, checked as the
    robot's own verify checks it (chain, head, projections and statistics equal to a full
    replay), and anchors signed on the robot against each log they belong to."""
    results: list[dict[str, Any]] = []
    ok = True
    with opened(setup, verifying=True) as central, Fleet(central) as robot_logs:
        try:
            chains = robot_logs.chains_of(robot)
        except FaultLedgerError as error:
            _fail(str(error))
        for chain in chains:
            with robot_logs.log(chain) as ledger:
                report_ = ledger.verify()
                matched: list[AnchorCheck] = []
                # Anchors signed on the robot belong to the log it writes now: its newest.
                if trusted is not None and anchor_paths and chain is chains[-1]:
                    anchored = verify_anchors(ledger, anchor_paths, trusted)
                    report_, matched = with_anchors(report_, anchored), anchored.matched
            ok = ok and report_.ok
            results.append({"robot_id": chain.robot_id, "ledger_id": chain.ledger_id,
                            "ok": report_.ok, "records": report_.records,
                            "head_seq": report_.head_seq, "head_hash": report_.head_hash,
                            "first_bad_seq": report_.first_bad_seq,
                            "problems": report_.problems,
                            "anchors": [str(m.path) for m in matched]})
    if as_json:
        typer.echo(json.dumps({"ok": ok, "robot_id": robot, "logs": results}, indent=2))
    else:
        for found in results:
            where = f"robot {found['robot_id']}, log {found['ledger_id']}"
            if found["ok"]:
                render.say(f"OK: {where}: {found['records']} records, chain intact, "
                           f"projections equal a full replay; head seq {found['head_seq']} "
                           f"hash {found['head_hash']}"
                           + "".join(f"; anchor {a} matches" for a in found["anchors"]))
            else:
                for problem in found["problems"]:
                    render.complain("FAILED:", f"{where}: {problem}")
                if found["first_bad_seq"] is not None:
                    typer.echo(f"first bad seq: {found['first_bad_seq']}")
    if not ok:
        raise typer.Exit(1)


def state_at(
    when: Annotated[str, typer.Argument(
        metavar="WHEN|SEQ", help=f"A seq number, or a time: {TIME_HELP}. A time means the "
        "records recorded at or before it (what the ledger knew then).")],
    as_json: JsonOption = False,
    wide: WideOption = False,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """The fault table (every status) as of a seq or a time.

    A replay of that log prefix, with the hash of its last record, which anchors it. A time
    means what the ledger knew then: the records recorded at or before it.
    """
    setup = prepare(db, config, shifts=shifts)
    moment = parse_moment(when, "WHEN|SEQ", setup.calendar)
    with opened(setup) as ledger:
        prefix = log_prefix(ledger, moment, setup.calendar, strict=True)
        digest = _stored_hash(ledger, prefix.seq)
    at = None if isinstance(moment, int) else moment.astimezone(UTC).isoformat()
    if as_json:
        typer.echo(json.dumps({"seq": prefix.seq, "hash": digest, "at": at,
                               "faults": [render.fault_dict(f) for f in prefix.faults]},
                              indent=2))
    else:
        out = render.console(wide=wide)
        out.print(render.faults_table(prefix.faults, prefix.title, setup.calendar,
                                      render.fit_width(out, wide)))
        out.print(cell(f"seq {prefix.seq} hash {digest}"))
    for note in prefix.notes:
        render.note(note)


@dataclass(frozen=True, slots=True)
class Prefix:
    """The fault table after a prefix of the log (`state-at`, `list --at`)."""

    seq: int
    faults: list[Fault]
    title: str
    notes: list[str]


LATE_SHOWN = 1000
"""Up to how many late records the note counts exactly."""


def log_prefix(ledger: FaultLedger, moment: datetime | int, calendar: ShiftCalendar, *,
               strict: bool = False) -> Prefix:
    """The table after seq ``moment``, or after the records recorded by a time, with the notes
    a person needs to read it: records recorded later that occurred before that time (the
    table is by recording time), nothing recorded yet, and (``list --at``, not ``strict``) a
    seq past the end of the log, which shows the current table."""
    notes: list[str] = []
    if isinstance(moment, int):
        if strict:
            seq = seq_recorded_by(ledger, moment)  # a seq past the end is an error
            return Prefix(seq, ledger.state_at(seq), f"faults as of seq {seq}", notes)
        faults = ledger.state_at(moment)  # checks the number; past the end: the whole log
        head = ledger.last_seq
        if moment > head:
            notes.append(f"seq {moment} is past the end of the log (its last seq is {head}): "
                         f"this is the table after seq {head}, the current one")
        seq = min(moment, head)
        return Prefix(seq, faults, f"faults as of seq {seq}", notes)
    seq = seq_recorded_by(ledger, moment)
    shown = render.zoned(moment, calendar)
    late = ledger.history(until=to_ns(moment) + 1, from_seq=seq + 1, limit=LATE_SHOWN + 1)
    if late:
        count = (f"more than {LATE_SHOWN} records" if len(late) > LATE_SHOWN
                 else "1 record" if len(late) == 1 else f"{len(late)} records")
        local = moment.astimezone(calendar.zone).isoformat(timespec="seconds")
        notes.append(f"the table is by recording time (what the ledger knew at {shown}): "
                     f"{count} recorded later occurred before it (sent late or back-dated, "
                     f"first seq {late[0].seq}) and are not in it; what occurred before it: "
                     f"faultledger history --until {local}")
    elif seq == 0:
        first = ledger.history(from_seq=1, to_seq=1)
        if first:
            notes.append(f"nothing was recorded at or before {shown}: the log's first record "
                         f"was recorded at "
                         f"{render.zoned(from_ns(first[0].recorded_at_ns), calendar)}")
    return Prefix(seq, ledger.state_at(seq),
                  f"faults as of seq {seq} (recorded at or before {shown})", notes)


# -- export ----------------------------------------------------------------------------------

def _export(rows: Iterator[StoredRecord] | Iterator[Tagged], write: Writer,
            identity: LedgerIdentity | None, output: Path | None, force: bool = False) -> int:
    """Stream rows out. A file appears only once complete (cli/output_files.py: a temporary
    file of its own beside it, then renamed; an existing one only replaced with ``force``)."""
    if output is None:
        try:
            count = write(rows, sys.stdout, identity)
            sys.stdout.flush()
        except BrokenPipeError:  # `| head`: the reader left; say nothing more
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            raise typer.Exit(1) from None
        return count
    try:
        with open_text_output(output, force) as out:
            count = write(rows, out, identity)
    except OutputFileError as error:
        _fail(str(error))
    return count


# -- helpers ---------------------------------------------------------------------------------
def _check_seq_range(from_seq: int | None, to_seq: int | None) -> None:
    if from_seq is not None and to_seq is not None and from_seq > to_seq:
        _fail(f"--from-seq {from_seq} is after --to-seq {to_seq}: the range is empty")


def _output_format(fmt: Format | None, as_json: bool, as_csv: bool) -> Format:
    chosen = [f for f in (fmt, Format.jsonl if as_json else None, Format.csv if as_csv else None)
              if f is not None]
    if len(set(chosen)) > 1:
        _fail("choose one output format: --format, --json or --csv")
    return chosen[0] if chosen else Format.table


def _anchor_inputs(files: list[Path] | None, public_key: Path | None, config: Path | None
                   ) -> tuple[list[Path], Ed25519PublicKey | None]:
    """The anchor files `verify` checks and the trusted key; no key: no anchor check.

    Without --anchor, the newest anchor in the config's anchors.directory is checked when the
    config also names anchors.public_key (an empty directory: a note, the chain alone).
    """
    try:
        settings = load_settings(config_path(config)).anchors
        key_path = public_key or settings.public_key
        paths = list(files or [])
        if not paths and settings.directory is not None and key_path is not None:
            newest = newest_anchor(settings.directory)
            if newest is None:
                render.complain("note:", f"no anchor in {settings.directory}: only the "
                                "chain is checked")
                return [], None
            paths = [newest]
        if paths and key_path is None:
            _fail("--anchor needs the trusted key: --public-key FILE (or anchors.public_key "
                  "in the config)")
        if key_path is not None and not paths:
            _fail("--public-key needs an anchor: --anchor FILE (or anchors.directory in the "
                  "config)")
        return paths, None if key_path is None else load_public_key(key_path)
    except FaultLedgerError as error:
        _fail(str(error))


def _identity_line(identity: LedgerIdentity | None) -> str:
    """Whose log was verified: what the log records, not what this machine is configured as."""
    if identity is None:
        return "robot_id and ledger_id: none recorded yet (the next writer records them)"
    return f"robot_id {identity.robot_id}, ledger_id {identity.ledger_id}"


def _stored_hash(ledger: FaultLedger, seq: int) -> str | None:
    """The stored hash of record ``seq`` (the genesis hash for 0), None when it is missing."""
    if seq == 0:
        return GENESIS_HASH
    return next((r.hash for r in export_history(ledger, from_seq=seq, to_seq=seq)), None)
