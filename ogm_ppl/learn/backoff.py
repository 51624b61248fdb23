r"""Back-off weights of the strictly positive table priors, fitted on held-out training plans (Witten-Bell).

Each level of a backed-off prior (:mod:`ogm_ppl.priors.backoff`, thesis Sections 5.2.2-5.2.3) mixes the
relative frequencies of its table with the next, coarser level:

.. math::

    p(i \mid b) = (1 - \lambda_b)\,\frac{c(b, i)}{n_b} + \lambda_b\, p_\text{back}(i), \qquad
    \lambda_b = \frac{\kappa T_b}{n_b + \kappa T_b},

``T_b`` the number of distinct inner configurations counted after border ``b``. One ``kappa`` per level sets
the mixture weights; it maximises the mean validation log-likelihood of the held-out (border, inner) pairs,
``max_kappa 1/|V| sum_{(b, i) in V} log p_kappa(i | b)``, bottom-up: ``patch3`` (3 x 3 windows against
independent cells with the fit part's ``lambda``), ``border`` (3 x 3 | 16 border cells against the smoothed
3 x 3 table), ``border1`` (1 cell | its 8 neighbours against ``(1 - lambda, lambda)``)
(:func:`~ogm_ppl.priors.backoff.fit_backoff_params`).

The training plans (a corpus's, or plan files of one's own) are split in their order: every
``validation_every``-th plan (index ``% validation_every == validation_every - 1``; 5 for the shipped weights)
is validation, the rest the fit part. Tables are counted on each part with the 8 symmetries (the fit part with
the shipped ``min_count_5x5 = 2`` cut, the validation part with every window). :func:`fit_backoff` writes
``backoff_<name>.json`` in the format of the shipped ``ogm_ppl/fitted/backoff_<corpus>.json``; read it with
``load_backoff_params(name, path=...)`` and apply it to tables counted on all the plans
(``backed_off_prior(kind, shape, tables, params=...)``, :func:`~ogm_ppl.learn.fit_tables`).
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from ogm_ppl.learn._fit_common import (
    FitResult,
    PlanPaths,
    TrainingPlans,
    command,
    fit_setup,
    run_provenance,
)

__all__ = ["VALIDATION_EVERY", "fit_backoff"]

#: every fifth training plan is validation for the shipped weights
VALIDATION_EVERY = 5
_FIT_MIN_COUNT_5X5 = 2


def fit_backoff(
    source: str | PlanPaths | TrainingPlans,
    out_dir: str | os.PathLike,
    *,
    limit: int | None = None,
    pixel_size: float | None = None,
    resolution: float = 0.05,
    name: str | None = None,
    validation_every: int = VALIDATION_EVERY,
    progress: bool = False,
) -> FitResult:
    """Fit the ``kappa`` of each back-off level on ``source``'s training plans (module docstring) and write
    ``backoff_<name>.json`` into ``out_dir`` (nothing else, atomically).

    Args:
        source, limit, pixel_size, resolution: the training plans, as :func:`~ogm_ppl.learn.fit_tables` takes
            them.
        out_dir: the folder the file goes to (created if missing).
        name: the file's name part and its ``corpus`` field (default the corpus, or ``plans``).
        validation_every: every this-many-th plan is validation (at least 2, at most the number of plans).
        progress: progress bars over the maps counted.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    out, plans, label, every, fit_idx, val_idx = fit_setup(
        source, out_dir, name, validation_every, limit=limit, pixel_size=pixel_size, resolution=resolution
    )
    options = [] if every == VALIDATION_EVERY else ["--validation-every", str(every)]
    options += [] if name is None else ["--name", label]
    cmd = command("backoff", plans, out, options)

    from ogm_ppl.priors.backoff import (
        BACKOFF_FORMAT,
        KAPPA_RANGE,
        backoff_patch_probs,
        border_log_likelihood,
        fit_backoff_params,
    )
    from ogm_ppl.priors.learn import count_tables

    t0 = time.perf_counter()
    tf = count_tables(plans.maps(fit_idx), symmetries=True, min_count_5x5=_FIT_MIN_COUNT_5X5, progress=progress)
    tv = count_tables(plans.maps(val_idx), symmetries=True, min_count_5x5=1, progress=progress)
    counted = time.perf_counter() - t0
    hp = fit_backoff_params(tf, tv, label)
    k3, kb, k1 = hp.kappa_patch3, hp.kappa_border, hp.kappa_border1
    lls = hp.provenance["validation_mean_log_lik"]
    fb, vb = tf.border_table().triples(), tv.border_table().triples()
    # references: the unsmoothed tables give -inf wherever a validation pair was never counted
    unseen_3 = float(tv.counts3x3[tf.counts3x3 == 0].sum() / tv.counts3x3.sum())
    ll_b_patch = border_log_likelihood(fb, vb, 1e12, backoff_patch_probs(tf, k3))  # kappa -> inf: 3 x 3 alone
    doc = {
        "format": BACKOFF_FORMAT,
        "format_version": 1,
        "corpus": label,
        "kappa_patch3": k3,
        "kappa_border": kb,
        "kappa_border1": k1,
        # kappa at the search's lower end: the validation likelihood still grows as the smoothing vanishes
        # (almost every validation pair was counted in the fit plans); the tables stay strictly positive
        "kappa_at_lower_bound": hp.provenance["kappa_at_lower_bound"],
        "kappa_search_range": list(KAPPA_RANGE),
        "validation": {
            "patch3_mean_log_lik": lls["patch3"],
            "border_mean_log_lik": lls["border"],
            "border_mean_log_lik_patch3_only": ll_b_patch,
            "border1_mean_log_lik": lls["border1"],
            "uncounted_share_patch3": unseen_3,
            "uncounted_share_border": unseen_share(fb, vb),
            "uncounted_share_border1": unseen_share(tf.border1_triples(), tv.border1_triples()),
        },
        "provenance": run_provenance(
            cmd,
            plans,
            validation=f"natural order, index % {every} == {every - 1} -> validation",
            fit_plans=len(fit_idx),
            validation_plans=len(val_idx),
            fit_names_sha256=plans.names_sha256(fit_idx),
            validation_names_sha256=plans.names_sha256(val_idx),
            symmetries=8,
            fit_min_count_5x5=_FIT_MIN_COUNT_5X5,
            formula="Witten-Bell: p(i|b) = (c(b,i) + kappa T_b p_back(i)) / (n_b + kappa T_b)",
            fitted_by="ogm_ppl.learn.fit_backoff",
            seconds=round(time.perf_counter() - t0, 1),
            counting_seconds=round(counted, 1),
        ),
    }
    from ogm_ppl.io import atomic_write_text

    path = atomic_write_text(out / f"backoff_{label}.json", json.dumps(doc, indent=1) + "\n")
    summary = {"kappa_patch3": k3, "kappa_border": kb, "kappa_border1": k1, "validation": doc["validation"]}
    return FitResult("backoff", (path,), doc["provenance"], summary, doc["provenance"]["seconds"])


def unseen_share(fit, val) -> float:
    """The share of the validation pairs' count ``val = (borders, inners, counts)`` whose (border, inner) pair
    the fit part ``fit`` never counted (where an unsmoothed table gives probability 0)."""
    fk = np.unique((np.asarray(fit[0], np.int64) << 9) | np.asarray(fit[1], np.int64))
    vk = (np.asarray(val[0], np.int64) << 9) | np.asarray(val[1], np.int64)
    c = np.asarray(val[2], np.float64)
    return float(c[~np.isin(vk, fk)].sum() / c.sum())
