"""Learning a net field: the torch conditionals of pseudo-likelihood equal the compiled ones, the held-out score
is their mean negative log, pseudo-likelihood recovers the conditionals of samples of a known net field to
within what the sample size allows, persistent contrastive divergence moves a perturbed field to its samples'
statistics, and the prior-sample statistics tell an ordered field from independent cells."""

import numpy as np
import torch

from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds
from ogm_ppl.priors import NetFieldPrior
from ogm_ppl.priors.compiled.net_field_patches import net_prior_sweeps
from ogm_ppl.priors.learn_net import (
    SAMPLE_STARTS,
    CellBatches,
    NetModel,
    eligible_cells,
    heldout_nll,
    pcd_loss,
    pcd_update,
    pl_loss,
    prior_sample_statistics,
    sample_statistics,
)


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


def test_sample_statistics_count_runs_along_rows_and_columns():
    """One wall across a 4 x 4 map: occupied runs are the row (4 cells) and 4 one-cell column crossings
    (8 cells in 5 runs); free runs are 3 rows of 4 and 2 runs in each column (24 cells in 11 runs)."""
    x = np.zeros((1, 4, 4), bool)
    x[0, 1, :] = True
    got = sample_statistics(x)
    assert got == {"occupied": 0.25, "occupied_run": 8 / 5, "free_run": 24 / 11}
    assert np.isnan(sample_statistics(np.zeros((1, 3, 3), bool))["occupied_run"])


# a two-phase field: one filter rewards windows mostly occupied, the other windows mostly free
TWO_PHASE = dict(filters=[np.ones((3, 3)), -np.ones((3, 3))], bias=[-4.5, 4.5], out=[1.0, 1.0])


def test_prior_sample_statistics_tell_an_ordered_field_from_independent_cells():
    """The two-phase field keeps each start (a flip costs 9 windows x 8 orientations x 1 = 72 nats): the starts'
    occupied shares differ by 1. A zero field is independent fair cells after one sweep: 2 chains x 16^2 read cells
    a start, so the two shares differ by at most 4 standard deviations, ``4 sqrt(2 * 0.25 / 512)``, and the mean
    runs are those of fair coins (2 cells) within the same relative margin."""
    ordered = NetFieldPrior((24, 24), **TWO_PHASE)
    row = prior_sample_statistics(ordered, chains=2, sweeps=3, edge=4, seed=0)
    assert row["start_gap"] == 1.0 and row["free"]["occupied"] == 0.0
    zero = NetFieldPrior((24, 24), np.zeros((1, 3, 3)), [0.0], [0.0])
    row = prior_sample_statistics(zero, chains=2, sweeps=1, edge=4, seed=0)
    tol = 4 * np.sqrt(2 * 0.25 / 512)
    assert abs(row["start_gap"]) <= tol
    for start in SAMPLE_STARTS:
        assert abs(row[start]["occupied_run"] / 2 - 1) <= 2 * tol and abs(row[start]["free_run"] / 2 - 1) <= 2 * tol


def test_pcd_moves_a_perturbed_field_to_its_samples_statistics():
    """Maximum likelihood with persistent chains (:func:`pcd_update`): 32 samples of the teacher (16 x 16, 50
    sweeps from noise: its disordered samples mix in a few) are the data; a student equal to the teacher but with
    its unary bias raised by 1.5 (its samples over 85 % occupied) takes 60 Adam steps (16 chains, 2 sweeps a step).
    16 fresh samples of the student then have the data's occupied share to within the larger of 4 standard errors
    of the difference of the two means (``32 x 256`` and ``16 x 256`` cells, treated as independent, widened 3 times
    for their correlation) and a third of the start's gap."""
    side, n, m = 16, 32, 16
    t = TEACHER
    teacher = NetFieldPrior((side, side), t["filters"], t["bias"], t["out"], t["unary"])
    data = np.ascontiguousarray(np.random.default_rng(1).random((n, side * side)) < 0.5, np.uint8)
    net_prior_sweeps(teacher.compiled(), data, 50, 1)
    student = NetModel(3, 1, "relu").load_arrays({k: np.asarray(v, np.float64) for k, v in TEACHER.items()})
    with torch.no_grad():
        student.unary.add_(1.5)

    def share_of_fresh_samples(seed: int) -> float:
        fresh = np.ascontiguousarray(np.random.default_rng(seed).random((m, side * side)) < 0.5, np.uint8)
        net_prior_sweeps(student.prior((side, side)).compiled(), fresh, 50, seed)
        return float(fresh.mean())

    target = float(data.mean())
    before = share_of_fresh_samples(5)
    opt = torch.optim.Adam(student.parameters(), lr=0.02)
    chains = np.ascontiguousarray(np.random.default_rng(2).random((16, side * side)) < 0.5, np.uint8)
    for i in range(60):
        batch = data[np.random.default_rng([4, i]).integers(0, n, 16)]
        pcd_update(student, opt, batch, chains, 2, 10 + i)
    after = share_of_fresh_samples(6)
    se = 3 * np.sqrt(target * (1 - target) * (1 / n + 1 / m) / (side * side))
    assert before - target > 0.25
    assert abs(after - target) <= max(4 * se, (before - target) / 3), (before, after, target)
