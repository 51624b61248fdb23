r"""Where a method's bits go on the unseen cells: NLL by distance to the nearest cell some ray reached.

A thin front of :func:`ogm_ppl.studies.unseen_by_distance.unseen_by_distance` (the protocol and the bins are
described there): one method, an amortised guide (``--guide``, a name ``ogm-ppl calibrate --guides`` takes) or a
prior sampled by the calibration protocol's three chains (``--prior``; ``--kernel``, ``--sweeps``, ``--burn`` as
``ogm-ppl calibrate`` takes them, ``--sweeps`` one run per value), binned on the held-out maps of each test corpus.

    python experiments/unseen_by_distance.py --guide houseexpo+ipa@sym --test houseexpo ipa   # about a minute
    python experiments/unseen_by_distance.py --prior border_bo@cal --kernel cycle --test dungeon --plans 2 \
        --sweeps 200 1000 3000
    python experiments/unseen_by_distance.py --plan-files out/log_plans --plan-set logs --plan-outside unknown

``--plan-files`` (and ``--plan-set``, ``--pixel-size``, ``--plan-outside``, as ``ogm-ppl calibrate`` takes them) bins
plans of other buildings too; a prior run on them must name its corpus (``KIND:CORPUS``).

Writes ``OUT/unseen_by_distance.json`` (settings, provenance, one row per corpus, bin and sweep count) and
prints a table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.calibration import KERNELS, USER_ERRORS, SettingsError
from ogm_ppl.cli.calibrate import add_plan_file_arguments
from ogm_ppl.studies.unseen_by_distance import TESTS, DistanceSettings, rows_table, unseen_by_distance


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    what = ap.add_mutually_exclusive_group()
    what.add_argument(
        "--guide", default=None, help="a guide name ogm-ppl calibrate --guides takes (default houseexpo+ipa@sym)"
    )
    what.add_argument("--prior", default=None, help="a prior name (KIND[:CORPUS][@MOD]), sampled by chains")
    ap.add_argument("--guide-dir", type=Path, default=None, help="read the guide as DIR/guide_C.npz")
    ap.add_argument("--kernel", default="cycle", choices=sorted(KERNELS), help="a prior's sampler")
    ap.add_argument("--sweeps", type=int, nargs="+", default=[200], help="kept sweeps per chain (one run each)")
    ap.add_argument("--burn", type=int, default=None, help="warm-up sweeps per chain (default: a quarter of --sweeps)")
    ap.add_argument(
        "--test", nargs="+", default=None, choices=TESTS, help="test corpora (default: all, or none with --plan-files)"
    )
    add_plan_file_arguments(ap)
    ap.add_argument(
        "--plans", type=int, default=None, help="held-out maps per test corpus (default 10; every plan of --plan-files)"
    )
    ap.add_argument("--out", type=Path, default=Path("out/unseen_by_distance"))
    args = ap.parse_args(argv)
    opts = {k: getattr(args, k) for k in ("guide", "prior", "guide_dir", "kernel", "burn", "test", "plans")}
    files = {k: getattr(args, k) for k in ("plan_files", "plan_set", "pixel_size", "plan_outside")}
    try:
        settings = DistanceSettings(**opts, **files, sweeps=tuple(args.sweeps))
    except SettingsError as e:
        ap.error(f"{e.flag}: {e.reason}")
    try:
        doc = unseen_by_distance(settings, args.out, log=lambda line: print(line, flush=True))
    except USER_ERRORS as e:
        raise SystemExit(f"unseen_by_distance.py: {e}") from None
    method = (
        f"{args.prior} ({args.kernel}, 3 chains)" if args.prior is not None else f"guide:{doc['settings']['guide']}"
    )
    print(rows_table(doc["rows"], method))
    print(f"wrote {args.out / 'unseen_by_distance.json'} ({doc['seconds']:.0f} s)")
    return doc


if __name__ == "__main__":
    main()
