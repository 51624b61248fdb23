r"""The guide's map without gradients (``amortised_fast``) against the reference network, to float32 rounding.

Tolerance, from float32 accumulation. A sum of ``n`` float32 products (bias included) computed in any order,
with or without fused multiply-adds, is within :math:`\gamma_n \sum_i |a_i|` of the exact sum,
:math:`\gamma_n = n u / (1 - n u)`, :math:`u = 2^{-24}`. So each layer ``l`` of a float32 pass is the exact
layer plus a perturbation ``delta_l`` of its pre-activation with
:math:`|\delta_l| \le \gamma_{n_l} (|W_l| * |h_{l-1}| + |b_l|)` (``*`` the convolution, ``n_l = 9 C_{l-1} + 1``;
likewise the ``1 x 1`` head and skip). To first order the output moves by :math:`\sum_l J_l \delta_l`, with
:math:`J_l` the float64 network's Jacobian of the logits in layer ``l``'s pre-activation, so

.. math:: |\hat g - g| \le \sum_l |J_l|\, \gamma_{n_l} (|W_l| * |h_{l-1}| + |b_l|) \ (+\ O(u^2)),

computed per cell in float64 on small grids (the Jacobian exactly, by autograd); the tests allow twice it for
the second-order terms, and the mean over the 8 symmetries adds :math:`\gamma_{10}` of the magnitudes it sums.
(The bound without the Jacobian, through :math:`|W_l|`, grows by the layers' absolute row sums, ~30 a layer, and
says nothing.) Both float32 paths, the reference and the fast one, must lie within it of the float64 network.
"""

import numpy as np
import pytest
import torch
from torch import nn

from ogm_ppl.inference.variational.amortised import AmortisedGuide, random_scene
from ogm_ppl.inference.variational.amortised_fast import fast_logits, turned_kernels
from ogm_ppl.inference.variational.amortised_net import GuideArchitecture, GuideNet, _symmetrised
from ogm_ppl.inference.variational.corpus_guides import corpus_guide
from ogm_ppl.priors.named import prior_by_name

U = 2.0**-24
SECOND_ORDER = 2.0


def gamma(n: int) -> float:
    return n * U / (1 - n * U)


def _conv(h, w, b, d):
    return nn.functional.conv2d(h, w, b, padding=d, dilation=max(d, 1))


def exact_and_bound(net: nn.Module, x: torch.Tensor, flip: bool = False, k: int = 0):
    """The float64 logits of the network with kernels turned by ``T^{-1}`` (``T x = rot90(flip(x), k)``), and
    the first-order bound of a float32 pass's error (module docstring), per cell: ``(logits, bound, magnitude)``."""
    x = x.double()
    layers = [
        (turned_kernels(c.weight.detach().double(), flip, k), c.bias.detach().double(), int(c.dilation[0]))
        for c in net.convs
    ]
    wh, bh = net.head.weight.detach().double(), net.head.bias.detach().double()
    ws, bs = net.skip.weight.detach().double(), net.skip.bias.detach().double()

    def run(*deltas):
        h = x
        for (w, b, d), p in zip(layers, deltas):
            h = torch.relu(_conv(h, w, b, d) + p)
        return (_conv(h, wh, bh, 0) + _conv(x, ws, bs, 0))[:, 0]

    h, local = x, []
    for w, b, d in layers:
        local.append(gamma(w[0].numel() + 1) * _conv(h.abs(), w.abs(), b.abs(), d))
        h = torch.relu(_conv(h, w, b, d))
    zeros = tuple(torch.zeros_like(v) for v in local)
    out = run(*zeros)
    jac = torch.autograd.functional.jacobian(run, zeros, vectorize=True)  # per layer: out.shape + layer.shape
    bound = sum((j.abs() * v).flatten(out.dim()).sum(-1) for j, v in zip(jac, local))
    head_mag = _conv(h.abs(), wh.abs(), bh.abs(), 0)[:, 0]
    skip_mag = _conv(x.abs(), ws.abs(), bs.abs(), 0)[:, 0]
    bound = bound + gamma(wh[0].numel() + 1) * head_mag + gamma(ws[0].numel() + 1) * skip_mag
    return out, bound, head_mag + skip_mag


def exact_logits_and_bound(net: nn.Module, x: torch.Tensor, symmetrize: bool):
    """The float64 logits and the tolerance for any float32 computation of them (module docstring)."""
    syms = [(f, k) for f in (False, True) for k in range(4)] if symmetrize else [(False, 0)]
    terms = [exact_and_bound(net, x, f, k) for f, k in syms]
    out = sum(t[0] for t in terms) / len(syms)
    bound = sum(t[1] for t in terms) / len(syms)
    mag = sum(t[2] for t in terms) / len(syms)
    return out, SECOND_ORDER * bound + (gamma(len(syms) + 2) * mag if symmetrize else 0.0)


def features(shape=(8, 11), seed=0):
    """Features of a small scanned scene (a corpus guide's architecture: no tile phase)."""
    prior = prior_by_name("patch3:generated", shape)
    scene = random_scene(prior, shape, 3, beams=36, max_range_cells=8.0, rng=np.random.default_rng(seed))
    model = scene.model()
    g = AmortisedGuide(model, phase=(0, 0))
    return model, g.features(model)[None]


@pytest.mark.parametrize("symmetrize", [False, True])
def test_the_fast_map_equals_the_reference_to_float32_rounding(symmetrize):
    """The shipped corpus guide on a scene's features and on random ones, one pass and symmetrised, fused
    and unfused: the fast logits and the reference's lie within the float32 bound of the float64 network."""
    net = corpus_guide("houseexpo+ipa").net
    _, x = features()
    xr = torch.rand((1, x.shape[1], 7, 9), generator=torch.Generator().manual_seed(1), dtype=torch.float32)
    for inp in (x, xr) if not symmetrize else (x,):
        exact, bound = exact_logits_and_bound(net, inp, symmetrize)
        with torch.no_grad():
            ref = _symmetrised(net, inp) if symmetrize else net(inp)
        assert ((ref.double() - exact).abs() <= bound).all()
        for fused, parallel in ((None, True), (False, True), (None, False)):
            fast = fast_logits(net, inp, symmetrize, fused=fused, parallel=parallel)
            assert fast.dtype == torch.float32 and fast.shape == ref.shape
            assert ((fast.double() - exact).abs() <= bound).all()
        assert bound.max() < 1e-2  # a tolerance, not a blank cheque: logits are O(10)


def test_turned_kernels_turn_the_grid_back():
    """``conv(x, T^{-1} W) == T^{-1} conv(T x, W)`` for every turn and flip, dilations and a non-square grid
    (float64: equal to rounding)."""
    gen = torch.Generator().manual_seed(2)
    x = torch.rand((1, 3, 11, 16), generator=gen, dtype=torch.float64)
    w = torch.rand((4, 3, 3, 3), generator=gen, dtype=torch.float64)
    for d in (1, 2, 5):
        for flip in (False, True):
            for k in range(4):
                xt = torch.rot90(torch.flip(x, dims=(-1,)) if flip else x, k, dims=(-2, -1))
                y = torch.rot90(_conv(xt, w, None, d), -k, dims=(-2, -1))
                y = torch.flip(y, dims=(-1,)) if flip else y
                torch.testing.assert_close(_conv(x, turned_kernels(w, flip, k), None, d), y)


def test_the_guide_uses_the_fast_map_without_gradients_and_the_reference_with_them():
    """``marginals`` (no gradients) equals the sigmoid of the differentiable ``cell_logits`` to the float32
    bound, plain and symmetrised; with gradients on, ``cell_logits`` still carries them."""
    model, x = features((9, 7), seed=3)
    g = AmortisedGuide(model, phase=(0, 0), channels=8, dilations=(1, 3, 1), seed=5)
    for sym in (False, True):
        g.symmetrize = sym
        exact, bound = exact_logits_and_bound(g.net, x, sym)
        with torch.no_grad():
            fast = g.cell_logits(model)
        assert ((fast - exact.reshape(-1)).abs() <= bound.reshape(-1)).all()
        slow = g.cell_logits(model)
        assert slow.requires_grad
        assert ((slow.detach() - exact.reshape(-1)).abs() <= bound.reshape(-1)).all()
        p = g.marginals(model)
        want = torch.where(model.known_free, 0.0, torch.sigmoid(exact.reshape(-1)))
        assert ((p - want).abs() <= bound.reshape(-1) / 4).all()  # sigmoid is 1/4-Lipschitz


def test_any_architecture_and_an_odd_grid():
    """Random weights of other widths and dilations, a grid of one row and one of one column."""
    arch = GuideArchitecture(5, (1, 3), (0, 0), "p21")
    torch.manual_seed(0)
    net = GuideNet(arch)
    for shape in ((1, 9), (13, 1), (6, 7)):
        x = torch.rand((1, arch.in_channels, *shape), generator=torch.Generator().manual_seed(3), dtype=torch.float32)
        for sym in (False, True):
            exact, bound = exact_logits_and_bound(net, x, sym)
            assert ((fast_logits(net, x, sym).double() - exact).abs() <= bound).all()
