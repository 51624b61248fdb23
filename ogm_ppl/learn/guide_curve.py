r"""Does more data pay for the corpus guide: its validation loss after training on more and more plans.

The guide's data curve follows the pattern field's (:mod:`~ogm_ppl.learn.data_curve`) rule: with
``P = numpy.random.default_rng(seed).permutation(training split)``, the guide of size ``N`` trains on ``P[:N]``
(so each sample holds every smaller one, and is the field curve's sample of that size) and every guide is
validated on the same ``validation`` plans ``P[N_max : N_max + validation]`` after the largest sample
(:func:`~ogm_ppl.calibration.leakage.guide_split`). Everything else is one set of
:class:`~ogm_ppl.learn.guide_settings.GuideTrainingSettings`: the same number of training windows, steps,
window, sensor, network and seed, so the sizes differ only in the plans the windows are drawn from, and the
validation windows are the same windows for every size (the record's ``windows_sha256`` shows it).

Per size, :func:`~ogm_ppl.learn.guide_training.train_corpus_guide` trains a guide into
``guide_<corpus>_<N>.npz`` (resumable from its checkpoint; a finished guide of the same command is reused), and
the curve records its validation loss in bits per unseen near-mapped cell (thesis Section 5.2.3)

.. math::

    \mathcal{L}_\mathrm{val}(N) = \frac{1}{|U|} \sum_{k \in U} -\log_2 q_{\phi_N}(m_k \mid z)

(``U``: the unseen near-mapped cells of the validation windows) at the last step (nothing chosen on the
validation set), at the validation-best step, and after the temperature fitted on those windows, beside the
training loss, the distinct plans the training windows came from and the minutes spent on data and training.
:func:`guide_data_curve` writes ``data_curve_guide_<corpus>.json`` (``ogm-ppl train-guide --curve-sizes``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from ogm_ppl.learn._fit_common import FitOptionError, FitResult, check_int, check_out_dir
from ogm_ppl.learn.guide_settings import GuideTrainingSettings

__all__ = ["GUIDE_CURVE_KIND", "curve_command", "curve_settings", "guide_data_curve"]

#: the ``kind`` of a guide's data curve (the field's curve has none: ``format`` ``ogm_ppl.data_curve`` alone)
GUIDE_CURVE_KIND = "guide"


def curve_settings(
    template: GuideTrainingSettings, corpus: str, sizes: Sequence[int], validation: int, seed: int
) -> list[GuideTrainingSettings]:
    """The settings of each size's guide: ``template`` with ``corpus`` alone, ``sample = N`` of seed ``seed``
    and ``validation`` plans after the largest size (``validation_after = max(sizes)``); checked.

    Raises:
        FitOptionError: ``sizes`` not ascending and distinct, a size or ``validation`` below 1, ``seed`` below 0.
    """
    ns = [check_int(n, "curve_sizes", 1) for n in sizes]
    if not ns or ns != sorted(set(ns)):
        raise FitOptionError("curve_sizes", f"give ascending distinct sizes, got {list(sizes)}")
    m = check_int(validation, "validation_sample", 1)
    seed = check_int(seed, "sample_seed", 0, 2**32 - 1)
    if template.plan_files:
        raise FitOptionError("plan_files", "a data curve samples a corpus's training split: no --plan-files")
    return [
        dataclasses.replace(
            template,
            corpus=(corpus,),
            sample=n,
            sample_seed=seed,
            validation_sample=m,
            validation_after=ns[-1],
            name=None,
        )
        for n in ns
    ]


def _finished(out: Path, command: str) -> dict | None:
    """The sidecar record of a guide at ``out`` written by ``command`` (its file's SHA-256 matching), else
    ``None``."""
    side = out.with_suffix(".json")
    if not (out.exists() and side.exists()):
        return None
    try:
        rec = json.loads(side.read_text())
    except ValueError:
        return None
    if not isinstance(rec, dict) or rec.get("provenance", {}).get("command") != command:
        return None
    if rec.get("sha256") != hashlib.sha256(out.read_bytes()).hexdigest():
        return None
    return rec


def guide_data_curve(
    corpus: str,
    out_dir: str | Path,
    *,
    sizes: Sequence[int] = (60, 600, 6000),
    validation: int = 300,
    seed: int = 0,
    settings: GuideTrainingSettings | None = None,
    progress: bool = True,
    fresh: bool = False,
) -> FitResult:
    """Train a guide on the first ``N`` plans of the ``seed`` permutation of ``corpus``'s training split for each
    ``N`` in ``sizes``, each validated on the same ``validation`` plans after the largest sample (module
    docstring); write ``guide_<corpus>_<N>.npz`` (+ ``.json``) for each and ``data_curve_guide_<corpus>.json``
    into ``out_dir`` (atomically).

    Args:
        corpus: a corpus of :data:`~ogm_ppl.learn.guide_settings.CORPORA`.
        sizes: training plans per guide (ascending, distinct); with ``validation`` at most the split.
        validation: validation plans (at least 1).
        seed: the permutation's seed (``--sample-seed``).
        settings: the training options shared by every size (default :class:`GuideTrainingSettings`'s); their
            ``corpus``, ``sample``, ``sample_seed``, ``validation_sample``, ``validation_after`` and ``name``
            are set here.
        progress: progress lines on stderr.
        fresh: ignore checkpoints and finished guides of an earlier call and train every size afresh.

    Returns:
        :class:`~ogm_ppl.learn.FitResult` (``kind`` ``"guide-data-curve"``; ``files``: the curve and the guides;
        ``summary["rows"]``). A size stopped early (Ctrl-C) raises :class:`KeyboardInterrupt` with its
        checkpoint kept: the same call resumes.

    Raises:
        FitOptionError: an option out of range (named, with its limit), before any plan is read.
        ValueError: ``validation`` plans after the largest size exceed the corpus's training split.
    """
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.learn.guide_training import train_corpus_guide
    from ogm_ppl.provenance import provenance

    template = settings or GuideTrainingSettings(corpus=(corpus,))
    runs = curve_settings(template, corpus, sizes, validation, seed)
    out = check_out_dir(out_dir)
    ns = [int(s.sample or 0) for s in runs]
    command = curve_command(template, corpus, ns, validation, seed, out)
    val_sha, of = _validation_digest(corpus, ns[-1], validation, seed)  # refuses a split too small, before work
    t0 = time.perf_counter()
    rows: list[dict] = []
    files: list[Path] = []
    windows: set[str] = set()
    for n, s in zip(ns, runs, strict=True):
        path = out / f"guide_{corpus}_{n}.npz"
        cmd = s.command(path)
        rec = None if fresh else _finished(path, cmd)
        if rec is None:
            r = train_corpus_guide(s, path, progress=progress, fresh=fresh, command=cmd)
            if not r.finished:
                raise KeyboardInterrupt(f"stopped in the guide of {n} plans; the same call resumes")
            rec = json.loads(r.sidecar.read_text())
        elif progress:
            print(f"{path}: already trained by the same command; reused", file=sys.stderr, flush=True)
        rows.append(_row(n, rec))
        windows.add(str(rec["validation"].get("windows_sha256")))
        files += [path, path.with_suffix(".json")]
    if len(windows) != 1:
        raise RuntimeError(f"the guides of {ns} plans were validated on different windows: {sorted(windows)}")
    prov = {**provenance(command), "seconds": round(time.perf_counter() - t0, 1)}
    doc = {
        "format": "ogm_ppl.data_curve",
        "format_version": 1,
        "kind": GUIDE_CURVE_KIND,
        "corpus": corpus,
        "score": "validation bits per unseen near-mapped cell of the corpus guide (ogm_ppl.learn.guide_curve)",
        "settings": {
            "sizes": ns,
            "validation": validation,
            "seed": seed,
            "split_of_plans": "first N of numpy.random.default_rng(seed).permutation(training plans); validation: "
            "the next `validation` after the largest N",
            "training": json.loads(runs[-1].fingerprint()),
        },
        "training_split_plans": of,
        "validation_names_sha256": val_sha,
        "validation_windows": template.val,
        "validation_windows_sha256": windows.pop(),
        "rows": rows,
        "provenance": prov,
    }
    path = atomic_write_text(out / f"data_curve_guide_{corpus}.json", json.dumps(doc, indent=1) + "\n")
    return FitResult("guide-data-curve", (path, *files), prov, {"rows": rows}, prov["seconds"])


def _validation_digest(corpus: str, after: int, validation: int, seed: int) -> tuple[str, int]:
    """SHA-256 of the validation plans' names in the training split's natural order (as the field's curve
    records its own, :meth:`~ogm_ppl.learn.TrainingPlans.names_sha256`) and the split's size."""
    from ogm_ppl.calibration.leakage import guide_base, guide_split

    _, val, _ = guide_split(corpus, after, seed, validation, after)
    held = set(val)
    base = guide_base(corpus)
    return hashlib.sha256("\n".join(n for n in base if n in held).encode()).hexdigest(), len(base)


def _row(n: int, rec: dict) -> dict:
    """One size's row of the curve from its guide's sidecar ``rec``."""
    hist = rec["history"]
    last, tail = hist[-1], hist[-min(3, len(hist)) :]
    v = rec["validation"]
    return {
        "plans": n,
        "training_plans_drawn": rec.get("training_plans_drawn"),
        "plan_names_sha256": rec["plan_names_sha256"],
        "validation_bits_per_unseen_cell_last": last["bits_per_unseen_cell"],
        "validation_bits_per_cell_last": last["bits_per_cell"],
        "validation_bits_per_unseen_cell_best": v.get("before_temperature", v["bits_per_unseen_cell"]),
        "validation_bits_per_unseen_cell_tempered": v["bits_per_unseen_cell"],
        "validation_unseen_cells": v["unseen_cells"],
        "kept_step": rec["training"]["kept_step"],
        "temperature": rec["training"]["temperature"],
        "train_bits_per_cell_tail": sum(h["train_bits_per_cell"] for h in tail) / len(tail),
        "minutes_data": round(rec["seconds"]["data"] / 60, 2),
        "minutes_training": round(rec["seconds"]["training"] / 60, 2),
        "guide_sha256": rec["sha256"],
    }


def curve_command(
    template: GuideTrainingSettings, corpus: str, sizes: Sequence[int], validation: int, seed: int, out: Path
) -> str:
    """The ``ogm-ppl train-guide --curve-sizes`` command line of a curve (options at their defaults omitted)."""
    base = dataclasses.replace(
        template,
        corpus=(corpus,),
        sample=None,
        sample_seed=0,
        validation_sample=None,
        validation_after=None,
        name=None,
    )
    words = shlex.split(base.command(out))[:-2]  # without "--out OUT"
    words += ["--curve-sizes", *map(str, sizes), "--validation-sample", str(validation)]
    words += ["--sample-seed", str(seed)] if seed else []
    return shlex.join([*words, "--out", str(out)])
