"""What every prior fit shares: the training plans (a corpus or plan files of one's own), the fit/validation
split, option checks that name the option and its limit, the output folder and the provenance of a file.

The training plans of a corpus are those the shipped priors were fitted on (thesis Section 5.2.2):
``generated`` = the maps of :func:`ogm_ppl.datasets.mapgen.iter_corpus` at 500 x 500 cells, seed 0 (the first
100); ``houseexpo`` and ``ipa`` = their training split without the buildings of the real logs
(:func:`~ogm_ppl.datasets.floorplans.training_plans`), ``dungeon`` = the first 300 of its training split; each
rasterised by :func:`~ogm_ppl.datasets.floorplans.load_plan`'s defaults (outside = occupied, 20-cell margin).
The other floor-plan corpora (``houseexpo-full``, ``r2v``, ``schools``; no shipped priors) likewise: their
training split, at 0.05 m (``--limit`` keeps the first plans, ``--sample N --sample-seed S`` a random subset of
``N`` kept in their natural order: ``houseexpo-full`` has 26,899; :func:`sample_indices`).
Plan files (:func:`~ogm_ppl.datasets.plan_files.plan_files`: ROS map YAMLs, HouseExpo layouts, images with a
pixel size, folders of them) are read by :func:`~ogm_ppl.datasets.plan_files.load_plan_file` at
``resolution`` metres per cell, in the order :func:`~ogm_ppl.datasets.plan_files.plan_files` lists them.
"""

from __future__ import annotations

import hashlib
import os
import re
import shlex
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from ogm_ppl import options
from ogm_ppl.datasets.floorplans import CORPORA as FLOORPLAN_CORPORA

__all__ = [
    "FitSetup",
    "fit_setup",
    "CORPORA",
    "SHIPPED_CORPORA",
    "FitOptionError",
    "FitResult",
    "TrainingPlans",
    "load_training_plans",
    "sample_indices",
    "validation_split",
]

#: the corpora the shipped priors were fitted on (the defaults of the fits that adjust shipped priors)
SHIPPED_CORPORA: tuple[str, ...] = ("generated", "houseexpo", "ipa", "dungeon")
#: the corpora whose training plans a prior can be fitted on by name: the generated maps and every floor-plan
#: corpus (:data:`ogm_ppl.datasets.floorplans.CORPORA`)
CORPORA: tuple[str, ...] = ("generated", *FLOORPLAN_CORPORA)
#: how many training plans of a corpus are taken by default (the others: all of them)
DEFAULT_LIMITS: dict[str, int] = {"generated": 100, "dungeon": 300}
#: the generated corpus: map shape, seed and frame
GENERATED_SHAPE, GENERATED_SEED, GENERATED_BORDER = (500, 500), 0, 20
_LABEL = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")
PlanPaths = str | os.PathLike | Sequence[str | os.PathLike]


class FitOptionError(ValueError):
    """An option of a prior fit is out of its range; ``option`` names it (its command-line spelling without
    the dashes, ``--min-count-5x5`` -> ``min_count_5x5``)."""

    def __init__(self, option: str, message: str) -> None:
        super().__init__(f"{option}: {message}")
        self.option = option
        self.reason = message  # the message without the option's name, for a caller that names it otherwise


def check_int(value: Any, option: str, lo: int, hi: int | None = None) -> int:
    """``value`` as an int in ``lo..hi`` (``hi`` None: no upper limit), else :class:`FitOptionError`
    (:func:`ogm_ppl.options.check_int`)."""
    return options.check_int(value, option, lo, hi, error=FitOptionError)


def check_float(
    value: Any, option: str, lo: float, hi: float | None = None, *, lo_open: bool = True, hi_open: bool = False
) -> float:
    """``value`` as a finite float in the interval from ``lo`` to ``hi`` (open or closed ends), else
    :class:`FitOptionError` naming the interval (:func:`ogm_ppl.options.check_float`)."""
    return options.check_float(value, option, lo, hi, lo_open=lo_open, hi_open=hi_open, error=FitOptionError)


def check_label(value: Any, option: str = "name") -> str:
    """A name that becomes part of a file name in the output folder: letters, digits, ``_ . + -``."""
    if not isinstance(value, str) or not _LABEL.match(value) or len(value) > 64:
        raise FitOptionError(
            option, f"must be 1 to 64 letters, digits or _ . + - (it names the files written), got {value!r}"
        )
    return value


def check_out_dir(out_dir: Any) -> Path:
    """The output folder (created when the files are written); refused when it is an existing file."""
    if out_dir is None or (isinstance(out_dir, str) and not out_dir):
        raise FitOptionError("out", "give the folder the fitted files go to")
    p = Path(out_dir)
    if p.exists() and not p.is_dir():
        raise FitOptionError("out", f"{p} is a file, not a folder")
    return p


@dataclass(frozen=True)
class TrainingPlans:
    """The maps a prior is fitted on: ``names`` in their order, read one at a time by :meth:`maps`.

    ``corpus`` is the corpus name or ``"files"``; ``source`` is the JSON-able record of where they come from
    and how they were read (it goes into every fitted file's provenance)."""

    corpus: str
    names: tuple[str, ...]
    source: dict
    files: tuple[Path, ...] = ()
    pixel_size: float | None = None
    resolution: float | None = None
    _extra: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.names)

    def names_sha256(self, indices: Sequence[int] | None = None) -> str:
        """SHA-256 of the names (of ``indices``), one a line: which plans, without listing them."""
        names = self.names if indices is None else [self.names[i] for i in indices]
        return hashlib.sha256("\n".join(names).encode()).hexdigest()

    def maps(self, indices: Sequence[int] | None = None) -> Iterator[Any]:
        """The maps (of ``indices``, ascending), one at a time: ``H x W`` bool arrays (generated, every cell
        known) or :class:`~ogm_ppl.datasets.floorplans.FloorPlan`\\ s."""
        idx = list(range(len(self))) if indices is None else sorted(int(i) for i in indices)
        if self.corpus == "generated":
            from ogm_ppl.datasets.mapgen import iter_corpus

            keep = set(idx)
            for i, m in enumerate(iter_corpus(len(self), GENERATED_SHAPE, seed=GENERATED_SEED)):
                if i in keep:
                    yield m
        elif self.files:
            from ogm_ppl.datasets.plan_files import load_plan_file

            for i in idx:
                yield load_plan_file(
                    self.files[i],
                    pixel_size=self.pixel_size,
                    resolution=0.05 if self.resolution is None else self.resolution,
                    name=self.names[i],
                )
        else:
            from ogm_ppl.datasets import floorplans as fp

            yield from fp.iter_plans(self.corpus, [self.names[i] for i in idx])

    def command_args(self) -> list[str]:
        """The command-line options that give these plans (``--corpus C`` or ``--plan-files ...``)."""
        if self.files:
            args = ["--plan-files", *(str(f) for f in self.files)]
            if self.pixel_size is not None:
                args += ["--pixel-size", f"{self.pixel_size:g}"]
            if self.resolution is not None and self.resolution != 0.05:
                args += ["--resolution", f"{self.resolution:g}"]
        else:
            args = ["--corpus", self.corpus]
        if self._extra.get("limit") is not None:
            args += ["--limit", str(self._extra["limit"])]
        if self._extra.get("sample") is not None:
            args += ["--sample", str(self._extra["sample"]), "--sample-seed", str(self._extra["sample_seed"])]
        return args


def load_training_plans(
    source: str | PlanPaths | TrainingPlans,
    *,
    limit: int | None = None,
    pixel_size: float | None = None,
    resolution: float = 0.05,
    sample: int | None = None,
    sample_seed: int = 0,
) -> TrainingPlans:
    """The training plans of ``source``: a corpus name (:data:`CORPORA`), plan files or folders of them, or a
    :class:`TrainingPlans` (returned as it is). ``limit`` keeps the first ``limit`` (default: 100 generated
    maps, 300 DungeonMaps plans, every plan else); ``sample`` (a floor-plan corpus only, not with ``limit``)
    keeps a random subset of ``sample`` of its training plans, :func:`sample_indices` with ``sample_seed``, in
    their natural order; ``pixel_size`` (metres per pixel of an image) and ``resolution`` (metres per cell)
    apply to plan files only (a corpus is read at its own resolution).

    Raises :class:`FitOptionError` naming the option for a bad one, and
    :class:`~ogm_ppl.datasets.plan_files.PlanFileError` for a missing or unreadable path."""
    if isinstance(source, TrainingPlans):
        return source
    lim = None if limit is None else check_int(limit, "limit", 1)
    if sample is not None:
        if not (isinstance(source, str) and source in CORPORA and source != "generated"):
            raise FitOptionError("sample", "applies to a floor-plan corpus by name only")
        if lim is not None:
            raise FitOptionError("sample", "give --limit or --sample, not both")
        return _sampled_plans(source, check_int(sample, "sample", 1), check_int(sample_seed, "sample_seed", 0))
    if isinstance(source, str) and source in CORPORA:
        if pixel_size is not None:
            raise FitOptionError("pixel_size", "applies to plan files only; a corpus is read at its own scale")
        return _corpus_plans(source, lim)
    if isinstance(source, str):
        raise FitOptionError(
            "corpus", f"must be one of {', '.join(CORPORA)}, got {source!r} (give plan files as paths: Path(...))"
        )
    from ogm_ppl.datasets.plan_files import plan_files, plan_names

    ps = None if pixel_size is None else check_float(pixel_size, "pixel_size", 0.0, 1e3)
    res = check_float(resolution, "resolution", 0.0, 10.0)
    paths = [source] if isinstance(source, (str, os.PathLike)) else list(source)
    if not paths:
        raise FitOptionError("plans", "give at least one plan file or folder")
    files = plan_files(paths)[:lim]
    names = tuple(plan_names(files))
    src = {
        "corpus": "files",
        "split": "the plan files given",
        "plans": len(files),
        "files": [str(f) for f in files],
        "plan_files_sha256": _files_sha256(files),
        "pixel_size": ps,
        "resolution": res,
        "outside": "occupied",
        "margin": 20,
        "wall_cells": 2,
        "sample": {"limit": lim, "order": "as plan_files lists them"},
        "plan_names_sha256": hashlib.sha256("\n".join(names).encode()).hexdigest(),
    }
    return TrainingPlans("files", names, src, tuple(files), ps, res, {"limit": lim})


def _files_sha256(files: Sequence[Path]) -> str:
    """One SHA-256 of the plans' bytes (each file and, for a ROS map, its image), in order."""
    from ogm_ppl.datasets.plan_files import plan_file_pieces

    h = hashlib.sha256()
    for f in files:
        for piece in plan_file_pieces(f):
            h.update(hashlib.sha256(piece.read_bytes()).digest())
    return h.hexdigest()


def _corpus_plans(corpus: str, limit: int | None) -> TrainingPlans:
    n_limit = DEFAULT_LIMITS.get(corpus) if limit is None else limit
    if corpus == "generated":
        n = int(n_limit or DEFAULT_LIMITS["generated"])
        src = {
            "corpus": "generated",
            "generator": "ogm_ppl.datasets.mapgen.iter_corpus",
            "n": n,
            "shape": list(GENERATED_SHAPE),
            "seed": GENERATED_SEED,
            "kinds": ["office", "corridor", "cluttered", "hall"],
            "border": GENERATED_BORDER,
            "resolution": None,
            "sample": {"limit": n, "order": "generation order"},
        }
        names = tuple(f"mapgen:{i}" for i in range(n))
    else:
        from ogm_ppl.datasets import floorplans as fp

        names = tuple(fp.training_plans(corpus, limit=n_limit))
        src = {
            "corpus": corpus,
            "split": "train",
            "plans": len(names),
            "excluded_buildings": list(fp.REAL_LOG_BUILDINGS),
            "split_rule": fp.split_rule(corpus),
            "resolution": fp.DEFAULT_RESOLUTION[corpus],
            "outside": "occupied",
            "margin": 20,
            "wall_cells": 2,
            "sample": {"limit": n_limit, "order": "natural"},
        }
    src["plan_names_sha256"] = hashlib.sha256("\n".join(names).encode()).hexdigest()
    return TrainingPlans(corpus, names, src, _extra={"limit": limit})


def sample_indices(n: int, k: int, seed: int) -> list[int]:
    """:func:`ogm_ppl.datasets.floorplans.sample_indices` (the first ``k`` of a seeded permutation of ``n``,
    ascending; nested across ``k``), refusing ``k > n`` with a :class:`FitOptionError` on ``sample``."""
    if k > n:
        raise FitOptionError("sample", f"must be at most the {n} training plans, got {k}")
    from ogm_ppl.datasets.floorplans import sample_indices as draw

    return draw(n, k, seed)


def _sampled_plans(corpus: str, k: int, seed: int) -> TrainingPlans:
    """A random subset of ``k`` of ``corpus``'s training plans (:func:`sample_indices`), in natural order."""
    full = _corpus_plans(corpus, None)
    idx = sample_indices(len(full), k, seed)
    names = tuple(full.names[i] for i in idx)
    src = {
        **full.source,
        "plans": len(names),
        "sample": {"random": k, "seed": seed, "of": len(full), "rule": "sample_indices", "order": "natural"},
        "plan_names_sha256": hashlib.sha256("\n".join(names).encode()).hexdigest(),
    }
    return TrainingPlans(corpus, names, src, _extra={"limit": None, "sample": k, "sample_seed": seed})


def validation_split(n: int, every: int, option: str = "validation_every") -> tuple[list[int], list[int]]:
    """Indices ``(fit, validation)`` of ``n`` plans in their order: plan ``i`` is validation when
    ``i % every == every - 1`` (every ``every``-th plan). Both parts must be non-empty."""
    k = check_int(every, option, 2)
    fit, val = [i for i in range(n) if i % k != k - 1], [i for i in range(n) if i % k == k - 1]
    if not fit or not val:
        raise FitOptionError(option, f"{n} plan(s) give no validation plan every {k}: use at most {max(n, 2)}")
    return fit, val


class FitSetup(NamedTuple):
    """The checked start of a fit validated on held-out plans (:func:`fit_setup`)."""

    out: Path
    plans: TrainingPlans
    #: the files' name part: ``name`` as given, else the corpus, else ``plans``
    label: str
    every: int
    fit_idx: list[int]
    val_idx: list[int]


def fit_setup(
    source: str | PlanPaths | TrainingPlans,
    out_dir: Any,
    name: str | None,
    validation_every: int,
    *,
    limit: int | None = None,
    pixel_size: float | None = None,
    resolution: float = 0.05,
) -> FitSetup:
    """The output folder, the files' name and the validation interval checked before any plan is read, then the
    training plans (:func:`load_training_plans`) and their split (:func:`validation_split`)."""
    out = check_out_dir(out_dir)
    label = check_label(name) if name is not None else None
    every = check_int(validation_every, "validation_every", 2)
    plans = load_training_plans(source, limit=limit, pixel_size=pixel_size, resolution=resolution)
    fit_idx, val_idx = validation_split(len(plans), every)
    return FitSetup(out, plans, label or ("plans" if plans.files else plans.corpus), every, fit_idx, val_idx)


def command(kind: str, plans: TrainingPlans, out_dir: Path, options: Sequence[str] = ()) -> str:
    """The ``ogm-ppl fit-prior`` command line that makes these files (recorded in their provenance)."""
    return shlex.join(["ogm-ppl", "fit-prior", kind, *plans.command_args(), "--out", str(out_dir), *options])


def run_provenance(cmd: str, plans: TrainingPlans, **more: Any) -> dict:
    """:func:`ogm_ppl.provenance.provenance` of ``cmd`` with the plans' ``source`` record and ``more``."""
    from ogm_ppl.provenance import provenance

    return {**provenance(cmd), **plans.source, **more}


@dataclass(frozen=True)
class FitResult:
    """What a fit wrote: ``files`` (in the output folder), the ``provenance`` recorded in them, a ``summary``
    of the fitted values and the wall-clock ``seconds``."""

    kind: str
    files: tuple[Path, ...]
    provenance: dict
    summary: dict
    seconds: float
