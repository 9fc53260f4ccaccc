"""Signed anchors of the log head (Ed25519): what the hash chain alone cannot prove.

Someone who can write the database can delete its newest records and move the checkpoint back,
or recompute every hash after an edit: the chain is then consistent again. An anchor is the
seq and hash of the head at some moment, signed with a key kept outside the database; checked
against the trusted public key it proves that the log held exactly that record at that seq,
so every record up to it (the hash folds in all of them) is the one that existed then.

An anchor file is one JSON object: ``format``, ``seq``, ``hash``, ``recorded_at_ns`` and
``recorded_at`` (of the head record), ``anchored_at_ns`` and ``anchored_at`` (when the anchor
was made), ``key_id`` (sha256 of the raw public key, first 16 hex digits), and ``signature``:
base64 of the Ed25519 signature over the canonical JSON (``canonical_json``) of all the other
fields. An empty log is not anchored (there is nothing to prove).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import json
import logging
import os
import re
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from cryptography.exceptions import InvalidSignature, UnsupportedAlgorithm
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import (
    Ed25519PrivateKey,
    Ed25519PublicKey,
)

from faultledger.domain.clock import NS_PER_SECOND, iso_ns
from faultledger.domain.integrity import canonical_json
from faultledger.errors import FaultLedgerError
from faultledger.service.config import AnchorSettings
from faultledger.service.ledger import FaultLedger
from faultledger.service.output_files import write_output
from faultledger.service.results import VerifyReport
from faultledger.store import event_log

log = logging.getLogger(__name__)

FORMAT = "faultledger-anchor/1"
FILE_MODE = 0o640
PRIVATE_KEY_MODE = 0o600
PUBLIC_KEY_MODE = 0o644
_HASH = re.compile(r"[0-9a-f]{64}")
_FILE_NAME = re.compile(r"anchor-\d{8}T\d{6}\.\d{3}Z-seq(\d+)\.json")
"""Names of the files `serve` writes: time (UTC, ms) first, so they sort by time."""


class AnchorError(FaultLedgerError):
    """A key or anchor file cannot be read or written, or is not what it must be."""


class AnchorRefused(AnchorError):
    """The log is in no state to be anchored (empty, broken chain, changed since the last)."""


# -- keys ----------------------------------------------------------------------------------------
def key_id(public_key: Ed25519PublicKey) -> str:
    """sha256 of the raw 32-byte public key, first 16 hex digits: names the key in anchors."""
    raw = public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).hexdigest()[:16]


def new_key_pair() -> tuple[Ed25519PrivateKey, bytes, bytes]:
    """A new Ed25519 key and its PEM files' contents: private (PKCS8, unencrypted), public."""
    private = Ed25519PrivateKey.generate()
    private_pem = private.private_bytes(serialization.Encoding.PEM,
                                        serialization.PrivateFormat.PKCS8,
                                        serialization.NoEncryption())
    public_pem = private.public_key().public_bytes(
        serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo)
    return private, private_pem, public_pem


def load_private_key(path: Path) -> Ed25519PrivateKey:
    """An unencrypted PEM Ed25519 private key (what ``generate_keys`` writes)."""
    data = _read(path, "private key")
    try:
        key = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError, UnsupportedAlgorithm) as error:
        raise AnchorError(f"{path} is not an unencrypted PEM private key: {error}") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise AnchorError(f"{path} is not an Ed25519 key ({type(key).__name__})")
    return key


def load_public_key(path: Path) -> Ed25519PublicKey:
    """A PEM Ed25519 public key: the one key anchors are trusted from."""
    data = _read(path, "public key")
    try:
        key = serialization.load_pem_public_key(data)
    except (ValueError, UnsupportedAlgorithm) as error:
        raise AnchorError(f"{path} is not a PEM public key: {error}") from None
    if not isinstance(key, Ed25519PublicKey):
        raise AnchorError(f"{path} is not an Ed25519 public key ({type(key).__name__})")
    return key


MAX_FILE_BYTES = 64 * 1024
"""More than any key or anchor file holds (an anchor is about 500 bytes): a larger file, or a
device such as /dev/zero, is refused after reading this much, never read into memory whole."""


def _read(path: Path, what: str) -> bytes:
    try:
        with path.open("rb") as file:
            data = file.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise AnchorError(f"cannot read {what} {path}: {error.strerror or error}") from None
    if len(data) > MAX_FILE_BYTES:
        raise AnchorError(f"cannot read {what} {path}: it holds more than "
                          f"{MAX_FILE_BYTES // 1024} KiB (no {what} file is that large)")
    return data


# -- files ---------------------------------------------------------------------------------------
def anchor_file_name(anchor: Anchor) -> str:
    """``anchor-20261121T230000.123Z-seq4711.json``: when it was made (UTC), then its seq."""
    moment = datetime.fromtimestamp(anchor.anchored_at_ns // NS_PER_SECOND, tz=UTC)
    millis = anchor.anchored_at_ns % NS_PER_SECOND // 1_000_000
    return f"anchor-{moment:%Y%m%dT%H%M%S}.{millis:03d}Z-seq{anchor.seq}.json"


def anchor_files(directory: Path) -> list[Path]:
    """The anchor files `serve` wrote to ``directory``, oldest first (by the time in the name).

    Raises AnchorError when the directory cannot be listed.
    """
    try:
        names = [entry.name for entry in os.scandir(directory)
                 if _FILE_NAME.fullmatch(entry.name)]
    except OSError as error:
        raise AnchorError(f"cannot list anchor directory {directory}: "
                          f"{error.strerror or error}") from None
    return [directory / name for name in sorted(names)]


def newest_anchor(directory: Path) -> Path | None:
    """The file in ``directory`` anchoring the highest seq (then the latest), None if none."""
    files = anchor_files(directory)
    return max(files, key=lambda p: (_named_seq(p), p.name)) if files else None


def _named_seq(path: Path) -> int:
    match = _FILE_NAME.fullmatch(path.name)
    return int(match[1]) if match else -1


# -- making anchors ------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Anchor:
    """The signed statement "record ``seq`` of the log had hash ``hash``"."""

    seq: int
    hash: str
    recorded_at_ns: int
    anchored_at_ns: int
    key_id: str
    signature: str
    """base64 of the Ed25519 signature over the canonical JSON of the other fields."""

    def document(self) -> dict[str, Any]:
        """The anchor file's JSON object."""
        return {**_signed_fields(self.seq, self.hash, self.recorded_at_ns, self.anchored_at_ns,
                                 self.key_id), "signature": self.signature}

    def to_json(self) -> bytes:
        return (json.dumps(self.document(), indent=2) + "\n").encode("utf-8")


def _signed_fields(seq: int, digest: str, recorded_at_ns: int, anchored_at_ns: int,
                   key: str) -> dict[str, Any]:
    return {"format": FORMAT, "seq": seq, "hash": digest, "recorded_at_ns": recorded_at_ns,
            "recorded_at": iso_ns(recorded_at_ns), "anchored_at_ns": anchored_at_ns,
            "anchored_at": iso_ns(anchored_at_ns), "key_id": key}



def make_anchor(ledger: FaultLedger, key: Ed25519PrivateKey, *,
                after: tuple[int, str] | None = None, now_ns: int | None = None) -> Anchor:
    """A signed anchor of the stored head of the log.

    The chain up to the head is checked first, so an anchor never certifies a broken chain:
    from seq 1, or, given ``after`` (the seq and hash of an earlier anchor, still stored), only
    the records after it. Raises AnchorRefused for an empty log, a broken chain, or a record
    ``after`` names that is gone or changed (the log was tampered with since).
    """
    with ledger._db.reading() as conn:
        seq, digest = event_log.head(conn)
        if seq == 0:
            raise AnchorRefused("the log is empty: there is nothing to anchor")
        start = 1
        if after is not None:
            stored = event_log.hash_at(conn, after[0])
            if stored is None:
                raise AnchorRefused(
                    f"record {after[0]}, anchored before, is gone (the log ends at seq {seq}): "
                    "records were removed; not anchoring (run `faultledger verify --anchor`)")
            if stored != after[1]:
                raise AnchorRefused(
                    f"record {after[0]} no longer has the hash anchored before: the log was "
                    "changed; not anchoring (run `faultledger verify --anchor`)")
            start = after[0] + 1
        if start <= seq:
            chain = event_log.check_chain(conn, start, seq)
            if chain.problem is not None:
                raise AnchorRefused(f"the hash chain is broken, not anchoring: {chain.problem}")
        head = event_log.find(conn, event_log.RecordFilter(from_seq=seq, to_seq=seq))[0]
    public = key.public_key()
    fields = _signed_fields(seq, digest, head.recorded_at_ns,
                            time.time_ns() if now_ns is None else now_ns, key_id(public))
    signature = key.sign(canonical_json(fields).encode("utf-8"))
    return Anchor(seq, digest, head.recorded_at_ns, fields["anchored_at_ns"], fields["key_id"],
                  base64.b64encode(signature).decode("ascii"))


# -- checking anchors ----------------------------------------------------------------------------
class _Invalid(Exception):
    """Why an anchor file cannot be trusted (a failed verify, not an error)."""


def parse_anchor(data: bytes, public_key: Ed25519PublicKey) -> Anchor:
    """The anchor in a file's bytes, once its signature is checked with the trusted key.

    Raises _Invalid naming the reason: not an anchor, signed by another key, or a signature
    that does not match the content (the file was edited).
    """
    try:
        document = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as error:
        raise _Invalid(f"not an anchor file (not JSON: {error})") from None
    if not isinstance(document, dict):
        raise _Invalid("not an anchor file (not a JSON object)")
    signature = document.pop("signature", None)
    if not isinstance(signature, str):
        raise _Invalid("not an anchor file (no signature)")
    trusted = key_id(public_key)
    if document.get("key_id") != trusted:
        raise _Invalid(f"signature by key {document.get('key_id')!r}, not by the trusted key "
                       f"{trusted!r}")
    try:
        raw = base64.b64decode(signature, validate=True)
        content = canonical_json(document).encode("utf-8")
        public_key.verify(raw, content)
    except (binascii.Error, ValueError, InvalidSignature):
        raise _Invalid("signature does not match the content: the file was changed after it "
                       "was signed (or was never signed with the trusted key)") from None
    if document.get("format") != FORMAT:
        raise _Invalid(f"unknown anchor format {document.get('format')!r} (this version reads "
                       f"{FORMAT!r})")
    seq, recorded, anchored = (_count(document, name)
                               for name in ("seq", "recorded_at_ns", "anchored_at_ns"))
    digest = document.get("hash")
    if not isinstance(digest, str) or not _HASH.fullmatch(digest):
        raise _Invalid("malformed anchor: hash is not 64 hex digits")
    return Anchor(seq, digest, recorded, anchored, trusted, signature)


def _count(document: dict[str, Any], name: str) -> int:
    value = document.get(name)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise _Invalid(f"malformed anchor: {name} is not a whole number of 0 or more")
    return value


@dataclass(frozen=True, slots=True)
class AnchorCheck:
    """One anchor file that was signed with the trusted key and matches the log."""

    path: Path
    anchor: Anchor


@dataclass(frozen=True, slots=True)
class AnchorReport:
    """Outcome of ``verify_anchors``: the anchors that match, and the problems found."""

    matched: list[AnchorCheck] = field(default_factory=list)
    first_bad_seq: int | None = None
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def verify_anchors(ledger: FaultLedger, paths: Sequence[Path],
                   public_key: Ed25519PublicKey) -> AnchorReport:
    """Check anchor files against the trusted public key and the log.

    Each anchor must be signed with ``public_key``; then, in seq order, its record must be
    stored with the anchored hash and the chain from seq 1 up to it must be intact. The first
    bad seq: for a log that ends before an anchor (seq N < S), N + 1; for a hash mismatch at S
    while the chain is consistent (every hash after a change recomputed), one past the highest
    anchor that still matches (or 1); for a broken chain, where it breaks. Raises AnchorError
    (nothing checked) when a file cannot be read.
    """
    problems: list[str] = []
    found: list[tuple[Path, Anchor]] = []
    for path in paths:
        data = _read(path, "anchor")
        try:
            found.append((path, parse_anchor(data, public_key)))
        except _Invalid as reason:
            problems.append(f"anchor {path}: {reason}")
    found.sort(key=lambda item: (item[1].seq, item[1].anchored_at_ns))
    matched: list[AnchorCheck] = []
    first_bad: int | None = None

    def bad(seq: int, problem: str) -> None:
        nonlocal first_bad
        first_bad = seq if first_bad is None else min(first_bad, seq)
        problems.append(problem)

    if not found:
        return AnchorReport(matched, first_bad, problems)
    with ledger._db.reading() as conn:
        head_seq = event_log.head(conn)[0]
        top = min(found[-1][1].seq, head_seq)
        chain = event_log.check_chain(conn, 1, top) if top > 0 else None
        broken_at = None if chain is None else chain.first_bad_seq
        if chain is not None and chain.problem is not None:
            bad(chain.first_bad_seq or 1, chain.problem)
        last_good = 0
        for path, anchor in found:
            made = f"made {iso_ns(anchor.anchored_at_ns)}"
            if anchor.seq > head_seq:
                bad(head_seq + 1, f"anchor {path} ({made}) holds seq {anchor.seq} but the log "
                    f"ends at seq {head_seq}: records {head_seq + 1}..{anchor.seq} were removed")
                continue
            stored = event_log.hash_at(conn, anchor.seq)
            if stored == anchor.hash and (broken_at is None or anchor.seq < broken_at):
                matched.append(AnchorCheck(path, anchor))
                last_good = anchor.seq
            elif stored == anchor.hash:
                continue  # its record matches, but the chain below it is broken (reported)
            elif broken_at is not None and broken_at <= anchor.seq:
                bad(broken_at, f"anchor {path} ({made}): record {anchor.seq} does not have the "
                    f"anchored hash; the chain is broken before it, at seq {broken_at}")
            else:
                bad(last_good + 1, f"anchor {path} ({made}): record {anchor.seq} does not have "
                    f"the anchored hash {anchor.hash} (stored: {stored}) although the chain is "
                    f"consistent: records in ({last_good}, {anchor.seq}] were changed or "
                    "replaced and the hashes after them recomputed")
    return AnchorReport(matched, first_bad, problems)


def with_anchors(report: VerifyReport, anchors: AnchorReport) -> VerifyReport:
    """``verify``'s report with the anchors' findings: the earliest first bad seq, and each
    problem once (a broken chain is found by both)."""
    if anchors.ok:
        return report
    firsts = [s for s in (report.first_bad_seq, anchors.first_bad_seq) if s is not None]
    problems = [*report.problems, *(p for p in anchors.problems if p not in report.problems)]
    return replace(report, ok=False, first_bad_seq=min(firsts) if firsts else None,
                   problems=problems)


# -- periodic anchors (`faultledger serve`) ------------------------------------------------------
class AnchorScheduler:
    """Writes an anchor file to ``directory`` every ``interval_sec`` when the head changed,
    and once more at ``stop``. A failure (no key, directory missing or full, a chain that no
    longer matches the last anchor) is one warning line; the thread keeps going."""

    def __init__(self, ledger: FaultLedger, key_path: Path, directory: Path,
                 interval_sec: float = 3600.0, keep: int | None = None) -> None:
        self._ledger = ledger
        self.key_path = key_path
        self.directory = directory
        self.interval_sec = interval_sec
        self.keep = keep
        self.last: Anchor | None = None
        """The newest anchor written (its seq and hash start the next chain check)."""
        self._key: Ed25519PrivateKey | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    @classmethod
    def from_settings(cls, ledger: FaultLedger, settings: AnchorSettings
                      ) -> AnchorScheduler | None:
        """A scheduler when ``anchors.key`` and ``anchors.directory`` are both set."""
        if settings.key is None or settings.directory is None:
            return None
        return cls(ledger, settings.key, settings.directory, settings.interval_sec,
                   settings.keep)

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="faultledger-anchors",
                                        daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """End the thread, then write the shutdown anchor (when the head changed)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.run_once()

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        while not self._stop.wait(self.interval_sec):
            self.run_once()

    def run_once(self) -> Path | None:
        """Write an anchor if the head moved since the last one; the file, or None."""
        with self._lock:
            try:
                path = self._write()
            except Exception as error:  # never let the thread die: one line, try again later
                log.warning("anchor not written to %s: %s", self.directory, error)
                return None
            if path is not None and self.keep is not None:
                self._prune(self.keep)
            return path

    def _write(self) -> Path | None:
        if self._key is None:
            self._key = load_private_key(self.key_path)
        last = self.last
        if last is not None:
            with self._ledger._db.reading() as conn:
                if event_log.head(conn) == (last.seq, last.hash):
                    return None
        anchor = make_anchor(self._ledger, self._key,
                             after=None if last is None else (last.seq, last.hash))
        path = self.directory / anchor_file_name(anchor)
        write_output(path, anchor.to_json(), mode=FILE_MODE)
        self.last = anchor
        log.info("anchored seq %d in %s", anchor.seq, path)
        return path

    def _prune(self, keep: int) -> None:
        try:
            for old in anchor_files(self.directory)[:-keep]:
                old.unlink(missing_ok=True)
        except (OSError, AnchorError) as error:
            log.warning("old anchors in %s not removed: %s", self.directory, error)
