r"""Backed-off (strictly positive) table priors: Sections 5.2.2 and 5.2.3 with Witten-Bell smoothing.

The tables of Sections 5.2.2-5.2.3 give configurations never counted in the corpus probability zero, so
a map with one unseen 3 x 3 configuration is impossible however strongly the data ask for it. Here each
level is interpolated with the next, coarser one (Witten-Bell, Chen & Goodman 1998):

.. math::

    p(i \mid b) = \frac{c(b, i) + \kappa\, T_b\, p_\text{back}(i)}{n_b + \kappa\, T_b}
                = (1 - \lambda_b)\,\frac{c(b, i)}{n_b} + \lambda_b\, p_\text{back}(i),
    \qquad \lambda_b = \frac{\kappa T_b}{n_b + \kappa T_b},

with ``c(b, i)`` the count of inner configuration ``i`` after border ``b``, ``n_b = sum_i c(b, i)``,
``T_b`` the number of distinct inners seen after ``b`` and ``kappa > 0`` one hyper-parameter per level.
A border never seen has ``n_b = 0`` and ``p(i | b) = p_back(i)``. The chain of levels is

* ``border_bo``: 3 x 3 | 16 border cells -> the smoothed 3 x 3 table -> independent cells;
* ``patch3_bo``: the 3 x 3 table (``b`` empty) -> independent cells ``p(i) = lambda^|i| (1 - lambda)^(9 - |i|)``
  with the corpus's ``lambda`` (the 512-entry smoothed table);
* ``border1_bo``: one cell | its 8 neighbours -> ``(1 - lambda, lambda)``.

Every configuration then has positive mass. ``p_back`` is any strictly positive dense table over the
``2^L`` inner codes (:class:`BackoffBorderPrior` takes it as an argument, e.g. a pattern-field marginal).

**Hyper-parameters** (:func:`fit_kappa`): the corpus's training plans are split deterministically (every
fifth plan, in the corpus's natural order, to validation), tables are counted on the fit part, and
``kappa`` maximises the mean validation log-likelihood of the (border, inner) pairs (of the 3 x 3
windows for ``patch3``). The chosen values are shipped in ``ogm_ppl/fitted/backoff_<corpus>.json``
(:func:`load_backoff_params`; written by :func:`ogm_ppl.learn.fit_backoff`, ``ogm-ppl fit-prior backoff``)
and applied to the full training tables.

**The prior over a map** is the tiling joint of :mod:`ogm_ppl.priors.border`,
``p(m) = prod_t p(inner_t | border_t) / Z``, now strictly positive. Patch Gibbs keeps the sparse
table's speed with an exact two-step update per tile (:mod:`ogm_ppl.inference._kernels.candidate_sweep`): a heat
bath restricted to the counted configurations ``S_b`` when the current one is among them, then with
probability ``p_escape`` an independence Metropolis-Hastings move proposing from ``p_back``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ogm_ppl.priors.compiled import tiles
from ogm_ppl.priors.local import LocalMapPrior, grid_shape, table_occupancy, tiles_log_prob, tiling
from ogm_ppl.priors.patch_table import _patch_hw

__all__ = [
    "BACKOFF_FORMAT",
    "BackoffBorderPrior",
    "BackoffParams",
    "backed_off_prior",
    "backoff_patch_probs",
    "border_log_likelihood",
    "fit_backoff_params",
    "fit_kappa",
    "independent_table",
    "load_backoff_params",
    "save_backoff_params",
    "table_log_likelihood",
    "witten_bell",
    "witten_bell_border",
]

BACKOFF_FORMAT = "ogm_ppl.backoff"
_FITTED = Path(__file__).resolve().parent.parent / "fitted"


def independent_table(lam: float, L: int) -> np.ndarray:
    r"""``(2^L,)`` float64: ``p(i) = lambda^{|i|} (1 - lambda)^{L - |i|}`` of independent cells (bit ``j`` of
    code ``i`` = cell ``j``)."""
    if not 0.0 < lam < 1.0:
        raise ValueError(f"lambda must lie in (0, 1), got {lam}")
    codes = np.arange(1 << L, dtype=np.int64)
    ones = ((codes[:, None] >> np.arange(L)) & 1).sum(1)
    return np.exp(ones * math.log(lam) + (L - ones) * math.log1p(-lam))


def _check_back(back, L: int) -> np.ndarray:
    p = np.asarray(back, dtype=np.float64).ravel()
    if p.shape != (1 << L,):
        raise ValueError(f"the back-off table must have 2^{L} = {1 << L} entries, got {p.size}")
    if not np.isfinite(p).all() or (p <= 0).any():
        raise ValueError("the back-off table must be finite and strictly positive")
    return p / p.sum()


def witten_bell(counts, kappa: float, back) -> np.ndarray:
    r"""A dense table smoothed towards ``back``: ``p(i) = (c_i + kappa T back_i) / (n + kappa T)``, ``T``
    the number of codes with ``c_i > 0`` (``counts`` and ``back``: ``(2^L,)``)."""
    c = np.asarray(counts, dtype=np.float64).ravel()
    L = c.size.bit_length() - 1
    p = _check_back(back, L)
    if not kappa > 0:
        raise ValueError(f"kappa must be positive, got {kappa}")
    n, T = c.sum(), float((c > 0).sum())
    if n == 0:
        return p
    return (c + kappa * T * p) / (n + kappa * T)


def witten_bell_border(border_codes, inner_codes, counts, kappa: float, back):
    r"""Witten-Bell ``p(i | b)`` (module docstring) from (border, inner, count) triples.

    Returns ``(borders, log_lambda, keys, logp)``: the sorted distinct borders ``b`` with
    ``log lambda_b``, and for every counted pair ``key = b << L | i`` (sorted) its smoothed
    ``log p(i | b)``. A pair not counted has ``log p = log lambda_b + log back(i)``; an unseen border
    ``log back(i)``.
    """
    b = np.asarray(border_codes).astype(np.int64).ravel()
    i = np.asarray(inner_codes).astype(np.int64).ravel()
    c = np.asarray(counts, dtype=np.float64).ravel()
    back = np.asarray(back, dtype=np.float64)
    L = back.size.bit_length() - 1
    back = _check_back(back, L)
    if not kappa > 0:
        raise ValueError(f"kappa must be positive, got {kappa}")
    if not (b.shape == i.shape == c.shape):
        raise ValueError("border_codes, inner_codes and counts must be of one length")
    if (i < 0).any() or (i >= (1 << L)).any():
        raise ValueError(f"inner codes must lie in 0..2^{L} - 1")
    if not np.isfinite(c).all() or (c < 0).any():
        raise ValueError("counts must be finite and non-negative")
    keys, inv = np.unique((b << L) | i, return_inverse=True)
    cnt = np.bincount(inv, weights=c, minlength=len(keys))
    keep = cnt > 0
    keys, cnt = keys[keep], cnt[keep]
    borders, binv = np.unique(keys >> L, return_inverse=True)
    n_b = np.bincount(binv, weights=cnt)
    T_b = np.bincount(binv).astype(np.float64)
    den = n_b + kappa * T_b
    inner = keys & ((np.int64(1) << L) - 1)
    logp = np.log((cnt + kappa * T_b[binv] * back[inner]) / den[binv])
    return borders, np.log(kappa * T_b / den), keys, logp


def _pair_log_probs(fit, val, kappa: float, back) -> tuple[np.ndarray, np.ndarray]:
    """``(log p_fit(i | b), count)`` of every validation pair, ``fit``/``val``: (border, inner, count)."""
    back = np.asarray(back, dtype=np.float64)
    L = back.size.bit_length() - 1
    fb, fi, fc = fit
    borders, log_lam, keys, logp = witten_bell_border(fb, fi, fc, kappa, back)
    vb = np.asarray(val[0]).astype(np.int64)
    vi = np.asarray(val[1]).astype(np.int64)
    vc = np.asarray(val[2], dtype=np.float64)
    vk = (vb << L) | vi
    out = np.log(back / back.sum())[vi]
    j = np.clip(np.searchsorted(borders, vb), 0, len(borders) - 1)
    seen = borders[j] == vb
    out[seen] = log_lam[j[seen]] + out[seen]
    q = np.clip(np.searchsorted(keys, vk), 0, len(keys) - 1)
    hit = keys[q] == vk
    out[hit] = logp[q[hit]]
    return out, vc


def border_log_likelihood(fit, val, kappa: float, back) -> float:
    """Mean validation log-likelihood per (border, inner) pair of the Witten-Bell table counted on
    ``fit`` (``(border, inner, count)`` triples; so is ``val``)."""
    lp, c = _pair_log_probs(fit, val, kappa, back)
    return float((lp * c).sum() / c.sum())


def table_log_likelihood(fit_counts, val_counts, kappa: float, back) -> float:
    """Mean validation log-likelihood per window of the dense smoothed table :func:`witten_bell`."""
    p = witten_bell(fit_counts, kappa, back)
    v = np.asarray(val_counts, dtype=np.float64)
    return float((v * np.log(p)).sum() / v.sum())


def fit_kappa(objective, lo: float = 1e-6, hi: float = 1e9, num: int = 61, iters: int = 40) -> tuple[float, float]:
    """``(kappa, objective(kappa))`` maximising ``objective`` over ``[lo, hi]``: a grid in ``log kappa``,
    then golden-section search in the bracket around the best grid point (the objective is smooth and
    in practice unimodal in ``log kappa``)."""
    xs = np.linspace(math.log(lo), math.log(hi), num)
    ys = np.array([objective(math.exp(x)) for x in xs])
    k = int(np.argmax(ys))
    a, b = xs[max(k - 1, 0)], xs[min(k + 1, num - 1)]
    g = (math.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = objective(math.exp(c)), objective(math.exp(d))
    for _ in range(iters):
        if fc > fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = objective(math.exp(c))
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = objective(math.exp(d))
    best = [(ys[k], xs[k]), (fc, c), (fd, d)]
    f, x = max(best)
    return math.exp(x), float(f)


# ------------------------------------------------------------------ shipped hyper-parameters
@dataclass(frozen=True)
class BackoffParams:
    """The fitted ``kappa`` of each level of one corpus (module docstring), with provenance."""

    corpus: str
    kappa_patch3: float
    kappa_border: float
    kappa_border1: float
    provenance: dict


def load_backoff_params(corpus: str, path=None) -> BackoffParams:
    """Read ``ogm_ppl/fitted/backoff_<corpus>.json`` (or ``path``), validated; errors name the file."""
    p = Path(path) if path is not None else _FITTED / f"backoff_{corpus}.json"
    if not p.is_file():
        raise FileNotFoundError(f"no back-off hyper-parameters for corpus {corpus!r}: {p} does not exist")
    try:
        d = json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"back-off parameters {p}: not valid JSON ({e})") from e
    if not isinstance(d, dict) or d.get("format") != BACKOFF_FORMAT:
        raise ValueError(f"back-off parameters {p}: format is not {BACKOFF_FORMAT!r}")
    if d.get("format_version") != 1:
        raise ValueError(f"back-off parameters {p}: format_version {d.get('format_version')!r} is not 1")
    if d.get("corpus") != corpus and path is None:
        raise ValueError(f"back-off parameters {p}: corpus is {d.get('corpus')!r}, expected {corpus!r}")
    vals = {}
    for k in ("kappa_patch3", "kappa_border", "kappa_border1"):
        v = d.get(k)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not (math.isfinite(v) and v > 0):
            raise ValueError(f"back-off parameters {p}: {k!r} must be a positive finite number, got {v!r}")
        vals[k] = float(v)
    prov = d.get("provenance")
    if not isinstance(prov, dict):
        raise ValueError(f"back-off parameters {p}: 'provenance' must be an object")
    return BackoffParams(str(d["corpus"]), provenance=prov, **vals)


def save_backoff_params(params: BackoffParams, path) -> Path:
    """Write ``params`` (:func:`fit_backoff_params`) as JSON in the format of the shipped ones, atomically; read
    them back with ``load_backoff_params(corpus, path=path)``. Returns the path."""
    from ogm_ppl.io import atomic_write_text

    doc = {
        "format": BACKOFF_FORMAT,
        "format_version": 1,
        "corpus": params.corpus,
        "kappa_patch3": float(params.kappa_patch3),
        "kappa_border": float(params.kappa_border),
        "kappa_border1": float(params.kappa_border1),
        "provenance": params.provenance,
    }
    return atomic_write_text(Path(path), json.dumps(doc, indent=1) + "\n")


def backoff_patch_probs(tables, kappa: float) -> np.ndarray:
    """The 512-entry smoothed 3 x 3 table of ``tables`` (:class:`~ogm_ppl.priors.tables.PriorTables`):
    :func:`witten_bell` of ``counts3x3`` towards independent cells with the corpus's ``lambda``."""
    return witten_bell(tables.counts3x3, kappa, independent_table(tables.lam, 9))


# ------------------------------------------------------------------ the prior
class BackoffBorderPrior(LocalMapPrior):
    r"""Witten-Bell ``p(inner | border)`` on a tiling by inner patches: :class:`~ogm_ppl.priors.BorderPatchPrior`
    with every configuration given positive mass (module docstring; Section 5.2.3).

    Args:
        shape: grid shape ``(K,)`` or ``(rows, cols)``.
        border_codes, inner_codes, counts: one entry per observed (border, inner) pair (codes as in
            :mod:`ogm_ppl.priors.border`).
        kappa: the Witten-Bell hyper-parameter (> 0).
        back: ``(2^L,)`` strictly positive back-off table over inner codes (normalised here).
        inner: ``(3, 3)``, ``(1, 1)``, ``L`` (1D run) or any ``(h, w)``.
        outside: value of cells off the grid (1: occupied, as walled maps; 0: free).
        origin: ``(row, col)`` where one tile starts.

    The compiled face is a :class:`~ogm_ppl.priors.compiled.bundles.Tiles` bundle with four segments:
    0 the counted pairs (smoothed ``log p(i | b)``; the candidates ``S_b`` of a tile with a seen border),
    1 the inner codes counted after any border with their ``log back(i)`` (the candidates of a tile whose
    border was never seen), 2 ``log lambda_b`` keyed by border (``border_seg``), 3 ``log back(i)`` over
    all ``2^L`` inner codes, and the back-off's cumulative table ``back_cdf`` the escape move samples.
    The candidate sets are fixed by the tile's border, so the restricted heat bath stays exact.

    >>> import torch
    >>> p = BackoffBorderPrior((4,), [0, 3], [0, 1], [9, 9], kappa=1.0, back=[0.5, 0.5], inner=1)
    >>> bool(np.isfinite(p.log_prob(torch.tensor([0., 1., 0., 1.]))))
    True
    """

    normalised = False

    def __init__(
        self,
        shape,
        border_codes,
        inner_codes,
        counts,
        kappa: float,
        back,
        inner=(3, 3),
        outside: int = 1,
        origin=(0, 0),
    ) -> None:
        self.rows, self.cols, self.ndim = grid_shape(shape)
        self.num_cells = self.rows * self.cols
        self.inner = _patch_hw(inner, self.ndim)
        if outside not in (0, 1):
            raise ValueError(f"outside must be 0 or 1, got {outside!r}")
        h, w = self.inner
        Li = h * w
        pad = (0, 1) if self.ndim == 1 else (1, 1)
        Lb = (h + 2 * pad[0]) * (w + 2 * pad[1]) - Li
        if Li + Lb > 62 or Li > 20:
            raise ValueError(f"windows of {Li + Lb} cells ({Li} inner) exceed the 62-bit keys / 2^20 back-off table")
        b = np.asarray(border_codes).astype(np.int64).ravel()
        if b.size and ((b < 0).any() or (b >= (np.int64(1) << Lb)).any()):
            raise ValueError(f"border codes must lie in 0..2^{Lb} - 1 ({Lb} border cells)")
        backp = _check_back(back, Li)
        borders, log_lam, keys, logp = witten_bell_border(b, inner_codes, counts, float(kappa), backp)
        if keys.size == 0:
            raise ValueError("the table has no mass")
        self.kappa, self.back = float(kappa), backp
        self.outside, self.pad = int(outside), pad
        origin = (0, int(origin)) if np.isscalar(origin) else tuple(int(o) for o in origin)  # type: ignore[arg-type]  # numpy's isscalar TypeGuard narrows to generic | complex | bytes
        self.origin = origin
        geo = tiling(self.rows, self.cols, self.inner, pad, origin)
        fill = geo[6] if outside else np.zeros_like(geo[6])
        all_inner = np.arange(1 << Li, dtype=np.int64)
        # the candidates of a tile whose border was never seen: the inners counted after any border
        seen_inner = np.unique(keys & ((np.int64(1) << Li) - 1))
        cdf = np.cumsum(backp)
        cdf /= cdf[-1]
        self._compiled = tiles(
            self.rows,
            self.cols,
            geo,
            Li,
            self.inner,
            pad,
            np.zeros(len(fill), np.int64),
            fill,
            [keys, seen_inner, borders, all_inner],
            [logp, np.log(backp[seen_inner]), log_lam, np.log(backp)],
            fallback=1,
            border_seg=2,
            back_cdf=cdf,
        )
        self.keys, self.log_probs = keys, logp
        self.border_codes, self.log_lambda = borders, log_lam
        # the counted inner patches' cell occupancy (as BorderPatchPrior's): the threshold of the "ogm"
        # initial map (ogm_ppl.inference.mcmc.kernel.initial_map), which otherwise falls back to 0.5 and
        # starts every unobserved cell (a map's solid outer border, wall interiors) free
        self.mean_occupancy = table_occupancy(inner_codes, counts, Li)

    def __repr__(self) -> str:
        return f"BackoffBorderPrior(inner={self.inner}, borders={len(self.border_codes)}, kappa={self.kappa:.3g})"

    def conditional(self, border: int) -> np.ndarray:
        """``(2^L,)`` ``p(inner | border)`` over all inner codes (sums to 1)."""
        Li = self.inner[0] * self.inner[1]
        out = self.back.copy()
        j = int(np.searchsorted(self.border_codes, border))
        if j < len(self.border_codes) and self.border_codes[j] == border:
            out *= math.exp(self.log_lambda[j])
            lo = np.searchsorted(self.keys, np.int64(border) << Li)
            hi = np.searchsorted(self.keys, (np.int64(border) + 1) << Li)
            out[self.keys[lo:hi] & ((1 << Li) - 1)] = np.exp(self.log_probs[lo:hi])
        return out

    def log_prob(self, maps):
        """``sum_t log p(inner_t | border_t)``: ``log p(m)`` up to ``log Z``, ``... x K -> ...``."""
        return tiles_log_prob(self, maps)

    def sample(self, sample_shape=(), generator=None, num_sweeps: int = 100):
        """Maps drawn by ``num_sweeps`` single-cell Gibbs sweeps on the prior alone (from uniform noise)."""
        return self._gibbs_sample(sample_shape, generator, num_sweeps)


#: the ``kappa`` search range of :func:`fit_backoff_params` (and of :func:`ogm_ppl.learn.fit_backoff`)
KAPPA_RANGE = (1e-6, 1e9)


def fit_backoff_params(fit, val, corpus: str = "own") -> BackoffParams:
    """The ``kappa`` of each level fitted as the shipped ones are (module docstring), for tables of your own:
    ``fit`` counted on some of your plans, ``val`` on the others (:func:`~ogm_ppl.priors.learn.count_tables`
    of each), bottom-up (the 3 x 3 table against independent cells with ``fit``'s ``lambda``, then the border
    table against that smoothed table, the 1-given-8 table against ``(1 - lambda, lambda)``). Apply them to the
    tables counted on all your plans: ``backed_off_prior(kind, shape, tables, params=...)``; keep them with
    :func:`save_backoff_params`."""
    ind = independent_table(fit.lam, 9)
    k3, ll3 = fit_kappa(lambda k: table_log_likelihood(fit.counts3x3, val.counts3x3, k, ind), *KAPPA_RANGE)
    back3 = backoff_patch_probs(fit, k3)
    fb, vb = fit.border_table().triples(), val.border_table().triples()
    kb, llb = fit_kappa(lambda k: border_log_likelihood(fb, vb, k, back3), *KAPPA_RANGE)
    back1 = np.array([1 - fit.lam, fit.lam])
    f1, v1 = fit.border1_triples(), val.border1_triples()
    k1, ll1 = fit_kappa(lambda k: border_log_likelihood(f1, v1, k, back1), *KAPPA_RANGE)
    prov = {
        "fitted_by": "fit_backoff_params",
        "kappa_search_range": list(KAPPA_RANGE),
        "validation_mean_log_lik": {"patch3": ll3, "border": llb, "border1": ll1},
        # at the search's lower end: the validation likelihood still grows as the smoothing vanishes (almost
        # every validation configuration was counted in the fit part); the tables stay strictly positive
        "kappa_at_lower_bound": [
            name for name, k in (("patch3", k3), ("border", kb), ("border1", k1)) if k <= 1.001 * KAPPA_RANGE[0]
        ],
    }
    return BackoffParams(corpus, kappa_patch3=k3, kappa_border=kb, kappa_border1=k1, provenance=prov)


def backed_off_prior(
    kind: str, shape, tables, corpus: str | None = None, params: BackoffParams | None = None
) -> LocalMapPrior:
    """The backed-off prior ``kind`` (``patch3_bo``, ``border_bo``, ``border1_bo``) over ``shape`` from
    ``tables``, with the hyper-parameters ``params`` (:func:`fit_backoff_params`, for tables of your own) or
    those fitted for the shipped ``corpus`` (:func:`load_backoff_params`)."""
    from ogm_ppl.priors.patch_table import PatchTablePrior

    if params is None and not corpus:
        raise ValueError(
            f"backed_off_prior({kind!r}): give params (fit_backoff_params on your own fit and validation "
            "tables) or the shipped corpus whose hyper-parameters to use"
        )
    hp = params if params is not None else load_backoff_params(str(corpus))
    back3 = backoff_patch_probs(tables, hp.kappa_patch3)
    if kind == "patch3_bo":
        return PatchTablePrior(shape, codes=np.arange(512), counts=back3, patch=(3, 3))
    if kind == "border_bo":
        b, i, c = tables.border_table().triples()
        return BackoffBorderPrior(shape, b, i, c, kappa=hp.kappa_border, back=back3)
    if kind == "border1_bo":
        lam = tables.lam
        b, i, c = tables.border1_triples()
        return BackoffBorderPrior(shape, b, i, c, kappa=hp.kappa_border1, back=[1 - lam, lam], inner=(1, 1))
    raise ValueError(f"unknown backed-off prior kind {kind!r}")
