r"""Priors by name, built from the learned tables shipped in ``ogm_ppl/fitted`` (Chapter 5).

A name is ``KIND`` or ``KIND:CORPUS``; ``CORPUS`` is one of :func:`~ogm_ppl.priors.tables.available_tables`
(``generated``, ``houseexpo``, ``ipa``, ``dungeon``, and ``houseexpo-full``, ``r2v``, ``schools``, whose count
tables, back-off weights and pattern fields are shipped without tempering exponents; default ``houseexpo``, the
real floor plans whose statistics are closest to the thesis's). A corpus is registered by its files in
``ogm_ppl/fitted``: ``prior_CORPUS.npz`` (the tables), ``backoff_CORPUS.json`` (the ``*_bo`` kinds),
``field_CORPUS.npz`` (``field``, ``field2``), ``net_CORPUS.npz`` (``net``, only where fitted) and
``temper_CORPUS.json`` (``@cal``), each written by
``ogm-ppl fit-prior`` with its provenance:

========================  ==========================================================================
``independent``           cells independent, ``lambda = 0.5`` (the uniform prior of Chapters 2-4)
``independent:CORPUS``    cells independent, ``lambda`` = the corpus's occupied share (thesis: 0.234)
``mrf:CORPUS``            :class:`MRFPrior`, 4-neighbourhood, ``lambda`` and ``psi = P(unequal) /
                          P(equal)`` of neighbour pairs in the corpus (Section 5.2.1)
``mrf8:CORPUS``           the same on the 8-neighbourhood
``patch3:CORPUS``         :class:`PatchTablePrior` over 3 x 3 tiles (Section 5.2.2), all configurations
``patch3_999:CORPUS``     the same truncated to the configurations carrying 99.9 % of the mass
``patch5:CORPUS``         5 x 5 tiles (sparse table of the configurations seen)
``border:CORPUS``         :class:`BorderPatchPrior`, a 3 x 3 patch given its 16 border cells (5.2.3)
``border1:CORPUS``        one cell given its 8 neighbours
``patch3_bo:CORPUS``      ``patch3`` smoothed towards independent cells (Witten-Bell, every
                          configuration positive; :mod:`~ogm_ppl.priors.backoff`)
``border_bo:CORPUS``      ``border`` backed off to ``patch3_bo``, which backs off to independent cells
``border1_bo:CORPUS``     ``border1`` backed off to ``(1 - lambda, lambda)``
``field:CORPUS``          :class:`PatternFieldPrior`, every 3 x 3 window's learned potential (PL + PCD)
``field2:CORPUS``         the same at two scales (3 x 3 windows of the map and of its 2 x 2 OR-pooling)
``net:CORPUS``            :class:`NetFieldPrior`, a small network on every ``w x w`` window, learned by
                          pseudo-likelihood (and PCD) on the corpus's training plans; shipped for the
                          corpora with a ``net_CORPUS.npz`` (:func:`net_corpora`)
========================  ==========================================================================

**Tempering.** Any name takes a suffix ``@BETA`` (a number ``>= 0``) or ``@cal``: the prior raised to the power
``beta`` (:class:`~ogm_ppl.priors.TemperedPrior`: every log-potential times ``beta``; ``beta < 1`` weakens the
coupling, towards the uniform distribution over the prior's support). ``@cal`` reads the exponent fitted for
the kind and corpus in ``ogm_ppl/fitted/temper_CORPUS.json`` (:func:`load_temper_params`; written by
``ogm-ppl fit-prior temper``, :func:`ogm_ppl.learn.fit_temper`, which chooses it on validation plans of the
corpus's training split by the NLL of the cells no ray reached). ``border_bo:ipa@cal``, ``mrf:houseexpo@0.5``.

The tables were learned on the corpus's *training* plans only, with the buildings of the real logs
excluded (:data:`~ogm_ppl.datasets.floorplans.REAL_LOG_BUILDINGS`): evaluate on held-out plans or logs.

**Your own kind** registers a factory under a name with :func:`register_prior`; from then on
``prior_by_name`` (and so the command line's ``--prior`` and experiment specs) builds it. Name the module in
``$OGM_PPL_METHODS`` (comma-separated modules, imported by :mod:`ogm_ppl.methods` in every process) for the
command line and dask workers to find it:

>>> from ogm_ppl.priors import IndependentPrior
>>> register_prior("half", lambda shape, tables: IndependentPrior(0.5, int(np.prod(shape))))
>>> prior_by_name("half", (4, 5)).num_cells
20
>>> unregister_prior("half")
>>> prior_by_name("independent:houseexpo", (4, 5)).num_cells
20
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl._registry import Registry
from ogm_ppl.exceptions import FittedSettingWarning
from ogm_ppl.priors.base import MapPrior

if TYPE_CHECKING:
    from ogm_ppl.priors.tables import PriorTables

__all__ = [
    "PRIOR_KINDS",
    "TEMPER_FORMAT",
    "CorpusTables",
    "TemperParams",
    "kind_corpora",
    "load_temper_params",
    "net_corpora",
    "prior_by_name",
    "prior_kinds",
    "register_prior",
    "split_prior_name",
    "unregister_prior",
]

#: the kinds the library ships (the module docstring's table)
PRIOR_KINDS: tuple[str, ...] = (
    "independent",
    "mrf",
    "mrf8",
    "patch3",
    "patch3_999",
    "patch5",
    "border",
    "border1",
    "patch3_bo",
    "border_bo",
    "border1_bo",
    "field",
    "field2",
    "net",
)
#: the kinds read from one fitted file per corpus that not every corpus has (:func:`kind_corpora`)
FILE_KINDS: tuple[str, ...] = ("net",)
DEFAULT_CORPUS = "houseexpo"

#: ``factory(shape, tables) -> MapPrior``: ``shape`` the grid's shape (a tuple), ``tables`` a
#: :class:`CorpusTables` (``tables()`` the corpus's :class:`~ogm_ppl.priors.tables.PriorTables`)
PriorFactory = Callable[[tuple, "CorpusTables"], MapPrior]
_REGISTRY: Registry[PriorFactory] = Registry("prior", PRIOR_KINDS)
_FACTORIES = _REGISTRY.factories


def register_prior(kind: str, factory: PriorFactory) -> None:
    """Make ``prior_by_name("KIND[:CORPUS]", shape)`` build ``factory(shape, tables)``.

    ``kind`` is a non-empty name without ``:``; registering a shipped kind or a name another factory took is
    refused (:func:`unregister_prior` first); the same factory's module run again (reloaded) registers anew.
    ``tables()`` returns the tables of ``CORPUS`` (default ``houseexpo``) or those passed to
    :func:`prior_by_name`.
    """
    _REGISTRY.register(kind, factory)


def unregister_prior(kind: str) -> None:
    """Remove a kind added by :func:`register_prior` (the shipped kinds stay)."""
    _REGISTRY.unregister(kind)


def prior_kinds() -> tuple[str, ...]:
    """Every kind :func:`prior_by_name` knows: the shipped ones, then the registered ones."""
    return _REGISTRY.kinds()


def _shape(shape) -> tuple[int, ...]:
    s = getattr(shape, "shape", shape)
    return tuple(int(v) for v in (s if np.ndim(s) else (s,)))


def prior_by_name(name: str, shape, tables: PriorTables | None = None) -> MapPrior:
    """The prior called ``name`` (``KIND[:CORPUS][@BETA|@cal]``, module docstring) over a grid of ``shape``
    (a tuple or a ``Grid``).

    Args:
        tables: a :class:`~ogm_ppl.priors.tables.PriorTables` (counted on plans of your own) to use instead of
            the shipped corpus's counts. A corpus in the name then picks only what was fitted for that
            shipped corpus: the back-off weights of the ``*_bo`` kinds (which, without a corpus, refuse: fit
            yours with :func:`~ogm_ppl.priors.backoff.fit_backoff_params`) and the ``@cal`` exponent;
            ``independent:ANY`` is the tables' own ``lambda`` (``independent`` alone, the uniform prior).
            The pattern fields (``field``, ``field2``) are not built from tables and refuse them.
    """
    kind, corpus, at, modifier = split_prior_name(name)
    factory = _REGISTRY.get(kind, name)
    if kind == "net" and tables is None and (corpus or DEFAULT_CORPUS) not in net_corpora():
        raise _no_net_field(corpus or DEFAULT_CORPUS)  # the net fits shipped, not the corpora with tables
    beta = _exponent(name, kind, corpus, modifier, tables) if at else 1.0
    if kind != "independent":  # (which keeps only the corpus's occupied share)
        _check_resolution(name, shape, corpus, tables, kind)
    prior = factory(_shape(shape), CorpusTables(corpus, tables))
    if beta == 1.0:
        return prior
    from ogm_ppl.priors.tempered import TemperedPrior

    return TemperedPrior(prior, beta)


def _recorded_resolution(provenance) -> float | None:
    """The ``resolution`` (metres per cell) a tables' provenance records, if it is a positive number."""
    res = provenance.get("resolution") if isinstance(provenance, dict) else None
    return float(res) if isinstance(res, int | float) and not isinstance(res, bool) and res > 0 else None


@lru_cache(maxsize=16)
def _corpus_resolution(corpus: str) -> float | None:
    """Metres per cell of the plans the shipped tables of ``corpus`` were counted on, where their provenance
    records it (``None``: not recorded, as for maps drawn in cells)."""
    try:
        return _recorded_resolution(json.loads((_FITTED / f"prior_{corpus}.json").read_text())["provenance"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _check_resolution(name: str, shape, corpus: str, tables, kind: str = "") -> None:
    """Warn (:class:`~ogm_ppl.exceptions.FittedSettingWarning`) when ``shape`` is a grid whose cells
    differ in size from those of the plans the prior's tables were counted on (by more than 1 %): its windows
    then span another piece of a building, and walls another number of cells."""
    res = getattr(shape, "resolution", None)
    if res is None or not (corpus or tables is not None):
        return
    learned = _recorded_resolution(tables.provenance) if tables is not None else _corpus_resolution(corpus)
    if learned is None or abs(float(res) / learned - 1.0) <= 0.01:
        return
    if kind == "net":  # a network fitted on the plans, not tables counted on them
        redo = f"fit a net field on plan files read at {float(res):g} m (ogm-ppl fit-prior net-field --resolution)"
    else:
        redo = (
            f"count tables on plans read at {float(res):g} m "
            "(ogm_ppl.priors.learn.count_tables; plan_files.load_plan_file(..., resolution=...))"
        )
    warnings.warn(
        FittedSettingWarning(
            f"prior {name!r} was learned on plans at {learned:g} m a cell and is used on a grid of {float(res):g} m "
            f"a cell: its windows span {float(res) / learned:.3g} times the space, and walls are another number of "
            f"cells thick. Map at {learned:g} m, or {redo}"
        ),
        stacklevel=3,
    )


def split_prior_name(name: str) -> tuple[str, str, str, str]:
    """``KIND[:CORPUS][@MOD]`` -> ``(kind, corpus, "@" or "", mod)`` (empty strings for the parts left out)."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"a prior name is a non-empty string, got {name!r}")
    base, at, modifier = name.partition("@")
    kind, _, corpus = base.partition(":")
    return kind, corpus, at, modifier


def _exponent(name: str, kind: str, corpus: str, modifier: str, tables) -> float:
    """The tempering exponent of ``name``'s ``@`` suffix (a number ``>= 0``, or ``cal``: the fitted one)."""
    if modifier == "cal":
        if not corpus and tables is not None:
            raise ValueError(f"{name!r}: '@cal' with your own tables needs the corpus in the name (KIND:CORPUS@cal)")
        params = load_temper_params(corpus or DEFAULT_CORPUS)
        if kind not in params.beta:
            raise ValueError(
                f"{name!r}: no fitted tempering exponent for kind {kind!r} on corpus {params.corpus!r} "
                f"(fitted: {', '.join(sorted(params.beta)) or 'none'}); give one as @BETA"
            )
        return params.beta[kind]
    try:
        beta = float(modifier)
    except ValueError:
        raise ValueError(f"{name!r}: the '@' suffix is a tempering exponent (a number >= 0) or 'cal'") from None
    if not (math.isfinite(beta) and beta >= 0.0):
        raise ValueError(f"{name!r}: a tempering exponent must be finite and >= 0, got {modifier!r}")
    return beta


# ------------------------------------------------------------------ fitted tempering exponents
TEMPER_FORMAT = "ogm_ppl.temper"
_FITTED = Path(__file__).resolve().parents[1] / "fitted"


@dataclass(frozen=True)
class TemperParams:
    """The fitted tempering exponent of each kind for one corpus (``beta[kind]``), with the validation scores
    and provenance of the fit."""

    corpus: str
    beta: dict[str, float]
    validation: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)


def load_temper_params(corpus: str, path=None) -> TemperParams:
    """Read ``ogm_ppl/fitted/temper_<corpus>.json`` (or ``path``), validated; errors name the file.

    The file: ``{"format": "ogm_ppl.temper", "format_version": 1, "corpus": ..., "beta": {kind: beta},
    "validation": {...}, "provenance": {...}}`` with every ``beta`` finite and in ``[0, 1]``."""
    p = Path(path) if path is not None else _FITTED / f"temper_{corpus}.json"
    if not p.is_file():
        raise FileNotFoundError(f"no fitted tempering exponents for corpus {corpus!r}: {p} does not exist")
    try:
        d = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"tempering exponents {p}: not valid JSON ({e})") from e
    if not isinstance(d, dict) or d.get("format") != TEMPER_FORMAT:
        raise ValueError(f"tempering exponents {p}: format is not {TEMPER_FORMAT!r}")
    if d.get("format_version") != 1:
        raise ValueError(f"tempering exponents {p}: format_version {d.get('format_version')!r} is not 1")
    if path is None and d.get("corpus") != corpus:
        raise ValueError(f"tempering exponents {p}: corpus is {d.get('corpus')!r}, expected {corpus!r}")
    beta = d.get("beta")
    if not isinstance(beta, dict):
        raise ValueError(f"tempering exponents {p}: 'beta' must be an object of kind -> exponent")
    out: dict[str, float] = {}
    for k, v in beta.items():
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not (math.isfinite(v) and 0.0 <= v <= 1.0):
            raise ValueError(f"tempering exponents {p}: beta[{k!r}] must be a number in [0, 1], got {v!r}")
        out[str(k)] = float(v)
    for key in ("validation", "provenance"):
        if not isinstance(d.get(key, {}), dict):
            raise ValueError(f"tempering exponents {p}: {key!r} must be an object")
    return TemperParams(str(d["corpus"]), out, d.get("validation", {}), d.get("provenance", {}))


class CorpusTables:
    """The ``tables`` argument of a prior factory: ``tables()`` loads (once) the tables of the corpus the
    name gave (``corpus``, ``""`` if none: the default corpus), or returns those passed to
    :func:`prior_by_name`. An unknown corpus is refused at once."""

    def __init__(self, corpus: str, tables: PriorTables | None = None) -> None:
        from ogm_ppl.priors.tables import available_tables

        if corpus and tables is None and corpus not in available_tables():
            raise ValueError(f"no shipped tables for corpus {corpus!r}; shipped: {available_tables()}")
        self.corpus = corpus
        self._tables = tables
        self.own = tables is not None  # tables given to prior_by_name, not the shipped ones

    def __call__(self) -> PriorTables:
        if self._tables is None:
            from ogm_ppl.priors.tables import tables_by_name

            self._tables = tables_by_name(self.corpus or DEFAULT_CORPUS)
        return self._tables


# ------------------------------------------------------------------ the shipped kinds
def _independent(shape, tables) -> MapPrior:
    from ogm_ppl.priors.independent import IndependentPrior

    K = int(np.prod(shape))
    if not tables.corpus:
        return IndependentPrior(0.5, K)  # the name alone is always the uniform prior
    return IndependentPrior(float(tables().lam), K)


def _mrf(conn: int) -> PriorFactory:
    def build(shape, tables) -> MapPrior:
        from ogm_ppl.priors.mrf import MRFPrior

        lam_c, psi = tables().mrf_fit(conn)
        order = 1 if conn == 4 else 2
        return MRFPrior(shape, order=order, psi=min(1.0, psi), cell_prior=lam_c, outside=float(tables().lam))

    return build


def _two_d(kind: str, shape) -> None:
    if len(shape) != 2:
        raise ValueError(f"prior {kind!r} is a 2D patch prior; the grid has shape {shape}")


def _patch3(mass: float | None) -> PriorFactory:
    def build(shape, tables) -> MapPrior:
        from ogm_ppl.priors.patch_table import PatchTablePrior

        _two_d("patch3", shape)
        return PatchTablePrior(shape, codes=np.arange(512), counts=tables().counts3x3, patch=(3, 3), mass=mass)

    return build


def _patch5(shape, tables) -> MapPrior:
    from ogm_ppl.priors.patch_table import PatchTablePrior

    _two_d("patch5", shape)
    t = tables()
    return PatchTablePrior(shape, codes=t.codes5x5, counts=t.counts5x5, patch=(5, 5))


def _border(shape, tables) -> MapPrior:
    from ogm_ppl.priors.border import BorderPatchPrior

    _two_d("border", shape)
    border, inner_codes, count = tables().border_table().triples()
    return BorderPatchPrior(shape, border, inner_codes, count, inner=(3, 3))


def _border1(shape, tables) -> MapPrior:
    from ogm_ppl.priors.border import BorderPatchPrior

    _two_d("border1", shape)
    border, centre, count = tables().border1_triples()
    return BorderPatchPrior(shape, border, centre, count, inner=(1, 1))


def _field(scales: int) -> PriorFactory:
    def build(shape, tables) -> MapPrior:
        from ogm_ppl.priors.pattern_field import field_by_name

        kind = "field" if scales == 1 else "field2"
        _two_d(kind, shape)
        if tables.own:
            raise ValueError(
                f"prior {kind!r} is a fitted pattern field, not count tables: fit one on your plans "
                "(ogm_ppl.priors.learn_field.fit_pattern_field; save_field / field_from_file keep it) and build a "
                "PatternFieldPrior, or leave out tables= for the shipped corpus's field"
            )
        return field_by_name(tables.corpus or DEFAULT_CORPUS, shape, scales)

    return build


def net_corpora() -> tuple[str, ...]:
    """The corpora with a shipped net field (``ogm_ppl/fitted/net_<corpus>.npz``), sorted."""
    return tuple(sorted(p.stem[len("net_") :] for p in _FITTED.glob("net_*.npz")))


def kind_corpora(kind: str) -> tuple[str, ...] | None:
    """The corpora ``KIND:CORPUS`` is shipped for when that is not every corpus with tables (``net``:
    :func:`net_corpora`); ``None`` for a kind built from any corpus's tables."""
    return net_corpora() if kind == "net" else None


def _net(shape, tables) -> MapPrior:
    from ogm_ppl.priors.net_field import net_from_file, net_path

    _two_d("net", shape)
    if tables.own:
        raise ValueError(
            "prior 'net' is a fitted net field, not count tables: fit one on your plans "
            "(ogm-ppl fit-prior net-field --plan-files ..., ogm_ppl.learn.fit_net_field) and read it with "
            "ogm_ppl.priors.net_field.net_from_file, or leave out tables= for a shipped corpus's net field"
        )
    corpus = tables.corpus or DEFAULT_CORPUS
    if corpus not in net_corpora():
        raise _no_net_field(corpus)
    return net_from_file(net_path(corpus), shape)


def _no_net_field(corpus: str) -> ValueError:
    from ogm_ppl.priors.net_field import net_path

    return ValueError(
        f"prior 'net:{corpus}': no shipped net field for corpus {corpus!r} ({net_path(corpus)} does not exist); "
        f"shipped: {', '.join(net_corpora()) or 'none'} (ogm-ppl fit-prior net-field --corpus C --ship)"
    )


for _kind, _factory in (
    ("independent", _independent),
    ("mrf", _mrf(4)),
    ("mrf8", _mrf(8)),
    ("patch3", _patch3(None)),
    ("patch3_999", _patch3(0.999)),
    ("patch5", _patch5),
    ("border", _border),
    ("border1", _border1),
    ("field", _field(1)),
    ("field2", _field(2)),
    ("net", _net),
):
    register_prior(_kind, _factory)


def _backed_off(kind: str) -> PriorFactory:
    def build(shape, tables) -> MapPrior:
        from ogm_ppl.priors.backoff import backed_off_prior

        _two_d(kind, shape)
        if tables.own and not tables.corpus:
            raise ValueError(
                f"prior {kind!r} with your own tables needs smoothing weights fitted on them: "
                f"backed_off_prior({kind!r}, shape, tables, params=fit_backoff_params(fit, val)) "
                "(ogm_ppl.priors.backoff), or name a shipped corpus (KIND:CORPUS) to smooth your counts with "
                "the weights fitted for it"
            )
        return backed_off_prior(kind, shape, tables(), tables.corpus or DEFAULT_CORPUS)

    return build


for _kind in ("patch3_bo", "border_bo", "border1_bo"):
    register_prior(_kind, _backed_off(_kind))
