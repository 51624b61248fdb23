"""``MapPrior.outside_occupancy``: the cell marginal the likelihood of a ray cut by the grid edge uses for the
cells beyond it. Table priors give the occupied share their tables counted, named MRFs the corpus's occupied
share, a bare MRF its own marginal (checked against the exact transfer-matrix marginal in 1D), and the
likelihood table of a model follows the value."""

import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.priors import IndependentPrior, MRFPrior
from ogm_ppl.priors.named import prior_by_name
from ogm_ppl.priors.tables import tables_by_name


def test_patch_table_gives_the_cell_marginal_of_its_table():
    t = tables_by_name("houseexpo")
    c = np.asarray(t.counts3x3, np.float64)
    ones = np.array([bin(code).count("1") for code in range(512)], np.float64)
    expected = float((c * ones).sum() / (9 * c.sum()))  # mean over the 9 in-tile positions of P(cell = 1)
    assert prior_by_name("patch3:houseexpo", (12, 12)).outside_occupancy() == pytest.approx(expected, abs=1e-12)
    # the backed-off table: the marginal of its smoothed probabilities (Witten-Bell moves ~3e-7 of mass)
    bo = prior_by_name("patch3_bo:houseexpo", (12, 12))
    ones_bo = np.array([bin(int(code)).count("1") for code in bo.codes], np.float64)
    assert bo.outside_occupancy() == pytest.approx(float((bo.probs * ones_bo).sum() / 9), abs=1e-12)
    assert bo.outside_occupancy() == pytest.approx(expected, abs=1e-5)


@pytest.mark.parametrize("kind", ["border", "border_bo", "border1"])
def test_border_priors_give_a_marginal_near_the_corpus_share(kind):
    p = prior_by_name(f"{kind}:houseexpo", (12, 12))
    lam = float(tables_by_name("houseexpo").lam)
    # the inner cells the border tables counted are the corpus's cells away from the plan edges
    assert p.outside_occupancy() == p.mean_occupancy and abs(p.outside_occupancy() - lam) < 0.05


@pytest.mark.parametrize("kind", ["mrf", "mrf8"])
def test_named_mrf_uses_the_corpus_share(kind):
    assert prior_by_name(f"{kind}:ipa", (12, 12)).outside_occupancy() == float(tables_by_name("ipa").lam)


def _chain_marginal(lam: float, psi: float) -> float:
    # stationary marginal of the infinite 1D chain p(m) ~ prod phi(m_k) prod psi^[m_j != m_k]:
    # symmetric transfer matrix T[a, b] = sqrt(phi(a)) psi^[a != b] sqrt(phi(b)); P(m = a) = v_a^2
    phi = np.array([1 - lam, lam])
    T = np.sqrt(phi)[:, None] * np.array([[1.0, psi], [psi, 1.0]]) * np.sqrt(phi)[None, :]
    w, v = np.linalg.eigh(T)
    top = v[:, np.argmax(w)]
    return float(top[1] ** 2 / (top**2).sum())


def test_bare_mrf_estimates_its_own_marginal():
    assert MRFPrior((5,), order=1, psi=1.0, cell_prior=0.3).outside_occupancy() == pytest.approx(0.3)
    p = MRFPrior((5,), order=1, psi=0.5, cell_prior=0.3)
    exact = _chain_marginal(0.3, 0.5)
    assert abs(exact - 0.3) > 0.04  # the conditional lambda is not the marginal
    # 8 chains x 40 centre cells x 10 draws 10 sweeps apart; correlation length ~1 cell: N_eff >~ 1000,
    # SE <~ sqrt(0.2 * 0.8 / 1000) = 0.013; 3 SE
    assert p.outside_occupancy() == pytest.approx(exact, abs=0.04)
    assert p.outside_occupancy() == p.outside_occupancy()  # cached, seeded
    with pytest.raises(ValueError, match="outside"):
        MRFPrior((5,), outside=1.5)
    assert MRFPrior((5,), outside=0.25).outside_occupancy() == 0.25


def test_stencil_prior_estimates_its_own_marginal():
    """A :class:`StencilPrior` (the documented way to a researcher's own pairwise prior) reports its cell
    marginal, not the uniform prior's 0.5: exact without coupling, and the 1D chain's transfer-matrix marginal
    within the sampling tolerance of :func:`test_bare_mrf_estimates_its_own_marginal` with it."""
    from ogm_ppl.priors import StencilPrior

    assert StencilPrior((4, 5), unary=-3.0).outside_occupancy() == pytest.approx(1 / (1 + math.exp(3.0)), abs=1e-15)
    # h = -1, J = 1.5, a = -0.2: interior log-odds h + 2 a + J (m_left + m_right); an Ising chain with
    # psi = exp(-J / 2) and lambda = sigmoid(h + 2 a + J)
    h, J, a = -1.0, 1.5, -0.2
    lam = 1 / (1 + math.exp(-(h + 2 * a + J)))
    exact = _chain_marginal(lam, math.exp(-J / 2))
    p = StencilPrior((30,), unary=h, offsets=[1], coupling=J, bias=a)
    assert p.outside_occupancy() == pytest.approx(exact, abs=0.04) and abs(exact - 0.5) > 0.04
    # the same field as an MRF gives the same estimate, to the bit
    lp = math.log(0.5)
    mrf = MRFPrior((10, 10), order=2, psi=0.5, cell_prior=0.3)
    field = StencilPrior((10, 10), math.log(0.3 / 0.7), [(0, 1), (1, 0), (1, 1), (1, -1)], -2 * lp, lp)
    assert field.outside_occupancy() == mrf.outside_occupancy()
    assert StencilPrior((5,), outside=0.25).outside_occupancy() == 0.25
    with pytest.raises(ValueError, match="outside"):
        StencilPrior((5,), outside=-0.1)


def test_likelihood_of_a_cut_ray_follows_the_priors_outside_occupancy():
    # a 9-cell line and a sensor reaching 20 cells: the "no hit in the grid" column equals the one an
    # independent prior with lambda = the prior's outside occupancy gives
    grid = Grid.line(9)
    rays = raycast(grid, Scans.one_d([3.0, 11.0, 17.0, 20.0], max_range=20.0))
    for prior in (MRFPrior((9,), order=1, psi=0.4, cell_prior=0.3), MRFPrior((9,), outside=0.7)):
        lam = prior.outside_occupancy()
        got = OccupancyModel(grid, rays, GaussianRange(2.0), prior).loglik_table
        ref = OccupancyModel(grid, rays, GaussianRange(2.0), IndependentPrior(lam, 9)).loglik_table
        torch.testing.assert_close(got, ref, rtol=0, atol=1e-14)
        assert not math.isclose(lam, 0.5)
