"""What the fits scored by the calibration protocol share: a corpus's fit/validation split, the tables of its
fit part, its usable validation windows, and the output folder (``out_dir``, or the package's fitted folder
when shipping).

The split is :func:`~ogm_ppl.learn.fit_backoff`'s: the corpus's training plans
(:func:`~ogm_ppl.learn.load_training_plans`, the real logs' buildings left out; or a random sample of them) in
their natural order, every fifth
(``index % 5 == 4``) *validation*, the rest *fit* (the shipped Witten-Bell ``kappa`` were chosen on exactly
this split, so the backed-off kinds may use them). Tables are counted on the fit part only, with the 8
symmetries and the shipped ``min_count_5x5 = 2`` (thesis Sections 5.2.2-5.2.3).

A kind fitted as a file on whole plans (:data:`~ogm_ppl.priors.named.FILE_KINDS`: the net field) counts no
tables: its exponent is scored on the plans its own fit kept for validation (:func:`file_kind_validation`), which
it never trained on, and its record holds its prior samples' statistics at each exponent (:func:`file_kind_record`).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ogm_ppl.learn._fit_common import FitOptionError, check_out_dir, load_training_plans, validation_split
from ogm_ppl.priors.named import FILE_KINDS  # the kinds fitted as files: tempered on their own validation plans

__all__ = [
    "FILE_KINDS",
    "VALIDATION_EVERY",
    "count_fit_tables",
    "file_kind_path",
    "file_kind_record",
    "file_kind_validation",
    "names_sha256",
    "output_folder",
    "shell_command",
    "split_names",
    "validation_windows",
]

#: every fifth training plan is validation
VALIDATION_EVERY = 5
#: the prior-sample check of a file kind at each exponent: chains of this side, per start, the cells at least
#: this far from the edges read, crops of the validation plans of the read part's side (the chains run the
#: protocol's ``burn + sweeps`` sweeps)
SAMPLE_CHECK = {"size": 40, "chains": 2, "edge": 8, "crops": 32}
_VALIDATION_RULE = re.compile(r"maps with index % (\d+) == (\d+)$")


def split_names(corpus: str, sample: int | None = None, seed: int = 0) -> tuple[list[str], list[str]]:
    """``(fit, validation)`` plan names of a floor-plan corpus: every fifth training plan is validation (of a
    random ``sample`` of them drawn with ``seed``, :func:`~ogm_ppl.learn.load_training_plans`, where given)."""
    plans = load_training_plans(corpus, sample=sample, sample_seed=seed)
    fit_idx, val_idx = validation_split(len(plans), VALIDATION_EVERY)
    return [plans.names[i] for i in fit_idx], [plans.names[i] for i in val_idx]


def names_sha256(names: Sequence[str]) -> str:
    """SHA-256 of plan names, one a line."""
    return hashlib.sha256("\n".join(names).encode()).hexdigest()


def count_fit_tables(corpus: str, fit: Sequence[str]) -> Any:
    """The tables of the plans ``fit`` of ``corpus`` (8 symmetries, ``min_count_5x5 = 2``)."""
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.priors.learn import count_tables

    return count_tables(fp.iter_plans(corpus, list(fit)), symmetries=True, min_count_5x5=2, progress=False)


def validation_windows(corpus: str, names: Sequence[str], n: int, window: int) -> list:
    """The first ``n`` validation plans of ``names`` whose ``window`` holds at least 200 free cells, cropped
    (:func:`~ogm_ppl.calibration.usable_windows`); :class:`FitOptionError` naming ``plans`` when fewer are."""
    from ogm_ppl.calibration import usable_windows

    out = usable_windows(corpus, list(names), n, window)
    if len(out) < n:
        raise FitOptionError("plans", f"{corpus}: only {len(out)} of the {n} validation plans have a usable window")
    return out


def output_folder(out_dir: str | os.PathLike | None, ship: bool) -> tuple[Path, list[str]]:
    """The folder the files go to and its command-line options: ``out_dir`` (``--out DIR``), or with
    ``ship=True`` the package's ``ogm_ppl/fitted`` (``--ship``). The fitted folder named as ``out_dir``, or
    both or neither given, is refused (:class:`FitOptionError` naming ``out``)."""
    from ogm_ppl.priors.tables import FITTED_DIR

    if ship:
        if out_dir is not None:
            raise FitOptionError("out", "give a folder or ship=True (--ship), not both")
        return Path(FITTED_DIR), ["--ship"]
    out = check_out_dir(out_dir)
    if out.resolve() == Path(FITTED_DIR).resolve():
        raise FitOptionError("out", f"{out} is the package's fitted folder: replace shipped files with --ship")
    return out, ["--out", str(out)]


def shell_command(kind: str, *args: Any) -> str:
    """``ogm-ppl fit-prior KIND ARGS...`` as one shell line."""
    return shlex.join(["ogm-ppl", "fit-prior", kind, *(str(a) for a in args)])


def file_kind_path(kind: str, corpus: str) -> Path:
    """The record of the shipped fit of file kind ``kind`` on ``corpus`` (:class:`FitOptionError` naming ``kinds``
    when there is none)."""
    from ogm_ppl.priors.net_field import net_path

    path = net_path(corpus).with_suffix(".json")
    if not path.is_file():
        raise FitOptionError("kinds", f"{kind!r}: no shipped {kind} fit for corpus {corpus!r} ({path} does not exist)")
    return path


def file_kind_validation(kind: str, corpus: str) -> list[str]:
    """The validation plans of the shipped fit of a file kind (``net``: ``ogm_ppl/fitted/net_<corpus>.json``):
    the corpus's training plans its record names as validation (``maps with index % N == N - 1``), which its
    fit never trained on. Refused (:class:`FitOptionError` naming ``kinds``) when the corpus has no such fit or
    its record names another plan list (another corpus version, a sample, a limit)."""
    path = file_kind_path(kind, corpus)
    try:
        rec = json.loads(path.read_text())
        rule = _VALIDATION_RULE.match(str(rec["settings"]["validation"]))
        digest = rec["provenance"]["plan_names_sha256"]
    except (ValueError, KeyError, TypeError) as e:
        raise FitOptionError("kinds", f"{kind!r}: {path} records no validation split ({e})") from None
    if rule is None or int(rule.group(2)) != int(rule.group(1)) - 1:
        raise FitOptionError("kinds", f"{kind!r}: {path} records a validation rule this fit does not read")
    names = list(load_training_plans(corpus).names)
    if names_sha256(names) != digest:
        raise FitOptionError(
            "kinds", f"{kind!r}: {path} was fitted on another list of {corpus} plans than the corpus's training plans"
        )
    _, val = validation_split(len(names), int(rule.group(1)))
    return [names[i] for i in val]


def file_kind_record(kind: str, corpus: str, windows: Sequence, s: Any, progress: bool = False) -> dict:
    """What a tempering file records of a file kind besides its scores: the validation plans scored and, at each
    exponent of ``s.betas``, the statistics of its prior samples beside the validation plans'
    (:func:`~ogm_ppl.priors.learn_net.prior_sample_statistics`, :data:`SAMPLE_CHECK`): occupied share and mean
    runs of occupied and of free cells, so an ordered phase (chains frozen at their start) shows."""
    import numpy as np

    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.priors import learn_net as ln
    from ogm_ppl.priors.named import prior_by_name

    c = SAMPLE_CHECK
    side = c["size"] - 2 * c["edge"]
    names = sorted({t.plan for t in windows})
    plans = [(np.asarray(p.occupancy, bool), np.asarray(p.known, bool)) for p in fp.iter_plans(corpus, names)]
    crops = ln.data_crops_known(plans, c["crops"], side, np.random.default_rng(s.seed))
    samples = []
    for b in s.betas:
        name = f"{kind}:{corpus}" + ("" if b == 1.0 else f"@{b:g}")
        prior = prior_by_name(name, (c["size"], c["size"]))
        row = {"beta": float(b)}
        row.update(ln.prior_sample_statistics(prior, c["chains"], s.burn + s.sweeps, c["edge"], s.seed))
        samples.append(row)
        if progress:
            print(f"  {corpus:>9} {kind:>10} beta {b:<5g} prior samples {ln.describe_statistics(row)}", flush=True)
    return _no_nan(
        {
            "validation_plans_scored": [t.name for t in windows],
            "prior_samples": samples,
            "validation_plan_statistics": ln.sample_statistics(crops.reshape(-1, side, side).astype(bool)),
            "prior_sample_check": {**c, "sweeps": s.burn + s.sweeps, "starts": list(ln.SAMPLE_STARTS)},
        }
    )


def _no_nan(x: Any) -> Any:
    """``x`` with every float NaN (a run length of maps holding no such run) as ``None``: JSON has no NaN."""
    if isinstance(x, dict):
        return {k: _no_nan(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_no_nan(v) for v in x]
    return None if isinstance(x, float) and x != x else x
