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


def blas_batch_invariant() -> bool:
    """Whether this machine's batched matrix products give a row the same bits whatever the
    other rows of the batch are. Intel CPUs with MKL were seen to; an AMD EPYC with MKL does not
    (float32 (k, 11, 11) products differ in the last bit between k = 8 and k = 7). Where it
    does not hold, a plan's controller output depends on which other plans share its control
    step's batch, so 'batched equals per sample' and 'one plan's fault leaves the others'
    costs untouched' can only hold up to the chaos that rounding seeds in a grasp."""
    g = torch.Generator().manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        a = torch.randn(8, 11, 11, generator=g, dtype=dtype)
        b = torch.randn(8, 11, 11, generator=g, dtype=dtype)
        full = a @ b
        keep = [0, 1, 2, 4, 5, 6, 7]
        if not torch.equal((a[keep] @ b[keep])[-1], full[7]) or not torch.equal((a[7:] @ b[7:])[0], full[7]):
            return False
    return True
