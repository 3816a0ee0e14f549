"""Drawing a CE iteration's samples row by row, and drawing again the rows a screen rejects.

What it does: ``row_sources`` says where each row of a batch comes from (the Gaussian, a mixture
mode, or uniform over the regions: Gaussian rows first, mode by mode, then the uniform share);
``draw_rows`` draws one row from each row's source with the search's generator, consuming it
exactly as one batch draw does (all the Gaussian noise, then the uniform rows), so a batch is
the same samples as before screening existed; ``screened_draw`` draws the rejected rows again
from their own sources (``ce.screen``), a bounded number of times, and returns the rejected draws.
What it doesn't: decide what is rejected (the screen, ``realize.realization.screening``), or
keep state (``realize.search.ce.optimizer`` holds the distribution and the generator).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from realize.search.ce.mixture import mode_counts
from realize.search.ce.state import CEState
from realize.tasks.param_layout import ParamLayout

__all__ = ["row_sources", "draw_rows", "screened_draw"]

UNIFORM = -1


def row_sources(state: CEState, n: int, uniform_share: float) -> Tensor:
    """(n,) int64: ``UNIFORM`` or the Gaussian (mixture mode) index of each row."""
    if state.mean is None or state.std is None:
        return torch.full((n,), UNIFORM, dtype=torch.long)
    n_u = int(round(uniform_share * n))
    n_g = n - n_u
    if state.weights is None:
        mode = torch.zeros(n_g, dtype=torch.long)
    else:  # mixture: rows of mode 0 first, then mode 1, ...
        mode = torch.repeat_interleave(torch.arange(state.weights.numel()), mode_counts(state.weights, n_g))
    return torch.cat([mode, torch.full((n_u,), UNIFORM, dtype=torch.long)])


def draw_rows(layout: ParamLayout, state: CEState, source: Tensor, generator: torch.Generator,
              dtype: torch.dtype) -> Tensor:
    """(len(source), D): one row from each row's source, projected into the regions."""
    gauss = source != UNIFORM
    n_g, n_u = int(gauss.sum()), int((~gauss).sum())
    parts = []
    if n_g:
        eps = torch.randn(n_g, layout.dim, generator=generator, dtype=dtype)
        if state.weights is None:
            parts.append(layout.project(state.mean + state.std * eps))
        else:
            mode = source[gauss]
            parts.append(layout.project(state.mean[mode] + state.std[mode] * eps))
    if n_u:
        parts.append(layout.sample_uniform(n_u, generator, dtype))
    Z = torch.cat(parts, dim=0)
    out = torch.empty_like(Z)
    out[torch.cat([torch.nonzero(gauss).flatten(), torch.nonzero(~gauss).flatten()])] = Z
    return out


def screened_draw(Z: Tensor, source: Tensor, screen: Callable[[Tensor], Tensor], tries: int,
                  draw: Callable[[Tensor], Tensor]) -> tuple[Tensor, Tensor]:
    """(Z, rejected): the rows ``screen`` rejects drawn again by ``draw(source_of_those_rows)``,
    up to ``tries`` times (a row still rejected then stays as it is and is simulated), and every
    rejected draw (k, D), in the order rejected."""
    rejected = []
    bad = screen(Z)
    for _ in range(tries):
        if not bool(bad.any()):
            break
        rejected.append(Z[bad].clone())
        Z = Z.clone()
        Z[bad] = draw(source[bad])
        bad = bad & screen(Z)
    return Z, (torch.cat(rejected) if rejected else Z[:0].clone())
