"""Where the checkout's own files are: the repository root and the Hydra config directory.

What it does: ``REPO_ROOT`` (relative task/PDDL paths fall back to it) and ``CONFIG_DIR``
(``configs/``, the Hydra config tree of the ``realize`` command).
What it doesn't: know run directories (``realize.run_dir``).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["REPO_ROOT", "CONFIG_DIR"]

REPO_ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO_ROOT / "configs"
