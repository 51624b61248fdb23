"""The settings of a calibration run (thesis Section 5.2): :class:`CalibrationSettings`, checked when made.

Every option of ``ogm-ppl calibrate`` is a field, with the same default. ``None`` for ``test``, ``train``,
``priors``, ``guides`` and ``plans`` means the protocol's default, which :meth:`CalibrationSettings.resolved`
fills in (with ``quick``, the smoke run's sizes). A value out of range raises
:class:`~ogm_ppl.calibration.errors.SettingsError` naming the field.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ogm_ppl.calibration.chains import KERNELS
from ogm_ppl.calibration.errors import SettingsError
from ogm_ppl.calibration.heldout import DEFAULT_TEST_CORPORA, PLAN_FILES_GUIDE, PLAN_FILES_PRIORS, TEST_CORPORA
from ogm_ppl.calibration.leakage import GUIDE_SYM
from ogm_ppl.calibration.names import default_priors
from ogm_ppl.inference.mcmc.tempering import TEMPERS, geometric_ladder
from ogm_ppl.priors.tables import available_tables

__all__ = ["PLAN_OUTSIDE", "CalibrationSettings", "parse_patch_overrides"]

#: how a plan file's unknown and exterior cells are read: occupied and scored, or unknown (never scored)
PLAN_OUTSIDE: tuple[str, ...] = ("occupied", "unknown")
#: the priors and training corpus of ``quick`` where none are given
QUICK_PRIORS: tuple[str, ...] = ("independent", "mrf", "border")
QUICK_TRAIN: tuple[str, ...] = ("houseexpo",)
#: held-out maps per test corpus when ``plans`` is not given
DEFAULT_PLANS = 2


def _names(v: Sequence[str] | str | None) -> tuple[str, ...] | None:
    if v is None:
        return None
    return (v,) if isinstance(v, str) else tuple(v)


@dataclass(frozen=True)
class CalibrationSettings:
    """The options of a calibration run (:func:`~ogm_ppl.calibration.run.calibrate`).

    What runs: ``test`` corpora (of :data:`~ogm_ppl.calibration.heldout.TEST_CORPORA`; default
    :data:`~ogm_ppl.calibration.heldout.DEFAULT_TEST_CORPORA`, or none with ``plan_files``), the priors
    ``priors`` (kinds or names ``KIND[:CORPUS][@MOD]``; default every kind and ``KIND@cal`` where fitted, or
    :data:`~ogm_ppl.calibration.heldout.PLAN_FILES_PRIORS` with plan files alone) learned on each ``train``
    corpus (default: the shipped table sets of the default test corpora; those of ``houseexpo-full``, ``r2v`` and
    ``schools`` run where named), the corpus guides ``guides`` (``C``, ``C1+C2``, ``C@sym``;
    default none, or :data:`~ogm_ppl.calibration.heldout.PLAN_FILES_GUIDE` with plan files) read from
    ``guide_dir`` (default the shipped ones), ``diagonal`` (each test corpus scored with the priors learned on
    it only), ``plans`` held-out maps per test corpus (default 2; every plan of the plan files).

    The maps and the sensor: ``window`` cells a side, held-out generated maps of ``generated_shape`` cells, a
    route of ``poses`` stops of ``beams`` beams per scan, ranges up to ``range_cells`` with noise ``sigma``
    cells, ``seed``.

    The chains: ``sweeps`` kept sweeps (at least 4: split R-hat halves each chain) after ``burn`` of the
    sampler ``kernel`` (a key of :data:`~ogm_ppl.calibration.chains.KERNELS`); for ``tempering``, ``rungs``
    rungs down to ``beta_min`` in (0, 1) on the factor ``temper``; for ``guided``, the corpus guide
    ``proposal_guide`` (``C``, ``C1+C2``, ``C@sym``, read from ``guide_dir``) proposes blocks of cells;
    ``patch`` overrides per kind (``KIND=RxC`` or ``KIND=1``); a prior whose update weighs more than
    ``max_support`` configurations is skipped; ``bias_file`` runs each prior it names biased beside it.

    Plan files of other buildings: ``plan_files`` (paths or folders), labelled ``plan_set``, images read at
    ``pixel_size`` metres per pixel, unknown cells read as ``plan_outside`` (``occupied`` or ``unknown``).

    The run: ``fresh`` ignores rows already in the output, ``figures`` draws the PNGs, ``quick`` is the smoke
    run (1 map of 48 cells per corpus, 40 sweeps after 10, 3 priors on ``houseexpo``).
    """

    test: tuple[str, ...] | None = None
    train: tuple[str, ...] | None = None
    priors: tuple[str, ...] | None = None
    guides: tuple[str, ...] | None = None
    guide_dir: str | None = None
    diagonal: bool = False
    plans: int | None = None
    window: int = 96
    generated_shape: int = 160
    poses: int = 3
    beams: int = 90
    range_cells: float = 75.0
    sigma: float = 1.0
    sweeps: int = 200
    burn: int = 50
    seed: int = 0
    kernel: str = "gibbs"
    rungs: int = 6
    beta_min: float = 0.1
    temper: str = "prior"
    proposal_guide: str = PLAN_FILES_GUIDE
    patch: tuple[str, ...] = ()
    bias_file: Path | None = None
    max_support: int = 4096
    plan_files: tuple[Path, ...] | None = None
    plan_set: str = "files"
    pixel_size: float | None = None
    plan_outside: str = "occupied"
    fresh: bool = False
    figures: bool = True
    quick: bool = False

    def __post_init__(self) -> None:
        norm = object.__setattr__  # frozen: normalise the given sequences and numbers once
        for f in ("test", "train", "priors", "guides"):
            norm(self, f, _names(getattr(self, f)))
        norm(self, "patch", _names(self.patch) or ())
        if self.plan_files is not None:
            files = (self.plan_files,) if isinstance(self.plan_files, (str, Path)) else self.plan_files
            norm(self, "plan_files", tuple(Path(p) for p in files) or None)
        if self.guide_dir is not None:
            norm(self, "guide_dir", str(self.guide_dir))
        if self.bias_file is not None:
            norm(self, "bias_file", Path(self.bias_file))
        for f in ("range_cells", "sigma", "beta_min"):
            norm(self, f, float(getattr(self, f)))
        if self.pixel_size is not None:
            norm(self, "pixel_size", float(self.pixel_size))
        self.validate()

    def validate(self) -> None:
        """Raise :class:`~ogm_ppl.calibration.errors.SettingsError` for the first setting out of range."""
        for c in self.test or ():
            if c not in TEST_CORPORA:
                raise SettingsError("test", f"{c!r} is not a test corpus ({', '.join(TEST_CORPORA)})")
        if self.kernel not in KERNELS:
            raise SettingsError("kernel", f"{self.kernel!r} is not a sampler ({', '.join(sorted(KERNELS))})")
        if self.temper not in TEMPERS:
            raise SettingsError("temper", f"{self.temper!r} is not one of {', '.join(TEMPERS)}")
        if self.plan_outside not in PLAN_OUTSIDE:
            raise SettingsError("plan_outside", f"{self.plan_outside!r} is not one of {', '.join(PLAN_OUTSIDE)}")
        if self.sweeps < 4:
            raise SettingsError("sweeps", f"must be at least 4 (split R-hat halves each chain), got {self.sweeps}")
        if self.burn < 0:
            raise SettingsError("burn", f"must be at least 0, got {self.burn}")
        for f in ("window", "generated_shape", "poses", "beams", "max_support"):
            if getattr(self, f) < 1:
                raise SettingsError(f, f"must be at least 1, got {getattr(self, f)}")
        for f in ("range_cells", "sigma"):
            if not (math.isfinite(getattr(self, f)) and getattr(self, f) > 0):
                raise SettingsError(f, f"must be a positive number, got {getattr(self, f)}")
        if self.seed < 0:
            raise SettingsError("seed", f"must be at least 0, got {self.seed}")
        if self.kernel == "tempering":
            if self.rungs < 1:
                raise SettingsError("rungs", f"must be at least 1, got {self.rungs}")
            try:
                geometric_ladder(self.rungs, self.beta_min)
            except ValueError as e:
                raise SettingsError("beta_min", str(e)) from None
        if self.kernel == "guided":
            base = self.proposal_guide.removesuffix(GUIDE_SYM) if isinstance(self.proposal_guide, str) else ""
            if not base or "@" in base:
                got = self.proposal_guide
                raise SettingsError("proposal_guide", f"a corpus guide is CORPUS, C1+C2 or C{GUIDE_SYM}, not {got!r}")
        parse_patch_overrides(self.patch)
        if self.plans is not None and self.plans < 1:
            raise SettingsError("plans", f"must be at least 1, got {self.plans}")
        if self.plan_files:
            reserved = {c.lower() for c in TEST_CORPORA} | {"none"}  # "none": the training corpus of OGM's rows
            if self.plan_set.lower() in reserved or not self.plan_set.replace("_", "").replace("-", "").isalnum():
                raise SettingsError(
                    "plan_set", f"{self.plan_set!r}: a name of letters, digits, - and _, not a test corpus nor 'none'"
                )
            if self.pixel_size is not None and not (math.isfinite(self.pixel_size) and self.pixel_size > 0):
                raise SettingsError("pixel_size", f"must be a positive number of metres, got {self.pixel_size}")
        elif self.pixel_size is not None:
            raise SettingsError("pixel_size", "applies to plan_files only")
        elif self.plan_outside != "occupied":
            raise SettingsError("plan_outside", "applies to plan_files only")

    @property
    def maps_per_corpus(self) -> int:
        """Held-out maps per test corpus: ``plans``, else :data:`DEFAULT_PLANS`."""
        return DEFAULT_PLANS if self.plans is None else self.plans

    def resolved(self) -> CalibrationSettings:
        """These settings with the defaults that depend on others filled in: ``quick``'s sizes (over those
        given) and its priors and training corpus (where none are given), the shipped training corpora of the
        default test corpora, every test corpus (none with plan files), the default priors
        (:func:`~ogm_ppl.calibration.names.default_priors`, or :data:`PLAN_FILES_PRIORS` with plan files alone)
        and guides (:data:`PLAN_FILES_GUIDE` with plan files)."""
        s = self
        if s.quick:
            s = dataclasses.replace(  # 1 map of 48 cells per corpus, 40 sweeps after 10, generated maps of 96
                s, plans=1, window=48, sweeps=40, burn=10, generated_shape=96
            )
            s = dataclasses.replace(s, priors=s.priors or QUICK_PRIORS, train=s.train or QUICK_TRAIN)
        train = s.train or tuple(c for c in available_tables() if c in DEFAULT_TEST_CORPORA)
        test = s.test if s.test is not None else (() if s.plan_files else DEFAULT_TEST_CORPORA)
        priors = s.priors
        if priors is None:  # plan files alone: the priors of the results page's buildings in no corpus
            priors = PLAN_FILES_PRIORS if s.plan_files and not test else tuple(default_priors(train))
        guides = s.guides
        if guides is None:  # a building in no corpus: the guide the docs recommend for one runs by default
            guides = (PLAN_FILES_GUIDE,) if s.plan_files else ()
        return dataclasses.replace(s, train=train, test=test, priors=priors, guides=guides)


def parse_patch_overrides(items: Sequence[str]) -> dict[str, tuple[int, int] | None]:
    """``KIND=RxC`` (patches of ``R x C`` cells) or ``KIND=1`` (single cells) per kind, as
    ``{kind: (R, C) or None}``; raises :class:`~ogm_ppl.calibration.errors.SettingsError` (``patch``)."""
    out: dict[str, tuple[int, int] | None] = {}
    for it in items:
        kind, _, spec = it.partition("=")
        try:
            if spec in ("1", "1x1"):
                out[kind] = None
            else:
                r, c = (int(v) for v in spec.lower().split("x"))
                if r < 1 or c < 1:
                    raise ValueError
                out[kind] = (r, c)
        except ValueError:
            raise SettingsError("patch", f"takes KIND=RxC (e.g. border1=3x3) or KIND=1, got {it!r}") from None
    return out
