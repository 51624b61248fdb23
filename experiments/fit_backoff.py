"""Fit the Witten-Bell hyper-parameters of the backed-off table priors on held-out training plans.

    python experiments/fit_backoff.py                 # every corpus -> ogm_ppl/fitted/backoff_<corpus>.json
    python experiments/fit_backoff.py --corpus ipa    # one corpus
    python experiments/fit_backoff.py --quick         # tiny corpora, written under out/backoff/ only

Each corpus is ``ogm_ppl.learn.fit_backoff`` (``ogm-ppl fit-prior backoff --corpus C --out DIR``): the
corpus's training plans split in their natural order, every fifth plan validation, each level's ``kappa``
maximising the validation log-likelihood (the module docstring of ``ogm_ppl.learn.backoff``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.learn import CORPORA, fit_backoff  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", choices=CORPORA, action="append")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    out_dir = ROOT / "out" / "backoff" if args.quick else ROOT / "ogm_ppl" / "fitted"
    for corpus in args.corpus or CORPORA:
        r = fit_backoff(corpus, out_dir, limit=10 if args.quick else None)
        v = r.summary["validation"]
        print(
            f"{corpus}: kappa patch3 {r.summary['kappa_patch3']:.4g} border {r.summary['kappa_border']:.4g} "
            f"border1 {r.summary['kappa_border1']:.4g}; val ll/pair border {v['border_mean_log_lik']:.4f} "
            f"(3x3 alone {v['border_mean_log_lik_patch3_only']:.4f}), uncounted border pairs "
            f"{v['uncounted_share_border']:.2%}; {r.seconds} s -> {r.files[0]}",
            flush=True,
        )


if __name__ == "__main__":
    main()
