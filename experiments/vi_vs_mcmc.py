"""One comparison harness: summed KL to the exact posterior against wall-clock time for
every method, on the 1D toy, on the 1000 wall datasets and on small 2D problems solved by brute force.

A thin front of :func:`ogm_ppl.studies.vi_vs_mcmc.run` (the methods, problems and scores are described in
:mod:`ogm_ppl.studies.vi_vs_mcmc`). Times are wall clock on this machine (one thread), warm caches, excluding the
KL evaluation. Writes ``out/vi_vs_mcmc/results.json``, ``table.md`` and ``kl_vs_time.png``.

    python experiments/vi_vs_mcmc.py            # about 7 minutes on 2 shared cores
    python experiments/vi_vs_mcmc.py --quick    # small settings, under a minute
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from ogm_ppl.studies.vi_vs_mcmc import QUICK, ComparisonSettingsError, Settings, replot, run, write_results  # noqa: E402


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small settings (under a minute)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--problems", default=None, help="comma-separated subset of toy,walls,2d:independent,2d:mrf8,2d:patch3"
    )
    ap.add_argument("--out", default=str(ROOT / "out" / "vi_vs_mcmc"))
    ap.add_argument("--replot", action="store_true", help="redraw table.md and the figure from results.json")
    args = ap.parse_args(argv)
    if args.replot:
        return replot(args.out)
    cfg = QUICK if args.quick else Settings()
    if args.problems:
        try:
            cfg = replace(cfg, problems=tuple(p.strip() for p in args.problems.split(",")))
        except ComparisonSettingsError as e:
            ap.error(f"--problems: {e.reason}")
    torch.set_num_threads(1)
    try:
        import numba

        numba.set_num_threads(1)
    except (ImportError, ValueError):
        pass
    res = run(cfg, args.seed, log=lambda s: print(s, file=sys.stderr, flush=True))
    res["quick"] = bool(args.quick)
    res["command"] = "python experiments/vi_vs_mcmc.py" + (" --quick" if args.quick else "")
    print(write_results(res, args.out))
    return res


if __name__ == "__main__":
    main()
