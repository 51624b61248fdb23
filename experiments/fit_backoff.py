"""Fit the Witten-Bell hyper-parameters of the backed-off table priors on held-out training plans.

    python experiments/fit_backoff.py                 # every corpus -> ogm_ppl/fitted/backoff_<corpus>.json
    python experiments/fit_backoff.py --corpus ipa    # one corpus
    python experiments/fit_backoff.py --quick         # tiny corpora, written under out/backoff/ only

Per corpus the training plans (those of ``experiments/prior_stats.py``: ``training_plans`` without the
real-log buildings; the first 300 DungeonMaps; the 100 generated maps of seed 0) are split in their
natural order: every fifth plan (index % 5 == 4) is *validation*, the rest *fit*. Tables are counted on
each part with the 8 symmetries (the fit part with the shipped ``min_count_5x5 = 2`` cut, the validation
part with every window), and each level's ``kappa`` maximises the validation log-likelihood per pair
(:func:`ogm_ppl.priors.backoff.fit_kappa`), bottom-up: ``patch3`` (3 x 3 windows against independent
cells), ``border`` (3 x 3 | 16 against the smoothed 3 x 3 table of the fit part), ``border1``
(1 | 8 against ``(1 - lambda, lambda)``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from ogm_ppl.datasets import floorplans as fp  # noqa: E402
from ogm_ppl.datasets.mapgen import iter_corpus  # noqa: E402
from ogm_ppl.io import atomic_write_text  # noqa: E402
from ogm_ppl.priors.backoff import (  # noqa: E402
    BACKOFF_FORMAT,
    KAPPA_RANGE,
    backoff_patch_probs,
    border_log_likelihood,
    fit_backoff_params,
)
from ogm_ppl.priors.learn import count_tables  # noqa: E402

CORPORA = ("generated", "houseexpo", "ipa", "dungeon")


def _split(n: int) -> tuple[list[int], list[int]]:
    idx = list(range(n))
    return [i for i in idx if i % 5 != 4], [i for i in idx if i % 5 == 4]


def _parts(corpus: str, quick: bool):
    """``(make_fit, make_val, provenance)``: generators of the two parts' maps."""
    if corpus == "generated":
        n = 10 if quick else 100
        fit, val = _split(n)

        def gen(keep):
            for i, m in enumerate(iter_corpus(n, (500, 500), seed=0)):
                if i in keep:
                    yield m

        prov = {"source": "ogm_ppl.datasets.mapgen.iter_corpus", "n": n, "shape": [500, 500], "seed": 0}
        return (lambda: gen(set(fit))), (lambda: gen(set(val))), prov, len(fit), len(val)
    limit = 10 if quick else (300 if corpus == "dungeon" else None)
    names = fp.training_plans(corpus, limit=limit)
    fit, val = _split(len(names))
    fn, vn = [names[i] for i in fit], [names[i] for i in val]
    prov = {
        "source": "ogm_ppl.datasets.floorplans.training_plans",
        "excluded_buildings": list(fp.REAL_LOG_BUILDINGS),
        "resolution": fp.DEFAULT_RESOLUTION[corpus],
        "fit_names_sha256": hashlib.sha256("\n".join(fn).encode()).hexdigest(),
        "validation_names_sha256": hashlib.sha256("\n".join(vn).encode()).hexdigest(),
    }
    return (lambda: fp.iter_plans(corpus, fn)), (lambda: fp.iter_plans(corpus, vn)), prov, len(fn), len(vn)


def fit_corpus(corpus: str, quick: bool) -> dict:
    t0 = time.perf_counter()
    make_fit, make_val, prov, n_fit, n_val = _parts(corpus, quick)
    tf = count_tables(make_fit(), symmetries=True, min_count_5x5=2, progress=False)
    tv = count_tables(make_val(), symmetries=True, min_count_5x5=1, progress=False)
    counted = time.perf_counter() - t0
    hp = fit_backoff_params(tf, tv, corpus)
    k3, kb, k1 = hp.kappa_patch3, hp.kappa_border, hp.kappa_border1
    lls = hp.provenance["validation_mean_log_lik"]
    ll3, llb, ll1 = lls["patch3"], lls["border"], lls["border1"]
    back3 = backoff_patch_probs(tf, k3)
    fb, vb = tf.border_table().triples(), tv.border_table().triples()
    f1, v1 = tf.border1_triples(), tv.border1_triples()
    # references: the unsmoothed tables give -inf wherever a validation pair was never counted
    unseen_b = float(_unseen_share(fb, vb))
    unseen_1 = float(_unseen_share(f1, v1))
    unseen_3 = float(tv.counts3x3[tf.counts3x3 == 0].sum() / tv.counts3x3.sum())
    ll_b_patch = border_log_likelihood(fb, vb, 1e12, back3)  # kappa -> inf: the smoothed 3 x 3 table alone
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        rev = ""
    return {
        "format": BACKOFF_FORMAT,
        "format_version": 1,
        "corpus": corpus,
        "kappa_patch3": k3,
        "kappa_border": kb,
        "kappa_border1": k1,
        # kappa at the search's lower end: the validation likelihood still grows as the smoothing vanishes
        # (almost every validation pair was counted in the fit plans); the tables stay strictly positive
        "kappa_at_lower_bound": hp.provenance["kappa_at_lower_bound"],
        "kappa_search_range": list(KAPPA_RANGE),
        "validation": {
            "patch3_mean_log_lik": ll3,
            "border_mean_log_lik": llb,
            "border_mean_log_lik_patch3_only": ll_b_patch,
            "border1_mean_log_lik": ll1,
            "uncounted_share_patch3": unseen_3,
            "uncounted_share_border": unseen_b,
            "uncounted_share_border1": unseen_1,
        },
        "provenance": {
            **prov,
            "split": "natural order, index % 5 == 4 -> validation",
            "fit_plans": n_fit,
            "validation_plans": n_val,
            "symmetries": 8,
            "fit_min_count_5x5": 2,
            "formula": "Witten-Bell: p(i|b) = (c(b,i) + kappa T_b p_back(i)) / (n_b + kappa T_b)",
            "fitted_by": "experiments/fit_backoff.py",
            "git": rev,
            "quick": quick,
            "seconds": round(time.perf_counter() - t0, 1),
            "counting_seconds": round(counted, 1),
        },
    }


def _unseen_share(fit, val) -> float:
    fk = np.unique((np.asarray(fit[0], np.int64) << 9) | np.asarray(fit[1], np.int64))
    vk = (np.asarray(val[0], np.int64) << 9) | np.asarray(val[1], np.int64)
    c = np.asarray(val[2], np.float64)
    return float(c[~np.isin(vk, fk)].sum() / c.sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", choices=CORPORA, action="append")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    out_dir = ROOT / "out" / "backoff" if args.quick else ROOT / "ogm_ppl" / "fitted"
    out_dir.mkdir(parents=True, exist_ok=True)
    for corpus in args.corpus or CORPORA:
        d = fit_corpus(corpus, args.quick)
        path = out_dir / f"backoff_{corpus}.json"
        atomic_write_text(path, json.dumps(d, indent=1) + "\n")
        v = d["validation"]
        print(
            f"{corpus}: kappa patch3 {d['kappa_patch3']:.4g} border {d['kappa_border']:.4g} "
            f"border1 {d['kappa_border1']:.4g}; val ll/pair border {v['border_mean_log_lik']:.4f} "
            f"(3x3 alone {v['border_mean_log_lik_patch3_only']:.4f}), uncounted border pairs "
            f"{v['uncounted_share_border']:.2%}; {d['provenance']['seconds']} s -> {path}",
            flush=True,
        )


if __name__ == "__main__":
    main()
