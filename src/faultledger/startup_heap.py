"""What a long-running server does with the heap it built to start."""

from __future__ import annotations

import gc


def freeze_startup_heap() -> None:
    """Move every object alive now (modules, the app, the ledger's projection) out of the
    cycle collector's way: a full collection then scans only what the process made since.

    Once rclpy, SQLAlchemy and FastAPI are loaded a server process tracks over 100,000
    objects: a full collection of all of them stopped every thread for ~40 ms in ``serve``,
    up to ~120 ms in the HTTP server during a heavy read (docs/performance.md). Called again
    by a second server of the same process, it only freezes what is new."""
    gc.collect()
    gc.freeze()
