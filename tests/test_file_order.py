"""make test's order (tests/file_seconds.py, conftest.py): the longest files first, each file's tests
together and in their own order, and the seconds read back from a durations log."""

from __future__ import annotations

from file_seconds import UNKNOWN_S, file_weight, load_table, seconds_per_file

LOG = """============================= slowest durations ==============================
12.50s call     tests/test_a.py::test_one[x]
0.50s setup    tests/test_a.py::test_one[x]
3.00s call     tests/test_b.py::TestK::test_two
0.25s teardown tests/test_a.py::test_three
(1 durations < 0.005s hidden.)
"""


def test_a_durations_log_sums_per_file() -> None:
    assert seconds_per_file(LOG) == {"test_a.py": 13.2, "test_b.py": 3.0}


def test_unknown_files_weigh_the_default() -> None:
    table = {"test_a.py": 13.2}
    assert file_weight("tests/test_a.py::test_one[x]", table) == 13.2
    assert file_weight("test_new.py::test_x", table) == UNKNOWN_S


def test_the_collected_order_is_longest_file_first_and_keeps_files_together(request) -> None:
    table = load_table()
    files = [it.nodeid.split("::", 1)[0] for it in request.session.items]
    runs = [f for i, f in enumerate(files) if i == 0 or files[i - 1] != f]
    assert len(runs) == len(set(runs)), "a file's tests were split apart"
    weights = [file_weight(f, table) for f in runs]
    assert weights == sorted(weights, reverse=True)
