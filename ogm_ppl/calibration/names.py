"""The methods of a calibration run by name (thesis Section 5.2): priors with their training corpus, biased
priors, corpus guides and the traditional-OGM baseline, and the digest of what each name scores.

A prior name is ``KIND[:CORPUS][@MOD]`` (:func:`~ogm_ppl.priors.named.split_prior_name`): ``KIND:CORPUS`` the
kind with the tables learned on ``CORPUS``, ``@cal`` that prior raised to its fitted tempering exponent
``beta``. ``NAME+bias`` is the prior times ``exp(h sum_k m_k)`` with ``h`` from a bias file
(:func:`load_bias_file`, :class:`~ogm_ppl.priors.BiasedPrior`); ``guide:C`` the amortised guide learned on
corpus ``C`` (:mod:`ogm_ppl.calibration.leakage`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ogm_ppl.calibration.errors import BiasFileError
from ogm_ppl.calibration.leakage import GUIDE_PREFIX
from ogm_ppl.inference.mcmc.fingerprint import digest, prior_name_digest
from ogm_ppl.priors.named import PRIOR_KINDS, kind_corpora, load_temper_params, prior_kinds, split_prior_name

if TYPE_CHECKING:
    from ogm_ppl.inference.variational.amortised import AmortisedGuide

__all__ = [
    "BIAS_FORMAT",
    "BIAS_SUFFIX",
    "OGM_LABEL",
    "OWN",
    "default_priors",
    "kind_label",
    "load_bias_file",
    "name_digest",
    "prior_names",
    "unbiased_name",
]

#: the baseline row: traditional OGM with the fitted ``p21`` update (never-observed cells keep ``q = 0.5``)
OGM_LABEL = "traditional OGM (p21)"
#: the training label of a prior kind of one's own named without a corpus (learned on one's own plans)
OWN = "own"
#: a prior name ending so is the prior times ``exp(h sum_k m_k)``, ``h`` from the bias file
#: (:class:`~ogm_ppl.priors.BiasedPrior`)
BIAS_SUFFIX = "+bias"
#: the format tag of a bias file (``{"format", "provenance", "settings", "bias": {prior name: h}}``), which
#: ``ogm-ppl fit-prior bias`` (:func:`ogm_ppl.learn.fit_bias`) writes
BIAS_FORMAT = "ogm_ppl.prior_bias"


def unbiased_name(name: str) -> tuple[str, bool]:
    """``(name without BIAS_SUFFIX, whether it had it)``."""
    return (name[: -len(BIAS_SUFFIX)], True) if name.endswith(BIAS_SUFFIX) else (name, False)


def kind_label(name: str) -> str:
    """The kind of a prior name with its tempering and bias suffixes: ``border_bo:ipa@cal`` -> ``border_bo@cal``,
    ``border1_bo:ipa+bias`` -> ``border1_bo+bias``."""
    name, biased = unbiased_name(name)
    kind, _, at, mod = split_prior_name(name)
    return kind + at + mod + (BIAS_SUFFIX if biased else "")


def prior_names(kinds: Sequence[str], train: Sequence[str]) -> list[tuple[str, str | None]]:
    """``(prior name, training corpus)`` pairs: ``KIND:CORPUS`` for every kind and training corpus (a name that
    already holds ``:CORPUS`` is kept), the uniform ``independent`` (trained on nothing) once, and a kind of
    one's own (not shipped) named without a corpus once, trained on :data:`OWN`. A kind shipped for some
    corpora only (:func:`~ogm_ppl.priors.named.kind_corpora`: ``net``) pairs with those of ``train`` it was
    fitted on; ``ValueError`` when that is none of them."""
    out: list[tuple[str, str | None]] = []
    for k in kinds:
        kind, corpus, at, mod = split_prior_name(k)
        if corpus:
            out.append((k, corpus))
            continue
        if kind not in PRIOR_KINDS:
            out.append((k, OWN))
            continue
        if kind == "independent" and not at:
            out.append(("independent", None))
        fitted = kind_corpora(kind)
        cs = [c for c in train if fitted is None or c in fitted]
        if not cs:
            raise ValueError(
                f"prior kind {kind!r} is shipped for {', '.join(fitted or ()) or 'no corpus'}, none of the "
                f"training corpora {', '.join(train)}: name one (KIND:CORPUS) or add it to --train"
            )
        out += [(f"{kind}:{c}{at}{mod}", c) for c in cs]  # a tempering suffix goes after the corpus
    return list(dict.fromkeys(out))


def default_priors(train: Sequence[str]) -> list[str]:
    """Every registered kind (a kind shipped for some corpora only, :func:`~ogm_ppl.priors.named.kind_corpora`,
    where it is shipped for every training corpus), then ``KIND@cal`` for each kind with a fitted tempering
    exponent on every training corpus (:func:`~ogm_ppl.priors.named.load_temper_params`)."""
    kinds = [k for k in prior_kinds() if (kind_corpora(k) is None or set(train) <= set(kind_corpora(k) or ()))]
    fitted: set[str] | None = None
    for c in train:
        try:
            have = set(load_temper_params(c).beta)
        except FileNotFoundError:
            have = set()
        fitted = have if fitted is None else fitted & have
    return kinds + [f"{k}@cal" for k in kinds if k in (fitted or set())]


def name_digest(name: str, bias: Mapping[str, float], guides: Mapping[str, AmortisedGuide]) -> str:
    """What a row of ``name`` scored, as a short hash: a guide's weights (and whether it is symmetrised,
    ``guides`` by corpus name); a prior's :func:`~ogm_ppl.inference.mcmc.fingerprint.prior_name_digest` (its
    tables, settings and log-densities: tables counted again, refitted weights or exponents change it) and its
    bias (``bias`` by prior name); ``"ogm"`` for :data:`OGM_LABEL`; ``"unfitted"`` for a ``@cal`` name without
    an exponent (skipped when run). Building each prior here also refuses an unknown name before anything
    runs (the errors of :func:`~ogm_ppl.priors.named.prior_by_name`)."""
    if name == OGM_LABEL:
        return "ogm"
    if name.startswith(GUIDE_PREFIX):
        g = guides[name[len(GUIDE_PREFIX) :]]
        return digest(*g.net.state_dict().values(), g.symmetrize)
    base, biased = unbiased_name(name)
    kind, corpus, _, mod = split_prior_name(base)
    if mod == "cal" and kind in PRIOR_KINDS and kind not in load_temper_params(corpus).beta:
        return "unfitted"
    return digest(prior_name_digest(base), bias.get(base) if biased else None)


def load_bias_file(path: str | Path | None) -> dict[str, float]:
    """The biases ``{prior name: h}`` of a bias file (``ogm-ppl fit-prior bias``, :func:`ogm_ppl.learn.fit_bias`,
    writes one; ``{}`` for no file), validated. Raises :class:`~ogm_ppl.calibration.errors.BiasFileError` naming
    the file."""
    if path is None:
        return {}
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise BiasFileError(f"{path}: not a bias file ({type(e).__name__}: {e})") from None
    bias = d.get("bias") if isinstance(d, dict) and d.get("format") == BIAS_FORMAT else None
    if not isinstance(bias, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        for k, v in bias.items()
    ):
        raise BiasFileError(f"{path}: not a bias file of format {BIAS_FORMAT!r} with finite biases by prior name")
    return {k: float(v) for k, v in bias.items()}
