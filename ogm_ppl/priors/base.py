r"""The map-prior interface every prior implements (Chapter 5).

A prior over binary maps ``m in {0, 1}^K`` answers three questions, all vectorised over a batch of maps:

* :meth:`MapPrior.log_prob` — ``log p(m)`` of full maps, shape ``B x K -> B`` (``-inf`` where a prior has
  zeros, e.g. the data-driven priors of Section 5.1 and 5.2.2);
* :meth:`MapPrior.log_prob_patch` — ``log p(m_C = c, m_{-C})`` for every configuration ``c`` of a patch
  ``C`` of ``L`` cells, up to an additive constant that does not depend on ``c``: what a (patch) Gibbs
  sweep needs (Eq. 4.2, Algorithm 1). The default sets each configuration into the map and calls
  ``log_prob``; priors override it with a local computation;
* :meth:`MapPrior.sample` — maps drawn from the prior.

Priors whose cells are independent also expose :meth:`MapPrior.cell_log_odds` (``K``). The compiled
kernels read a prior through :meth:`MapPrior.compiled`: a bundle of arrays of one kind
(:mod:`ogm_ppl.priors.compiled`: independent cells, stencil, tiles), or ``None`` for the generic path
through :meth:`MapPrior.log_prob_patch`. The Pyro model wraps any prior in
:class:`~ogm_ppl.models.occupancy.MapDistribution`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from ogm_ppl.priors.compiled import CompiledPrior

__all__ = ["MapPrior"]


class MapPrior:
    """Base class of priors over binary maps of ``num_cells`` cells."""

    num_cells: int
    #: whether some map has zero mass (``log_prob`` ``-inf``): the unsmoothed count tables; a kernel warns
    #: (:class:`~ogm_ppl.inference.mcmc.kernel.MasslessStartWarning`) when it starts from such a map
    can_be_zero: bool = False

    def log_prob(self, maps: torch.Tensor) -> torch.Tensor:  # pragma: no cover - interface
        """``log p(m)`` for maps of shape ``... x K`` (0/1 values) -> ``...``."""
        raise NotImplementedError

    def log_prob_patch(self, maps: torch.Tensor, cells: torch.Tensor, configs: torch.Tensor) -> torch.Tensor:
        """``log p(m_C = c, m_{-C})`` up to a constant in ``c``.

        Args:
            maps: ``B x K`` (or ``K``) current maps.
            cells: ``L`` cell indices of the patch ``C``.
            configs: ``W x L`` configurations (0/1).

        Returns:
            ``B x W`` (or ``W``).
        """
        maps = torch.as_tensor(maps)
        squeeze = maps.dim() == 1
        maps = maps.reshape(-1, maps.shape[-1])
        B, W = maps.shape[0], configs.shape[0]
        trial = maps[:, None, :].expand(B, W, maps.shape[-1]).clone()
        trial[:, :, cells] = configs.to(trial.dtype)[None]
        out = self.log_prob(trial)
        return out[0] if squeeze else out

    def outside_occupancy(self) -> float:
        """Occupancy probability ``lambda_out`` of a cell outside the map, used to marginalise the part of
        a ray beyond the grid edge (:class:`~ogm_ppl.models.OccupancyModel`): the prior's cell marginal
        ``P(m_k = 1)`` away from the edges. Default: the prior's ``mean_occupancy`` attribute where it has one
        (the table priors: the occupied share of the cells their tables counted), else 0.5 (the uniform
        prior). Priors whose cell marginal is not a parameter override it (:class:`~ogm_ppl.priors.MRFPrior`
        estimates it by prior Gibbs sampling)."""
        return float(getattr(self, "mean_occupancy", 0.5))

    def cell_log_odds(self) -> torch.Tensor | None:
        """Per-cell prior log-odds ``l(lambda_k)`` if cells are independent a priori, else ``None``."""
        return None

    def compiled(self) -> CompiledPrior | None:
        """The prior's compiled face: a bundle of :mod:`ogm_ppl.priors.compiled` the kernels read (each kind
        with its compiled cell and patch conditionals), or ``None`` for the generic path, one
        :meth:`log_prob_patch` call per update (correct, for small maps). The default gives priors with
        independent cells (:meth:`cell_log_odds` not ``None``) the
        :class:`~ogm_ppl.priors.compiled.IndependentCells` bundle."""
        lo = self.cell_log_odds()
        if lo is None:
            return None
        from ogm_ppl.priors.compiled import independent_cells

        return independent_cells(lo.detach().cpu().numpy())

    def sample(self, sample_shape=(), generator: torch.Generator | None = None) -> torch.Tensor:
        """Maps drawn from the prior, ``sample_shape x K`` (float 0/1)."""
        raise NotImplementedError  # pragma: no cover - interface

    def sample_given_free(
        self, free: torch.Tensor, sample_shape=(), generator: torch.Generator | None = None, max_rounds: int = 200
    ) -> torch.Tensor:
        """Maps drawn from the prior conditioned on the ``free`` cells (boolean ``K``) being 0.

        Independent priors (:meth:`cell_log_odds` not ``None``) draw and clear those cells (exact). Others
        use rejection in rounds (exact); after ``max_rounds`` rounds the maps still missing are drawn and
        cleared, with a warning (exact only if the cells are independent of the rest)."""
        free = torch.as_tensor(free, dtype=torch.bool)
        shape = torch.Size(sample_shape)
        if not free.any() or self.cell_log_odds() is not None:
            maps = torch.as_tensor(self.sample(shape, generator=generator), dtype=torch.float64).clone()
            maps[..., free] = 0.0
            return maps
        n = shape.numel()
        out = torch.empty(n, self.num_cells, dtype=torch.float64)
        todo = torch.arange(n)
        for _ in range(max_rounds):
            if not len(todo):
                break
            draw = torch.as_tensor(self.sample((len(todo),), generator=generator), dtype=torch.float64)
            if not ((draw == 0) | (draw == 1)).all():
                raise ValueError(f"{type(self).__name__}.sample returned values other than 0/1 (NaN parameters?)")
            ok = (draw[:, free] == 0).all(-1)
            out[todo[ok]] = draw[ok]
            todo = todo[~ok]
        if len(todo):
            import warnings

            warnings.warn(
                f"{type(self).__name__}: {len(todo)} of {n} prior draws still occupied a known-free "
                "cell after rejection; those cells were cleared (approximate)",
                stacklevel=2,
            )
            draw = torch.as_tensor(self.sample((len(todo),), generator=generator), dtype=torch.float64).clone()
            draw[:, free] = 0.0
            out[todo] = draw
        return out.reshape(shape + (self.num_cells,))
