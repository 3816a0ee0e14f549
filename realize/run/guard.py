"""How a run ends: signals become an ``interrupted`` status, failures an ``error.txt``, and the
final write always happens, shielded from a second Ctrl-C.

What it does:
  * ``RunSignals``: while a run is active, SIGINT and SIGTERM raise ``RunInterrupted`` (a
    ``KeyboardInterrupt``) in the main thread; the old handlers come back afterwards;
  * ``RunGuard``: the context around a run loop. Leaving it normally gives status ``done``; a
    ``KeyboardInterrupt`` gives ``interrupted`` (swallowed; ``exit_code`` 130 for SIGINT, 143 for
    SIGTERM); any other exception gives ``failed``: its traceback goes to ``error.txt`` and it
    propagates. In every case ``finish(status, error)`` (the final result write) and then
    ``close()`` run with SIGINT/SIGTERM ignored;
  * ``EXIT_CONFIG`` (2): the exit code of a run refused for its config.
What it doesn't: know what is written (``realize.sinks``) or what runs (``realize.run.loop``).
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

from realize.run_dir.jsonio import atomic_write_text

__all__ = ["RunInterrupted", "RunSignals", "RunGuard", "shielded", "EXIT_CONFIG", "EXIT_FAILED", "EXIT_SIGNAL"]

log = logging.getLogger("realize")

EXIT_CONFIG = 2
EXIT_FAILED = 1  # a run that failed (error.txt written)
EXIT_SIGNAL = {signal.SIGINT: 130, signal.SIGTERM: 143}


class RunInterrupted(KeyboardInterrupt):
    """Raised in the main thread by SIGTERM (SIGINT raises ``KeyboardInterrupt`` itself)."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"signal {signal.Signals(signum).name}")
        self.signum = signum


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class RunSignals:
    """SIGINT/SIGTERM -> ``RunInterrupted`` in the main thread while the run is active.

    SIGINT gets an explicit handler too: a process started in the background by a
    non-interactive shell inherits SIGINT as *ignored*, and ``kill -INT`` should still stop it.
    """

    def __init__(self) -> None:
        self.old: dict[int, Any] = {}

    def __enter__(self) -> RunSignals:
        if _main_thread():

            def handler(signum: int, frame: Any) -> None:
                raise RunInterrupted(signum)

            for s in (signal.SIGINT, signal.SIGTERM):
                try:
                    self.old[s] = signal.signal(s, handler)
                except (ValueError, OSError):  # pragma: no cover
                    pass
        return self

    def __exit__(self, *exc: Any) -> None:
        for s, h in self.old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """Ignore SIGINT/SIGTERM while the final files are written (main thread only)."""
    old: dict[int, Any] = {}
    if _main_thread():
        for s in (signal.SIGINT, signal.SIGTERM):
            try:
                old[s] = signal.signal(s, signal.SIG_IGN)
            except (ValueError, OSError):  # pragma: no cover
                pass
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


class RunGuard:
    """End of a run loop, however it ends (see the module docstring).

    ``n_done()`` counts the complete iterations (for the interrupt message); ``finish(status,
    error)`` writes the final result; ``close()`` releases everything (sinks, scene)."""

    def __init__(self, n_done: Callable[[], int], finish: Callable[[str, str | None], None],
                 close: Callable[[], None], error_file: Path | None = None) -> None:
        self.n_done, self.finish, self.close = n_done, finish, close
        self.error_file = error_file
        self.status, self.exit_code, self.error = "running", 0, None

    def __enter__(self) -> RunGuard:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> bool:
        if kind is None:
            self.status = "done"
        elif issubclass(kind, KeyboardInterrupt):
            signum = exc.signum if isinstance(exc, RunInterrupted) else signal.SIGINT
            self.status, self.exit_code = "interrupted", EXIT_SIGNAL.get(signum, 130)
            self.error = f"interrupted by {signal.Signals(signum).name} after {self.n_done()} complete iteration(s)"
        elif issubclass(kind, Exception):
            self.status, self.error = "failed", f"{kind.__name__}: {exc}"
            with shielded():
                try:
                    if self.error_file is not None:
                        atomic_write_text(self.error_file, "".join(traceback.format_exception(kind, exc, tb)))
                    self.finish(self.status, self.error)
                except Exception as e:  # the run's own failure is the one to report
                    log.warning("writing the failed run's result failed too (%s: %s)", type(e).__name__, e)
                finally:
                    self.close()
            return False
        else:
            return False
        with shielded():  # a second Ctrl-C must not cut the final write short
            try:
                self.finish(self.status, self.error if self.status == "interrupted" else None)
            finally:
                self.close()
        return True
