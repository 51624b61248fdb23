r"""The guide's logits kept up to date as the features change on a few cells: every layer's activations are
held, and a change of the features on a set of cells :math:`S_0` recomputes, layer by layer, only the cells
whose stencil reaches a changed cell,

.. math:: S_l = S_{l-1} \oplus d_l \{-1, 0, 1\}^2, \qquad l = 1, \dots, n,

(``d_l`` the layer's dilation), so the logits change on :math:`S_n`, within ``sum_l d_l`` cells of
:math:`S_0` (the receptive field ``1 + 2 sum_l d_l`` of
:class:`~ogm_ppl.inference.variational.amortised_net.GuideArchitecture`). Each recomputed cell's
pre-activation is a gathered row of its stencil's ``9 C`` inputs times the kernel as a ``9 C x C'`` matrix
(the same sums as the convolution, in another order: equal to a full pass to float32 rounding). Activations
live in zero-bordered ``(H + 2P) x (W + 2P) x C`` buffers (``P = max d_l``), so the grid edge's zero padding
needs no test. The symmetrised logits keep one set of activations per turn and flip (the turned kernels of
:mod:`~ogm_ppl.inference.variational.amortised_fast`): 8 times the memory.
"""

from __future__ import annotations

import torch
from torch import nn

from ogm_ppl.inference.variational.amortised_fast import _SYMMETRIES, turned_kernels

__all__ = ["IncrementalLogits"]


def _dilate(mask: torch.Tensor, d: int) -> torch.Tensor:
    """Cells whose ``3 x 3`` stencil of dilation ``d`` holds a cell of ``mask`` (``H x W`` bool)."""
    H, W = mask.shape
    p = torch.zeros((H + 2 * d, W + 2 * d), dtype=torch.bool)
    p[d : d + H, d : d + W] = mask
    out = torch.zeros_like(mask)
    for i in (0, d, 2 * d):
        for j in (0, d, 2 * d):
            out |= p[i : i + H, j : j + W]
    return out


class IncrementalLogits:
    r"""The logits of a :class:`~ogm_ppl.inference.variational.amortised_net.GuideNet` over one grid's
    features, updated where the features change (module docstring).

    Args:
        net: the network (its weights are read once).
        x: the features, ``C x H x W`` float32.
        symmetrize: the mean over the 8 turns and flips (``AmortisedGuide.symmetrize``).

    :attr:`logits` (``H x W`` float32) is the current map's logits; :meth:`update` changes the features and
    returns the cells recomputed.
    """

    def __init__(self, net: nn.Module, x: torch.Tensor, symmetrize: bool = False) -> None:
        if x.dim() != 3:
            raise ValueError(f"features must be C x H x W, got shape {tuple(x.shape)}")
        convs = list(net.convs)  # type: ignore[arg-type]
        self.dilations = [int(c.dilation[0]) for c in convs]
        self.pad = P = max(self.dilations)
        C, H, W = x.shape
        self.shape = (H, W)
        syms = _SYMMETRIES if symmetrize else ((False, 0),)
        with torch.no_grad():
            # per symmetry, per layer: the kernel as a (9 C_in) x C_out matrix, taps row-major, channels minor
            self._mats = [
                [
                    turned_kernels(c.weight.detach().float(), f, k).permute(2, 3, 1, 0).reshape(-1, c.out_channels)
                    for c in convs
                ]
                for f, k in syms
            ]
            self._bias = [c.bias.detach().float() for c in convs]
            self._head = (net.head.weight.detach().float().reshape(-1), net.head.bias.detach().float())  # type: ignore[union-attr]
            self._skip = (net.skip.weight.detach().float().reshape(-1), net.skip.bias.detach().float())  # type: ignore[union-attr]
        self._x = torch.zeros((H + 2 * P, W + 2 * P, C), dtype=torch.float32)
        self._x[P : P + H, P : P + W] = x.permute(1, 2, 0)
        self._acts = [
            [torch.zeros((H + 2 * P, W + 2 * P, c.out_channels), dtype=torch.float32) for c in convs] for _ in syms
        ]
        self.logits = torch.zeros((H, W), dtype=torch.float32)
        self._recompute(torch.ones((H, W), dtype=torch.bool))

    def update(self, x: torch.Tensor, changed: torch.Tensor) -> torch.Tensor:
        """Set the features of the ``changed`` cells (``H x W`` bool) to those of ``x`` (``C x H x W``) and
        recompute the logits that depend on them; returns the ``H x W`` mask of the recomputed logits."""
        H, W = self.shape
        P = self.pad
        changed = torch.as_tensor(changed, dtype=torch.bool)
        if changed.shape != (H, W) or x.shape[-2:] != (H, W):
            raise ValueError(f"features and mask must cover the {H} x {W} grid")
        r, c = changed.nonzero(as_tuple=True)
        self._x[r + P, c + P] = x[:, r, c].T.float()
        return self._recompute(changed)

    def _recompute(self, changed: torch.Tensor) -> torch.Tensor:
        P = self.pad
        masks, m = [], changed
        for d in self.dilations:
            m = _dilate(m, d)
            masks.append(m)
        with torch.no_grad():
            r, c = masks[-1].nonzero(as_tuple=True)
            sw, sb = self._skip
            out = self._x[r + P, c + P] @ sw + sb
            head = torch.zeros_like(out)
            for mats, acts in zip(self._mats, self._acts):
                src = self._x
                for mat, b, d, mask, dst in zip(mats, self._bias, self.dilations, masks, acts):
                    rr, cc = mask.nonzero(as_tuple=True)
                    for lo in range(0, rr.numel(), 1 << 16):  # blocks of rows: the gathered stencils stay small
                        i, j = rr[lo : lo + (1 << 16)] + P, cc[lo : lo + (1 << 16)] + P
                        taps = [src[i + di, j + dj] for di in (-d, 0, d) for dj in (-d, 0, d)]
                        dst[i, j] = torch.relu(torch.cat(taps, 1) @ mat + b)
                    src = dst
                hw, hb = self._head
                head += src[r + P, c + P] @ hw + hb
            self.logits[r, c] = out + head / len(self._mats)
        return masks[-1]
