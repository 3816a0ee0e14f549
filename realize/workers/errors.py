"""The error a run stops with when its rollout workers cannot go on (a light module: the CLI
imports it to print the message without a traceback)."""

__all__ = ["WorkerFailed"]


class WorkerFailed(RuntimeError):
    """A rollout worker died twice on the same rows, could not start, or raised during a rollout.
    The message names the worker, its rows, how it ended and its last log lines."""
