"""Where realize's files are: the checkout's root, its Hydra config directory and the per-user cache.

What it does: ``REPO_ROOT`` (relative task/PDDL paths fall back to it), ``CONFIG_DIR``
(``configs/``, the Hydra config tree of the ``realize`` command) and ``cache_dir`` (the per-user
folder of files realize derives once and keeps: converted URDFs, built fabric steps).
What it doesn't: know run directories (``realize.run_dir``).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["REPO_ROOT", "CONFIG_DIR", "cache_dir"]

REPO_ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO_ROOT / "configs"


def cache_dir(name: str) -> Path:
    """``$XDG_CACHE_HOME/realize/<name>`` (default ``~/.cache``), made if missing; where the home
    folder is read-only, ``<temp>/realize-<name>``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    d = Path(base) / "realize" / name
    try:
        d.mkdir(parents=True, exist_ok=True)
        return d
    except OSError:
        d = Path(tempfile.gettempdir()) / f"realize-{name}"
        d.mkdir(parents=True, exist_ok=True)
        return d
