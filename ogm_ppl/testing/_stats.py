"""The chi-square checks the contracts (and the library's tests) share.

:func:`multinomial_goodness_of_fit` is Pyro's test of the same name
(``pyro.distributions.testing.gof``: the same statistic, degrees of freedom and truncation) with the survival
function taken from SciPy: Pyro's ``chi2sf`` (1.9) stops its series after 100 terms, so for statistics above
about 160-200 (10 to 63 degrees of freedom) it returns p-values near 0.5 where the true value is below
1e-18, and a check at ``p > 1e-3`` passes samplers that are plainly wrong.

>>> import torch
>>> round(multinomial_goodness_of_fit(torch.tensor([0.5, 0.5]), torch.tensor([500.0, 500.0])), 6)
1.0
"""

from __future__ import annotations

import math
import warnings

import torch

__all__ = ["check_draws", "multinomial_goodness_of_fit"]


@torch.no_grad()
def multinomial_goodness_of_fit(probs: torch.Tensor, counts: torch.Tensor, *, total_count: int | None = None) -> float:
    """p-value of ``counts`` drawn from ``probs`` (1-D): ``sum (c - N p)^2 / (N p (1 - p))`` over the bins of
    positive probability, with one degree of freedom fewer unless the data are truncated (``total_count``
    given: the counts of the bins shown out of that many draws). A bin of probability 1 gives 1 or 0; a count
    where the probability is 0 gives ``inf`` (as Pyro's)."""
    from scipy.stats import chi2

    assert probs.dim() == 1 and probs.shape == counts.shape
    truncated = total_count is not None
    n = int(counts.sum()) if total_count is None else int(total_count)
    assert n >= counts.sum()
    stat, dof = 0.0, 0
    for p, c in zip(probs.tolist(), counts.tolist()):
        if abs(p - 1) < 1e-8:
            return 1.0 if c == n else 0.0
        assert p < 1, f"bad probability: {p:g}"
        if p > 0:
            var = n * p * (1 - p)
            if not var > 1:
                raise ValueError("goodness of fit is inaccurate here: use more samples")
            stat += (c - n * p) ** 2 / var
            dof += 1
        else:
            warnings.warn("zero probability in goodness-of-fit test", stacklevel=2)
            if c > 0:
                return math.inf
    if not truncated:
        dof -= 1
    return float(chi2.sf(stat, dof))


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
