r"""The guide's map without gradients, near the convolutions' achievable rate on the CPU: the logits of
:class:`~ogm_ppl.inference.variational.amortised_net.GuideNet` and their average over the symmetries of the
square, equal to the reference (:meth:`GuideNet.forward`, ``_symmetrised``) up to float32 rounding.

What changes against the reference, none of it the arithmetic's meaning:

* activations in channels-last memory (``B x H x W x C`` in memory), each ``3 x 3`` convolution with its
  ReLU fused (oneDNN's convolution with an element-wise post-op where this torch has it; else the two
  torch calls);
* the ``1 x 1`` head and skip as matrix-vector products over the channels-last activations;
* the symmetrised map without turning the grid: for a turn or flip :math:`T` of the grid and a convolution
  with zero padding and an odd kernel :math:`W` (cross-correlation, dilation :math:`d`),

  .. math:: T^{-1} \bigl(W \star T x\bigr) = (T^{-1} W) \star x,

  the kernel turned back as an image. By induction over the layers (ReLU and the ``1 x 1`` convolutions
  act per cell, so they commute with :math:`T`),
  :math:`T_s^{-1} g_\phi(T_s x) = g_{\phi_s}(x)` with every ``3 x 3`` kernel of :math:`\phi` turned by
  :math:`T_s^{-1}`, and :math:`\bar g_\phi(x) = \tfrac18 \sum_s g_{\phi_s}(x)`: 8 passes of networks with
  turned weights over the same channels-last input, the skip (a ``1 x 1`` convolution, which every
  :math:`T_s` leaves as it is) computed once. No copy of the grid is turned, and non-square grids need no
  care.

The float32 results differ from the reference's by the order of the sums only; every order obeys the
recursive-summation bound :math:`|\hat s - s| \le \gamma_n \sum_i |a_i|`, :math:`\gamma_n = n u / (1 - n u)`,
:math:`u = 2^{-24}`, which the tests propagate through the layers.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import torch
from torch import nn

__all__ = ["fast_logits", "turned_kernels"]

# (flip the columns, quarter turns k): T_s x = rot90(flip(x), k), the order of the reference's loop
_SYMMETRIES = tuple((flip, k) for flip in (False, True) for k in range(4))


def turned_kernels(weight: torch.Tensor, flip: bool, k: int) -> torch.Tensor:
    r"""The kernel ``T^{-1} W`` of the module docstring for ``T x = rot90(flip(x), k)`` (flip of the columns
    when ``flip``): ``O x I x kh x kw -> O x I x kw x kh`` (``kh == kw`` for a square kernel), so that
    ``conv(x, T^{-1} W) == T^{-1} conv(T x, W)`` for zero padding and odd kernels."""
    w = torch.rot90(weight, -k, dims=(-2, -1))
    return torch.flip(w, dims=(-1,)) if flip else w


def _fused_available() -> bool:
    try:
        return bool(torch.backends.mkldnn.is_available()) and hasattr(torch.ops.mkldnn, "_convolution_pointwise")
    except (AttributeError, RuntimeError):  # pragma: no cover - a torch without the mkldnn ops
        return False


_FUSED = _fused_available()


def _conv_relu(h: torch.Tensor, w: torch.Tensor, b: torch.Tensor, d: int, fused: bool) -> torch.Tensor:
    """``relu(conv(h, w) + b)``, ``3 x 3``, dilation and zero padding ``d``; ``B x C x H x W`` channels-last."""
    if fused:
        return torch.ops.mkldnn._convolution_pointwise(h, w, b, [d, d], [1, 1], [d, d], 1, "relu", [None], "")
    return torch.relu(nn.functional.conv2d(h, w, b, padding=d, dilation=d))


def _pointwise(h: torch.Tensor, conv: nn.Conv2d) -> torch.Tensor:
    """A ``C -> 1`` ``1 x 1`` convolution of channels-last ``h`` (``B x C x H x W``): ``B x H x W``."""
    w = conv.weight.detach().reshape(-1).to(h.dtype)
    b = conv.bias.detach().to(h.dtype)  # type: ignore[union-attr]
    B, C, H, W = h.shape
    return torch.mv(h.permute(0, 2, 3, 1).reshape(-1, C), w).reshape(B, H, W) + b


def fast_logits(
    net: nn.Module, x: torch.Tensor, symmetrize: bool = False, *, fused: bool | None = None, parallel: bool = True
) -> torch.Tensor:
    r"""The logits ``g_phi(x)`` of a :class:`~ogm_ppl.inference.variational.amortised_net.GuideNet`
    (``symmetrize``: :math:`\bar g_\phi(x) = \tfrac18 \sum_s T_s^{-1} g_\phi(T_s x)` over the 8 turns and
    flips), ``B x C x H x W -> B x H x W`` float32, no gradients.

    ``fused``: use oneDNN's fused convolution and ReLU (default: where this torch has it and ``x`` is a
    float32 CPU tensor); ``False`` gives the same sums through ``conv2d`` and ``relu``. ``parallel``: the
    symmetrised map's 8 passes side by side on torch's threads, one thread each (torch's thread count is
    restored after), else each pass on all threads; equal to float32 rounding either way.
    """
    if fused is None:
        fused = _FUSED and x.device.type == "cpu" and x.dtype == torch.float32
    with torch.inference_mode():
        xc = x.contiguous(memory_format=torch.channels_last)
        convs = list(net.convs)  # type: ignore[arg-type]
        weights = [c.weight.detach().to(x.dtype) for c in convs]
        biases = [c.bias.detach().to(x.dtype) for c in convs]
        dils = [int(c.dilation[0]) for c in convs]
        out = _pointwise(xc, net.skip)  # type: ignore[arg-type]

    def one(sym: tuple[bool, int]) -> torch.Tensor:
        flip, k = sym
        with torch.inference_mode():  # thread-local: set in each worker
            h = xc
            for w, b, d in zip(weights, biases, dils):
                ws = turned_kernels(w, flip, k).contiguous(memory_format=torch.channels_last)
                h = _conv_relu(h, ws, b, d, fused)
            return _pointwise(h, net.head)  # type: ignore[arg-type]

    syms = _SYMMETRIES if symmetrize else ((False, 0),)
    threads = torch.get_num_threads()
    if len(syms) > 1 and threads > 1 and parallel:
        # the symmetries side by side, one thread each (faster than each pass on all threads: the
        # 24-channel convolutions scale poorly); the heads are summed in the symmetries' order
        torch.set_num_threads(1)
        try:
            with ThreadPoolExecutor(min(threads, len(syms))) as pool:
                heads = list(pool.map(one, syms))
        finally:
            torch.set_num_threads(threads)
    else:
        heads = [one(s) for s in syms]
    with torch.inference_mode():
        head = heads[0]
        for h in heads[1:]:
            head = head + h
        out = out + head / len(syms)
    return out.clone()  # a normal tensor (inference tensors cannot enter autograd later)
