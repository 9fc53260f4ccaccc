"""The application API: validate, append durably, project, notify (SPEC §6)."""
