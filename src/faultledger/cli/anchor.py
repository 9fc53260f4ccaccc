"""`faultledger anchor`: signed anchors of the log head (Ed25519). Registered by cli/main.py.

`anchor keygen` writes a key pair; `anchor [export]` signs the head of the log. `verify
--anchor FILE --public-key PUB.pem` (cli/audit.py) checks the log against anchors. The
database is only read. Bad input, an unreadable key or an existing output file is one line on
stderr and exit 2; a log that cannot be anchored (empty, broken chain) is exit 1.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from faultledger.cli import render
from faultledger.cli.options import HELP_MARKUP, ConfigOption, DbOption, opened, prepare
from faultledger.cli.options import fail as _fail
from faultledger.errors import FaultLedgerError
from faultledger.service import anchors
from faultledger.service.config import config_path, load_settings
from faultledger.service.output_files import OutputFileError, check_target, write_output

anchor_app = typer.Typer(
    help="Signed anchors of the log head (Ed25519).\n\nTamper evidence beyond the hash "
    "chain. Without a subcommand: the same as `anchor export`.",
    invoke_without_command=True,
    rich_markup_mode=HELP_MARKUP,
)

KeyOption = Annotated[Path | None, typer.Option(
    "--key", metavar="FILE",
    help="Ed25519 private key (PEM) to sign with (default: the config's anchors.key). "
    "Keep it outside the database.")]
OutputOption = Annotated[Path | None, typer.Option(
    "--output", "-o", metavar="FILE",
    help="Write the anchor to this new file (mode 0640; default: stdout).")]
ForceOption = Annotated[bool, typer.Option(
    "--force", help="Replace an existing output file.")]


def register(app: typer.Typer) -> None:
    """Add `anchor` (with `export` and `keygen`) to the `faultledger` app."""
    app.add_typer(anchor_app, name="anchor")


@anchor_app.callback()
def anchor_default(
    ctx: typer.Context,
    key: KeyOption = None,
    output: OutputOption = None,
    force: ForceOption = False,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Export a signed anchor of the log head (the same as `anchor export`)."""
    if ctx.invoked_subcommand is not None:
        if key is not None or output is not None or force:
            _fail(f"give the options after `anchor {ctx.invoked_subcommand}`")
        return
    export(key, output, force, db, config)


@anchor_app.command("export")
def export(
    key: KeyOption = None,
    output: OutputOption = None,
    force: ForceOption = False,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Sign the head of the log and print the anchor as JSON.

    The anchor holds the seq, the hash, when it was recorded and when it was anchored; it is
    printed, or written to --output. The chain is checked first: a broken one, or an empty
    log, is not anchored (exit 1).
    """
    try:
        key_path = key or load_settings(config_path(config)).anchors.key
        if key_path is None:
            _fail("give the private key to sign with: --key FILE (or anchors.key in the config)")
        private_key = anchors.load_private_key(key_path)
    except FaultLedgerError as error:
        _fail(str(error))
    if output is not None:
        try:
            check_target(output, force)  # before reading the log; checked again when written
        except OutputFileError as error:
            _fail(str(error))
    with opened(prepare(db, config)) as ledger:
        try:
            anchor = anchors.make_anchor(ledger, private_key)
        except anchors.AnchorRefused as refused:
            _fail(str(refused), 1)
    data = anchor.to_json()
    if output is None:
        typer.echo(data.decode("utf-8"), nl=False)
        return
    try:
        write_output(output, data, force, anchors.FILE_MODE)
    except FaultLedgerError as error:
        _fail(str(error))
    render.console(stderr=True).print(
        f"anchored seq {anchor.seq} hash {anchor.hash} (key {anchor.key_id}) in {output}",
        highlight=False, markup=False)


@anchor_app.command("keygen")
def keygen(
    private_key: Annotated[Path, typer.Option(
        "--private-key", metavar="FILE",
        help="New private key file (PEM, mode 0600). Keep it off the "
        "robot's data disk if the robot itself is not trusted.")],
    public_key: Annotated[Path, typer.Option(
        "--public-key", metavar="FILE",
        help="New public key file (PEM): what `verify --public-key` trusts.")],
    force: Annotated[bool, typer.Option("--force", help="Replace existing key files.")] = False,
) -> None:
    """Generate an Ed25519 key pair for anchors.

    Neither file is written when one exists (unless --force).
    """
    if private_key.absolute() == public_key.absolute():
        _fail("the private and the public key need two different files")
    key, private_pem, public_pem = anchors.new_key_pair()
    try:
        check_target(private_key, force)
        check_target(public_key, force)
        write_output(private_key, private_pem, force, anchors.PRIVATE_KEY_MODE)
        write_output(public_key, public_pem, force, anchors.PUBLIC_KEY_MODE)
    except OutputFileError as error:
        _fail(str(error))
    typer.echo(f"key {anchors.key_id(key.public_key())}: private key {private_key} (0600), "
               f"public key {public_key}")
