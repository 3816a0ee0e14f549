"""Shared helpers of the simulator tests: the app's composed config, torch on one thread."""

from __future__ import annotations

from typing import Any, Iterator

import pytest
import torch

from realize.paths import CONFIG_DIR


def compose_config(*overrides: str, job_name: str = "tests") -> dict[str, Any]:
    """The app's resolved config (``configs/config.yaml`` + defaults) as plain data, CPU backend."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name=job_name):
        cfg = compose(config_name="config", overrides=["device=cpu", *overrides])
    d = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(d, dict)
    d.pop("hydra", None)
    return d


@pytest.fixture(scope="module")
def torch_single_thread() -> Iterator[None]:
    """Torch beside PhysX on a small machine: one intra-op thread (as BatchedScene uses)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
