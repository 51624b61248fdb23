"""Leakage checks: a prior or guide learned from a corpus is never scored on a map it was learned from.

:func:`training_set` rebuilds the training set of the shipped tables of a corpus from their recorded provenance
(plan names checked against the stored SHA-256; the generated corpus's seed streams); :func:`check_heldout`
refuses test maps in it, of a building in it (also across two corpora of the same buildings: ``houseexpo`` and
``houseexpo-full`` share their house ids), or of a real log's building; :func:`load_corpus_guide` refuses a
corpus guide whose record is not the training set it names (:func:`guide_plans`: the tables' training set, or a
stated random sample of the corpus's training split, with or without a validation set drawn apart from it:
:func:`guide_split`), so the same check covers it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.priors.tables import FITTED_DIR

if TYPE_CHECKING:
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

__all__ = [
    "GUIDE_JOIN",
    "GUIDE_PREFIX",
    "GUIDE_SYM",
    "GUIDE_CORPORA",
    "GuideNameError",
    "LeakageError",
    "check_heldout",
    "guide_corpora",
    "guide_base",
    "guide_for",
    "guide_path",
    "guide_plans",
    "guide_split",
    "guide_training_sets",
    "load_corpus_guide",
    "names_digest",
    "training_set",
]


class LeakageError(ValueError):
    """A test map belongs to the training set of the prior or guide to be scored on it."""


class GuideNameError(ValueError):
    """A corpus guide's name is not ``CORPUS``, ``C1+C2`` or either with ``@sym``."""


def _tables_provenance(corpus: str) -> dict:
    path = FITTED_DIR / f"prior_{corpus}.json"
    try:
        prov = json.loads(path.read_text())["provenance"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise LeakageError(f"{path}: cannot read the tables' provenance ({type(e).__name__}: {e})") from None
    if not isinstance(prov, dict):
        raise LeakageError(f"{path}: 'provenance' is not an object")
    return prov


def training_set(corpus: str) -> set[str]:
    """Names of the maps the shipped tables of ``corpus`` were learned from, rebuilt from their provenance
    (``ogm_ppl/fitted/prior_<corpus>.json``). Floor plans: ``training_plans(corpus, excluded_buildings,
    limit=plans)``, or its random subset where the provenance records one (``sample``: ``random``, ``seed``;
    :func:`~ogm_ppl.datasets.floorplans.sample_indices`), checked against the recorded SHA-256 of the names;
    ``generated``: ``"seedstream:E/K"`` for each spawned child (entropy ``E``, spawn key ``K``) of the recorded
    seed."""
    prov = _tables_provenance(corpus)
    path = FITTED_DIR / f"prior_{corpus}.json"
    if corpus == "generated":
        try:
            children = np.random.SeedSequence(int(prov["seed"])).spawn(int(prov["n"]))
        except (KeyError, TypeError, ValueError) as e:
            raise LeakageError(f"{path}: provenance lacks the generator's seed and n ({e})") from None
        return {f"seedstream:{c.entropy}/{tuple(c.spawn_key)}" for c in children}
    try:
        excl = tuple(prov["excluded_buildings"])
        sample = prov.get("sample")
        if isinstance(sample, dict) and sample.get("random") is not None:  # a random subset (``--sample``)
            names = fp.training_plans(corpus, exclude_buildings=excl)
            names = [names[i] for i in fp.sample_indices(len(names), int(sample["random"]), int(sample["seed"]))]
        else:
            names = fp.training_plans(corpus, exclude_buildings=excl, limit=int(prov["plans"]))
        want = prov["plan_names_sha256"]
    except (KeyError, TypeError, ValueError) as e:
        raise LeakageError(f"{path}: provenance lacks plans / excluded_buildings / plan_names_sha256 ({e})") from None
    got = hashlib.sha256("\n".join(names).encode()).hexdigest()
    if got != want:
        raise LeakageError(
            f"{path}: the training plans rebuilt from its provenance hash to {got[:12]}..., not the recorded "
            f"{want[:12]}...: the floor-plan data changed since the tables were learned"
        )
    return set(names)


def _identity(corpus: str, plan: str) -> str:
    """What :func:`training_set` would call the map ``plan`` of ``corpus``."""
    if corpus == "generated":
        seed = int(plan.rsplit("seed", 1)[1])
        s = np.random.SeedSequence(seed)
        return f"seedstream:{s.entropy}/{tuple(s.spawn_key)}"
    return plan


def _namespace(corpus: str) -> str:
    """The corpus whose buildings ``corpus``'s plans show (:func:`~ogm_ppl.datasets.floorplans.building_namespace`;
    ``generated`` is its own)."""
    return corpus if corpus == "generated" else fp.building_namespace(corpus)


def check_heldout(test_corpus: str, plans: Sequence[str], train_corpus: str | None, train: set[str] | None = None):
    """Refuse (:class:`LeakageError`) to score a prior learned on ``train_corpus`` on ``plans`` of
    ``test_corpus`` if one of them is a plan of a real-log building, or (same corpus, or two corpora of one
    building namespace: ``houseexpo`` and ``houseexpo-full``, :data:`~ogm_ppl.datasets.floorplans.BUILDING_NAMESPACE`)
    one of the training maps (``train``, default :func:`training_set`) or of the same building as one of them.
    ``train_corpus`` ``None``: a prior learned from nothing (the uniform prior); only the real-log check applies."""
    for p in plans:
        if test_corpus != "generated" and fp.excluded(p):
            raise LeakageError(f"{test_corpus} plan {p!r} is of a real-log building; it is excluded everywhere")
    if train_corpus is None or _namespace(train_corpus) != _namespace(test_corpus):
        return
    train = training_set(train_corpus) if train is None else train
    ids = {_identity(test_corpus, p): p for p in plans}
    clash = sorted(ids[i] for i in set(ids) & train)
    if test_corpus != "generated":
        buildings = {fp.building_of(train_corpus, t) for t in train}
        clash += sorted(p for p in plans if p not in clash and fp.building_of(test_corpus, p) in buildings)
    if clash:
        raise LeakageError(
            f"{len(clash)} {test_corpus} test map(s) are in (or share a building with) the training set of the "
            f"{train_corpus} tables: {clash[:3]}"
        )


#: the corpora a guide can be learned on: every floor-plan corpus the library reads, and the generated maps
GUIDE_CORPORA: tuple[str, ...] = (*fp.CORPORA, "generated")


def guide_plans(corpus: str, sample: int | None = None, seed: int = 0) -> tuple[list[str], dict]:
    """The maps a corpus guide learns from (sorted) and what its record says of them (``split``, ``sample``).

    ``sample`` ``None``: the training set of the corpus's shipped tables (:func:`training_set`, the plans the
    tables counted). ``sample = N``: a random ``min(N, n)`` of the corpus's whole training split of ``n`` maps
    (:func:`~ogm_ppl.datasets.floorplans.training_plans`, real-log buildings left out; ``generated``: the
    tables' maps), drawn by :func:`~ogm_ppl.datasets.floorplans.sample_indices` with ``seed`` (a smaller
    sample of one seed is a subset of a larger one). Either is a subset of the training split, so every
    held-out plan stays held out.

    >>> names, rec = guide_plans("schools", sample=10, seed=0)
    >>> len(names), rec["sample"]["random"], rec["sample"]["of"], rec["split"]
    (10, 10, 39, 'train')
    """
    if corpus not in GUIDE_CORPORA:
        raise ValueError(f"unknown corpus {corpus!r}; a guide is learned on one of {', '.join(GUIDE_CORPORA)}")
    if sample is None:
        return sorted(training_set(corpus)), {"split": "train", "sample": None}
    if isinstance(sample, bool) or not isinstance(sample, int) or sample < 1:
        raise ValueError(f"a sample of {sample!r} plans: it must be a whole number of at least 1")
    base = guide_base(corpus)
    k = min(sample, len(base))
    names = [base[i] for i in fp.sample_indices(len(base), k, seed)]
    rule = "sample_indices of the training split (natural order), real-log buildings left out"
    return sorted(names), {"split": "train", "sample": {"random": k, "seed": seed, "of": len(base), "rule": rule}}


def guide_base(corpus: str) -> list[str]:
    """The maps a guide's sample of ``corpus`` is drawn from: its training split in natural order (the
    ``generated`` tables' maps)."""
    if corpus not in GUIDE_CORPORA:
        raise ValueError(f"unknown corpus {corpus!r}; a guide is learned on one of {', '.join(GUIDE_CORPORA)}")
    return sorted(training_set(corpus)) if corpus == "generated" else fp.training_plans(corpus)


#: how a fixed validation set is drawn (the data curves' rule, :mod:`ogm_ppl.learn.data_curve`)
VALIDATION_RULE = (
    "with P = numpy.random.default_rng(seed).permutation(training split): training P[:sample], "
    "validation P[after:after + plans] (after >= sample)"
)


def guide_split(
    corpus: str, sample: int, seed: int, validation: int, after: int | None = None
) -> tuple[list[str], list[str], dict]:
    """``(training, validation, record)``: a guide's training plans and a validation set fixed apart from them,
    both drawn from ``corpus``'s training split (:func:`guide_plans`' maps, ``n`` of them) by the data curves'
    rule. With ``P = numpy.random.default_rng(seed).permutation(n)``, the training plans are ``P[:sample]``
    (the very plans of ``guide_plans(corpus, sample, seed)``, a smaller sample a subset of a larger one) and the
    validation plans ``P[after : after + validation]`` (``after`` at least ``sample``, default ``sample``): so
    guides of every sample size up to ``after`` share one validation set, disjoint from each one's training
    plans, and the pattern field's data curve (:func:`~ogm_ppl.learn.data_curve.field_data_curve`, ``after``
    its largest size) draws its own the same way. Both lists sorted; ``record`` is :func:`guide_plans`'
    with ``sample["validation"]`` (``plans``, ``after``, ``rule``).

    Raises:
        ValueError: ``sample`` or ``validation`` below 1, ``after`` below ``sample``, or ``after + validation``
            above ``n`` (the message names ``--validation-sample`` / ``--validation-after`` and the limit).

    >>> tr, val, rec = guide_split("schools", 10, 0, 5, after=20)
    >>> len(tr), len(val), set(tr) & set(val), rec["sample"]["validation"]["after"]
    (10, 5, set(), 20)
    """
    for v, flag in ((sample, "--sample"), (validation, "--validation-sample"), (seed, "--sample-seed")):
        if isinstance(v, bool) or not isinstance(v, int) or v < (0 if flag == "--sample-seed" else 1):
            raise ValueError(
                f"{flag} must be a whole number of at least {0 if flag == '--sample-seed' else 1}, got {v!r}"
            )
    after = sample if after is None else after
    if isinstance(after, bool) or not isinstance(after, int) or after < sample:
        raise ValueError(f"--validation-after must be a whole number of at least --sample ({sample}), got {after!r}")
    base = guide_base(corpus)
    n = len(base)
    if after + validation > n:
        raise ValueError(
            f"--validation-sample {validation} after the first {after} plans: {corpus} has {n} training plans, so "
            f"--validation-sample may be at most {max(n - after, 0)}"
        )
    perm = np.random.default_rng(seed).permutation(n)
    train = sorted(base[int(i)] for i in perm[:sample])
    val = sorted(base[int(i)] for i in perm[after : after + validation])
    rule = "sample_indices of the training split (natural order), real-log buildings left out"
    held = {"plans": validation, "after": after, "rule": VALIDATION_RULE}
    sample_rec = {"random": sample, "seed": seed, "of": n, "rule": rule, "validation": held}
    return train, val, {"split": "train", "sample": sample_rec}


def _recorded_plans(corpus: str, record: dict, path: Path) -> list[str]:
    """The plans a guide's record of ``corpus`` names: its ``sample`` rebuilt by :func:`guide_plans`, or (no
    sample recorded, as every guide learned on the tables' plans) the tables' :func:`training_set`."""
    sample = record.get("sample")
    if sample is None:
        return sorted(training_set(corpus))
    try:
        n, seed, of = int(sample["random"]), int(sample["seed"]), int(sample["of"])
        held = sample.get("validation")
        if held is not None:
            tr, val, rec = guide_split(corpus, n, seed, int(held["plans"]), int(held["after"]))
            names = sorted(tr + val)
        else:
            names, rec = guide_plans(corpus, n, seed)
    except (KeyError, TypeError, ValueError) as e:
        raise LeakageError(f"{path}: its record of {corpus} has a malformed sample ({e})") from None
    if rec["sample"]["of"] != of:
        raise LeakageError(
            f"{path}: its record of {corpus} sampled {n} of {of} training plans; the training split now holds "
            f"{rec['sample']['of']}: the floor-plan data changed since the guide was learned"
        )
    return names


GUIDE_PREFIX = "guide:"
GUIDE_JOIN = "+"  # a guide learned on several corpora: guide:houseexpo+ipa
GUIDE_SYM = "@sym"  # the guide symmetrised: guide:houseexpo+ipa@sym


def guide_corpora(name: str) -> list[str]:
    """The corpora a guide named ``C``, ``C1+C2`` (either with ``@sym``) was learned on, by its name (a guide
    given a name of its own, e.g. ``real``, names them in its record: :func:`guide_training_sets`)."""
    return name.removesuffix(GUIDE_SYM).split(GUIDE_JOIN)


def _is_join(name: str) -> bool:
    return all(c in GUIDE_CORPORA for c in name.split(GUIDE_JOIN))


def guide_for(name: str, directory: Path | None = None) -> AmortisedGuide:
    """The guide a ``--guides`` name ``C``, ``C1+C2`` or either with ``@sym`` scores
    (:func:`load_corpus_guide` from ``directory``, default the shipped ones; symmetrised for ``@sym``)."""
    base = name.removesuffix(GUIDE_SYM)
    if not base or "@" in base:
        raise GuideNameError(f"a corpus guide is named CORPUS, C1+C2 or either with {GUIDE_SYM}, not {name!r}")
    guide = load_corpus_guide(base, directory=directory)
    if name.endswith(GUIDE_SYM):
        guide.symmetrize = True
    return guide


def names_digest(names) -> str:
    """SHA-256 of the sorted map names joined by newlines: what a corpus guide records of its training set."""
    return hashlib.sha256("\n".join(sorted(names)).encode()).hexdigest()


def guide_path(corpus: str, directory: Path | None = None) -> Path:
    """The amortised guide learned on ``corpus``'s training plans (:func:`~ogm_ppl.inference.variational.corpus_guide`):
    ``guide_<corpus>.npz`` in ``directory`` (default the shipped guides, ``ogm_ppl/fitted``)."""
    return Path(directory or FITTED_DIR) / f"guide_{corpus}.npz"


def _source_records(name: str, meta: dict, path: Path) -> dict:
    """``corpus -> record`` of the corpora a guide's record ``meta`` names (checked against its ``name``: a
    ``C1+C2`` name must list exactly those corpora; a name of its own, any corpora of :data:`GUIDE_CORPORA`)."""
    if meta.get("corpus") != name:
        raise LeakageError(f"{path}: its record names corpus {meta.get('corpus')!r}, not {name!r}")
    joined = _is_join(name)
    parts = guide_corpora(name)
    records = {name: meta} if joined and len(parts) == 1 else meta.get("corpora")
    if joined and (not isinstance(records, dict) or sorted(records) != sorted(parts)):
        raise LeakageError(f"{path}: its record does not list the training sets of {', '.join(parts)}")
    if not isinstance(records, dict) or not records or any(c not in GUIDE_CORPORA for c in records):
        raise LeakageError(f'{path}: its record does not list the corpora it was learned on ("corpora")')
    if not all(isinstance(r, dict) for r in records.values()):
        raise LeakageError(f"{path}: its record of a corpus is not an object")
    return records


def guide_training_sets(name: str, meta: dict, path: Path | str = "guide") -> dict[str, set[str]]:
    """``corpus -> training maps`` of a guide named ``name`` whose record is ``meta`` (its ``trained_for``),
    each rebuilt (:func:`guide_plans`) and checked against the record's SHA-256 of the names; refused
    (:class:`LeakageError`) when the record does not name ``name``, lacks a corpus or names other plans."""
    path = Path(path)
    out: dict[str, set[str]] = {}
    for c, rec in _source_records(name, meta, path).items():
        names = _recorded_plans(c, rec, path)
        got, want = rec.get("plan_names_sha256"), names_digest(names)
        if got != want:
            what = f"the training set of the {c} tables"
            if rec.get("sample"):
                what = "the random sample of its training split it records"
            raise LeakageError(f"{path}: its record of {c} (plans {str(got)[:12]}...) is not {what} ({want[:12]}...)")
        out[c] = set(names)
    return out


def load_corpus_guide(corpus: str, train: set[str] | None = None, directory: Path | None = None):
    """The guide of :func:`guide_path`, refused (:class:`LeakageError`) unless its record names ``corpus`` and,
    for every corpus it was learned on, the SHA-256 of the very plans it names (:func:`guide_training_sets`:
    the corpus's tables' training set, or the random sample of its training split it records), so that
    :func:`check_heldout` covers it as it covers the tables. ``corpus`` is ``C``, ``C1+C2`` (each corpus's
    plans recorded under ``"corpora"``) or a name of the guide's own (``real``: its corpora listed in its
    record). ``train`` replaces the rebuilt set of a one-corpus guide (a test's own set)."""
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

    path = guide_path(corpus, directory)
    guide = AmortisedGuide.load(path)
    meta = guide.trained_for
    records = _source_records(corpus, meta, path)
    if train is not None and len(records) == 1:
        (c, rec), want = next(iter(records.items())), names_digest(train)
        if rec.get("plan_names_sha256") != want:
            raise LeakageError(
                f"{path}: its record of {c} (plans {str(rec.get('plan_names_sha256'))[:12]}...) is not the "
                f"training set of the {c} tables ({want[:12]}...)"
            )
        return guide
    guide_training_sets(corpus, meta, path)
    return guide
