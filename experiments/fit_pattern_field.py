"""Fit the shipped pattern fields (``field:CORPUS`` one scale, ``field2:CORPUS`` two scales) per corpus.

    python experiments/fit_pattern_field.py                    # all corpora -> ogm_ppl/fitted/field_*.npz + .json
    python experiments/fit_pattern_field.py --corpus dungeon   # one corpus
    python experiments/fit_pattern_field.py --quick            # tiny corpora, writes under out/field_quick only
    python experiments/fit_pattern_field.py --check-only       # rerun the sampler check of the shipped fits

Each corpus is ``ogm_ppl.learn.fit_field`` (``ogm-ppl fit-prior field --corpus C --out DIR``; the recipe, the
training maps and the validation split are in the module docstring of ``ogm_ppl.learn.field``). ``--quick``:
10 maps per corpus and every third power ``beta``. ``--check-only`` is ``ogm_ppl.learn.field.recheck_field``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.learn import CORPORA, FieldSettings, fit_field  # noqa: E402
from ogm_ppl.learn.field import recheck_field  # noqa: E402
from ogm_ppl.priors.pattern_field import FITTED_DIR  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", action="append", choices=CORPORA, help="fit only these (repeatable)")
    ap.add_argument("--quick", action="store_true", help="10 maps per corpus, 4 powers beta, out/field_quick")
    ap.add_argument("--out", default=None, help="output folder (default ogm_ppl/fitted, or out/field_quick)")
    ap.add_argument("--check-only", action="store_true", help="only rerun the sampler check of existing fits")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else (ROOT / "out" / "field_quick" if args.quick else FITTED_DIR)
    settings = FieldSettings(betas=FieldSettings().betas[::3]) if args.quick else FieldSettings()
    for corpus in args.corpus or CORPORA:
        if args.check_only:
            print(f"{corpus}:", flush=True)
            recheck_field(corpus, out)
        else:
            fit_field(corpus, out, settings=settings, limit=10 if args.quick else None)


if __name__ == "__main__":
    main()
