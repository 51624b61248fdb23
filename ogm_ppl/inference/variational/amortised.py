r"""Amortised inference compiled from the model: a neural guide ``q(m | z)`` over 2D maps (inference
compilation, Le, Baydin and Wood 2017; Pyro's ``CSIS``).

Traditional OGM with a fitted update term (Section 2.5) is already an *amortised* mean-field posterior: one
function of the readings, fitted once, gives ``q(m | z) = prod_k Bernoulli(sigmoid(l_k))`` for any data. Its
update of cell ``k`` sees only the readings whose ray crosses ``k``.
:class:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide` keeps the mean-field family but lets
every cell's logit depend on the evidence around it (and on the prior's structure) through a small fully
convolutional network:

.. math::
    q_\phi(m \mid z) = \prod_{k \in \text{latent}} \mathrm{Bernoulli}\bigl(m_k;\
        \sigma(g_\phi(x(z))_k)\bigr),

where ``x(z)`` rasterises the readings per cell
(:func:`~ogm_ppl.inference.variational.amortised_features.evidence_features`: pass-through and hit counts,
the hit share, the p21 evidence grid of Section 2.4/2.5, the observed and pinned masks, and the tile
phase of a patch prior, Section 5.2.2) and ``g_phi`` is a stack of 3 x 3 convolutions (any grid size;
:mod:`~ogm_ppl.inference.variational.amortised_net`).

**Training (inference compilation).** The guide is fitted to the model's own joint: maps from the prior
and readings simulated by the forward sensor model, ``(m, z) ~ p(m) p(z | m)`` (Section 2.1, 2.6), with

.. math::
    \mathcal{L}(\phi) = \mathbb{E}_{p(m, z)}\bigl[-\log q_\phi(m \mid z)\bigr]
        = \mathbb{E}_{p(z)}\bigl[\mathrm{KL}(p(m \mid z) \,\|\, q_\phi(m \mid z))\bigr] + \text{const},

the forward (inclusive) KL averaged over data: it needs no posterior samples and no likelihood evaluations, only
simulation (Le et al. 2017, Eq. 4). For a mean-field ``q`` its minimiser at each ``z`` is the posterior's
marginals, the quantity the thesis's maps report (Chapter 4, Eq. 4.6). The training function is
:func:`ogm_ppl.learn.train_prior_guide`;
:meth:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide.csis_loss` is the batch estimate, and
``pyro.infer.CSIS(model.model, guide, ...)`` trains the same objective one trace at a time (the guide takes
``observations={"z": ...}``).

**Three uses.** :meth:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide.marginals` is a one-pass
map estimate; :func:`~ogm_ppl.inference.variational.amortised_guide.guide_initial_map` starts Gibbs (Chapter 4)
near the posterior; and because ``log q(m | z)`` is exact and cheap, the guide is an independence
Metropolis-Hastings proposal inside Gibbs sweeps that keeps the exact posterior stationary
(:class:`~ogm_ppl.inference.mcmc.guided.GuidedGibbs`, data-driven MCMC).

**Artefacts.** :meth:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide.save` writes a plain
``.npz`` (no pickle): the architecture fields and one float32 array per weight.
:meth:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide.load` validates every field (types, ranges,
the weight names and shapes the architecture implies, finite values) and raises
:class:`~ogm_ppl.inference.variational.amortised_files.GuideFileError` naming the path and what is wrong;
loading into an existing guide of another architecture is refused the same way. The trained guide ships as
``ogm_ppl/fitted/guide_amortised.npz`` (:func:`~ogm_ppl.inference.variational.corpus_guides.shipped_guide`) with
a JSON sidecar of its training settings and held-out loss.

**Modules.** This module gathers the names of its parts, one job each:

* :mod:`~ogm_ppl.inference.variational.amortised_features` -- the features ``x(z)`` of the evidence;
* :mod:`~ogm_ppl.inference.variational.amortised_net` -- the architecture and the network ``g_phi``;
* :mod:`~ogm_ppl.inference.variational.amortised_guide` -- the guide ``q_phi(m | z)`` and its starting maps;
* :mod:`~ogm_ppl.inference.variational.amortised_files` -- the artefact format, its writer and validating reader;
* :mod:`~ogm_ppl.inference.variational.corpus_guides` -- the shipped guides by name;
* :mod:`~ogm_ppl.inference.variational.amortised_scenes` -- the simulated scenes training draws from.
"""

from ogm_ppl.inference.variational.amortised_features import FEATURE_VERSION, evidence_features, feature_names
from ogm_ppl.inference.variational.amortised_files import FORMAT, GuideFileError
from ogm_ppl.inference.variational.amortised_guide import AmortisedGuide, guide_initial_map
from ogm_ppl.inference.variational.amortised_net import GuideArchitecture, GuideNet
from ogm_ppl.inference.variational.amortised_scenes import Scene, random_scene
from ogm_ppl.inference.variational.corpus_guides import (
    SHIPPED_GUIDE,
    corpus_guide,
    corpus_guide_path,
    corpus_guides,
    shipped_guide,
    unknown_corpus_message,
)

__all__ = [
    "AmortisedGuide",
    "GuideArchitecture",
    "GuideFileError",
    "GuideNet",
    "evidence_features",
    "feature_names",
    "guide_initial_map",
    "shipped_guide",
    "corpus_guide",
    "corpus_guide_path",
    "corpus_guides",
    "unknown_corpus_message",
    "SHIPPED_GUIDE",
    "Scene",
    "random_scene",
    "FORMAT",
    "FEATURE_VERSION",
]
