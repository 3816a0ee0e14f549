"""``realize.file_lock``: a second process waits for the lock's holder (order of writes to a shared
file), and a folder that is missing is made."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from realize.file_lock import file_lock

CHILD = """
import sys
from pathlib import Path
from realize.file_lock import file_lock
lock, log = Path(sys.argv[1]), Path(sys.argv[2])
with open(log, "a") as f:
    f.write("child waits\\n")
with file_lock(lock):
    with open(log, "a") as f:
        f.write("child has it\\n")
"""


def test_a_second_process_waits_for_the_holder(tmp_path: Path) -> None:
    lock, log = tmp_path / "sub" / "x.lock", tmp_path / "log.txt"
    with file_lock(lock):
        child = subprocess.Popen([sys.executable, "-c", CHILD, str(lock), str(log)])
        while not log.is_file():  # the child is at the lock
            time.sleep(0.01)
        time.sleep(0.3)
        with open(log, "a") as f:
            f.write("holder releases\n")
    assert child.wait(timeout=60) == 0
    assert log.read_text().splitlines() == ["child waits", "holder releases", "child has it"]
