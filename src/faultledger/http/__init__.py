"""The HTTP adapter (SPEC §10, docs/http.md): FastAPI routes over one FaultLedger."""
