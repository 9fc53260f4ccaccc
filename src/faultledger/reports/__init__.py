"""Reports shared by the adapters: built from the service API (FaultLedger), rendered for
people. ``faultledger report-shift`` (cli) and ``GET /api/v1/shift-report`` (http) use the same
builder and the same HTML, so the two can never disagree."""
