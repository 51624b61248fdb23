r"""The guide's logits kept up to date as the features change on a few cells: every layer's activations are
held, and a change of the features on a set of cells :math:`S_0` recomputes, layer by layer, only the cells
whose stencil reaches a changed cell,

.. math:: S_l = S_{l-1} \oplus d_l \{-1, 0, 1\}^2, \qquad l = 1, \dots, n,

(``d_l`` the layer's dilation), so the logits change on :math:`S_n`, within ``sum_l d_l`` cells of
:math:`S_0` (the receptive field ``1 + 2 sum_l d_l`` of
:class:`~ogm_ppl.inference.variational.amortised_net.GuideArchitecture`). Activations live in zero-bordered
``(H + 2P + T) x (W + 2P + T) x C`` buffers (``P = max d_l`` before the grid, ``P + T`` after it, ``T`` the
largest tile side), flattened, so the grid edge's zero padding needs no test; the sets :math:`S_l` are found
inside the bounding box of :math:`S_0` grown by ``sum_l d_l``, so an update costs what its cells cost, not the
grid's size. The last layer's activations feed only the head and are not kept.

Layer ``l`` is recomputed as one dense convolution (oneDNN's, ReLU fused where this torch has it) over a batch
of ``T_l x T_l`` tiles: the tiles of a lattice anchored at the box's corner that hold a cell of :math:`S_l`,
each read with its halo of ``d_l`` cells (``T_l + 2 d_l`` runs of as many contiguous cells a tile, gathered into
a buffer kept between updates; no padding); only the cells
of :math:`S_l` are written back, so a cell outside :math:`S_l` keeps the value computed from the same inputs
before. Each written cell's pre-activation is the same sum as a full pass's convolution, in another order:
equal to it to float32 rounding (the recursive-summation bound of
:mod:`~ogm_ppl.inference.variational.amortised_fast`). ``T_l = min(max(8, 2 d_l), 32)`` trades the tiles'
cells outside :math:`S_l` (small tiles waste fewer) against the halo (``(T + 2d)^2 / T^2`` reads a cell): on
the Intel log at 5 cm with the corpus guide (dilations 1, 2, 4, 8, 16, 1) the tiles hold 1.22 times the
multiply-adds of the cells of :math:`S_l` (median over the scans), and the convolutions run at the rate of a
dense pass. Against a matrix product per block of gathered ``9 C``-rows of the cells of :math:`S_l` alone, this
costs the same CPU time on one thread (the tiles' extra cells cost what the gathers saved) and runs faster on
several (one parallel call a layer instead of one a block).

Cost of an update: about ``sum_l |S_l| 9 C_{l-1} C_l`` multiply-adds (times the tiles' waste), against
``H W sum_l 9 C_{l-1} C_l`` for a full pass. Memory: ``4 (H + 2P + T)(W + 2P + T) sum_{l<n} C_l`` bytes of
activations (float32). The symmetrised logits keep one set of activations per turn and flip (the turned
kernels of :mod:`~ogm_ppl.inference.variational.amortised_fast`): 8 times the memory and the work.
"""

from __future__ import annotations

import torch
from torch import nn

from ogm_ppl.inference.variational.amortised_fast import _FUSED, _SYMMETRIES, turned_kernels

__all__ = ["IncrementalLogits"]


def _tile_side(d: int) -> int:
    """Side of the tiles a layer of dilation ``d`` is recomputed on: small tiles waste fewer cells outside
    :math:`S_l`, large ones read fewer halo cells (``(T + 2d)^2 / T^2`` reads a cell)."""
    return min(max(8, 2 * d), 32)


def _conv_relu(h: torch.Tensor, w: torch.Tensor, b: torch.Tensor, d: int, fused: bool) -> torch.Tensor:
    """``relu(conv(h, w) + b)``, ``3 x 3``, dilation ``d``, no padding; ``B x C x H x W`` channels-last."""
    if fused:
        return torch.ops.mkldnn._convolution_pointwise(h, w, b, [0, 0], [1, 1], [d, d], 1, "relu", [None], "")
    return torch.relu(nn.functional.conv2d(h, w, b, dilation=d))


def _dilate(mask: torch.Tensor, d: int) -> torch.Tensor:
    """Cells whose ``3 x 3`` stencil of dilation ``d`` holds a cell of ``mask`` (``H x W`` bool): the row
    dilation of the column dilation (the square stencil is separable)."""
    H, W = mask.shape
    rows = mask.clone()
    if d < H:
        rows[d:] |= mask[:-d]
        rows[:-d] |= mask[d:]
    out = rows.clone()
    if d < W:
        out[:, d:] |= rows[:, :-d]
        out[:, :-d] |= rows[:, d:]
    return out


class IncrementalLogits:
    r"""The logits of a :class:`~ogm_ppl.inference.variational.amortised_net.GuideNet` over one grid's
    features, updated where the features change (module docstring).

    Args:
        net: the network (its weights are read once).
        x: the features, ``C x H x W`` float32.
        symmetrize: the mean over the 8 turns and flips (``AmortisedGuide.symmetrize``).

    :attr:`logits` (``H x W`` float32) is the current map's logits; :meth:`update` (a mask and new features)
    and :meth:`update_cells` (flat cell indices and their feature rows) change the features and recompute
    what depends on them. The first logits come from dense convolutions over the whole grid.
    :attr:`last_work` holds, per layer, the cells of :math:`S_l` the latest update wrote and the cells of the
    tiles it computed (``(|S_l|, tiles x T_l^2)``; empty before an update): the multiply-adds of layer ``l``
    are those cells times ``9 C_{l-1} C_l`` (times 8 symmetrised).
    """

    def __init__(self, net: nn.Module, x: torch.Tensor, symmetrize: bool = False) -> None:
        if x.dim() != 3:
            raise ValueError(f"features must be C x H x W, got shape {tuple(x.shape)}")
        convs = list(net.convs)  # type: ignore[arg-type]
        self.dilations = [int(c.dilation[0]) for c in convs]
        self.reach = sum(self.dilations)
        self.pad = P = max(self.dilations)
        C, H, W = x.shape
        if C != convs[0].in_channels:
            raise ValueError(f"the network reads {convs[0].in_channels} feature channels, got {C}")
        self.shape = (H, W)
        self._tile = [_tile_side(d) for d in self.dilations]
        # zero border: P rows and columns before the grid, P + the largest tile after it (a tile at the box's
        # far edge reads past the grid)
        self._width = Wp = W + 2 * P + max(self._tile)
        syms = _SYMMETRIES if symmetrize else ((False, 0),)
        with torch.no_grad():
            # per symmetry, per layer: the turned kernel, channels-last for the convolution
            self._kernels = [
                [
                    turned_kernels(c.weight.detach().float(), f, k).contiguous(memory_format=torch.channels_last)
                    for c in convs
                ]
                for f, k in syms
            ]
            self._bias = [c.bias.detach().float() for c in convs]
            self._head = (net.head.weight.detach().float().reshape(-1, 1), net.head.bias.detach().float())  # type: ignore[union-attr]
            self._skip = (net.skip.weight.detach().float().reshape(-1, 1), net.skip.bias.detach().float())  # type: ignore[union-attr]
        # a tile's cells as row offsets from its corner in the flattened padded buffers
        self._offsets = {T: (torch.arange(T)[:, None] * Wp + torch.arange(T)[None]).reshape(-1) for T in self._tile}
        self._scratch: dict[tuple[int, int], torch.Tensor] = {}  # gathered windows, kept between updates
        self.last_work: list[tuple[int, int]] = []
        n = (H + 2 * P + max(self._tile)) * Wp
        self._x = torch.zeros((n, C), dtype=torch.float32)
        self._x[self._flat(torch.arange(H * W))] = x.permute(1, 2, 0).reshape(H * W, C).float()
        self._acts = [[torch.zeros((n, c.out_channels), dtype=torch.float32) for c in convs[:-1]] for _ in syms]
        self.logits = torch.zeros((H, W), dtype=torch.float32)
        self._full_pass(convs, syms)

    def _full_pass(self, convs: list, syms) -> None:
        """Every layer over the whole grid by dense convolutions (the turned kernels, zero padding): the same
        sums as the gathered rows in another order, so equal to them to float32 rounding."""
        H, W = self.shape
        rows = self._flat(torch.arange(H * W))
        with torch.no_grad():
            x = self._x[rows].T.reshape(1, -1, H, W)
            head = torch.zeros((H, W), dtype=torch.float32)
            for (f, k), acts in zip(syms, self._acts):
                h = x
                for layer, (c, b, d) in enumerate(zip(convs, self._bias, self.dilations)):
                    w = turned_kernels(c.weight.detach().float(), f, k)
                    h = torch.relu(nn.functional.conv2d(h, w, b, padding=d, dilation=d))
                    if layer < len(acts):
                        acts[layer][rows] = h[0].permute(1, 2, 0).reshape(H * W, -1)
                hw, hb = self._head
                head += (h[0].permute(1, 2, 0).reshape(H * W, -1) @ hw + hb).reshape(H, W)
            sw, sb = self._skip
            self.logits[:] = (x[0].permute(1, 2, 0).reshape(H * W, -1) @ sw + sb).reshape(H, W) + head / len(syms)

    @property
    def features(self) -> torch.Tensor:
        """The current features, ``C x H x W`` float32 (a copy)."""
        H, W = self.shape
        return self._x[self._flat(torch.arange(H * W))].T.reshape(-1, H, W).clone()

    def _flat(self, k: torch.Tensor) -> torch.Tensor:
        """Row of flat cell index ``k`` (row-major over ``H x W``) in the padded buffers."""
        W, P = self.shape[1], self.pad
        return (k // W + P) * self._width + (k % W + P)

    def update(self, x: torch.Tensor, changed: torch.Tensor) -> torch.Tensor:
        """Set the features of the ``changed`` cells (``H x W`` bool) to those of ``x`` (``C x H x W``) and
        recompute the logits that depend on them; returns the ``H x W`` mask of the recomputed logits."""
        H, W = self.shape
        changed = torch.as_tensor(changed, dtype=torch.bool)
        if changed.shape != (H, W) or x.shape[-2:] != (H, W):
            raise ValueError(f"features and mask must cover the {H} x {W} grid")
        k = changed.reshape(-1).nonzero().flatten()
        return self.update_cells(k, x.reshape(x.shape[0], -1)[:, k].T)

    def update_cells(self, cells: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        """Set the features of flat cells ``cells`` (``n`` int64, row-major) to ``rows`` (``n x C``) and
        recompute the logits that depend on them; returns the ``H x W`` mask of the recomputed logits."""
        H, W = self.shape
        cells = torch.as_tensor(cells, dtype=torch.int64).flatten()
        done = torch.zeros((H, W), dtype=torch.bool)
        if cells.numel() == 0:
            self.last_work = [(0, 0)] * len(self.dilations)
            return done
        if int(cells.min()) < 0 or int(cells.max()) >= H * W:
            raise ValueError(f"cells must lie in 0..{H * W - 1}")
        if rows.shape != (cells.numel(), self._x.shape[1]):
            raise ValueError(f"rows must be {cells.numel()} x {self._x.shape[1]}, got {tuple(rows.shape)}")
        self._x[self._flat(cells)] = rows.float()
        r, c = cells // W, cells % W
        R = self.reach
        r0, c0 = max(int(r.min()) - R, 0), max(int(c.min()) - R, 0)
        r1, c1 = min(int(r.max()) + R + 1, H), min(int(c.max()) + R + 1, W)
        box = torch.zeros((r1 - r0, c1 - c0), dtype=torch.bool)
        box[r - r0, c - c0] = True
        done[r0:r1, c0:c1] = self._recompute_box(box, r0, c0)
        return done

    def _gather(self, src: torch.Tensor, starts: torch.Tensor, n: int) -> torch.Tensor:
        """The runs of ``n`` cells of ``src`` (rows of the flattened buffer) starting at ``starts``, ``n`` runs
        a window: ``len(starts) / n x n x n x C``, in a scratch buffer kept between updates."""
        C = src.shape[1]
        runs = src.as_strided((src.shape[0] - n + 1, n * C), (C, 1))  # run p: cells p .. p + n - 1
        size = starts.numel() * n * C
        buf = self._scratch.get((n, C))
        if buf is None or buf.numel() < size:
            buf = self._scratch[(n, C)] = torch.empty(
                max(size, 2 * (0 if buf is None else buf.numel())), dtype=src.dtype
            )
        out = buf[:size].view(starts.numel(), n * C)
        torch.index_select(runs, 0, starts, out=out)
        return out.view(-1, n, n, C)

    def _recompute_box(self, changed: torch.Tensor, r0: int, c0: int) -> torch.Tensor:
        """Recompute every layer on the cells the changed cells of the box at ``(r0, c0)`` reach (the box
        holds the whole reach, or touches the grid's edge); returns the box's mask of recomputed logits.

        Layer ``l`` runs one dense convolution over the ``T x T`` tiles (anchored at the box's corner) that
        hold a cell of :math:`S_l`, each read with its halo of ``d_l`` cells from the zero-bordered buffer, and
        writes back the cells of :math:`S_l` only."""
        h, w = changed.shape
        Wp, P = self._width, self.pad
        masks = []
        m = changed
        for d in self.dilations:
            m = _dilate(m, d)
            masks.append(m)
        # per layer: the tiles (rows, cols), the padded row of each tile's corner, and the written cells
        plans = []
        for m, T, d in zip(masks, self._tile, self.dilations):
            nr, nc = -(-h // T), -(-w // T)
            mp = torch.zeros((nr * T, nc * T), dtype=torch.bool)
            mp[:h, :w] = m
            tiles = mp.view(nr, T, nc, T).permute(0, 2, 1, 3)
            tr, tc = tiles.reshape(nr, nc, T * T).any(2).nonzero(as_tuple=True)
            sel = tiles[tr, tc].reshape(-1).nonzero().flatten()  # cells of S_l in the batch's (b, i, j) order
            corner = (tr * T + (r0 + P)) * Wp + (tc * T + (c0 + P))
            rows = (corner[:, None] + self._offsets[T][None]).reshape(-1)[sel]
            # the window's rows of T + 2d cells, each a contiguous run of the buffers
            window = ((corner - d * (Wp + 1))[:, None] + torch.arange(T + 2 * d) * Wp).reshape(-1)
            plans.append((window, sel, rows))
        self.last_work = [
            (int(sel.numel()), int(window.numel()) // (T + 2 * d) * T * T)
            for (window, sel, _), T, d in zip(plans, self._tile, self.dilations)
        ]
        last = plans[-1][2]
        with torch.no_grad():
            sw, sb = self._skip
            hw, hb = self._head
            out = torch.zeros(last.numel(), dtype=torch.float32)
            for weights, acts in zip(self._kernels, self._acts):
                src = self._x
                for layer, (wt, b, d, T, (window, sel, rows)) in enumerate(
                    zip(weights, self._bias, self.dilations, self._tile, plans)
                ):
                    n = T + 2 * d  # B x C x n x n, channels-last
                    batch = self._gather(src, window, n).permute(0, 3, 1, 2)
                    a = _conv_relu(batch, wt, b, d, _FUSED)
                    a = a.permute(0, 2, 3, 1).reshape(-1, a.shape[1]).index_select(0, sel)
                    if layer < len(acts):
                        acts[layer].index_copy_(0, rows, a)
                        src = acts[layer]
                    else:  # the last layer: straight into the head
                        out += torch.addmm(hb, a, hw).reshape(-1)
            logits = torch.addmm(sb, self._x.index_select(0, last), sw).reshape(-1) + out / len(self._kernels)
        g = last - ((r0 + P) * Wp + (c0 + P))  # the cells' rows and columns in the box
        self.logits[g // Wp + r0, g % Wp + c0] = logits
        return masks[-1]
