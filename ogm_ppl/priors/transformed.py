"""The shared face of a prior whose log-potentials are a fixed transform of another prior's: the base's
bookkeeping, its compiled bundle transformed once (``bundle.<method>(value)``), and draws by single-cell Gibbs
sweeps of that bundle. :class:`~ogm_ppl.priors.TemperedPrior` (``p~(m)^beta``) and
:class:`~ogm_ppl.priors.BiasedPrior` (``p~(m) exp(h sum_k m_k)``) are the two."""

from __future__ import annotations

import numpy as np
import torch

from ogm_ppl.priors.base import MapPrior


class TransformedPrior(MapPrior):
    """A prior built from ``base`` whose compiled bundle is ``bundle.<BUNDLE_METHOD>(value)``.

    A subclass sets :attr:`BUNDLE_METHOD` and :attr:`WHAT` (for the error of a bundle without the method), calls
    ``super().__init__(base, value, normalised)`` and writes ``log_prob``, ``log_prob_patch`` and
    ``cell_log_odds``; ``value`` is the transform's parameter (``self._value``)."""

    BUNDLE_METHOD = ""
    WHAT = ""

    def __init__(self, base: MapPrior, value: float, normalised: bool) -> None:
        self.base = base
        self._value = value
        self.num_cells = base.num_cells
        self.normalised = bool(normalised and getattr(base, "normalised", True))
        self.can_be_zero = bool(getattr(base, "can_be_zero", False))  # -inf stays -inf under every transform
        for attr in ("rows", "cols", "ndim", "shape"):
            if hasattr(base, attr):
                setattr(self, attr, getattr(base, attr))
        self._bundle = None
        self._bundle_ready = False

    def outside_occupancy(self) -> float:
        return self.base.outside_occupancy()

    def compiled(self):
        if not self._bundle_ready:
            bundle = self.base.compiled()
            if bundle is not None:
                if not hasattr(bundle, self.BUNDLE_METHOD):
                    raise TypeError(
                        f"the compiled bundle {type(bundle).__name__} of {type(self.base).__name__} has no "
                        f"{self.BUNDLE_METHOD}() method: it cannot be {self.WHAT}"
                    )
                bundle = getattr(bundle, self.BUNDLE_METHOD)(self._value)
            self._bundle, self._bundle_ready = bundle, True
        return self._bundle

    def _draws(self, sample_shape, generator: torch.Generator | None, num_sweeps: int) -> torch.Tensor:
        """Maps from this prior: independent cells exactly (when ``cell_log_odds`` is known), otherwise
        ``num_sweeps`` single-cell Gibbs sweeps of the transformed bundle from uniform noise."""
        shape = torch.Size(sample_shape)
        lo = self.cell_log_odds()
        if lo is not None:
            u = torch.rand(shape + (self.num_cells,), generator=generator, dtype=torch.float64)
            return (u < torch.sigmoid(lo)).to(torch.float64)
        bundle = self.compiled()
        if bundle is None:
            raise TypeError(f"{type(self).__name__} of {type(self.base).__name__} (no compiled face) cannot sample")
        from ogm_ppl.priors.compiled import prior_gibbs_sweeps

        B = int(np.prod(shape)) if len(shape) else 1
        u = torch.rand((B, self.num_cells), generator=generator, dtype=torch.float64)
        maps = np.ascontiguousarray((u < 0.5).numpy(), dtype=np.uint8)
        seed = int(torch.randint(0, 2**31 - 1, (1,), generator=generator))
        prior_gibbs_sweeps(bundle, maps, int(num_sweeps), seed)
        return torch.from_numpy(maps.astype(np.float64)).reshape(*shape, self.num_cells)
