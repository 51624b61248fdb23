"""The chi-square check the contracts share."""

from __future__ import annotations

import torch
from pyro.distributions.testing.gof import multinomial_goodness_of_fit

__all__ = ["check_draws"]


def check_draws(probs: torch.Tensor, counts: torch.Tensor, what: str) -> None:
    """Chi-square of ``counts`` against ``probs`` (p-value above ``1e-3``): no count where ``probs`` is 0;
    bins of expected count below 5 pooled into one."""
    n = int(counts.sum())
    assert counts[probs <= 1e-15].sum() == 0, f"{what}: draws where the probability is 0"
    big = probs * n >= 5
    p = torch.cat([probs[big], probs[~big].sum()[None]])
    c = torch.cat([counts[big], counts[~big].sum()[None]])
    if p[-1] * n < 5:
        p, c = p[:-1], c[:-1]
    pval = multinomial_goodness_of_fit(p / p.sum(), c, total_count=int(c.sum()))
    assert pval > 1e-3, f"{what}: chi-square p-value {pval:.2e}"
