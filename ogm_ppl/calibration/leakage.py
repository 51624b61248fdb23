"""Leakage checks: a prior or guide learned from a corpus is never scored on a map it was learned from.

:func:`training_set` rebuilds the training set of the shipped tables of a corpus from their recorded provenance
(plan names checked against the stored SHA-256; the generated corpus's seed streams); :func:`check_heldout`
refuses test maps in it, of a building in it (also across two corpora of the same buildings: ``houseexpo`` and
``houseexpo-full`` share their house ids), or of a real log's building; :func:`load_corpus_guide` refuses a
corpus guide whose record is not that very training set, so the same check covers it.
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
    "GuideNameError",
    "LeakageError",
    "check_heldout",
    "guide_corpora",
    "guide_for",
    "guide_path",
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
    limit=plans)``, checked against the recorded SHA-256 of the names; ``generated``: ``"seedstream:E/K"``
    for each spawned child (entropy ``E``, spawn key ``K``) of the recorded seed."""
    prov = _tables_provenance(corpus)
    path = FITTED_DIR / f"prior_{corpus}.json"
    if corpus == "generated":
        try:
            children = np.random.SeedSequence(int(prov["seed"])).spawn(int(prov["n"]))
        except (KeyError, TypeError, ValueError) as e:
            raise LeakageError(f"{path}: provenance lacks the generator's seed and n ({e})") from None
        return {f"seedstream:{c.entropy}/{tuple(c.spawn_key)}" for c in children}
    try:
        names = fp.training_plans(corpus, exclude_buildings=tuple(prov["excluded_buildings"]), limit=int(prov["plans"]))
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


GUIDE_PREFIX = "guide:"
GUIDE_JOIN = "+"  # a guide learned on several corpora: guide:houseexpo+ipa
GUIDE_SYM = "@sym"  # the guide symmetrised: guide:houseexpo+ipa@sym


def guide_corpora(name: str) -> list[str]:
    """The corpora a guide named ``C``, ``C1+C2`` (either with ``@sym``) was learned on."""
    return name.removesuffix(GUIDE_SYM).split(GUIDE_JOIN)


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


def load_corpus_guide(corpus: str, train: set[str] | None = None, directory: Path | None = None):
    """The guide of :func:`guide_path`, refused (:class:`LeakageError`) unless its record names ``corpus`` and
    the SHA-256 of the very plans the corpus's tables were learned from (``train``, default
    :func:`training_set`), so that :func:`check_heldout` covers it as it covers the tables. A guide of several
    corpora (``C1+C2``, :func:`guide_corpora`) records each one's plans under ``"corpora"``; each is checked
    against that corpus's :func:`training_set` (``train`` applies to a one-corpus guide only)."""
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

    path = guide_path(corpus, directory)
    guide = AmortisedGuide.load(path)
    meta = guide.trained_for
    parts = guide_corpora(corpus)
    if meta.get("corpus") != corpus:
        raise LeakageError(f"{path}: its record names corpus {meta.get('corpus')!r}, not {corpus!r}")
    records = {corpus: meta} if len(parts) == 1 else meta.get("corpora")
    if not isinstance(records, dict) or sorted(records) != sorted(parts):
        raise LeakageError(f"{path}: its record does not list the training sets of {', '.join(parts)}")
    for c in parts:
        got = records[c].get("plan_names_sha256") if isinstance(records[c], dict) else None
        want = names_digest(training_set(c) if train is None or len(parts) > 1 else train)
        if got != want:
            raise LeakageError(
                f"{path}: its record of {c} (plans {str(got)[:12]}...) is not the training set of the {c} tables "
                f"({want[:12]}...)"
            )
    return guide
