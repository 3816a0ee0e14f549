"""Fixtures shared by the test files (helpers that are not fixtures: ``helpers.py``)."""

from __future__ import annotations

from typing import Iterator

import pytest

from file_seconds import file_weight, load_table


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Longest test files first (``file_seconds.py``), each file's tests kept together in their
    order: the worker processes of ``make test`` then end close together."""
    table = load_table()
    items.sort(key=lambda it: (-file_weight(it.nodeid, table), it.nodeid.split("::", 1)[0]))


@pytest.fixture(scope="module")
def torch_single_thread() -> Iterator[None]:
    """Torch beside PhysX on a small machine: one intra-op thread (as BatchedScene uses)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture
def no_sim(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if anything builds a simulator."""
    import realize.scene

    class NoScene:
        def __init__(self, *a, **k) -> None:
            raise AssertionError("a simulator was built for an invalid config")

        @classmethod
        def from_spec(cls, *a, **k) -> None:
            raise AssertionError("a simulator was built for an invalid config")

    monkeypatch.setattr(realize.scene, "BatchedScene", NoScene)
