"""What the fits scored by the calibration protocol share: a corpus's fit/validation split, the tables of its
fit part, its usable validation windows, and the output folder (``out_dir``, or the package's fitted folder
when shipping).

The split is :func:`~ogm_ppl.learn.fit_backoff`'s: the corpus's training plans
(:func:`~ogm_ppl.learn.load_training_plans`, the real logs' buildings left out; or a random sample of them) in
their natural order, every fifth
(``index % 5 == 4``) *validation*, the rest *fit* (the shipped Witten-Bell ``kappa`` were chosen on exactly
this split, so the backed-off kinds may use them). Tables are counted on the fit part only, with the 8
symmetries and the shipped ``min_count_5x5 = 2`` (thesis Sections 5.2.2-5.2.3).
"""

from __future__ import annotations

import hashlib
import os
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ogm_ppl.learn._fit_common import FitOptionError, check_out_dir, load_training_plans, validation_split

__all__ = [
    "VALIDATION_EVERY",
    "count_fit_tables",
    "names_sha256",
    "output_folder",
    "shell_command",
    "split_names",
    "validation_windows",
]

#: every fifth training plan is validation
VALIDATION_EVERY = 5


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
