"""Persistence: the SQL schema, the append-only event store and the projection tables."""
