"""Contract checks every prior must pass: normalised, patch conditionals and samples agree with ``log_prob``,
and the compiled conditional the kernels read agrees with it too."""

from __future__ import annotations

import itertools
import math

import torch

__all__ = ["PriorContract"]


class PriorContract:
    """Mix into a pytest class and define ``make_prior(num_cells)``.

    A prior whose ``log_prob`` is exact only up to its log partition function says so with
    ``normalised = False`` (and is normalised here by enumeration). Priors with a compiled local
    conditional (``prior.local()``) also get their compiled cell log-odds checked against ``log_prob``.
    """

    num_cells = 6
    num_prior_samples = 20000

    def make_prior(self, num_cells):  # pragma: no cover - to be provided
        raise NotImplementedError

    def _all_maps(self):
        return torch.tensor(list(itertools.product([0.0, 1.0], repeat=self.num_cells)), dtype=torch.float64)

    def _log_prob(self, prior, maps):
        lp = prior.log_prob(maps)
        if getattr(prior, "normalised", True) is False:
            lp = lp - torch.logsumexp(prior.log_prob(self._all_maps()), 0)
        return lp

    def test_normalised_over_all_maps(self):
        lp = self._log_prob(self.make_prior(self.num_cells), self._all_maps())
        assert lp.shape == (2**self.num_cells,) and not torch.isnan(lp).any()
        assert abs(torch.logsumexp(lp, 0).item()) < 1e-10

    def test_patch_conditional_matches_log_prob(self):
        prior = self.make_prior(self.num_cells)
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
        from pyro.distributions.testing.gof import multinomial_goodness_of_fit

        prior = self.make_prior(self.num_cells)
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

        prior = self.make_prior(self.num_cells)
        bundle = prior.compiled()
        if bundle is None:
            return
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

        prior = self.make_prior(self.num_cells)
        bundle = prior.compiled()
        if bundle is None:
            return
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
