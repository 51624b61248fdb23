import json
from importlib import resources

import pytest
import torch

from ogm_ppl.datasets import wall_datasets
from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss, fit_delta, warm_start_pn
from ogm_ppl.models import PN, Elfes, MarshallBarfoot, Moravec, delta_by_name
from ogm_ppl.models.delta import (
    NeuralDelta,
    family_from_dict,
    family_to_dict,
    fitted_names,
    load_fitted,
)


@pytest.fixture(scope="module")
def small():
    return wall_datasets(num=12, F=20, wall=14, sigma=2.0, num_readings=(1, 4), seed=3)


def test_loss_matches_evidence_grid_and_metrics(small):
    """The batched loss equals traditional OGM per dataset scored with metrics.cross_entropy."""
    from ogm_ppl import raycast
    from ogm_ppl.datasets import toy_1d
    from ogm_ppl.inference import evidence_grid
    from ogm_ppl.metrics import cross_entropy

    fam = Elfes(2.0, -6.0, max_kappa=small.F)
    total = 0.0
    for d, z in enumerate(small.readings):
        toy = toy_1d(num_cells=small.F + 1, wall=small.wall, readings=z, max_range=small.F)
        q = evidence_grid(raycast(toy.grid, toy.scans), fam).probabilities
        total += float(cross_entropy(small.exact[d, 1:], q[1:]))
    with torch.no_grad():
        assert float(cross_entropy_loss(fam, small)) == pytest.approx(total / len(small), rel=1e-10)


@pytest.mark.parametrize(
    "make",
    [
        lambda: Moravec(0.7, -0.4),
        lambda: Elfes(2.3, -3.0, max_kappa=20),
        lambda: PN(torch.linspace(-1.0, 0.3, 5)),
        lambda: NeuralDelta(20, hidden=4),
    ],
)
def test_loss_gradient_is_correct(small, make):
    fam = make()
    names = [n for n, _ in fam.named_parameters()]
    inputs = tuple(p.detach().clone().requires_grad_(True) for p in fam.parameters())

    class Loss(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.fam = fam

        def forward(self):
            return cross_entropy_loss(self.fam, small)

    loss = Loss()

    def f(*values):
        return torch.func.functional_call(loss, {f"fam.{n}": v for n, v in zip(names, values)}, ())

    assert torch.autograd.gradcheck(f, inputs)


def test_fit_decreases_loss_and_warm_start_is_exact(small):
    fam = Moravec.haehnel()
    with torch.no_grad():
        before = float(cross_entropy_loss(fam, small))
    res = fit_delta(fam, small)
    assert res.train_loss < before
    g = torch.autograd.grad(cross_entropy_loss(fam, small), list(fam.parameters()))
    assert max(float(x.abs().max()) for x in g) < 1e-5  # at a stationary point
    prev = fit_delta(PN.zeros(4), small).family
    for N in (5, 6):
        nxt = warm_start_pn(prev, N)
        d = torch.arange(-40, 40, dtype=torch.float64)
        torch.testing.assert_close(nxt.delta(d), prev.delta(d))  # same function, one more parameter
        prev = nxt


def test_shipped_artefacts_load_and_round_trip():
    names = fitted_names()
    for n in ("moravec_opt", "elfes_opt", "p1", "p21", "neural_opt", "p21_dd", "marshall_barfoot_opt"):
        assert n in names
    for n in names:
        fam, rec = load_fitted(n)
        assert rec["training"]["seed"] == 0 and rec["training"]["num"] == 1000
        t = fam.table(76, 76)
        assert torch.isfinite(t).all()
        again = family_from_dict(json.loads(json.dumps(family_to_dict(fam))))
        torch.testing.assert_close(again.table(76, 76), t)
    assert delta_by_name("p21").N == 21
    with pytest.raises(ValueError, match="unknown Delta family"):
        family_from_dict({"family": "os.system", "params": {}})


def test_refit_from_the_shipped_seed_reproduces_the_shipped_parameters():
    rec = json.loads((resources.files("ogm_ppl") / "fitted" / "delta_moravec_opt.json").read_text())
    tr = rec["training"]
    data = wall_datasets(
        num=tr["num"],
        F=tr["F"],
        wall=tr["wall"],
        sigma=tr["sigma"],
        num_readings=tuple(tr["num_readings"]),
        seed=tr["seed"],
    )
    for name, fam in (
        ("moravec_opt", Moravec.haehnel()),
        ("marshall_barfoot_opt", MarshallBarfoot(1.3863, 2)),
        ("elfes_opt", Elfes(3.0, -10.0, max_kappa=tr["F"])),
    ):
        fit_delta(fam, data, max_iter=tr["max_iter"], tol=tr["tol"])
        shipped, _ = load_fitted(name)
        for (k, a), (_, b) in zip(fam.state_dict().items(), shipped.state_dict().items()):
            torch.testing.assert_close(a, b, rtol=0, atol=1e-6, msg=name + "." + k)
    prev = None
    for N in (1, 2, 3):
        prev = fit_delta(warm_start_pn(prev, N), data, max_iter=tr["max_iter"], tol=tr["tol"]).family
    torch.testing.assert_close(prev.values, load_fitted("p3")[0].values, rtol=0, atol=1e-6)
