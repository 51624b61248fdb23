"""Backed-off (Witten-Bell) tables: every configuration has mass, the conditionals are normalised and
match the formula, the compiled weights equal ``log_prob`` differences, the fitted hyper-parameters load
and are validated, and the named kinds build."""

import json
import math

import numpy as np
import pytest
import torch

from ogm_ppl.priors import BackoffBorderPrior, prior_by_name
from ogm_ppl.priors.backoff import (
    backoff_patch_probs,
    border_log_likelihood,
    fit_kappa,
    independent_table,
    load_backoff_params,
    witten_bell,
    witten_bell_border,
)
from ogm_ppl.priors.compiled.tiles import sparse_key_log_factor
from ogm_ppl.priors.tables import available_tables, tables_by_name
from ogm_ppl.testing import PriorContract


def _table(nb, ni, seed, density):
    rng = np.random.default_rng(seed)
    b, i = np.meshgrid(np.arange(2**nb), np.arange(2**ni), indexing="ij")
    counts = rng.integers(1, 9, b.shape).astype(float)
    counts[rng.random(b.shape) > density] = 0
    return b.ravel(), i.ravel(), counts.ravel()


class TestBackoffRun1D(PriorContract):
    num_prior_samples = 8000

    def make_prior(self, num_cells):
        return BackoffBorderPrior((num_cells,), *_table(2, 2, 1, 0.4), kappa=0.5, back=[0.4, 0.1, 0.2, 0.3], inner=2)


class TestBackoffCellGiven8Neighbours2D(PriorContract):
    num_prior_samples = 6000

    def make_prior(self, num_cells):
        b, i, c = _table(8, 1, 2, 0.5)
        keep = b % 3 != 0  # a third of the borders unseen: they read the back-off table
        return BackoffBorderPrior(
            (2, num_cells // 2), b[keep], i[keep], c[keep], kappa=2.0, back=[0.7, 0.3], inner=(1, 1), outside=0
        )


def _sparse_prior(seed=0):
    # 3 x 3 inners given 16 border cells: a 25-cell window, so the factors are looked up sparsely
    rng = np.random.default_rng(seed)
    b = rng.integers(0, 1 << 16, 300)
    i = rng.integers(0, 512, 300)
    c = rng.integers(1, 20, 300).astype(float)
    back = rng.random(512) + 0.1
    return BackoffBorderPrior((5, 5), b, i, c, kappa=0.7, back=back, inner=(3, 3), origin=(1, 1)), (b, i, c, back)


def test_conditionals_sum_to_one_and_match_witten_bell():
    p, (b, i, c, back) = _sparse_prior()
    back = back / back.sum()
    lp = p.compiled()
    assert lp.dense_bits < 0  # the sparse path
    for border in [int(b[0]), int(b[7]), 12345 if 12345 not in b else 12346]:
        cond = p.conditional(border)
        assert abs(cond.sum() - 1.0) < 1e-12 and (cond > 0).all()
        sel = b == border
        n_b = c[sel].sum()
        cnt = np.zeros(512)
        np.add.at(cnt, i[sel], c[sel])
        T_b = (cnt > 0).sum()
        want = (cnt + 0.7 * T_b * back) / (n_b + 0.7 * T_b) if n_b else back
        np.testing.assert_allclose(cond, want, rtol=1e-12, atol=0)
        keys = (np.int64(border) << 9) | np.arange(512, dtype=np.int64)
        got = np.array([sparse_key_log_factor(lp, 0, k) for k in keys.tolist()])
        np.testing.assert_allclose(got, np.log(want), rtol=0, atol=1e-12)


def test_every_map_has_mass_where_the_sparse_table_has_none():
    g = torch.Generator().manual_seed(0)
    maps = (torch.rand(200, 64, generator=g) < 0.4).double()
    for kind in ("border", "border1", "patch3"):
        raw = prior_by_name(f"{kind}:houseexpo", (8, 8)).log_prob(maps)
        bo = prior_by_name(f"{kind}_bo:houseexpo", (8, 8)).log_prob(maps)
        assert torch.isfinite(bo).all(), kind
        assert torch.isinf(raw).any(), kind  # the unsmoothed table rules out some noise maps


def test_compiled_patch_weights_equal_log_prob_differences():
    """The weights a 3 x 3 tile update reads (own factor + neighbours, sparse lookups) equal
    ``log p(m_C = c, m_-C)`` differences, for every configuration of the middle tile."""
    from ogm_ppl.priors.compiled import patch_prior_batch

    p, _ = _sparse_prior(1)
    rng = np.random.default_rng(3)
    maps = (rng.random((5, 25)) < 0.5).astype(np.uint8)
    cells = np.array([6, 7, 8, 11, 12, 13, 16, 17, 18], np.int64)
    cands = np.arange(512, dtype=np.int64)
    got = np.empty((5, 512))
    patch_prior_batch(p.compiled(), maps, cells, cands, got)
    trial = np.repeat(maps[:, None, :], 512, 1).astype(np.float64)
    trial[:, :, cells] = (cands[:, None] >> np.arange(9)) & 1
    want = p.log_prob(torch.from_numpy(trial)).numpy()
    assert np.isfinite(got).all()
    d = got - want
    assert (d.max(1) - d.min(1) < 1e-10).all()


def test_witten_bell_limits_and_dense_table():
    back = independent_table(0.3, 2)
    np.testing.assert_allclose(back, [0.49, 0.21, 0.21, 0.09])
    c = np.array([6.0, 0.0, 2.0, 0.0])
    p = witten_bell(c, 1.0, back)
    np.testing.assert_allclose(p, (c + 2 * back) / 10)
    assert abs(p.sum() - 1) < 1e-15
    np.testing.assert_allclose(witten_bell(c, 1e-12, back), c / 8, atol=1e-11)
    borders, log_lam, keys, logp = witten_bell_border([1, 1, 2], [0, 2, 3], [3, 1, 4], 0.5, back)
    assert borders.tolist() == [1, 2]
    np.testing.assert_allclose(np.exp(log_lam), [0.5 * 2 / (4 + 1), 0.5 / (4 + 0.5)])
    assert keys.tolist() == [4 | 0, 4 | 2, 8 | 3]
    np.testing.assert_allclose(np.exp(logp), [(3 + 1 * back[0]) / 5, (1 + 1 * back[2]) / 5, (4 + 0.5 * back[3]) / 4.5])
    with pytest.raises(ValueError, match="strictly positive"):
        witten_bell(c, 1.0, [0.5, 0.5, 0.0, 0.0])


def test_fit_kappa_maximises_the_validation_likelihood():
    back = np.full(4, 0.25)
    fit = (np.array([0, 0, 1]), np.array([0, 1, 2]), np.array([8.0, 2.0, 5.0]))
    val = (np.array([0, 0, 1, 1]), np.array([0, 3, 2, 1]), np.array([7.0, 1.0, 4.0, 1.0]))
    k, ll = fit_kappa(lambda x: border_log_likelihood(fit, val, x, back))
    assert abs(ll - border_log_likelihood(fit, val, k, back)) < 1e-12
    for f in (0.5, 0.9, 1.1, 2.0):
        assert border_log_likelihood(fit, val, k * f, back) <= ll + 1e-12


@pytest.mark.parametrize("corpus", available_tables())
def test_shipped_hyper_parameters_load(corpus):
    hp = load_backoff_params(corpus)
    assert hp.corpus == corpus and hp.kappa_border > 0 and hp.kappa_patch3 > 0 and hp.kappa_border1 > 0
    assert hp.provenance["validation_plans"] > 0 and hp.provenance["fit_plans"] > hp.provenance["validation_plans"]
    p3 = backoff_patch_probs(tables_by_name(corpus), hp.kappa_patch3)
    assert p3.shape == (512,) and (p3 > 0).all() and abs(p3.sum() - 1) < 1e-12


def test_bad_hyper_parameter_files_are_refused(tmp_path):
    good = json.loads((load_backoff_params.__globals__["_FITTED"] / "backoff_ipa.json").read_text())
    cases = {
        "notjson": "{",
        "format": json.dumps({**good, "format": "x"}),
        "version": json.dumps({**good, "format_version": 2}),
        "negative": json.dumps({**good, "kappa_border": -1.0}),
        "nan": json.dumps({**good, "kappa_patch3": math.nan}),
        "prov": json.dumps({**good, "provenance": 3}),
    }
    for name, text in cases.items():
        path = tmp_path / f"{name}.json"
        path.write_text(text)
        with pytest.raises(ValueError, match=str(path)):
            load_backoff_params("ipa", path)
    with pytest.raises(FileNotFoundError, match="backoff_nowhere"):
        load_backoff_params("nowhere")


def test_your_own_tables_get_their_own_weights_or_a_clear_refusal(tmp_path):
    """Tables counted on plans of your own: the backed-off kinds refuse to smooth them with the default
    corpus's weights unless a corpus is named; ``fit_backoff_params`` fits weights on them (the shipped
    fitting, as ``ogm_ppl.learn.fit_backoff`` runs it), and the pattern fields refuse tables outright."""
    from ogm_ppl.datasets.mapgen import generate_map
    from ogm_ppl.priors import prior_by_name
    from ogm_ppl.priors.backoff import backed_off_prior, fit_backoff_params, load_backoff_params, save_backoff_params
    from ogm_ppl.priors.learn import count_tables

    maps = [generate_map(k, (80, 80), seed=i, border=4) for i, k in enumerate(["office", "hall"] * 3)]
    fit = count_tables(maps[:4], symmetries=True, progress=False)
    val = count_tables(maps[4:], symmetries=True, progress=False)
    for kind in ("patch3_bo", "border_bo", "border1_bo"):
        with pytest.raises(ValueError, match="fit_backoff_params"):
            prior_by_name(kind, (12, 12), tables=fit)
    hp = fit_backoff_params(fit, val, "mine")
    assert hp.corpus == "mine" and all(k > 0 for k in (hp.kappa_patch3, hp.kappa_border, hp.kappa_border1))
    kept = save_backoff_params(hp, tmp_path / "weights" / "backoff_mine.json")
    assert load_backoff_params("mine", path=kept) == hp  # the shipped format, read back as it was
    own = backed_off_prior("border_bo", (12, 12), fit, params=hp)
    assert own.kappa == hp.kappa_border
    named = prior_by_name("border_bo:houseexpo", (12, 12), tables=fit)  # a corpus named: its weights, your counts
    assert named.kappa == load_backoff_params("houseexpo").kappa_border
    with pytest.raises(ValueError, match="give params"):
        backed_off_prior("patch3_bo", (12, 12), fit)
    for kind in ("field", "field2"):
        with pytest.raises(ValueError, match="fitted pattern field"):
            prior_by_name(kind, (12, 12), tables=fit)
