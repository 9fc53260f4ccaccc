"""Pure fault semantics: events, policy, the debounce state machine and the projector (no I/O)."""
