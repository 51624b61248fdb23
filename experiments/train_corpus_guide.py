"""Train a corpus guide: ``ogm-ppl train-guide`` (:func:`ogm_ppl.learn.train_corpus_guide`) with the package's
fitted guide as the default output.

The options are the command's (``--help``; the loss, the windows, the validation and the checkpoints are in
:mod:`ogm_ppl.learn.guide_training`); without ``--out`` the guide goes to ``ogm_ppl/fitted/guide_<corpus>.npz``
(``guide_<c1>+<c2>.npz`` for several corpora), as ``ogm-ppl train-guide --ship`` writes it.

    python experiments/train_corpus_guide.py --corpus houseexpo        # 7-15 min on 2 cores
    python experiments/train_corpus_guide.py --corpus ipa --steps 20 --examples 16 --out /tmp/g.npz   # smoke
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.cli.train_guide import add_arguments, settings_from_args, shipped_path
from ogm_ppl.learn import train_corpus_guide
from ogm_ppl.provenance import command_line


def main(argv=None, stop_after: int | None = None) -> dict | None:
    """The command line; returns the guide's record, or ``None`` when stopped (``stop_after`` steps, Ctrl-C)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(ap, out_required=False, curve=False)  # the data curve: ogm-ppl train-guide --curve-sizes
    args = ap.parse_args(argv)
    try:
        settings = settings_from_args(args)
        out = Path(args.out) if args.out else shipped_path(settings)
        r = train_corpus_guide(
            settings, out, progress=not args.quiet, stop_after=stop_after, fresh=args.fresh, command=command_line()
        )
    except ValueError as e:
        raise SystemExit(f"train_corpus_guide.py: error: {e}") from None
    return r.record


if __name__ == "__main__":
    main()
