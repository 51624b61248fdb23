r"""Does more data pay: the held-out score of a pattern field fitted on more and more training plans.

One random permutation of a floor-plan corpus's training plans (``numpy.random.default_rng(seed)``, as
:func:`~ogm_ppl.learn._fit_common.sample_indices` draws ``--sample``): its first ``N`` plans train the field of
size ``N`` (so each sample holds every smaller one), the ``validation`` plans after the largest sample score
every field. Nothing of the test split is read.

Per size ``N``, the field is fitted as :func:`~ogm_ppl.learn.fit_field` fits it up to its tempering: the
``2 x 2`` field by maximum pseudo-likelihood, then the ``3 x 3`` one-scale field with the penalty
``lambda_/2 |theta - theta0|^2`` centred on the ``2 x 2`` field's :func:`backoff_potentials`
(:class:`~ogm_ppl.learn.FieldSettings` ``w``, ``backoff_w``, ``lambda_``, ``backoff_lambda_``, ``pl_max_iter``).
The score is the mean held-out pseudo-log-likelihood per cell of the validation plans,

.. math::

    \mathrm{PLL}_\mathrm{val} = \frac{1}{|V|} \sum_{k \in V} \log_2 p(m_k \mid m_{N(k)}; \theta_N)
    \quad\text{(bits per cell; } V \text{ the cells whose } (2w-1)^2 \text{ neighbourhood is known)},

beside the share of validation ``3 x 3`` windows whose configuration no training window showed (the mass an
unsmoothed table would give zero). The tempering and sampler check of the shipped fits (minutes each,
independent of ``N``) are left out: the curve measures what the data add to the fitted potentials.

:func:`field_data_curve` writes ``data_curve_<corpus>.json`` (``ogm-ppl fit-prior data-curve``): per size the
score, the training PLL, the distinct neighbourhoods and the minutes spent reading the plans it adds and
fitting, and the minutes a fit of that size alone takes (reading its plans, fitting).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
from collections.abc import Sequence

import numpy as np

from ogm_ppl.learn._fit_common import (
    FitOptionError,
    FitResult,
    TrainingPlans,
    check_int,
    check_out_dir,
    load_training_plans,
)

__all__ = ["DATA_CURVE_FORMAT", "field_data_curve"]

DATA_CURVE_FORMAT = "ogm_ppl.data_curve"


def field_data_curve(
    corpus: str,
    out_dir: str | os.PathLike,
    *,
    sizes: Sequence[int] = (60, 600, 6000),
    validation: int = 300,
    seed: int = 0,
    settings=None,
    progress: bool = True,
) -> FitResult:
    """Fit the PL pattern field on the first ``N`` plans of a random permutation of ``corpus``'s training split
    for each ``N`` in ``sizes`` and score each on the same ``validation`` plans (module docstring); write
    ``data_curve_<corpus>.json`` into ``out_dir`` (atomically).

    Args:
        corpus: a floor-plan corpus (:data:`~ogm_ppl.learn.CORPORA` less ``generated``).
        sizes: training plans per fit (ascending, at least 1 each); with ``validation`` at most the split.
        validation: plans scored (at least 1).
        seed: the permutation's seed.
        settings: :class:`~ogm_ppl.learn.FieldSettings` (its PL part is used; default the shipped fits').
        progress: a line per stage.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    from ogm_ppl.learn.field import FieldSettings

    s = (settings or FieldSettings()).checked()
    out = check_out_dir(out_dir)
    if corpus == "generated":
        raise FitOptionError("corpus", "a floor-plan corpus: the generated maps have no training split to sample")
    ns = [check_int(n, "sizes", 1) for n in sizes]
    if not ns or ns != sorted(set(ns)):
        raise FitOptionError("sizes", f"give ascending distinct sizes, got {list(sizes)}")
    n_val = check_int(validation, "validation", 1)
    seed = check_int(seed, "seed", 0, 2**32 - 1)
    full = load_training_plans(corpus)
    if ns[-1] + n_val > len(full):
        raise FitOptionError(
            "sizes", f"the largest size plus {n_val} validation plans must be at most the {len(full)} training plans"
        )
    perm = np.random.default_rng(seed).permutation(len(full))
    val_idx = sorted(int(i) for i in perm[ns[-1] : ns[-1] + n_val])
    say = print if progress else (lambda *a, **k: None)

    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.learn._fit_common import run_provenance
    from ogm_ppl.priors.learn_field import backoff_potentials, fit_pl, validation_pll

    sizes_arg = ["--sizes", *map(str, ns), "--validation", str(n_val), "--seed", str(seed)]
    cmd = " ".join(["ogm-ppl", "fit-prior", "data-curve", "--corpus", corpus, "--out", str(out), *sizes_arg])
    prov = run_provenance(cmd, full)  # the commit and date of the run's start
    t0 = time.perf_counter()
    _, va = _stats(full, val_idx, s.backoff_w, s.w)
    val_seconds = time.perf_counter() - t0
    say(f"{corpus}: {n_val} validation plans read in {val_seconds:.1f} s", flush=True)
    rows: list[dict] = []
    acc = None
    prev, read = 0, 0.0
    for n in ns:
        t1 = time.perf_counter()
        new = _stats(full, sorted(int(i) for i in perm[prev:n]), s.backoff_w, s.w)
        acc = new if acc is None else (_add(acc[0], new[0]), _add(acc[1], new[1]))
        tr_small, tr = acc
        t_read = time.perf_counter() - t1
        phi, _, _ = fit_pl(tr_small, 1, s.backoff_lambda_, s.pl_max_iter, progress=False)
        theta, _, pll_train = fit_pl(
            tr, 1, s.lambda_, s.pl_max_iter, theta0=backoff_potentials(phi, s.backoff_w, s.w), progress=False
        )
        pll_val = validation_pll(va, theta)
        read += t_read
        t_fit = time.perf_counter() - t1 - t_read
        row = {
            "plans": n,
            "names_sha256": full.names_sha256(sorted(int(i) for i in perm[:n])),
            "train_cells_pl": int(tr.counts1.sum()),
            "distinct_neighbourhoods": len(tr.keys1),
            "train_pll_bits": pll_train / math.log(2),
            "validation_pll_bits": pll_val / math.log(2),
            "validation_windows_unseen_share": float(va.win1[tr.win1 == 0].sum() / max(va.win1.sum(), 1)),
            "minutes_reading_added": round(t_read / 60, 3),
            "minutes_fitting": round(t_fit / 60, 3),
            "minutes_from_scratch": round((read + t_fit) / 60, 3),
        }
        rows.append(row)
        prev = n
        say(
            f"{corpus}: {n} plans: validation PLL {row['validation_pll_bits']:.6f} bits/cell, unseen windows "
            f"{row['validation_windows_unseen_share']:.2e}, {row['minutes_from_scratch']:.2f} min",
            flush=True,
        )
    prov["seconds"] = round(time.perf_counter() - t0, 1)
    doc = {
        "format": DATA_CURVE_FORMAT,
        "format_version": 1,
        "corpus": corpus,
        "score": "mean held-out pseudo-log-likelihood per cell (bits) of the PL 3 x 3 field (module docstring)",
        "settings": {
            "sizes": ns,
            "validation": n_val,
            "seed": seed,
            "split_of_plans": "first N of numpy.random.default_rng(seed).permutation(training plans); validation: "
            "the next `validation`",
            **{k: getattr(s, k) for k in ("w", "backoff_w", "lambda_", "backoff_lambda_", "pl_max_iter")},
        },
        "validation_names_sha256": full.names_sha256(val_idx),
        "validation_cells_pl": int(va.counts1.sum()),
        "minutes_reading_validation": round(val_seconds / 60, 3),
        "rows": rows,
        "provenance": prov,
    }
    path = atomic_write_text(out / f"data_curve_{corpus}.json", json.dumps(doc, indent=1) + "\n")
    return FitResult("data-curve", (path,), prov, {"rows": rows}, prov["seconds"])


def _stats(plans: TrainingPlans, idx: Sequence[int], w_small: int, w: int, chunk: int = 128):
    """:func:`~ogm_ppl.priors.learn_field.field_stats` of the plans ``idx`` at window sides ``w_small`` and
    ``w``, each plan read once (``chunk`` plans held at a time)."""
    from ogm_ppl.priors.learn_field import field_stats

    it = iter(plans.maps(idx))
    out = None
    while batch := [(m.occupancy, m.known) for m in itertools.islice(it, chunk)]:
        part = (field_stats(batch, w_small, 1), field_stats(batch, w, 1))
        out = part if out is None else (_add(out[0], part[0]), _add(out[1], part[1]))
    if out is None:
        raise FitOptionError("sizes", "no plan to read")
    return out


def _add(a, b):
    """The :class:`~ogm_ppl.priors.learn_field.FieldStats` of two disjoint sets of maps together (one scale)."""
    from ogm_ppl.priors.learn_field import FieldStats
    from ogm_ppl.priors.learn_field._stats import _merge

    keys, counts = _merge([a.keys1, b.keys1], [a.counts1, b.counts1])
    return FieldStats(
        a.w, 1, keys, counts, a.keys2, a.counts2, a.win1 + b.win1, a.win2 + b.win2, a.n_maps + b.n_maps,
        a.n_cells + b.n_cells,
    )  # fmt: skip
