r"""Count tables of a corpus or of plans of one's own: the learned priors' patch and border statistics.

The tables (thesis Sections 5.2.2-5.2.3; :class:`~ogm_ppl.priors.tables.PriorTables`) count every window of
every training map, with the map's 8 flips and rotations: the cell counts (``lambda``, the occupied share),
the 3 x 3 and 5 x 5 window configurations, neighbour pairs, ``1 x 8`` lines and runs. A table prior is the
relative frequency of a configuration among the windows,

.. math::

    \hat p(c) = \frac{n(c)}{\sum_{c'} n(c')},

and a border prior the frequency of an inner 3 x 3 configuration ``i`` among the 5 x 5 windows whose 16
border cells read ``b``, ``p(i | b) = n(b, i) / sum_i' n(b, i')``. 5 x 5 codes seen fewer than
``min_count_5x5`` times are dropped (their total is kept as ``truncated_mass``), which keeps a corpus's file
well under 1 MB.

:func:`fit_tables` writes ``prior_<name>.npz`` (:func:`~ogm_ppl.priors.tables.save_tables`) and
``prior_<name>.json`` (its SHA-256, size, provenance and :meth:`~ogm_ppl.priors.tables.PriorTables.summary`)
into the folder named; ``load_tables(path)`` reads them back, and
``prior_by_name("border", shape, tables=load_tables(path))`` builds any table prior from them. The shipped
``ogm_ppl/fitted/prior_<corpus>.npz`` are this fit of each corpus
(``ogm-ppl fit-prior tables --corpus C --out ogm_ppl/fitted``).

>>> import tempfile
>>> r = fit_tables("generated", tempfile.mkdtemp(), limit=1, progress=False)  # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import json
import os
import time

from ogm_ppl.learn._fit_common import (
    FitResult,
    PlanPaths,
    TrainingPlans,
    check_int,
    check_label,
    check_out_dir,
    command,
    load_training_plans,
    run_provenance,
)

__all__ = ["MIN_COUNT_5X5", "fit_tables"]

#: the shipped tables drop 5 x 5 codes seen fewer times than this
MIN_COUNT_5X5 = 2


def fit_tables(
    source: str | PlanPaths | TrainingPlans,
    out_dir: str | os.PathLike,
    *,
    limit: int | None = None,
    pixel_size: float | None = None,
    resolution: float = 0.05,
    name: str | None = None,
    min_count_5x5: int = MIN_COUNT_5X5,
    progress: bool = True,
) -> FitResult:
    """Count the tables of ``source``'s training plans (module docstring) and write ``prior_<name>.npz`` and
    ``prior_<name>.json`` into ``out_dir`` (nothing else, atomically).

    Args:
        source: a corpus name (``generated``, ``houseexpo``, ``ipa``, ``dungeon``), plan files or folders of
            them (:func:`~ogm_ppl.datasets.plan_files.plan_files`), or :class:`TrainingPlans`.
        out_dir: the folder the two files go to (created if missing).
        limit: the first ``limit`` training plans (default: the corpus's 100 generated maps, 300 DungeonMaps
            plans, every plan else).
        pixel_size, resolution: how plan files are read (metres per image pixel, metres per cell).
        name: the files' name part (default the corpus, or ``plans`` for plan files).
        min_count_5x5: 5 x 5 codes seen fewer times are dropped (1 keeps them all).
        progress: a progress bar over the maps.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    plans, out, label, min5 = _check(source, out_dir, limit, pixel_size, resolution, name, min_count_5x5)
    from ogm_ppl.priors.learn import count_tables
    from ogm_ppl.priors.tables import save_tables

    t0 = time.perf_counter()
    options = [] if min5 == MIN_COUNT_5X5 else ["--min-count-5x5", str(min5)]
    options += [] if name is None else ["--name", label]
    prov = run_provenance(command("tables", plans, out, options), plans)
    tables = count_tables(plans.maps(), symmetries=True, min_count_5x5=min5, progress=progress, provenance=prov)
    seconds = round(time.perf_counter() - t0, 2)
    path = save_tables(tables, out / f"prior_{label}.npz")
    summary = tables.summary()
    info = {
        "file": path.name,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "bytes": path.stat().st_size,
        "learning_seconds_incl_reading": seconds,
        "provenance": tables.provenance,
        "statistics": summary,
    }
    from ogm_ppl.io import atomic_write_text

    side = atomic_write_text(out / f"prior_{label}.json", json.dumps(info, indent=1) + "\n")
    return FitResult("tables", (path, side), tables.provenance, summary, seconds)


def _check(source, out_dir, limit, pixel_size, resolution, name, min_count_5x5):
    """Every option of :func:`fit_tables`, checked before anything is read."""
    out = check_out_dir(out_dir)
    min5 = check_int(min_count_5x5, "min_count_5x5", 1)
    label = check_label(name) if name is not None else None
    plans = load_training_plans(source, limit=limit, pixel_size=pixel_size, resolution=resolution)
    return plans, out, label or ("plans" if plans.files else plans.corpus), min5
