"""Contract checks every prior must pass: normalised, patch conditionals and samples agree with ``log_prob``,
and the compiled conditional the kernels read agrees with it too."""

from __future__ import annotations

import itertools
import math

import torch

__all__ = ["PriorContract"]


class PriorContract:
    """Mix into a pytest class and define ``make_prior(num_cells)`` (a 1D prior of ``num_cells`` cells) and,
    for a prior with structure across rows, ``make_prior_2d(shape)`` (the same prior on a ``2 x 3`` grid):
    every check then runs on both, as the 1D checks never see a vertical or diagonal neighbour.

    A prior whose ``log_prob`` is exact only up to its log partition function says so with
    ``normalised = False`` (and is normalised here by enumeration). Priors with a compiled form
    (``prior.compiled()`` not ``None``) also get the bundle's cell and patch conditionals checked against
    ``log_prob``.
    """

    num_cells = 6
    #: the grid of :meth:`make_prior_2d`: ``num_cells`` cells in rows x cols
    shape_2d = (2, 3)
    num_prior_samples = 20000

    def make_prior(self, num_cells):  # pragma: no cover - to be provided
        raise NotImplementedError

    def make_prior_2d(self, shape):
        """The prior on the 2D grid ``shape`` (rows, cols), or ``None`` (the default) to check it in 1D only."""
        return None

    def _priors(self):
        """The priors every check runs on: ``make_prior(num_cells)`` and, if given, ``make_prior_2d``."""
        yield self.make_prior(self.num_cells)
        prior_2d = self.make_prior_2d(self.shape_2d)
        if prior_2d is not None:
            assert math.prod(self.shape_2d) == self.num_cells, "shape_2d must hold num_cells cells"
            yield prior_2d

    def _all_maps(self):
        return torch.tensor(list(itertools.product([0.0, 1.0], repeat=self.num_cells)), dtype=torch.float64)

    def _log_prob(self, prior, maps):
        lp = prior.log_prob(maps)
        if getattr(prior, "normalised", True) is False:
            # normalised in float64: in a float32 prior's own dtype the normalisation would add float32
            # roundings that one CPU's logsumexp leaves and another's rounds to 0
            lp = lp.to(torch.float64) - torch.logsumexp(prior.log_prob(self._all_maps()).to(torch.float64), 0)
        return lp

    def test_normalised_over_all_maps(self):
        for prior in self._priors():
            lp = self._log_prob(prior, self._all_maps())
            name = type(prior).__name__
            assert lp.shape == (2**self.num_cells,), (
                f"{name}: log_prob of {2**self.num_cells} maps has shape {lp.shape}"
            )
            assert not torch.isnan(lp).any(), f"{name}: log_prob is NaN for {int(torch.isnan(lp).sum())} maps"
            # summed in float64 (2**num_cells terms: off by under 2**num_cells * eps64, far below 1e-10), so the
            # verdict is the prior's own values' and not the rounding of a float32 logsumexp on this CPU
            total = torch.logsumexp(lp.to(torch.float64), 0).item()
            dtype = prior.log_prob(self._all_maps()[:1]).dtype
            assert abs(total) < 1e-10, (
                f"{name}: log of the sum of p over all {2**self.num_cells} maps is {total:.3g}, not 0 (within 1e-10); "
                f"log_prob dtype {dtype} (float32 arithmetic, e.g. torch.where of Python floats, is off by ~1e-8)"
            )

    def test_outside_occupancy_is_the_priors_own(self):
        """``outside_occupancy()`` (the occupancy the model gives the cells past the grid's edge) lies in
        ``[0, 1]``; a prior left with the base class's default (0.5, no ``mean_occupancy``) must occupy its
        cells with probability near 0.5 (within 0.1 on the mean exact marginal), or it is a prior that forgot
        to say its occupancy."""
        from ogm_ppl.priors.base import MapPrior

        for prior in self._priors():
            lam = float(prior.outside_occupancy())
            assert 0.0 <= lam <= 1.0, lam
            if type(prior).outside_occupancy is MapPrior.outside_occupancy and not hasattr(prior, "mean_occupancy"):
                p = self._log_prob(prior, self._all_maps()).exp()
                mean = float((p[:, None] * self._all_maps()).sum(0).mean())
                assert abs(mean - lam) <= 0.1, (
                    f"{type(prior).__name__}: outside_occupancy() is the default {lam} but its cells are occupied "
                    f"with probability {mean:.3f}: override outside_occupancy (or set mean_occupancy)"
                )

    def test_patch_conditional_matches_log_prob(self):
        for prior in self._priors():
            maps = self._all_maps()
            cells = torch.tensor([1, 3, 4])
            configs = torch.tensor(list(itertools.product([0.0, 1.0], repeat=3)), dtype=torch.float64)
            got = prior.log_prob_patch(maps, cells, configs)  # B x W
            trial = maps[:, None, :].repeat(1, len(configs), 1)
            trial[:, :, cells] = configs
            want = prior.log_prob(trial)
            # equal up to a per-map constant (finite entries), same -inf pattern
            assert torch.equal(torch.isinf(got), torch.isinf(want))
            fin = torch.isfinite(want)
            diff = torch.where(fin, got - want, torch.nan)
            spread = diff.nan_to_num(-math.inf).amax(1) - diff.nan_to_num(math.inf).amin(1)
            rows = fin.any(1)
            assert (spread[rows] < 1e-10).all()

    def test_samples_follow_log_prob(self):
        from ogm_ppl.testing._stats import multinomial_goodness_of_fit

        for prior in self._priors():
            g = torch.Generator().manual_seed(0)
            s = prior.sample((self.num_prior_samples,), generator=g)
            codes = (s * (2 ** torch.arange(self.num_cells - 1, -1, -1))).sum(-1).long()
            counts = torch.bincount(codes, minlength=2**self.num_cells).double()
            probs = self._log_prob(prior, self._all_maps()).exp()
            support = probs > 0
            assert counts[~support].sum() == 0  # nothing sampled where the prior has no mass
            # chi-square needs expected counts of at least ~5: test the common maps (a truncated test)
            big = probs * counts.sum() >= 5
            assert multinomial_goodness_of_fit(probs[big], counts[big], total_count=int(counts.sum())) > 1e-3

    def test_compiled_cell_conditional_matches_log_prob(self):
        """The log-odds the compiled kernels read equal ``log p(m_k = 1, m_-k) - log p(m_k = 0, m_-k)``."""
        import numpy as np

        from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds

        for prior in self._priors():
            bundle = prior.compiled()
            if bundle is None:
                continue
            maps = self._all_maps()
            for k in range(self.num_cells):
                on, off = maps.clone(), maps.clone()
                on[:, k], off[:, k] = 1.0, 0.0
                a, b = prior.log_prob(on), prior.log_prob(off)
                for i in range(len(maps)):
                    m = maps[i].numpy().astype(np.uint8)
                    got = prior_log_odds(bundle, k, m)
                    assert np.array_equal(m, maps[i].numpy().astype(np.uint8))  # state restored
                    if torch.isinf(a[i]) and torch.isinf(b[i]):  # a map the prior rules out either way
                        continue
                    want = float(a[i] - b[i])
                    assert (math.isinf(want) and got == want) or abs(got - want) < 1e-10, (k, i, got, want)

    def test_compiled_patch_weights_match_log_prob(self):
        """The patch weights the compiled patch kernels read (``patch_prior_batch``, through the bundle's
        registered ``patch_prior_weights``) equal ``log p(m_C = c, m_-C)`` up to a constant per map."""
        import numpy as np

        from ogm_ppl.priors.compiled import patch_prior_batch

        for prior in self._priors():
            bundle = prior.compiled()
            if bundle is None:
                continue
            maps = self._all_maps()
            cells = np.array([1, 3, 4], np.int64)
            cands = np.arange(8, dtype=np.int64)
            got = np.empty((len(maps), 8))
            patch_prior_batch(bundle, np.ascontiguousarray(maps.numpy().astype(np.uint8)), cells, cands, got)
            configs = torch.tensor(list(itertools.product([0.0, 1.0], repeat=3)), dtype=torch.float64).flip(1)
            trial = maps[:, None, :].repeat(1, 8, 1)
            trial[:, :, torch.from_numpy(cells)] = configs  # candidate j sets bit b = the b-th patch cell
            want = prior.log_prob(trial).numpy()
            assert np.array_equal(np.isinf(got), np.isinf(want))
            fin = np.isfinite(want)
            with np.errstate(invalid="ignore"):  # -inf - -inf where both rule a map out
                diff = np.where(fin, got - want, np.nan)
            rows = fin.any(1)
            spread = np.nanmax(diff[rows], 1) - np.nanmin(diff[rows], 1)
            assert (spread < 1e-10).all()
