"""Learning a net field: the torch conditionals of pseudo-likelihood equal the compiled ones, the held-out score
is their mean negative log, and pseudo-likelihood recovers the conditionals of samples of a known net field to
within what the sample size allows."""

import numpy as np
import torch

from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds
from ogm_ppl.priors import NetFieldPrior
from ogm_ppl.priors.compiled.net_field_patches import net_prior_sweeps
from ogm_ppl.priors.learn_net import CellBatches, NetModel, eligible_cells, heldout_nll, pcd_loss, pl_loss


def test_torch_conditionals_equal_the_compiled_ones():
    rng = np.random.default_rng(0)
    g = rng.random((14, 17)) < 0.4
    known = np.ones_like(g)
    known[0, 3] = False  # the cells within 4 of it have no whole neighbourhood
    cb = CellBatches([(g, known)], 5)
    assert cb.n_cells == len(eligible_cells(known, 5)) == (14 - 8) * (17 - 8) - 1 * 4
    nb, y = cb.draw(10**9, rng)
    for act in ("relu", "softplus"):
        model = NetModel(5, 2, act, seed=1, unary=0.3)
        with torch.no_grad():
            model.out.mul_(20)
        got = model.log_odds(nb, y).detach().numpy()
        b = model.prior(g.shape).compiled()
        m = np.ascontiguousarray(g.ravel(), np.uint8)
        want = np.array([prior_log_odds(b, int(k), m) for k in cb.cells[0]])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        nll, n = heldout_nll(lambda shape, model=model: model.prior(shape).compiled(), [(g, known)], 5)
        assert n == cb.n_cells
        assert abs(nll - float(pl_loss(model, nb, y).detach())) < 1e-12


def test_pcd_loss_gradient_is_data_minus_model_statistics():
    """``d/d unary`` of the PCD loss is the chains' occupied share minus the data's."""
    model = NetModel(3, 1, seed=0)
    data = (torch.rand(4, 8, 8, generator=torch.Generator().manual_seed(0)) < 0.3).double()
    chains = (torch.rand(4, 8, 8, generator=torch.Generator().manual_seed(1)) < 0.6).double()
    pcd_loss(model, data, chains).backward()
    assert abs(float(model.unary.grad) - float(chains.mean() - data.mean())) < 1e-12


# a net field with ordered, wall-like samples: one filter (8 orientations) favouring a line through the centre
TEACHER = dict(filters=[[[0.0, -0.8, 0.0], [0.9, 1.2, 0.9], [0.0, -0.8, 0.0]]], bias=[-0.5], out=[0.3], unary=-0.5)


def _samples(n: int, side: int, seed: int) -> list:
    t = TEACHER
    teacher = NetFieldPrior((side, side), t["filters"], t["bias"], t["out"], t["unary"])
    rng = np.random.default_rng(seed)
    maps = np.ascontiguousarray(rng.random((n, side * side)) < 0.5, np.uint8)
    net_prior_sweeps(teacher.compiled(), maps, 200, seed)
    return [(m.reshape(side, side).astype(bool), np.ones((side, side), bool)) for m in maps]


def test_pseudo_likelihood_recovers_a_known_fields_conditionals():
    """Samples of the teacher (12 maps of 24 x 24, 200 sweeps from noise each); a student of two filters fitted by
    pseudo-likelihood (LBFGS, full batch) on their ``N = 4800`` interior cells. On 8 fresh samples the mean
    conditional KL(teacher || student) is at most ``4 p / (2N)`` (``p = 23`` parameters): the expected excess
    held-out log-loss of a maximum-likelihood fit is ``p / (2N)`` (``tr(J^-1 K) / (2N)`` for pseudo-likelihood,
    whose scores of neighbouring cells are correlated: measured 1.5 ``p / (2N)`` here), and far below the KL of
    ignoring the neighbours."""
    torch.manual_seed(0)
    train, test = _samples(12, 24, 1), _samples(8, 24, 2)
    cb = CellBatches(train, 3)
    nb, y = cb.draw(10**9, np.random.default_rng(0))
    student = NetModel(3, 2, "relu", seed=0)
    opt = torch.optim.LBFGS(
        student.parameters(), max_iter=200, line_search_fn="strong_wolfe", tolerance_grad=1e-9, tolerance_change=1e-12
    )

    def closure():
        opt.zero_grad()
        loss = pl_loss(student, nb, y)
        loss.backward()
        return loss

    opt.step(closure)
    teacher = NetModel(3, 1, "relu").load_arrays({k: np.asarray(v, np.float64) for k, v in TEACHER.items()})
    tb = CellBatches(test, 3)
    nbt, yt = tb.draw(10**9, np.random.default_rng(0))
    with torch.no_grad():
        pt = torch.sigmoid(teacher.log_odds(nbt, yt))
        ps = torch.sigmoid(student.log_odds(nbt, yt))

    def kl(p, q):
        return float((p * (p.log() - q.log()) + (1 - p) * (torch.log1p(-p) - torch.log1p(-q))).mean())

    p, N = sum(x.numel() for x in student.parameters()), cb.n_cells
    assert (p, N) == (23, 4800)
    got = kl(pt, ps)
    assert got <= 4 * p / (2 * N), (got, p / (2 * N))
    share = torch.full_like(pt, float(y.mean()))
    assert kl(pt, share) > 50 * got
