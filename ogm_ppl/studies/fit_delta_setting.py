r"""Update terms Delta fitted for one sensor setting (thesis Section 2.5 at noise ``sigma`` and range ``F`` in
cells) against the shipped ones (fitted at ``sigma = 3``, ``F = 75``, wall 60), on held-out data of that
setting.

:func:`ogm_ppl.learn.fit_delta_setting` fits each term on ``num`` wall datasets of the setting (the wall at
``round(0.8 F)`` unless given). Each fitted term and the shipped term of the same name are scored on ``heldout``
fresh datasets of the setting (seed ``seed + 1``) by the training loss, the mean over datasets of the summed cell
cross-entropy against the exact posterior marginals ``p``,

.. math::

    \mathrm{CE}(q) = \frac{1}{D} \sum_{d=1}^{D} \sum_k -p_{dk} \log q_{dk} - (1 - p_{dk}) \log(1 - q_{dk})

(nats; :func:`~ogm_ppl.inference.variational.delta_fit.cross_entropy_loss`). ``compare_full`` also times the fit
without the near-wall reduction (:func:`~ogm_ppl.inference.variational.setting_fit.fit_on_data`), whose loss must
agree.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

__all__ = ["delta_setting_heldout", "delta_setting_lines"]


def delta_setting_heldout(
    sigma: float,
    F: int,
    *,
    wall: int | None = None,
    num: int = 1000,
    heldout: int = 500,
    seed: int = 0,
    names: Sequence[str] = ("p21", "moravec_opt"),
    out_dir: str | Path | None = None,
    compare_full: bool = False,
) -> dict:
    """Fit ``names`` for the setting (module docstring; ``out_dir``: write the fitted terms there, or read those of
    the same setting already there) and score them and the shipped terms on held-out data.

    Returns ``{"sigma", "F", "wall", "num", "heldout", "seconds": the fit in all, "terms": {name: {"data_s",
    "fit_s", "train_ce", "heldout_ce_fit", "heldout_ce_shipped"}}, "full": [{"name", "reduce", "seconds",
    "iterations", "train_ce"}] (with ``compare_full``)}``.

    Raises:
        FitOptionError: a setting out of range (:func:`ogm_ppl.learn.fit_delta_setting`'s checks).
    """
    import torch

    from ogm_ppl.datasets import wall_datasets
    from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss
    from ogm_ppl.inference.variational.setting_fit import fit_on_data
    from ogm_ppl.learn import fit_delta_setting
    from ogm_ppl.models import delta_by_name
    from ogm_ppl.models.delta import family_from_dict

    torch.optim.LBFGS([torch.zeros(1, requires_grad=True)])  # the first optimiser imports torch._dynamo: not the fit's
    wall = round(0.8 * F) if wall is None else wall
    t0 = time.perf_counter()
    r = fit_delta_setting(out_dir, family=list(names), sigma=sigma, F=F, wall=wall, num=num, seed=seed, reuse=True)
    total = time.perf_counter() - t0
    held = wall_datasets(num=heldout, F=F, wall=wall, sigma=sigma, seed=seed + 1)  # as heldout= would
    terms = {}
    for name, term in r.summary["terms"].items():
        tr = term["training"]
        with torch.no_grad():
            mine = float(cross_entropy_loss(family_from_dict(term["delta"]), held))
            shipped = float(cross_entropy_loss(delta_by_name(name), held))
        sec = tr.get("seconds") or {}
        terms[name] = {
            "data_s": sec.get("data", float("nan")),
            "fit_s": sec.get("fit", float("nan")),
            "train_ce": tr["train_cross_entropy"],
            "heldout_ce_fit": mine,
            "heldout_ce_shipped": shipped,
        }
    full = []
    if compare_full:
        data = wall_datasets(num=num, F=F, wall=wall, sigma=sigma, seed=seed)
        for name in names:
            for reduce in (True, False):
                t = time.perf_counter()
                res = fit_on_data(name, data, reduce=reduce)
                full.append(
                    {
                        "name": name,
                        "reduce": reduce,
                        "seconds": time.perf_counter() - t,
                        "iterations": res.iterations,
                        "train_ce": res.train_loss,
                    }
                )
    return {
        "sigma": sigma,
        "F": F,
        "wall": wall,
        "num": num,
        "heldout": heldout,
        "seconds": total,
        "terms": terms,
        "full": full,
    }


def delta_setting_lines(doc: dict) -> list[str]:
    """A :func:`delta_setting_heldout` result as lines: the setting, a Markdown table of the terms, the unreduced
    fits' times."""
    lines = [
        f"setting: sigma {doc['sigma']:g} cells, F {doc['F']}, wall {doc['wall']}, {doc['num']} training / "
        f"{doc['heldout']} held-out datasets; fit_delta_setting {doc['seconds']:.1f} s in all",
        "| term | data s (training) | fit s | train CE | held-out CE (fit) | held-out CE (shipped) |",
        "|---|---|---|---|---|---|",
    ]
    for name, t in doc["terms"].items():
        lines.append(
            f"| {name} | {t['data_s']:.1f} | {t['fit_s']:.2f} | {t['train_ce']:.4f} | {t['heldout_ce_fit']:.4f} | "
            f"{t['heldout_ce_shipped']:.4f} |"
        )
    for f in doc["full"]:
        lines.append(
            f"{f['name']} reduce={f['reduce']}: {f['seconds']:.2f} s, {f['iterations']} iterations, "
            f"train CE {f['train_ce']:.6f}"
        )
    return lines
