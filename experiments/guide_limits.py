r"""What limits a corpus guide's prediction of unseen cells: its calibration, or what it can tell apart?

A thin front of :func:`ogm_ppl.studies.guide_limits.guide_limits` (what it reports is described there): per
guide, its NLL on the unseen cells of a test corpus's held-out maps, the oracle recalibrations' lower bounds
and the guides' ensemble, with per-map rows.

    python experiments/guide_limits.py --test ipa --guides ipa houseexpo+ipa@sym   # ~2 min on 2 cores
    python experiments/guide_limits.py --test houseexpo --guides houseexpo houseexpo+ipa@sym --guide-dir DIR
    python experiments/guide_limits.py --test ipa --guides ipa ipa=out/capacity/c12 ipa=out/capacity/c48

Writes ``--out`` (default ``out/guide_limits``)/``guide_limits.json`` (settings, provenance, per-map rows, summary).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.calibration import TEST_CORPORA, USER_ERRORS, SettingsError
from ogm_ppl.studies.guide_limits import guide_limits


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--test", required=True, choices=TEST_CORPORA, help="the test corpus")
    ap.add_argument(
        "--guides",
        nargs="+",
        required=True,
        help="guide names, as ogm-ppl calibrate --guides takes; NAME=DIR reads that guide from DIR (e.g. one trained "
        "with other --channels), so several trainings of one guide can be compared",
    )
    ap.add_argument("--guide-dir", type=Path, default=None, help="read the guides as DIR/guide_CORPUS.npz")
    ap.add_argument("--plans", type=int, default=10, help="held-out maps of the test corpus (default 10)")
    ap.add_argument("--out", type=Path, default=Path("out/guide_limits"))
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    log = lambda line: print(line, flush=True)
    try:
        doc = guide_limits(args.test, args.guides, guide_dir=args.guide_dir, plans=args.plans, out=args.out, log=log)
    except SettingsError as e:
        raise SystemExit(f"guide_limits.py: {e.flag} {e.reason}") from None
    except USER_ERRORS as e:
        raise SystemExit(f"guide_limits.py: {e}") from None
    for g, s in doc["summary"].items():
        print(f"{g}: " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in s.items()))
    print(f"wrote {args.out / 'guide_limits.json'}")
    return doc


if __name__ == "__main__":
    main()
