"""The `faultledger` command line: translates arguments into FaultLedger calls."""
