"""The robot side of a fleet (docs/fleet.md): push every record of this robot's log, verbatim,
to a central (``client``: the HTTP protocol; ``push``: the loop that keeps the central caught
up, for `faultledger sync` and `serve`'s ``fleet:``), and check the central's copy against the
log (``check``: `verify --central`). An adapter: it reads the log through the service only."""
