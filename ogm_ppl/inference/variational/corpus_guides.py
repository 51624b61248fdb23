r"""Shipped guides by name: the trained guide of the learned prior (:func:`shipped_guide`) and the guides
learned on the training plans of floor-plan corpora (:func:`corpus_guide`), each an ``.npz`` artefact in
``ogm_ppl/fitted`` (``guide_amortised.npz``, ``guide_<corpus>.npz``) with a JSON sidecar of its training
settings and held-out loss.

A corpus guide approximates the posterior marginal with the corpus itself as the prior,

.. math:: q_\phi(m_k = 1 \mid z) \approx p_\text{corpus}(m_k = 1 \mid z)
    = \sum_m m_k\, p_\text{corpus}(m)\, p(z \mid m) / p_\text{corpus}(z).
"""

from __future__ import annotations

from pathlib import Path

from ogm_ppl.inference.variational.amortised_files import GuideFileError
from ogm_ppl.inference.variational.amortised_guide import AmortisedGuide
from ogm_ppl.models.occupancy import OccupancyModel

__all__ = [
    "SHIPPED_GUIDE",
    "corpus_guide",
    "corpus_guide_path",
    "corpus_guides",
    "shipped_guide",
    "unknown_corpus_message",
]

SHIPPED_GUIDE = Path(__file__).resolve().parent.parent.parent / "fitted" / "guide_amortised.npz"


def shipped_guide(model: OccupancyModel | None = None) -> AmortisedGuide:
    """The trained guide shipped in ``ogm_ppl/fitted/guide_amortised.npz`` (trained for the prior and
    sensor in its ``trained_for``; see the JSON sidecar)."""
    return AmortisedGuide.load(SHIPPED_GUIDE, model)


def corpus_guide_path(corpus: str) -> Path:
    """Where the guide learned on ``corpus``'s training plans ships: ``ogm_ppl/fitted/guide_<corpus>.npz``."""
    return SHIPPED_GUIDE.parent / f"guide_{corpus}.npz"


def corpus_guides() -> list[str]:
    """The corpora with a shipped corpus guide (:func:`corpus_guide`)."""
    paths = SHIPPED_GUIDE.parent.glob("guide_*.npz")  # a training's checkpoint (.ckpt.npz) beside them is none
    return sorted(p.stem.removeprefix("guide_") for p in paths if p != SHIPPED_GUIDE and not p.stem.endswith(".ckpt"))


def unknown_corpus_message(corpus: str) -> str:
    """Why ``corpus`` names no shipped corpus guide: the corpora that have one (names are case-sensitive: a
    hint when the lower-case name is one) and how to train one. :func:`corpus_guide`, ``init="guide:CORPUS"``
    and the methods' options say it alike.

    >>> unknown_corpus_message("HouseExpo")  # doctest: +ELLIPSIS
    "no guide learned on corpus 'HouseExpo' (did you mean 'houseexpo'?); shipped: ..., houseexpo, ..."
    """
    shipped = corpus_guides()
    low = corpus.lower() if isinstance(corpus, str) else None
    hint = f" (did you mean {low!r}?)" if low != corpus and low in shipped else ""
    return (
        f"no guide learned on corpus {corpus!r}{hint}; shipped: {', '.join(shipped)} "
        "(ogm-ppl train-guide --corpus C --out FILE.npz trains one: ogm_ppl.learn.train_corpus_guide)"
    )


def corpus_guide(corpus: str, model: OccupancyModel | None = None) -> AmortisedGuide:
    r"""The guide trained on the training plans of a floor-plan corpus (:func:`ogm_ppl.learn.train_corpus_guide`,
    ``ogm-ppl train-guide --corpus C``):
    windows of the plans the corpus's prior tables were learned from, scanned by the stop-and-scan simulator,
    so that ``q(m_k = 1 | z)`` approximates the posterior marginal with the corpus itself as the prior,

    .. math:: q_\phi(m_k = 1 \mid z) \approx p_\text{corpus}(m_k = 1 \mid z)
        = \sum_m m_k\, p_\text{corpus}(m)\, p(z \mid m) / p_\text{corpus}(z),

    with a receptive field of ``1 + 2 * sum(dilations)`` cells (Chapter 5's question, what a map predicts of the
    cells no ray reached, answered by a network instead of a table). Its ``trained_for`` names the corpus, the
    SHA-256 of its training plans' names and the sensor it was trained for (3 stops x 90 beams, 75-cell range
    by default); evaluate it on held-out plans only, with that sensor
    (:meth:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide.check_setting` warns otherwise).
    Unknown corpus: :class:`~ogm_ppl.inference.variational.amortised_files.GuideFileError`
    (:func:`unknown_corpus_message`).
    """
    if corpus not in corpus_guides():
        raise GuideFileError(unknown_corpus_message(corpus))
    return AmortisedGuide.load(corpus_guide_path(corpus), model)
