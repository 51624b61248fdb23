r"""What a map predicts where no ray reached: the mean marginal of the never-observed cells of each map an
experiment wrote, per algorithm and dataset.

A cell is never observed when traditional OGM leaves it at its prior, ``q_k = 0.5`` (the baseline algorithm of
the spec, ``ogm`` with ``prior = 0.5``). For an algorithm's marginals ``q'`` on dataset ``D`` the study reports

.. math::

    \bar q'_D = \frac{1}{|N_D|} \sum_{k \in N_D} q'_k, \qquad N_D = \{k : q^{\mathrm{OGM}}_k = 0.5\}

(NaN when ``N_D`` is empty). What a prior predicts there, far from every ray, decides the "all cells" scores of
Table 6.4 on maps with a large unobserved exterior.

:func:`unobserved_means` computes it; :func:`unobserved_text` is its printed summary.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ogm_ppl.studies.errors import StudyInputError

__all__ = ["marginals", "unobserved_means", "unobserved_text"]


def marginals(path: str | Path) -> np.ndarray:
    """The ``marginals`` array (float64, flattened) of a map file an experiment wrote; a file without it is a
    :class:`~ogm_ppl.studies.errors.StudyInputError` naming the path."""
    with np.load(path, allow_pickle=False) as z:
        if "marginals" not in z:
            raise StudyInputError(f"{path}: no 'marginals' array (keys {sorted(z.keys())})")
        return np.asarray(z["marginals"], dtype=np.float64).reshape(-1)


def unobserved_means(out_dir: str | Path, baseline: str = "ogm") -> dict[str, dict[str, float]]:
    """``{algorithm: {dataset: mean marginal over the cells the baseline leaves at 0.5}}`` of the experiment
    folder ``out_dir`` (module docstring).

    Raises:
        FileNotFoundError: no maps folder, or a dataset without the baseline's map.
        StudyInputError: a map without marginals, or of another size than the baseline's.
    """
    maps = Path(out_dir) / "maps"
    if not maps.is_dir():
        raise FileNotFoundError(f"{maps}: no maps folder (run the experiment with [output] maps = true)")
    res: dict[str, dict[str, float]] = {}
    for d in sorted(p for p in maps.iterdir() if p.is_dir()):
        base = d / f"{baseline}.npz"
        if not base.exists():
            raise FileNotFoundError(f"{base}: the baseline map is missing")
        never = marginals(base) == 0.5
        for f in sorted(d.glob("*.npz")):
            q = marginals(f)
            if q.shape != never.shape:
                raise StudyInputError(f"{f}: {q.size} cells, the baseline has {never.size}")
            res.setdefault(f.stem, {})[d.name] = float(q[never].mean()) if never.any() else float("nan")
    return res


def unobserved_text(res: dict[str, dict[str, float]]) -> str:
    """An :func:`unobserved_means` result as one line per algorithm: the mean over datasets and the range."""
    lines = []
    for alg, per in res.items():
        v = np.array(list(per.values()))
        lines.append(
            f"{alg:>24}: mean {np.nanmean(v):.3f}, range {np.nanmin(v):.2f}-{np.nanmax(v):.2f} over {len(v)} datasets"
        )
    return "\n".join(lines)
