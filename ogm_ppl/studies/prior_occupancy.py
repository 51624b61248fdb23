r"""How much of a region with no readings does a prior fill? Each prior's own occupied share against its
corpus's (thesis Chapter 5, Sections 5.2.2-5.2.3).

A prior learned from a corpus predicts a cell no ray reached from the cells around it; far from any reading its
prediction is what the prior itself holds,

.. math::

    s = E_p\Big[\frac{1}{|K|} \sum_{k \in K} m_k\Big],

the occupied share of maps drawn from it (``K`` the cells of an empty window). At the maximum-likelihood fit of
a joint whose sufficient statistics include the occupied share (an independent prior's ``lambda``; a pattern
field's window codes) that share equals the training corpus's (moment matching). The tables of Chapter 5 are
products of tile conditionals, not normalised fits of a joint, so nothing makes theirs match.

For each prior kind (``KIND[@cal]``, ``@cal`` tempered as in ``ogm-ppl calibrate``) learned on each training
corpus, :func:`prior_occupancy` runs three chains of the prior's mixing cycle
(:func:`~ogm_ppl.inference.mcmc.mixing_cycle`: the calibration protocol's sampler) on a ``window`` square with
no readings (one short ray at the centre, which the model needs; its cells are not counted), from the all-free
map, the all-occupied map and a prior draw, recording the occupied share every ``every`` sweeps
(:func:`~ogm_ppl.learn.bias.occupancy_trace`). The prior's share ``s`` is the mean over the second half of the
three chains; the corpus's is ``lambda`` of its tables (the occupied share of its training plans). A ``@cal``
kind without a fitted exponent on a corpus is skipped there.

With ``fit_bias`` it also fits, per prior, the bias ``h`` of :class:`~ogm_ppl.priors.BiasedPrior` (the prior
times ``exp(h sum_k m_k)``) whose share is the corpus's: :func:`ogm_ppl.learn.fit_bias`, which writes
``bias.json`` (read by ``ogm-ppl calibrate --bias-file``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path

__all__ = ["PRIORS", "TRAIN", "prior_occupancy", "prior_occupancy_lines"]

#: the corpora the priors are learned on, by default
TRAIN: tuple[str, ...] = ("generated", "houseexpo", "ipa", "dungeon")
#: the prior kinds, by default
PRIORS: tuple[str, ...] = ("border_bo", "border_bo@cal", "border1_bo", "border1_bo@cal", "patch3")
#: the file :func:`prior_occupancy` writes
FILE_NAME = "prior_occupancy.json"


def prior_occupancy(
    priors: Sequence[str] = PRIORS,
    train: Sequence[str] = TRAIN,
    settings=None,
    out_dir: str | Path | None = None,
    *,
    fit_bias: bool = False,
    command: str | None = None,
    progress: bool = True,
) -> dict:
    """Each prior's occupied share of an empty window beside its corpus's (module docstring).

    Args:
        priors: prior kinds, ``KIND`` or ``KIND@cal`` (the corpus comes from ``train``).
        train: the corpora the priors learned on.
        settings: a :class:`~ogm_ppl.learn.bias.BiasSettings` (the window, the chains, the bias's bisection).
        out_dir: write ``prior_occupancy.json`` (the returned dict) there; with ``fit_bias`` also ``bias.json``.
        fit_bias: also fit each prior's bias ``h`` (needs ``out_dir``); each row gets a ``"fit"``.
        command: the command recorded in the provenance (default this process's).
        progress: a progress line per prior (:class:`~ogm_ppl.progress.Progress`).

    Returns:
        ``{"provenance", "settings", "starts", "rows", "skipped", "seconds"}``: ``rows`` one dict a prior
        (``prior``, ``kind``, ``train``, ``corpus_share``, ``share``, ``chain_shares``, ``traces``, ``seconds``,
        ``patch``, and ``fit`` when fitted), ``skipped`` maps a prior to the reason.

    Raises:
        FitOptionError: a setting out of range, a name that is not a prior kind or that names a corpus.
        StudyOptionError: ``fit_bias`` without ``out_dir``.
    """
    from ogm_ppl.learn.bias import STARTS, BiasSettings, occupancy_trace, prior_targets
    from ogm_ppl.priors.tables import tables_by_name
    from ogm_ppl.progress import Progress
    from ogm_ppl.provenance import provenance
    from ogm_ppl.studies.errors import StudyOptionError

    s = (settings or BiasSettings()).checked()
    if fit_bias and out_dir is None:
        raise StudyOptionError("out_dir", "fitting the biases writes bias.json: give the folder")
    targets, skipped = prior_targets(list(priors), list(train))
    fits: dict = {}
    if fit_bias:
        from ogm_ppl.learn import fit_bias as fit

        assert out_dir is not None
        r = fit(priors, out_dir, train=train, settings=s, progress=False)
        fits = json.loads(r.files[0].read_text())["fits"]
    t0 = time.perf_counter()
    run = {k: getattr(s, k) for k in ("window", "sweeps", "every", "seed")}
    bisection = {k: getattr(s, k) for k in ("bias_range", "bias_steps")}
    rows: list[dict] = []
    with Progress(len(targets), "prior occupancy", unit="prior", enabled=progress, after=10.0) as bar:
        for name, kind, corpus in targets:
            lam = float(tables_by_name(corpus).lam)
            rows.append({"prior": name, "kind": kind, "train": corpus, "corpus_share": lam, **occupancy_trace(name, s)})
            if fit_bias:
                rows[-1]["fit"] = {k: v for k, v in fits[name].items() if k not in ("kind", "train", "corpus_share")}
            bar.update(note=name)
    doc = {
        "provenance": provenance(command),
        "settings": {"priors": list(priors), "train": list(train), **run, "fit_bias": fit_bias, **bisection},
        "starts": list(STARTS),
        "rows": rows,
        "skipped": skipped,
        "seconds": time.perf_counter() - t0,
    }
    if out_dir is not None:
        from ogm_ppl.io import atomic_write_text

        atomic_write_text(Path(out_dir) / FILE_NAME, json.dumps(doc, indent=1, allow_nan=False))
    return doc


def prior_occupancy_lines(doc: dict) -> list[str]:
    """A :func:`prior_occupancy` result as a table of lines: per prior the corpus's share, the prior's and each
    chain's (and the biased prior's under it when fitted); the skipped priors last."""
    w = doc["settings"]["window"]
    lines = [
        f"occupied share of an empty {w} x {w} window, second half of 3 chains",
        f"{'prior':28s} {'corpus':>7s} {'prior':>6s}  chains (free, occupied, prior start)",
    ]
    for r in doc["rows"]:
        chains = " ".join(f"{v:.3f}" for v in r["chain_shares"])
        lam = r["corpus_share"]
        lines.append(f"{r['prior']:28s} {lam:7.3f} {r['share']:6.3f}  {chains}  ({r['seconds']:.0f} s)")
        if "fit" in r:
            f = r["fit"]
            chains = " ".join(f"{v:.3f}" for v in f["chain_shares"])
            lines.append(f"{'  biased, h = ' + format(f['bias'], '+.3f'):28s} {lam:7.3f} {f['share']:6.3f}  {chains}")
    lines += [f"{name:28s} skipped: {reason}" for name, reason in doc["skipped"].items()]
    return lines
