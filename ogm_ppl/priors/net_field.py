r"""A learned field of a small network on every ``w x w`` window, tied over the 8 symmetries of the square.

.. math:: \log \tilde p(m) = a \sum_k m_k + \sum_{(r_0, c_0)} f_\theta(x_{r_0 : r_0 + w,\; c_0 : c_0 + w}),
          \qquad f_\theta(x) = \sum_{h < H} v_h \sum_{g \in D_4} \sigma(\langle g W_h, x\rangle + b_h),

over every anchor of a window holding at least one grid cell (``(rows + w - 1) (cols + w - 1)`` windows: each
cell lies in ``w^2`` of them, at the grid's edges too), ``x`` the map inside the grid and the constant ``pad``
(0.5 by default, neither free nor occupied) past its edge. ``W_h`` are ``H`` filters of ``w x w`` weights,
``g W_h`` their 8 rotations and reflections, so ``f`` is invariant under the 8 symmetries of the window; the
network has ``U = 8 H`` hidden units (biases ``b_h``, output weights ``v_h`` shared by a filter's orientations),
``sigma`` ReLU or softplus, and ``a`` a unary bias. Every map has positive probability; ``log_prob`` omits
``log Z`` (``normalised = False``). The pattern field (:class:`~ogm_ppl.priors.PatternFieldPrior`) tables one
potential per window code, which stops at ``w = 4``; the network scores windows up to ``9 x 9`` with
``H (w^2 + 2) + 1`` parameters.

The Gibbs kernels read the compiled conditionals of :mod:`ogm_ppl.priors.compiled.net_field`; learning (maximum
pseudo-likelihood, then persistent contrastive divergence): :mod:`ogm_ppl.priors.learn_net` and
:func:`ogm_ppl.learn.fit_net_field`. Files: :func:`save_net_field`, :func:`load_net_field`, :func:`net_from_file`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from ogm_ppl.io import read_npz
from ogm_ppl.priors.compiled.net_field import ACTIVATIONS, MAX_NET_WINDOW, MAX_UNITS, NetField, net_field
from ogm_ppl.priors.compiled.net_field_patches import net_prior_sweeps
from ogm_ppl.priors.local import LocalMapPrior, grid_shape

__all__ = [
    "EXACT_SAMPLE_CELLS",
    "NET_FORMAT_VERSION",
    "NET_KIND",
    "NetFieldPrior",
    "energy",
    "load_net_field",
    "net_from_file",
    "net_path",
    "oriented",
    "oriented_np",
    "save_net_field",
]

NET_FORMAT_VERSION = 1
#: grids of at most this many cells are sampled exactly, by enumerating their maps
EXACT_SAMPLE_CELLS = 12
#: the ``kind`` string a net-field file holds
NET_KIND = "net_field"
FITTED_DIR = Path(__file__).resolve().parent.parent / "fitted"


def oriented_np(filters: np.ndarray) -> np.ndarray:
    """The ``8 H x w x w`` unit filters of ``H x w x w`` filters: unit ``8 h + 2 k`` is ``rot90(W_h, k)`` and
    ``8 h + 2 k + 1`` its transpose (the 8 symmetries of the square)."""
    out = []
    for f in np.asarray(filters, np.float64):
        for k in range(4):
            r = np.rot90(f, k)
            out += [r, r.T]
    return np.ascontiguousarray(np.stack(out))


def oriented(filters: torch.Tensor) -> torch.Tensor:
    """:func:`oriented_np` in torch (differentiable): ``H x w x w -> 8 H x w x w``."""
    views = []
    for k in range(4):
        r = torch.rot90(filters, k, dims=(-2, -1))
        views += [r, r.transpose(-2, -1)]
    return torch.stack(views, 1).reshape(-1, *filters.shape[-2:])


def activation_fn(name: str):
    """The torch function of an activation of :data:`~ogm_ppl.priors.compiled.net_field.ACTIVATIONS` (softplus
    written out, ``max(x, 0) + log1p(exp(-|x|))``, as the compiled code computes it)."""
    if name == "relu":
        return torch.relu
    if name == "softplus":
        return lambda x: torch.clamp(x, min=0) + torch.log1p(torch.exp(-x.abs()))
    raise ValueError(f"activation must be one of {ACTIVATIONS}, got {name!r}")


def energy(x: torch.Tensor, filters, bias, out, unary, pad: float, activation: str) -> torch.Tensor:
    r"""``log p~`` of ``B x R x C`` maps (values in [0, 1]; differentiable in the parameters): ``filters``
    ``H x w x w``, ``bias``, ``out`` ``H``, ``unary`` a scalar. The windows by one ``conv2d`` of the map padded with
    ``pad`` by ``w - 1`` on each side: ``B x 8H x (R + w - 1) x (C + w - 1)`` pre-activations."""
    w = filters.shape[-1]
    units = oriented(filters)[:, None]  # U x 1 x w x w
    xp = torch.nn.functional.pad(x[:, None], (w - 1,) * 4, value=float(pad))
    pre = torch.nn.functional.conv2d(xp, units) + bias.repeat_interleave(8)[None, :, None, None]
    act = activation_fn(activation)(pre)
    return (act * out.repeat_interleave(8)[None, :, None, None]).sum((1, 2, 3)) + unary * x.sum((1, 2))


class NetFieldPrior(LocalMapPrior):
    r"""The net field ``log p~(m) = a sum_k m_k + sum_windows f_theta(window)`` (module docstring).

    Args:
        shape: grid shape ``(rows, cols)`` (or a :class:`~ogm_ppl.Grid`; a 1D grid ``(K,)`` is one row, its
            windows padded above and below).
        filters: ``H x w x w`` first-layer weights (each used in its 8 orientations; ``w`` in 1..9).
        bias: ``H`` hidden biases; out: ``H`` output weights.
        unary: the unary bias ``a`` (log-odds added to every cell).
        pad: the value a cell past the grid's edge reads as (0.5 by default).
        activation: ``"relu"`` (default) or ``"softplus"``.
        occupancy: the field's cell marginal away from the edges (stored with a fit; ``None``: estimated once by
            prior Gibbs sampling when :meth:`outside_occupancy` is asked).

    >>> p = NetFieldPrior((3, 4), np.zeros((2, 5, 5)), np.zeros(2), np.zeros(2))
    >>> float(p.log_prob(torch.ones(12)))
    0.0
    """

    normalised = False

    def __init__(
        self,
        shape,
        filters,
        bias,
        out,
        unary: float = 0.0,
        pad: float = 0.5,
        activation: str = "relu",
        occupancy: float | None = None,
    ) -> None:
        self.rows, self.cols, self.ndim = grid_shape(shape)
        self.shape = (self.cols,) if self.ndim == 1 else (self.rows, self.cols)
        self.num_cells = self.rows * self.cols
        f = np.asarray(filters, np.float64)
        if f.ndim != 3 or f.shape[1] != f.shape[2] or not 1 <= f.shape[1] <= MAX_NET_WINDOW:
            raise ValueError(f"filters must be H x w x w with w in 1..{MAX_NET_WINDOW}, got shape {f.shape}")
        if not 1 <= 8 * f.shape[0] <= MAX_UNITS:
            raise ValueError(f"a net field has 1..{MAX_UNITS // 8} filters (8 units each), got {f.shape[0]}")
        self.filters = f
        self.w, self.hidden = f.shape[1], f.shape[0]
        self.bias = np.asarray(bias, np.float64).reshape(-1)
        self.out = np.asarray(out, np.float64).reshape(-1)
        self.unary, self.pad, self.activation = float(unary), float(pad), str(activation)
        if not 0.0 <= self.pad <= 1.0:
            raise ValueError(f"pad must lie in [0, 1], got {pad}")
        if occupancy is not None and not 0.0 <= float(occupancy) <= 1.0:
            raise ValueError(f"occupancy must lie in [0, 1], got {occupancy}")
        self.occupancy = None if occupancy is None else float(occupancy)
        if self.occupancy is not None:
            self.mean_occupancy = self.occupancy
        self._compiled: NetField = net_field(  # type: ignore[assignment]
            self.rows,
            self.cols,
            oriented_np(f),
            np.repeat(self.bias, 8),
            np.repeat(self.out, 8),
            self.unary,
            self.pad,
            self.activation,
        )
        self._params = tuple(torch.from_numpy(a) for a in (f, self.bias, self.out))

    def __repr__(self) -> str:
        return f"NetFieldPrior(shape={self.shape}, w={self.w}, hidden={self.hidden}x8, {self.activation})"

    def log_prob(self, maps):
        """``log p~(m)`` (without ``-log Z``) for ``... x K`` maps -> ``...`` (float64, vectorised)."""
        maps = torch.as_tensor(maps, dtype=torch.float64)
        batch = maps.shape[:-1]
        x = (maps.reshape(-1, self.rows, self.cols) != 0).to(torch.float64)
        f, b, v = self._params
        return energy(x, f, b, v, self.unary, self.pad, self.activation).reshape(batch)

    def sample(self, sample_shape=(), generator=None, num_sweeps: int = 200):
        """Maps drawn exactly from the ``2^K`` maps' probabilities on a grid of at most :data:`EXACT_SAMPLE_CELLS`
        cells, else by ``num_sweeps`` compiled single-cell Gibbs sweeps on the prior alone from uniform noise
        (:func:`~ogm_ppl.priors.compiled.net_field_patches.net_prior_sweeps`)."""
        shape = torch.Size(sample_shape)
        B = int(np.prod(shape)) if len(shape) else 1
        K = self.num_cells
        if K <= EXACT_SAMPLE_CELLS:
            maps = ((torch.arange(2**K)[:, None] >> torch.arange(K)) & 1).to(torch.float64)
            lp = self.log_prob(maps)
            idx = torch.multinomial(torch.softmax(lp, 0), B, replacement=True, generator=generator)
            return maps[idx].reshape(*shape, K)
        u = torch.rand((B, K), generator=generator, dtype=torch.float64)
        grid = np.ascontiguousarray((u < 0.5).numpy(), dtype=np.uint8)
        seed = int(torch.randint(0, 2**31 - 1, (1,), generator=generator))
        net_prior_sweeps(self._compiled, grid, int(num_sweeps), seed)
        return torch.from_numpy(grid.astype(np.float64)).reshape(*shape, K)

    def with_shape(self, shape) -> NetFieldPrior:
        """The same field over a grid of another ``shape``."""
        return NetFieldPrior(
            shape, self.filters, self.bias, self.out, self.unary, self.pad, self.activation, self.occupancy
        )

    def tempered(self, beta: float) -> NetFieldPrior:
        """The field of ``beta log p~`` (output weights and unary bias times ``beta``; the marginal re-estimated)."""
        b = float(beta)
        return NetFieldPrior(
            self.shape, self.filters, self.bias, self.out * b, self.unary * b, self.pad, self.activation
        )

    def outside_occupancy(self) -> float:
        """The field's cell marginal ``P(m_k = 1)`` (the fitted value, or a seeded estimate: 8 prior Gibbs chains
        of 48 x 48 cells, 300 sweeps, the centre 32 x 32 cells of the last 100 sweeps)."""
        if self.occupancy is None:
            self.occupancy = estimate_occupancy(self.with_shape((48, 48))._compiled)
            self.mean_occupancy = self.occupancy
        return self.occupancy


def estimate_occupancy(bundle: NetField, chains: int = 8, sweeps: int = 300, seed: int = 0) -> float:
    """``P(m_k = 1)`` of a net field away from the edges, by prior Gibbs chains on the bundle's grid (from noise;
    the cells at least 8 from the edges over the last 100 sweeps, read every 10)."""
    rng = np.random.default_rng(seed)
    R, C = bundle.rows, bundle.cols
    maps = np.ascontiguousarray(rng.random((chains, R * C)) < 0.5, dtype=np.uint8)
    net_prior_sweeps(bundle, maps, max(sweeps - 100, 0), seed)
    tot = 0.0
    for i in range(10):
        net_prior_sweeps(bundle, maps, 10, seed + 1 + i)
        tot += float(maps.reshape(chains, R, C)[:, 8:-8, 8:-8].mean())
    return tot / 10


# ------------------------------------------------------------------ files
#: the arrays of a net-field file: key -> shape (``None``: checked against ``w`` and ``H``)
_SCALARS = ("format_version", "w", "unary", "pad", "occupancy")


def net_path(corpus: str) -> Path:
    """The shipped fit of ``corpus``: ``ogm_ppl/fitted/net_<corpus>.npz``."""
    return FITTED_DIR / f"net_{corpus}.npz"


def net_arrays(prior: NetFieldPrior) -> dict[str, np.ndarray]:
    """The arrays of a net-field file of ``prior`` (its cell marginal estimated now where it has none)."""
    return {
        "format_version": np.array(NET_FORMAT_VERSION, np.int64),
        "kind": np.array(NET_KIND),
        "w": np.array(prior.w, np.int64),
        "filters": prior.filters,
        "bias": prior.bias,
        "out": prior.out,
        "unary": np.array(prior.unary, np.float64),
        "pad": np.array(prior.pad, np.float64),
        "activation": np.array(prior.activation),
        "occupancy": np.array(prior.outside_occupancy(), np.float64),
    }


def save_net_field(path, prior: NetFieldPrior) -> Path:
    """Write ``prior``'s parameters to an ``.npz`` (atomically; no pickles): read back by :func:`net_from_file`."""
    from ogm_ppl.io import atomic_write

    if not isinstance(prior, NetFieldPrior):
        raise TypeError(f"save_net_field: expected a NetFieldPrior, got {type(prior).__name__}")
    path = Path(path)
    with atomic_write(path, "wb") as f:
        np.savez(f, **net_arrays(prior))  # type: ignore[arg-type]
    return path


def load_net_field(path) -> dict:
    """Read and validate a net-field file: the format version and kind (a pattern field's file or any other is
    refused), ``w`` in 1..9, ``filters`` ``H x w x w``, ``bias`` and ``out`` of ``H``, finite numbers, ``pad`` and
    ``occupancy`` in [0, 1], a known activation. Returns the values (numpy arrays, ``w`` an int, ``activation`` a
    str); raises ``ValueError`` naming the path and what is wrong."""
    path = Path(path)
    d = read_npz(path, "a net field written by save_net_field")
    if "kind" not in d:
        other = " (a pattern field: load it with field_from_file)" if "theta" in d else ""
        raise ValueError(f"{path}: not a net-field file: no 'kind'{other}")
    kind = d["kind"]
    if kind.shape != () or kind.dtype.kind != "U" or str(kind) != NET_KIND:
        raise ValueError(f"{path}: holds kind {kind!r}, not {NET_KIND!r}")
    missing = sorted({*_SCALARS, "filters", "bias", "out", "activation"} - set(d))
    if missing:
        raise ValueError(f"{path}: missing arrays {missing}")
    for k in (*_SCALARS, "filters", "bias", "out"):
        a = d[k]
        if not np.issubdtype(a.dtype, np.number) or not np.isfinite(a).all():
            raise ValueError(f"{path}: {k!r} must be finite numbers")
        if k in _SCALARS and a.shape != ():
            raise ValueError(f"{path}: {k!r} must be a scalar, got shape {a.shape}")
    for k in ("format_version", "w"):
        if not np.issubdtype(d[k].dtype, np.integer):
            raise ValueError(f"{path}: {k!r} must be an integer")
    if int(d["format_version"]) != NET_FORMAT_VERSION:
        raise ValueError(f"{path}: format version {int(d['format_version'])}, this library reads {NET_FORMAT_VERSION}")
    w = int(d["w"])
    if not 1 <= w <= MAX_NET_WINDOW:
        raise ValueError(f"{path}: window side w = {w} outside 1..{MAX_NET_WINDOW}")
    f = d["filters"]
    H = f.shape[0] if f.ndim == 3 else -1
    if f.shape != (H, w, w) or not 1 <= 8 * H <= MAX_UNITS:
        raise ValueError(
            f"{path}: 'filters' has shape {f.shape}, expected H x {w} x {w} with 1 <= H <= {MAX_UNITS // 8}"
        )
    for k in ("bias", "out"):
        if d[k].shape != (H,):
            raise ValueError(f"{path}: {k!r} has shape {d[k].shape}, expected ({H},)")
    for k in ("pad", "occupancy"):
        if not 0.0 <= float(d[k]) <= 1.0:
            raise ValueError(f"{path}: {k!r} = {float(d[k])} outside [0, 1]")
    act = d["activation"]
    if act.shape != () or act.dtype.kind != "U" or str(act) not in ACTIVATIONS:
        raise ValueError(f"{path}: activation {act!r} is not one of {ACTIVATIONS}")
    out: dict[str, Any] = {k: np.asarray(d[k], np.float64) for k in ("filters", "bias", "out")}
    out.update(w=w, unary=float(d["unary"]), pad=float(d["pad"]), occupancy=float(d["occupancy"]))
    out["activation"] = str(act)
    return out


def net_from_file(path, shape) -> NetFieldPrior:
    """The net field of a file of :func:`save_net_field` (or :func:`~ogm_ppl.learn.fit_net_field`) over ``shape``."""
    d = load_net_field(path)
    return NetFieldPrior(
        shape, d["filters"], d["bias"], d["out"], d["unary"], d["pad"], d["activation"], occupancy=d["occupancy"]
    )
