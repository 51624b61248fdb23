r"""Fitting update terms Delta as amortised variational inference (Section 2.5).

Traditional OGM with an update term Delta *is* an amortised mean-field posterior,

.. math:: q_\Delta(m \mid z) = \prod_k \mathrm{Bernoulli}\bigl(\sigma(\textstyle\sum_n \Delta(\kappa_{n,k}; z_n))\bigr),

and fitting Delta means minimising the summed cell cross-entropy ``H(p_exact, q_Delta)`` (equivalently the
cell-wise KL, Section 2.5) over a set of 1D datasets whose exact posterior is known. For a stationary 1D
robot the logits are one matrix product, ``counts @ T^T``, of the datasets' reading counts and the family's
``(kappa, z)`` table, so a fit over 900 datasets costs milliseconds per evaluation; we use L-BFGS with a
strong-Wolfe line search (the thesis: BFGS with a mixed quadratic/cubic line search).

Fitting takes any data with ``counts`` (``D x (F + 2)`` readings per dataset, max range last), ``exact``
(``D x (F + 1)`` exact marginals), ``F`` and ``subset(index)``: the :class:`FitData` protocol, met by
:class:`~ogm_ppl.inference.variational.wall_data.WallDatasets` (this module imports no dataset code).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import torch
from torch import nn

from ogm_ppl.models.delta import PN, DeltaFamily

__all__ = [
    "FitData",
    "cross_entropy_loss",
    "fit_delta",
    "DeltaFitResult",
    "cross_validate",
    "warm_start_pn",
    "minimise",
]


class FitData(Protocol):
    """What the fit needs of a set of 1D datasets (all tensors float64)."""

    @property
    def F(self) -> int: ...

    @property
    def counts(self) -> torch.Tensor:
        """D x (F + 2): how often each kappa reading 0..F and max range occurred."""

    @property
    def exact(self) -> torch.Tensor:
        """D x (F + 1): exact posterior marginals of cells 0..F."""

    def subset(self, index: torch.Tensor, /) -> FitData: ...

    def __len__(self) -> int: ...


def logits(family: DeltaFamily, data: FitData) -> torch.Tensor:
    """``D x (F + 1)`` evidence of every cell of every dataset (prior 0.5): ``counts @ T^T``."""
    T = family.table(data.F + 1, data.F + 1)  # (F + 1) x (F + 2)
    return data.counts @ T.T


def cross_entropy_loss(family: DeltaFamily, data: FitData) -> torch.Tensor:
    """Mean over datasets of the summed cell cross-entropy ``H(p_exact, q_Delta)`` over cells 1..F (nats)."""
    lg = logits(family, data)[:, 1:]
    p = data.exact[:, 1:]
    # -p log sigmoid(l) - (1 - p) log(1 - sigmoid(l)) = p softplus(-l) + (1 - p) softplus(l)
    ce = p * nn.functional.softplus(-lg) + (1 - p) * nn.functional.softplus(lg)
    return ce.sum(1).mean()


@dataclass
class DeltaFitResult:
    family: DeltaFamily
    train_loss: float
    iterations: int


def fit_delta(family: DeltaFamily, data: FitData, max_iter: int = 500, tol: float = 1e-10) -> DeltaFitResult:
    """Minimise :func:`cross_entropy_loss` over the family's parameters with L-BFGS (deterministic)."""
    return minimise(family, lambda: cross_entropy_loss(family, data), max_iter=max_iter, tol=tol)


def minimise(
    family: DeltaFamily, objective: Callable[[], torch.Tensor], max_iter: int = 500, tol: float = 1e-10
) -> DeltaFitResult:
    """Minimise ``objective()`` (a scalar of the family's parameters) with the L-BFGS of :func:`fit_delta`:
    strong-Wolfe line search, gradient tolerance ``tol``; ``train_loss`` is ``objective()`` at the end."""
    params = [p for p in family.parameters() if p.requires_grad]
    if not params:
        with torch.no_grad():
            return DeltaFitResult(family, float(objective()), 0)
    opt = torch.optim.LBFGS(
        params,
        lr=1.0,
        max_iter=max_iter,
        max_eval=2 * max_iter,
        tolerance_grad=tol,
        tolerance_change=1e-14,
        history_size=50,
        line_search_fn="strong_wolfe",
    )

    def closure():
        opt.zero_grad()
        loss = objective()
        loss.backward()
        return loss

    opt.step(closure)
    state = opt.state[opt._params[0]]
    with torch.no_grad():
        final = float(objective())
    return DeltaFitResult(family, final, int(state.get("n_iter", 0)))


def warm_start_pn(previous: PN | None, N: int) -> PN:
    """pN initialised from p(N-1) so that it starts at the same function: the new value sits at the near
    end (copying the old first value, which already applied there) or the far end (0, as before)."""
    if previous is None:
        return PN.zeros(N)
    new = PN.zeros(N)
    with torch.no_grad():
        old = previous.values.detach()
        shift = previous.lo - new.lo  # 1 if the new value was added at the near end
        new.values[shift : shift + previous.N] = old
        if shift == 1:
            new.values[0] = old[0]
    return new


def cross_validate(make_family, data: FitData, folds: int = 10, **fit_kwargs) -> dict:
    """``folds``-fold cross-validation: fit on all but one fold, score the held-out fold.

    ``make_family(fold)`` returns a fresh family. Returns train/test losses per fold and the families.
    """
    D = len(data)
    if D % folds:
        raise ValueError(f"{D} datasets do not split into {folds} equal folds")
    size = D // folds
    out: dict[str, list] = {"train": [], "test": [], "families": []}
    for k in range(folds):
        test = torch.arange(k * size, (k + 1) * size)
        train = torch.cat([torch.arange(0, k * size), torch.arange((k + 1) * size, D)])
        fam = make_family(k)
        res = fit_delta(fam, data.subset(train), **fit_kwargs)
        with torch.no_grad():
            out["test"].append(float(cross_entropy_loss(fam, data.subset(test))))
        out["train"].append(res.train_loss)
        out["families"].append(fam)
    return out
