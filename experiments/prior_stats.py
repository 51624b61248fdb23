"""Report the thesis's patch statistics of the prior tables per corpus (Section 5.2.2-5.2.3).

    python experiments/prior_stats.py            # statistics of the shipped tables -> out/prior_stats.{md,json}
    python experiments/prior_stats.py --fit      # re-learn ogm_ppl/fitted/prior_*.npz (+ .json provenance) first
    python experiments/prior_stats.py --fit --quick   # tiny corpora, for a smoke test (writes under out/ only)

The command line of :func:`ogm_ppl.studies.prior_stats.prior_stats` (the statistics are in
:mod:`ogm_ppl.studies.prior_stats`). ``--fit`` is :func:`ogm_ppl.learn.fit_tables` of each corpus
(``ogm-ppl fit-prior tables --corpus C --out DIR``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.priors.tables import FITTED_DIR  # noqa: E402
from ogm_ppl.studies.prior_stats import QUICK_LIMITS, fit_corpus_tables, prior_stats, prior_stats_markdown  # noqa: E402


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", action="store_true", help="re-learn the tables first")
    ap.add_argument("--quick", action="store_true", help="tiny corpora; tables go to out/prior_tables_quick/")
    ap.add_argument("--out", default=str(ROOT / "out" / "prior_stats"), help="output path stem")
    args = ap.parse_args(argv)
    table_dir = ROOT / "out" / "prior_tables_quick" if args.quick else FITTED_DIR
    timings = None
    if args.fit:
        fits = fit_corpus_tables(table_dir, QUICK_LIMITS if args.quick else None)
        for name, r in fits.items():
            print(f"{name}: {r.files[0]} {r.files[0].stat().st_size / 1e6:.2f} MB, {r.seconds} s", flush=True)
        timings = {name: r.seconds for name, r in fits.items()}
    out = Path(args.out)
    doc = prior_stats(table_dir, out.parent, name=out.stem, timings=timings)
    print(prior_stats_markdown(doc))
    return doc


if __name__ == "__main__":
    main()
