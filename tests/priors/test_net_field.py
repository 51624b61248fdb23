"""The net-field prior: the prior contract on enumerable grids (ReLU and softplus, 1D and 2D, windows larger than
the grid), compiled cell and patch conditionals equal to ``log_prob`` differences to 1e-12, kept conditionals a
function of the neighbourhood, the symmetry tying, and its files (the kernel contract under it:
``tests/inference/mcmc/test_net_field_kernels.py``)."""

import numpy as np
import pytest
import torch

from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds
from ogm_ppl.priors import BiasedPrior, NetFieldPrior, TemperedPrior
from ogm_ppl.priors.compiled import NetField, patch_prior_batch
from ogm_ppl.priors.compiled.net_field_patches import net_log_prob_batch
from ogm_ppl.priors.net_field import load_net_field, net_from_file, oriented_np, save_net_field
from ogm_ppl.testing import PriorContract


def random_net(shape, w=3, hidden=2, activation="relu", seed=0, scale=0.5, pad=0.5, out=0.5):
    """A seeded net field; its cell marginal stated (0.4), not estimated by prior chains on 48 x 48 cells (which
    ``test_outside_occupancy_is_stored_or_estimated`` checks)."""
    rng = np.random.default_rng(seed)
    return NetFieldPrior(
        shape,
        rng.normal(0, scale, (hidden, w, w)),
        rng.normal(0, 1, hidden),
        rng.normal(0, out, hidden),
        rng.normal(0, 0.2),
        pad,
        activation,
        occupancy=0.4,
    )


class TestContractRelu(PriorContract):
    """``w = 3`` windows on an 8-cell row and a 2 x 4 grid: every window crosses the edge."""

    num_cells = 8
    shape_2d = (2, 4)
    num_prior_samples = 4000

    def make_prior(self, num_cells):
        return random_net((num_cells,), 3, 2, "relu", 0, scale=0.7, out=0.3)

    def make_prior_2d(self, shape):
        return random_net(shape, 3, 2, "relu", 1, scale=0.7)


class TestContractSoftplus(PriorContract):
    """Softplus units, padding 0 and 1, and a window wider than the grid (``w = 5`` on 2 x 3)."""

    num_cells = 6
    shape_2d = (2, 3)
    num_prior_samples = 1000  # 64 maps; softplus costs an exp and a log1p a unit

    def make_prior(self, num_cells):
        return random_net((num_cells,), 3, 1, "softplus", 2, scale=0.7, pad=0.0, out=0.3)

    def make_prior_2d(self, shape):
        return random_net(shape, 5, 1, "softplus", 3, scale=0.5, pad=1.0, out=0.1)


@pytest.mark.parametrize(
    "shape,w,act", [((5, 6), 3, "relu"), ((6, 7), 5, "softplus"), ((8, 9), 7, "relu"), ((9, 6), 9, "relu")]
)
def test_compiled_conditionals_equal_log_prob_differences(shape, w, act):
    """Cell conditionals (through the memo's three paths: two-word keys and window memo for ``w <= 6``, longer
    keys for ``w = 7``, no window memo for ``w >= 8``), whole-map energies and patch weights against ``log_prob``."""
    p = random_net(shape, w, 2, act, 4, scale=0.3, out=0.05)  # |log p~| of order 50: differences exact to ~1e-14
    K = p.num_cells
    rng = np.random.default_rng(1)
    maps = torch.from_numpy((rng.random((8, K)) < rng.uniform(0.2, 0.8, (8, 1))).astype(np.float64))
    on, off = maps[:, None, :].repeat(1, K, 1), maps[:, None, :].repeat(1, K, 1)
    idx = torch.arange(K)
    on[:, idx, idx], off[:, idx, idx] = 1.0, 0.0
    want = (p.log_prob(on) - p.log_prob(off)).numpy()
    mm = np.ascontiguousarray(maps.numpy().astype(np.uint8))
    for i in range(len(maps)):
        got = np.array([prior_log_odds(p.compiled(), k, mm[i]) for k in range(K)])
        np.testing.assert_allclose(got, want[i], rtol=0, atol=1e-12)
    lp = np.empty(len(maps))
    net_log_prob_batch(p.compiled(), mm, lp)
    np.testing.assert_allclose(lp, p.log_prob(maps).numpy(), rtol=1e-13, atol=1e-12)
    R, C = shape
    patches = []
    for h, ww in ((3, 3), (2, 2)):
        for r0, c0 in ((0, 0), (R - h, C - ww)):
            patches.append(np.array([(r0 + a) * C + c0 + b for a in range(h) for b in range(ww)], np.int64))
    patches.append(np.array([0, -1, C + 1, 2 * C - 1, -1, K - 1], np.int64))  # pinned / scattered cells
    for patch in patches:
        live = patch[patch >= 0]
        L = len(live)
        for cands in (np.arange(1 << L, dtype=np.int64), np.array([5, 0, (1 << L) - 1, 2], np.int64)):
            got = np.empty((len(maps), len(cands)))
            patch_prior_batch(p.compiled(), mm, patch, cands, got)
            trial = maps[:, None, :].repeat(1, len(cands), 1)
            trial[:, :, torch.from_numpy(live)] = ((torch.from_numpy(cands)[:, None] >> torch.arange(L)) & 1).double()
            d = got - p.log_prob(trial).numpy()
            assert (d.max(1) - d.min(1)).max() < 1e-12, patch


def test_the_field_is_tied_over_the_8_symmetries():
    p = random_net((7, 7), 3, 3, "relu", 5)
    g = (np.random.default_rng(0).random((7, 7)) < 0.4).astype(np.float64)
    images = [np.rot90(g, k) for k in range(4)]
    images += [x.T for x in images]
    lp = p.log_prob(torch.from_numpy(np.stack([x.ravel() for x in images])))
    torch.testing.assert_close(lp, lp[:1].expand(8), rtol=0, atol=1e-11)
    units = oriented_np(p.filters)
    assert units.shape == (24, 3, 3)
    np.testing.assert_array_equal(units[2], np.rot90(p.filters[0]))
    np.testing.assert_array_equal(units[9], p.filters[1].T)


def test_tempered_and_biased_bundles():
    p = random_net((5, 6), 3, 2, "softplus", 7)
    m = torch.from_numpy((np.random.default_rng(0).random((4, 30)) < 0.5).astype(float))
    q = p.tempered(0.4)
    torch.testing.assert_close(q.log_prob(m), 0.4 * p.log_prob(m), rtol=0, atol=1e-12)
    b = p.compiled().tempered(0.4)
    assert isinstance(b, NetField)
    mm = np.ascontiguousarray(m.numpy().astype(np.uint8))
    for k in (0, 7, 29):
        assert abs(prior_log_odds(b, k, mm[0]) - prior_log_odds(q.compiled(), k, mm[0])) < 1e-12
        t = TemperedPrior(p, 0.4).compiled()
        assert abs(prior_log_odds(t, k, mm[0]) - 0.4 * prior_log_odds(p.compiled(), k, mm[0])) < 1e-12
        h = BiasedPrior(p, 0.7).compiled()
        assert abs(prior_log_odds(h, k, mm[1]) - prior_log_odds(p.compiled(), k, mm[1]) - 0.7) < 1e-12
    assert p.compiled().factor_extent() == 2
    assert p.compiled().window(6, 2, 2, 3, 3).rows == 3


@pytest.mark.parametrize("w", [3, 7, 9])
def test_kept_conditionals_are_a_function_of_the_neighbourhood(w):
    """One bundle asked about cells of several maps in turn, each map changing a cell at a time, answers what a
    bundle with nothing kept answers, bit for bit, at the edges and inside."""
    p = random_net((10, 11), w, 2, "relu", 13, scale=0.4)
    shared = p.compiled()
    rng = np.random.default_rng(3)
    maps = np.ascontiguousarray(rng.random((3, p.num_cells)) < 0.4, dtype=np.uint8)
    for step in range(400):
        m = maps[step % 3]
        m[rng.integers(p.num_cells)] ^= rng.random() < 0.5
        k = int(rng.integers(p.num_cells))
        got = prior_log_odds(shared, k, m)
        assert got == prior_log_odds(p.with_shape(p.shape).compiled(), k, m), (step, k)
    both = np.repeat(maps[:1], 2, 0).astype(np.float64)
    both[0, k], both[1, k] = 1.0, 0.0
    want = p.log_prob(torch.from_numpy(both))
    assert abs(prior_log_odds(shared, k, maps[0]) - float(want[0] - want[1])) < 1e-12


def test_outside_occupancy_is_stored_or_estimated():
    z = np.zeros((1, 3, 3))
    assert NetFieldPrior((4, 4), z, [0.0], [0.0], occupancy=0.3).outside_occupancy() == 0.3
    # all weights 0: cells are independent fair coins
    assert abs(NetFieldPrior((4, 4), z, [0.0], [0.0]).outside_occupancy() - 0.5) < 0.02
    assert NetFieldPrior((4, 4), z, [0.0], [0.0], unary=3.0).outside_occupancy() > 0.9


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="H x w x w"):
        NetFieldPrior((4, 4), np.zeros((2, 3, 4)), np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match="U = 16"):
        NetFieldPrior((4, 4), np.zeros((2, 3, 3)), np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError, match="finite"):
        NetFieldPrior((4, 4), np.full((2, 3, 3), np.nan), np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match="activation"):
        NetFieldPrior((4, 4), np.zeros((2, 3, 3)), np.zeros(2), np.zeros(2), activation="tanh")
    with pytest.raises(ValueError, match="pad"):
        NetFieldPrior((4, 4), np.zeros((2, 3, 3)), np.zeros(2), np.zeros(2), pad=2.0)


# ------------------------------------------------------------------ files
def test_a_net_field_saves_and_loads_back(tmp_path):
    p = random_net((6, 7), 3, 2, "softplus", 11)
    p.occupancy = 0.37
    path = save_net_field(tmp_path / "net.npz", p)
    back = net_from_file(path, (6, 7))
    maps = (torch.rand(10, 42, generator=torch.Generator().manual_seed(0)) < 0.4).double()
    torch.testing.assert_close(back.log_prob(maps), p.log_prob(maps), rtol=0, atol=0)
    assert back.outside_occupancy() == 0.37 and back.activation == "softplus" and back.pad == 0.5
    assert net_from_file(path, (3, 3)).num_cells == 9


def test_load_refuses_bad_files(tmp_path):
    p = random_net((4, 4), 3, 2, "relu", 12)
    p.occupancy = 0.4
    good = dict(np.load(save_net_field(tmp_path / "ok.npz", p)))

    def write(name, **change):
        d = {**good, **change}
        for k in [k for k, v in change.items() if v is None]:
            del d[k]
        np.savez(tmp_path / name, **d)
        return tmp_path / name

    assert load_net_field(tmp_path / "ok.npz")["w"] == 3
    for name, change, match in [
        ("kind.npz", {"kind": np.array("pattern_field")}, "kind"),
        ("nokind.npz", {"kind": None}, "not a net-field file"),
        ("version.npz", {"format_version": np.int64(2)}, "version"),
        ("missing.npz", {"bias": None}, "missing"),
        ("shape.npz", {"bias": np.zeros(3)}, "shape"),
        ("nan.npz", {"filters": np.full((2, 3, 3), np.nan)}, "finite"),
        ("w.npz", {"w": np.int64(4)}, "filters"),
        ("occ.npz", {"occupancy": np.float64(1.5)}, "occupancy"),
        ("act.npz", {"activation": np.array("tanh")}, "activation"),
    ]:
        with pytest.raises(ValueError, match=match):
            load_net_field(write(name, **change))
    np.savez(tmp_path / "field.npz", w=np.int64(3), theta=np.zeros(102), occupancy=np.float64(0.3))
    with pytest.raises(ValueError, match="pattern field"):
        load_net_field(tmp_path / "field.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"junk\.npz"):
        load_net_field(tmp_path / "junk.npz")


def test_the_calibrated_name_is_the_shipped_net_raised_to_its_fitted_exponent():
    """``net:houseexpo@cal``: ``log_prob`` is the shipped field's times the exponent of
    ``ogm_ppl/fitted/temper_houseexpo.json`` (the same product), and its compiled conditionals are theirs times it to
    1e-12 relative (the tempered bundle scales the output weights, so the sums round apart)."""
    from ogm_ppl.priors.named import load_temper_params, prior_by_name

    beta = load_temper_params("houseexpo").beta["net"]
    cal, base = prior_by_name("net:houseexpo@cal", (6, 7)), prior_by_name("net:houseexpo", (6, 7))
    assert isinstance(cal, TemperedPrior) and cal.beta == beta < 1.0
    maps = (torch.rand(5, 42, generator=torch.Generator().manual_seed(0)) < 0.4).double()
    assert torch.equal(cal.log_prob(maps), base.log_prob(maps) * beta)
    m = np.ascontiguousarray(maps[0].numpy(), np.uint8)
    got = np.array([prior_log_odds(cal.compiled(), k, m) for k in range(42)])
    want = beta * np.array([prior_log_odds(base.compiled(), k, m) for k in range(42)])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
