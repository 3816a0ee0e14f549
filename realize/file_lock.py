"""An exclusive lock on a file, held across processes: ``with file_lock(path): ...``.

What it does: ``flock`` on ``path`` (made, with its folder, if missing) for the ``with`` block, so
that processes that share a file (a sweep's summary, a built fabric step in the cache) take turns;
where the platform or the file system has no ``flock`` it locks nothing and the block still runs.
What it doesn't: write files (``realize.run_dir.jsonio.atomic_write_text`` and ``os.replace``
keep a reader from meeting half a file), or time out.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["file_lock"]


@contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on ``path`` for the block (a no-op where unsupported)."""
    fd: int | None = None
    try:
        import fcntl

        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        fcntl.flock(fd, fcntl.LOCK_EX)
    except (ImportError, OSError):
        if fd is not None:
            os.close(fd)
        fd = None
    try:
        yield
    finally:
        if fd is not None:
            import fcntl

            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
