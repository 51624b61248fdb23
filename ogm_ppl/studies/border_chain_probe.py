r"""Why the border prior trails on simulated office maps (README, Table 6.4): the prior mass and likelihood of a
3 x 3 patch Gibbs chain with ``border:generated`` from the thresholded OGM start, sweep by sweep, beside the true
map's; and the true map's tiles whose (border, inner) pair the tables never counted.

The border prior of Section 5.2.3 is the product of tile conditionals
``p(m) = prod_t p(inner_t | border_t)`` over the 3 x 3 tiles ``t`` of the map with their 16-cell borders (cells
off the grid read as occupied). A tile whose pair was never counted gets only its back-off mass, so a true map
with many such tiles can be far less likely under the prior than the chain's maps: the study reports, for the
dataset's truth ``m*`` and after each sweep of :class:`~ogm_ppl.inference.PatchGibbs`, ``log p(m)`` and
``log p(z | m)`` (:class:`~ogm_ppl.sensors.GaussianRange`, ``sigma`` cells) and the cells unlike the truth.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ogm_ppl.studies._inputs import check_int, check_positive, float64

__all__ = ["border_chain_probe", "border_chain_probe_lines", "unseen_tiles"]


def unseen_tiles(truth: np.ndarray, corpus: str = "generated") -> tuple[int, int]:
    """``(tiles, tiles whose (16-cell border, 3 x 3 inner) pair is not in the corpus's border table)`` of the
    3 x 3 tiling of ``truth``; cells off the grid read as occupied, as the prior's ``outside = 1``."""
    from ogm_ppl.priors.tables import tables_by_name

    b, i, _ = tables_by_name(corpus).border_table().triples()
    seen = set(zip(b.tolist(), i.tolist()))
    P = np.pad(truth.astype(np.int64), 2, constant_values=1)
    ring = [(r, c) for r in range(5) for c in range(5) if not (1 <= r <= 3 and 1 <= c <= 3)]
    inner = [(r, c) for r in range(1, 4) for c in range(1, 4)]
    n = unseen = 0
    for r0 in range(0, truth.shape[0] - 2, 3):
        for c0 in range(0, truth.shape[1] - 2, 3):
            W = P[r0 : r0 + 5, c0 : c0 + 5]
            key = (
                sum(int(W[r, c]) << j for j, (r, c) in enumerate(ring)),
                sum(int(W[r, c]) << k for k, (r, c) in enumerate(inner)),
            )
            n += 1
            unseen += key not in seen
    return n, unseen


def border_chain_probe(folder: str | Path, dataset: str, sweeps: int = 12, sigma: float = 3.0) -> dict:
    """The probe of the module docstring on ``dataset`` of the experiment folder ``folder`` (its
    ``datasets/<dataset>.npz`` and ``.eval.npz``): ``{"tiles", "unseen_tiles", "truth": {"log_prior",
    "log_likelihood"}, "sweeps": [{"sweep", "log_prior", "log_likelihood", "cells_unlike_truth", "seconds"}]}``.
    The chain is seeded 0 (torch's generator is seeded here).

    Raises:
        StudyOptionError: ``sweeps`` below 1 or ``sigma`` not positive.
    """
    import torch

    from ogm_ppl import GaussianRange, OccupancyModel, raycast
    from ogm_ppl.datasets.dataset_file import load_dataset
    from ogm_ppl.inference import PatchGibbs
    from ogm_ppl.priors import prior_by_name
    from ogm_ppl.studies.errors import StudyInputError

    check_int(sweeps, "sweeps", 1)
    check_positive(sigma, "sigma")
    folder = Path(folder)
    with float64():
        d = load_dataset(folder / "datasets" / f"{dataset}.npz")
        if d.grid is None:
            raise StudyInputError(f"{folder / 'datasets' / dataset}.npz: the dataset has no grid")
        truth = np.load(folder / "datasets" / f"{dataset}.eval.npz")["truth"]
        prior = prior_by_name("border:generated", d.grid.shape)
        model = OccupancyModel(d.grid, raycast(d.grid, d.scans), GaussianRange(sigma), prior)
        n, unseen = unseen_tiles(truth)
        t = torch.from_numpy(truth.ravel().astype(np.float64))
        t[model.known_free] = 0.0
        doc: dict = {
            "tiles": n,
            "unseen_tiles": unseen,
            "truth": {
                "log_prior": float(prior.log_prob(t[None])[0]),
                "log_likelihood": float(model.log_likelihood(t[None])[0]),
            },
            "sweeps": [],
        }
        torch.manual_seed(0)
        k = PatchGibbs(model, patch=(3, 3))
        k.setup(0)
        p = k.initial_params
        for s in range(sweeps):
            t0 = time.perf_counter()
            p = k.sample(p)
            m = torch.from_numpy(k.state.astype(np.float64))[None]
            doc["sweeps"].append(
                {
                    "sweep": s + 1,
                    "log_prior": float(prior.log_prob(m)[0]),
                    "log_likelihood": float(model.log_likelihood(m)[0]),
                    "cells_unlike_truth": int((k.state != truth.ravel()).sum()),
                    "seconds": time.perf_counter() - t0,
                }
            )
    return doc


def border_chain_probe_lines(doc: dict) -> list[str]:
    """A :func:`border_chain_probe` result as lines: the truth's, then one per sweep."""
    tr = doc["truth"]
    lines = [
        f"true map: log prior {tr['log_prior']:.1f}, log likelihood {tr['log_likelihood']:.1f}; "
        f"{doc['unseen_tiles']} of {doc['tiles']} tiles never counted"
    ]
    for s in doc["sweeps"]:
        lines.append(
            f"sweep {s['sweep']}: log prior {s['log_prior']:.1f}, log likelihood {s['log_likelihood']:.1f}, "
            f"cells unlike the truth {s['cells_unlike_truth']}, {s['seconds']:.1f} s"
        )
    return lines
