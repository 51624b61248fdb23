"""``ogm-ppl corpus-stats NAME``: statistics of a floor-plan corpus as rasterised here, and a figure of a few of its
plans beside their sources (:mod:`ogm_ppl.datasets.floorplans.stats`).

Writes under ``--out`` (default ``out/corpus_stats``) ``corpus_stats_NAME.json`` (the statistics with their
provenance) and ``corpus_NAME.png``; prints a summary line. ``--split`` and ``--limit`` rasterise fewer plans
(the split counts always cover the whole corpus).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from ogm_ppl.cli._common import _jsonable, _nonneg_int, _pos_float, _pos_int, _prepare_out_dir


def add_parser(sub) -> None:
    """The ``corpus-stats`` subcommand's options."""
    from ogm_ppl.datasets.floorplans import CORPORA, SPLITS

    p = sub.add_parser(
        "corpus-stats",
        help="statistics of a floor-plan corpus (JSON) and a figure of plans beside their sources",
        description="Plans, buildings and splits of a floor-plan corpus, and of the plans rasterised (with the "
        "exterior unknown): cells, known share, occupied share, wall thickness in cells, sizes; a figure of a "
        "few plans beside their sources.",
    )
    p.add_argument("corpus", choices=CORPORA, metavar="NAME", help=f"the corpus: {', '.join(CORPORA)}")
    p.add_argument("--split", choices=SPLITS, default=None, help="rasterise this split's plans only (default all)")
    p.add_argument("--limit", type=_pos_int, default=None, help="rasterise the first N plans only (default all)")
    p.add_argument("--resolution", type=_pos_float, default=None, help="metres per cell (default the corpus's, 0.05)")
    p.add_argument(
        "--figure-plans", type=_nonneg_int, default=3, help="plans in the figure, spread over those read (3; 0: none)"
    )
    p.add_argument("--out", type=Path, default=Path("out/corpus_stats"), help="output folder (out/corpus_stats)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def run(args) -> int:
    """``ogm-ppl corpus-stats``: write the statistics and the figure; print a summary."""
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.datasets.floorplans.stats import corpus_stats, plan_figure
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.provenance import command_line, provenance

    _prepare_out_dir(args.out)
    t0 = time.perf_counter()
    res = "default" if args.resolution is None else args.resolution
    say = None if args.quiet else (lambda line: print(line, flush=True))
    stats = corpus_stats(args.corpus, split=args.split, limit=args.limit, resolution=res, progress=say)
    doc = {"provenance": provenance(command_line()), **stats}
    path = atomic_write_text(args.out / f"corpus_stats_{args.corpus}.json", json.dumps(_jsonable(doc), indent=1))
    written = [path]
    if args.figure_plans:
        names = fp.list_plans(args.corpus)
        if args.split is not None:
            names = [n for n in names if fp.split_of(args.corpus, n) == args.split]
        names = names[: args.limit]
        k = min(args.figure_plans, len(names))
        picks = [names[round(i * (len(names) - 1) / max(k - 1, 1))] for i in range(k)]
        written.append(plan_figure(args.corpus, picks, args.out / f"corpus_{args.corpus}.png", res))
    wall = stats["wall_thickness_cells"]["percentiles"] or {}
    print(
        f"{args.corpus}: {stats['plans']:,} plans of {stats['buildings']:,} buildings rasterised "
        f"({stats['plans_in_corpus']:,} in the corpus), {stats['cells']:,} cells, known share "
        f"{stats['known_share']:.3f}, occupied share {stats['occupied_share']:.3f}, walls "
        f"{wall.get('p50', float('nan')):g} cells (median); {time.perf_counter() - t0:.1f} s; wrote "
        + ", ".join(str(w) for w in written)
    )
    return 0
