r"""The amortised guide's network: its architecture (validated) and the fully convolutional logits
``g_phi``, with their average over the symmetries of the square.

``g_phi`` is a stack of 3 x 3 convolutions with ReLU (zero padding, so any grid size), dilations
``d_1, ..., d_n``, a 1 x 1 head and a 1 x 1 linear skip from the features; its receptive field is
``1 + 2 * sum_i d_i`` cells. Symmetrised, with :math:`T_s` the ``s``-th of the 4 quarter turns, each with and
without a flip of the columns,

.. math:: \bar g_\phi(x) = \tfrac18 \sum_s T_s^{-1} g_\phi(T_s x),

which commutes with every turn and flip of the scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from ogm_ppl.inference.variational.amortised_features import _BASE_FEATURES, _delta

__all__ = ["GuideArchitecture", "GuideNet"]

_MAX_CHANNELS, _MAX_LAYERS, _MAX_DILATION, _MAX_PHASE = 256, 16, 16, 16


@dataclass(frozen=True)
class GuideArchitecture:
    """What fixes the network's weights' names and shapes (validated; stored in every artefact).

    Attributes:
        channels: hidden channels of every 3 x 3 convolution.
        dilations: one 3 x 3 convolution (ReLU after it) per entry, with that dilation; the receptive
            field is ``1 + 2 * sum(dilations)`` cells.
        phase: tile phase features ``(h, w)`` (``(0, 0)``: none).
        delta: the update term of the log-odds feature (a :func:`~ogm_ppl.models.delta.delta_by_name`).
    """

    channels: int = 16
    dilations: tuple[int, ...] = (1, 2, 4, 1)
    phase: tuple[int, int] = (3, 3)
    delta: str = "p21"

    def __post_init__(self) -> None:
        problems = _architecture_problems(self.channels, self.dilations, self.phase, self.delta)
        if problems:
            raise ValueError(f"bad guide architecture: {problems}")
        object.__setattr__(self, "channels", int(self.channels))
        object.__setattr__(self, "dilations", tuple(int(d) for d in self.dilations))
        object.__setattr__(self, "phase", tuple(int(p) for p in self.phase))

    @property
    def in_channels(self) -> int:
        return len(_BASE_FEATURES) + (self.phase[0] + self.phase[1] if self.phase[0] and self.phase[1] else 0)

    @property
    def receptive_field(self) -> int:
        return 1 + 2 * sum(self.dilations)


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _architecture_problems(channels, dilations, phase, delta) -> str:
    if not _is_int(channels) or not 1 <= channels <= _MAX_CHANNELS:
        return f"channels must be an integer in 1..{_MAX_CHANNELS}, got {channels!r}"
    try:
        dil = tuple(dilations)
    except TypeError:
        return f"dilations must be a sequence of integers, got {dilations!r}"
    if not 1 <= len(dil) <= _MAX_LAYERS or not all(_is_int(d) and 1 <= d <= _MAX_DILATION for d in dil):
        return f"dilations must be 1..{_MAX_LAYERS} integers in 1..{_MAX_DILATION}, got {dilations!r}"
    try:
        ph = tuple(phase)
    except TypeError:
        return f"phase must be (h, w), got {phase!r}"
    if len(ph) != 2 or not all(_is_int(p) and 0 <= p <= _MAX_PHASE for p in ph) or (ph[0] == 0) != (ph[1] == 0):
        return f"phase must be (h, w) with both in 1..{_MAX_PHASE}, or (0, 0), got {phase!r}"
    if not isinstance(delta, str):
        return f"delta must be a name, got {delta!r}"
    try:
        _delta(delta)
    except (ValueError, KeyError, TypeError) as e:
        return f"delta {delta!r} is not a known update term ({e})"
    return ""


class GuideNet(nn.Module):
    """Fully convolutional logits: ``3 x 3`` convolutions with ReLU (zero padding, so any grid size),
    a ``1 x 1`` head, plus a ``1 x 1`` linear skip from the features. ``B x C x H x W -> B x H x W``."""

    def __init__(self, arch: GuideArchitecture) -> None:
        super().__init__()
        c_in, c = arch.in_channels, arch.channels
        convs = []
        for d in arch.dilations:
            convs.append(nn.Conv2d(c_in, c, 3, padding=d, dilation=d, dtype=torch.float32))
            c_in = c
        self.convs = nn.ModuleList(convs)
        self.head = nn.Conv2d(c, 1, 1, dtype=torch.float32)
        self.skip = nn.Conv2d(arch.in_channels, 1, 1, dtype=torch.float32)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = x
        for conv in self.convs:
            h = torch.relu(conv(h))
        return (self.head(h) + self.skip(x))[:, 0]


def _symmetrised(net: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """``mean_s T_s^{-1} net(T_s x)`` over the 4 quarter turns, each with and without a flip of the columns:
    ``B x C x H x W -> B x H x W``."""
    out = torch.zeros(x.shape[0], *x.shape[-2:], dtype=x.dtype, device=x.device)
    for flip in (False, True):
        xf = torch.flip(x, dims=(-1,)) if flip else x
        for k in range(4):
            y = torch.rot90(net(torch.rot90(xf, k, dims=(-2, -1))), -k, dims=(-2, -1))
            out += torch.flip(y, dims=(-1,)) if flip else y
    return out / 8
