"""Kept for ``scripts/bench_rollout.py``, which imports ``compose_config`` from here; the tests
use ``helpers.py`` (and the fixtures in ``conftest.py``)."""

from helpers import compose_config  # noqa: F401
