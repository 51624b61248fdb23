r"""The thesis's patch statistics of the prior tables, per corpus (Sections 5.2.2-5.2.3).

Each corpus's tables (:class:`~ogm_ppl.priors.tables.PriorTables`, counted by :func:`ogm_ppl.learn.fit_tables`
over every window of every training plan with its 8 flips and rotations; 5 x 5 codes seen fewer than
``MIN_COUNT_5X5`` times dropped, their mass kept in ``truncated_mass``) give the statistics of
:meth:`~ogm_ppl.priors.tables.PriorTables.summary`: the cell prior ``lambda``, the shares of all-free and
all-occupied 3 x 3 and 5 x 5 windows, how many configurations occur and how many carry 99.9 % of the windows,
the 16-cell and 8-cell borders, and ``psi = P(unequal) / P(equal)`` of 4-neighbours. Beside them the
4-neighbour MRF of Section 5.2.1 fitted by pseudo-likelihood
(:meth:`~ogm_ppl.priors.tables.PriorTables.mrf_fit`: ``lambda`` and ``psi`` of
``l(m_k | nbrs) = l(lambda) + (n_0 - n_1) log psi``), and the thesis's numbers (:data:`THESIS`).

:func:`prior_stats` reads the tables of a folder and writes ``<name>.md`` and ``<name>.json`` into a folder
given; :func:`fit_corpus_tables` counts the tables of every corpus first.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["QUICK_LIMITS", "ROWS", "THESIS", "fit_corpus_tables", "prior_stats", "prior_stats_markdown"]

#: the thesis's statistics (Sections 5.2.2-5.2.3)
THESIS: dict[str, float] = {
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
#: ``--quick``: the first plans of each corpus only (a smoke test)
QUICK_LIMITS: dict[str, int] = {"generated": 4, "houseexpo": 3, "ipa": 3, "dungeon": 5}


def _rows() -> list[tuple[str, str, str]]:
    from ogm_ppl.learn.tables import MIN_COUNT_5X5

    return [
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


#: the table's rows: (statistic, label, format)
ROWS: list[tuple[str, str, str]] = _rows()


#: the corpora whose count tables the library ships (``ogm_ppl/fitted/prior_<corpus>.npz``)
SHIPPED_CORPORA = ("generated", "houseexpo", "ipa", "dungeon")


def fit_corpus_tables(
    out_dir: str | Path, limits: Mapping[str, int] | None = None, *, progress: bool = True
) -> dict[str, Any]:
    """:func:`ogm_ppl.learn.fit_tables` of each corpus whose tables the library ships (generated, houseexpo, ipa,
    dungeon) into ``out_dir`` (``limits``: the first plans of each corpus only, e.g. :data:`QUICK_LIMITS`):
    ``{corpus: FitResult}`` (:class:`~ogm_ppl.learn.FitResult`)."""
    from ogm_ppl.learn import fit_tables

    return {
        name: fit_tables(name, out_dir, limit=None if limits is None else limits[name], progress=progress)
        for name in SHIPPED_CORPORA
    }


def prior_stats(
    table_dir: str | Path,
    out_dir: str | Path | None = None,
    *,
    name: str = "prior_stats",
    timings: Mapping[str, float] | None = None,
) -> dict:
    """The statistics of the tables ``prior_<corpus>.npz`` in ``table_dir`` (each corpus whose file is there):
    ``{"thesis": THESIS, "corpora": {corpus: {"statistics", "provenance"}}, "timings": timings}``. With
    ``out_dir``, also writes ``<name>.md`` (:func:`prior_stats_markdown`) and ``<name>.json`` (the dict) there.
    ``timings``: seconds of each corpus's counting, reported as given."""
    from ogm_ppl.learn import CORPORA
    from ogm_ppl.priors.tables import load_tables

    stats = {}
    for corpus in CORPORA:
        p = Path(table_dir) / f"prior_{corpus}.npz"
        if p.is_file():
            t = load_tables(p)
            lam4, psi4 = t.mrf_fit(4)
            summary = {**t.summary(), "mrf_lambda": lam4, "mrf_psi": psi4}  # pseudo-likelihood, 4-neighbours
            stats[corpus] = {"statistics": summary, "provenance": t.provenance}
    doc = {"thesis": THESIS, "corpora": stats, "timings": None if timings is None else dict(timings)}
    if out_dir is not None:
        from ogm_ppl.io import atomic_write_text

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / f"{name}.md", prior_stats_markdown(doc) + "\n")
        atomic_write_text(out / f"{name}.json", json.dumps(doc, indent=1) + "\n")
    return doc


def prior_stats_markdown(doc: dict) -> str:
    """A :func:`prior_stats` result as Markdown: a row per statistic, a column for the thesis and per corpus,
    then each corpus's provenance and the counting times."""
    stats, timings = doc["corpora"], doc["timings"]
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
    return "\n".join(lines)
