r"""Independent cell prior: ``p(m) = prod_k lambda_k^{m_k} (1 - lambda_k)^{1 - m_k}`` (Section 2.4).

``lambda_ = 0.5`` is the uniform prior over maps of Chapters 2-4; 0.234 is the thesis's "more realistic"
cell prior (Fig. 1.10e).
"""

from __future__ import annotations

import torch

from ogm_ppl.priors.base import MapPrior

__all__ = ["IndependentPrior"]


class IndependentPrior(MapPrior):
    """Cells independent with occupancy probability ``lambda_`` (a scalar or one value per cell).

    >>> round(IndependentPrior(0.5, num_cells=3).log_prob(torch.tensor([1.0, 0.0, 1.0])).item(), 4)  # 3 log(1/2)
    -2.0794
    """

    def __init__(self, lambda_, num_cells: int | None = None) -> None:
        lam = torch.as_tensor(lambda_, dtype=torch.float64)
        if torch.isnan(lam).any() or (lam <= 0).any() or (lam >= 1).any():
            raise ValueError(f"IndependentPrior.lambda_ must lie in (0, 1), got {lambda_!r}")
        if num_cells is not None and (isinstance(num_cells, bool) or int(num_cells) != num_cells or num_cells < 1):
            raise ValueError(f"IndependentPrior.num_cells must be a whole number >= 1, got {num_cells!r}")
        if lam.dim() == 0:
            if num_cells is None:
                raise ValueError("IndependentPrior with a scalar lambda_ needs num_cells")
            lam = lam.expand(int(num_cells)).clone()
        elif num_cells is not None and lam.numel() != num_cells:
            raise ValueError(f"IndependentPrior.lambda_ has {lam.numel()} values for {num_cells} cells")
        self.lambda_ = lam.flatten()
        self.num_cells = self.lambda_.numel()
        self._log_on = torch.log(self.lambda_)
        self._log_off = torch.log1p(-self.lambda_)

    def __repr__(self) -> str:
        lam = self.lambda_
        shown = f"{lam[0].item():.4g}" if bool((lam == lam[0]).all()) else "per-cell"
        return f"IndependentPrior(lambda_={shown}, num_cells={self.num_cells})"

    def log_prob(self, maps):
        maps = torch.as_tensor(maps, dtype=torch.float64)
        return (maps * self._log_on + (1 - maps) * self._log_off).sum(-1)

    def log_prob_patch(self, maps, cells, configs):
        configs = torch.as_tensor(configs, dtype=torch.float64)
        cells = torch.as_tensor(cells, dtype=torch.long)
        lp = (configs * self._log_on[cells] + (1 - configs) * self._log_off[cells]).sum(-1)  # W
        maps = torch.as_tensor(maps)
        return lp if maps.dim() == 1 else lp.expand(maps.shape[0], -1)

    def outside_occupancy(self) -> float:
        """The mean ``lambda_`` (cells outside the map are exchangeable with those inside)."""
        return float(self.lambda_.mean())

    def cell_log_odds(self):
        return self._log_on - self._log_off

    def sample(self, sample_shape=(), generator=None):
        shape = torch.Size(sample_shape) + (self.num_cells,)
        u = torch.rand(shape, generator=generator, dtype=torch.float64)
        return (u < self.lambda_).to(torch.float64)
