"""Report the thesis's patch statistics of the prior tables per corpus (Section 5.2.2-5.2.3).

    python experiments/prior_stats.py            # statistics of the shipped tables -> out/prior_stats.{md,json}
    python experiments/prior_stats.py --fit      # re-learn ogm_ppl/fitted/prior_*.npz (+ .json provenance) first
    python experiments/prior_stats.py --fit --quick   # tiny corpora, for a smoke test (writes under out/ only)

``--fit`` is ``ogm_ppl.learn.fit_tables`` of each corpus (``ogm-ppl fit-prior tables --corpus C --out DIR``;
the corpora's training plans: ``ogm_ppl.learn``). The tables keep every window with the 8 flips/rotations;
5 x 5 codes seen fewer than ``MIN_COUNT_5X5`` times are dropped (their mass is kept in ``truncated_mass``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.io import atomic_write_text  # noqa: E402
from ogm_ppl.learn import CORPORA, fit_tables  # noqa: E402
from ogm_ppl.learn.tables import MIN_COUNT_5X5  # noqa: E402
from ogm_ppl.priors.tables import FITTED_DIR, load_tables  # noqa: E402

THESIS = {
    "lambda": 0.234,
    "free3x3": 0.743,
    "occupied3x3": 0.211,
    "distinct3x3": 124,
    "distinct3x3_999": 50,
    "free5x5": 0.7198,
    "occupied5x5": 0.1892,
    "distinct5x5": 2329,
    "distinct5x5_999": 436,
    "distinct_border16": 865,
    "max_inner_per_border16": 13,
    "distinct_border8": 84,
    "mixed_border8": 40,
}
ROWS = [
    ("lambda", "cell prior lambda", "{:.3f}"),
    ("free3x3", "all-free 3x3 windows", "{:.1%}"),
    ("occupied3x3", "all-occupied 3x3 windows", "{:.1%}"),
    ("distinct3x3", "distinct 3x3 configurations (of 512)", "{}"),
    ("distinct3x3_999", "3x3 configurations carrying 99.9%", "{}"),
    ("free5x5", "all-free 5x5 windows", "{:.1%}"),
    ("occupied5x5", "all-occupied 5x5 windows", "{:.1%}"),
    ("distinct5x5", "distinct 5x5 configurations (stored)", "{}"),
    ("distinct5x5_999", "5x5 configurations carrying 99.9%", "{}"),
    ("distinct_border16", "distinct 16-cell borders", "{}"),
    ("max_inner_per_border16", "max 3x3 configurations under one border", "{}"),
    ("single_inner_border16_share", "borders with a single 3x3 configuration", "{:.1%}"),
    ("distinct_border8", "distinct 8-cell borders (of 256)", "{}"),
    ("mixed_border8", "8-cell borders seen with both centre values", "{}"),
    ("psi4", "psi = P(unequal)/P(equal), 4-neighbours", "{:.4f}"),
    ("windows3x3", "3x3 windows counted (x8 symmetries)", "{:.3g}"),
    ("truncated_mass", f"5x5 windows dropped by the count >= {MIN_COUNT_5X5} cut", "{}"),
]


#: ``--quick``: the first plans of each corpus only (a smoke test)
QUICK_LIMITS = {"generated": 4, "houseexpo": 3, "ipa": 3, "dungeon": 5}


def fit(out_dir: Path, quick: bool) -> dict:
    """``ogm_ppl.learn.fit_tables`` of every corpus into ``out_dir``; the seconds of each."""
    timings = {}
    for name in CORPORA:
        r = fit_tables(name, out_dir, limit=QUICK_LIMITS[name] if quick else None)
        timings[name] = r.seconds
        path = r.files[0]
        print(f"{name}: {path} {path.stat().st_size / 1e6:.2f} MB, {timings[name]} s", flush=True)
    return timings


def report(table_dir: Path, out: Path, timings: dict | None) -> None:
    stats = {}
    for name in CORPORA:
        p = table_dir / f"prior_{name}.npz"
        if p.is_file():
            t = load_tables(p)
            lam4, psi4 = t.mrf_fit(4)
            summary = {**t.summary(), "mrf_lambda": lam4, "mrf_psi": psi4}  # pseudo-likelihood, 4-neighbours
            stats[name] = {"statistics": summary, "provenance": t.provenance}
    names = list(stats)
    lines = [
        "# Patch statistics per corpus (thesis Section 5.2.2-5.2.3)",
        "",
        "Every window of every map, with the 8 flips/rotations (the thesis sampled 10^10 5x5 patches from ten "
        "500x500 maps). 5x5 counts are after dropping codes seen once (`truncated_mass`).",
        "",
        "| statistic | thesis | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for key, label, fmt in ROWS:
        th = THESIS.get(key)
        cells = [fmt.format(stats[n]["statistics"][key]) for n in names]
        lines.append(f"| {label} | {'' if th is None else fmt.format(th)} | " + " | ".join(cells) + " |")
    lines.append(
        "| MRF (4-neighbour) lambda, psi by pseudo-likelihood |  | "
        + " | ".join(
            f"{stats[n]['statistics']['mrf_lambda']:.3f}, {stats[n]['statistics']['mrf_psi']:.4f}" for n in names
        )
        + " |"
    )
    lines += ["", "Provenance:", ""]
    for n in names:
        p = stats[n]["provenance"]
        lines.append(f"- **{n}**: {json.dumps({k: v for k, v in p.items() if k != 'plan_names_sha256'})}")
    if timings:
        lines += ["", "Learning time (reading + counting, this machine): " + json.dumps(timings)]
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out.with_suffix(".md"), "\n".join(lines) + "\n")
    atomic_write_text(
        out.with_suffix(".json"),
        json.dumps({"thesis": THESIS, "corpora": stats, "timings": timings}, indent=1) + "\n",
    )
    print("\n".join(lines))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", action="store_true", help="re-learn the tables first")
    ap.add_argument("--quick", action="store_true", help="tiny corpora; tables go to out/prior_tables_quick/")
    ap.add_argument("--out", default=str(ROOT / "out" / "prior_stats"), help="output path stem")
    args = ap.parse_args(argv)
    table_dir = ROOT / "out" / "prior_tables_quick" if args.quick else FITTED_DIR
    timings = fit(table_dir, args.quick) if args.fit else None
    report(table_dir, Path(args.out), timings)


if __name__ == "__main__":
    main()
