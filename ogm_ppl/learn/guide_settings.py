r"""The settings of a corpus guide's training (:func:`~ogm_ppl.learn.guide_training.train_corpus_guide`), checked
in one place.

:class:`GuideTrainingSettings` holds every option of ``ogm-ppl train-guide``: where the maps come from (floor-plan
corpora, plan files of one's own, or both), the simulated sensor (stops or a driven route, beams, field of
view, range in cells or metres, range noise), the network (channels, dilations) and the optimisation (steps,
batch, learning rate, validation, checkpoints, seed). Building one checks them all and raises
:class:`GuideSettingsError` (a :class:`ValueError`) naming the option and its limit, before any map is read;
work too large for memory (:data:`MAX_EXAMPLE_BYTES` of training and validation windows) is refused the same
way.

>>> s = GuideTrainingSettings(corpus="ipa", steps=20, examples=16)
>>> s.corpus, s.range_cells, s.sources
(('ipa',), 75.0, ('ipa',))
>>> GuideTrainingSettings(corpus="ipa", examples=0)
Traceback (most recent call last):
...
ogm_ppl.learn.guide_settings.GuideSettingsError: --examples must be at least 1, got 0
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "BYTES_PER_CELL",
    "CELL_M",
    "CORPORA",
    "FILES_SOURCE",
    "MAX_EXAMPLE_BYTES",
    "MIN_FREE_CELLS",
    "MIN_WINDOW",
    "NAME_PATTERN",
    "GuideSettingsError",
    "GuideTrainingSettings",
]

#: the corpora a guide can be trained on: the thesis's four first, then the larger floor-plan corpora (each
#: one's training split only: :func:`~ogm_ppl.calibration.leakage.guide_plans`)
CORPORA: tuple[str, ...] = ("houseexpo", "ipa", "dungeon", "generated", "houseexpo-full", "r2v", "schools")
#: a guide's own name (``--name``): lower-case letters, digits, ``-`` and ``_``
NAME_PATTERN = re.compile(r"^[a-z0-9][a-z0-9_-]{0,39}$")
#: the label of the plan files of one's own among a guide's sources (and its record's ``corpus``)
FILES_SOURCE = "files"
#: metres per cell of the training maps: the corpora's plans and plan files are read at 0.05 m a cell
CELL_M = 0.05
#: bytes a training window holds per cell: 7 float32 feature channels, the float32 truth, 2 bool masks
BYTES_PER_CELL = 7 * 4 + 4 + 2
#: a training window holds at least this many known free cells, so its side is at least :data:`MIN_WINDOW`
MIN_FREE_CELLS = 200
MIN_WINDOW = math.isqrt(MIN_FREE_CELLS - 1) + 1
#: the most memory the training and validation windows may take: ``(examples + val) * window^2 * BYTES_PER_CELL``
MAX_EXAMPLE_BYTES = 4 * 2**30


class GuideSettingsError(ValueError):
    """An option of a guide's training is out of its range; ``option`` names it (the settings field)."""

    def __init__(self, option: str, message: str) -> None:
        super().__init__(message)
        self.option = option


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


_INT_AT_LEAST_1 = (
    "examples",
    "val",
    "window",
    "beams",
    "channels",
    "steps",
    "batch",
    "eval_every",
    "crops",
    "checkpoint_every",
)


@dataclass(frozen=True)
class GuideTrainingSettings:
    """Every option of a corpus guide's training (``ogm-ppl train-guide``; the flag of field ``f_g`` is
    ``--f-g``).

    Maps: ``corpus`` (names of :data:`CORPORA`; their tables' training plans, or with ``sample = N`` a random
    ``N`` of each corpus's training split, all of a corpus that holds fewer, drawn with ``sample_seed``:
    :func:`~ogm_ppl.calibration.leakage.guide_plans`) and ``plan_files`` (plan files or folders of them,
    :func:`~ogm_ppl.datasets.plan_files.plan_files`; ``pixel_size`` metres per pixel for images). Each
    source's plans, sorted by name, are split: every fifth one a validation plan. ``examples`` training and
    ``val`` validation windows of ``window x window`` cells are shared evenly between the sources. ``name``:
    the guide's name (``guide:NAME``; default the sources joined, ``C1+C2``), its corpora then listed in its
    record only.

    Sensor: ``poses`` stops (0 with ``scan_whole_map``: the route planner's own number), ``beams`` beams a
    full turn, range ``range_cells`` (or ``range_m`` metres at :data:`CELL_M` a cell), Gaussian range noise
    ``sigma`` cells. ``scan_whole_map`` scans each whole map along a planned route (planned for
    ``plan_range_cells``, default the range) and crops ``crops`` windows of it; ``drive`` (path steps in cells,
    one drawn per map) scans while driving that route, ``fov`` degrees ahead.

    Network and optimisation: ``channels`` and ``dilations`` of the guide's network
    (:class:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide`), ``steps`` Adam steps of ``batch``
    windows at learning rate ``lr`` (cosine schedule), validation every ``eval_every`` steps, a checkpoint
    every ``checkpoint_every`` steps, ``seed``; ``temperature``: fit a temperature on the validation windows.

    Raises:
        GuideSettingsError: an option out of range (named, with its limit).
    """

    corpus: tuple[str, ...] = ()
    plan_files: tuple[Path, ...] = ()
    pixel_size: float | None = None
    sample: int | None = None
    sample_seed: int = 0
    name: str | None = None
    examples: int = 600
    val: int = 60
    window: int = 96
    poses: int = 3
    scan_whole_map: bool = False
    drive: tuple[float, ...] | None = None
    fov: float = 360.0
    plan_range_cells: float | None = None
    crops: int = 8
    beams: int = 90
    range_cells: float = 75.0
    range_m: float | None = None
    sigma: float = 1.0
    channels: int = 24
    dilations: tuple[int, ...] = (1, 2, 4, 8, 16, 1)
    steps: int = 2500
    batch: int = 8
    lr: float = 3e-3
    eval_every: int = 100
    seed: int = 0
    temperature: bool = True
    checkpoint_every: int = field(default=100, compare=False)

    def __post_init__(self) -> None:
        def put(name: str, value) -> None:
            object.__setattr__(self, name, value)

        put("corpus", (self.corpus,) if isinstance(self.corpus, str) else tuple(self.corpus))
        files = (self.plan_files,) if isinstance(self.plan_files, (str, os.PathLike)) else self.plan_files
        put("plan_files", tuple(Path(p) for p in files))
        put("dilations", tuple(self.dilations))
        if self.drive is not None:
            put("drive", tuple(float(s) for s in self.drive))
        if self.range_m is not None:
            if not _finite_positive(self.range_m):
                raise GuideSettingsError("range_m", f"--range-m must be a finite range above 0 m, got {self.range_m}")
            cells = self.range_m / CELL_M
            if self.range_cells not in (75.0, cells):
                raise GuideSettingsError("range_m", "give the range once: --range-cells or --range-m, not both")
            put("range_cells", cells)
        self._check()

    # ------------------------------------------------------------------ checks
    def _check(self) -> None:
        from ogm_ppl.inference.variational.amortised_net import _MAX_CHANNELS, _MAX_DILATION, _MAX_LAYERS

        def bad(option: str, message: str) -> GuideSettingsError:
            return GuideSettingsError(option, message)

        unknown = [c for c in self.corpus if c not in CORPORA]
        if unknown:
            raise bad("corpus", f"--corpus {unknown[0]!r} is not a corpus; choose from {', '.join(CORPORA)}")
        if len(set(self.corpus)) != len(self.corpus):
            raise bad("corpus", f"--corpus names a corpus twice: {' '.join(self.corpus)}")
        if not self.sources:
            raise bad("corpus", "no maps to train on: give --corpus, --plan-files or both")
        n = self.sample
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise bad("sample", f"--sample must be a whole number of at least 1 plan, got {self.sample!r}")
        if self.sample is not None and not self.corpus:
            raise bad("sample", "--sample draws from the corpora's training plans: it needs --corpus")
        if isinstance(self.sample_seed, bool) or not isinstance(self.sample_seed, int) or self.sample_seed < 0:
            raise bad("sample_seed", f"--sample-seed must be a whole number of at least 0, got {self.sample_seed!r}")
        if self.sample is None and self.sample_seed != 0:
            raise bad("sample_seed", "--sample-seed needs --sample")
        if self.name is not None:
            if not isinstance(self.name, str) or not NAME_PATTERN.match(self.name):
                raise bad(
                    "name",
                    f"--name must be 1-40 lower-case letters, digits, '-' or '_' (starting with a letter or digit), "
                    f"got {self.name!r}",
                )
            if self.name in CORPORA and self.sources != (self.name,):
                raise bad("name", f"--name {self.name!r} is a corpus's name: a guide named so is learned on it alone")
        for k in _INT_AT_LEAST_1:
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise bad(k, f"{_flag(k)} must be at least 1, got {v!r}")
        if self.window < MIN_WINDOW:
            raise bad(
                "window",
                f"--window must be at least {MIN_WINDOW} cells (a training window holds at least {MIN_FREE_CELLS} "
                f"known free cells), got {self.window}",
            )
        if len(self.sources) > min(self.examples, self.val):
            raise bad("examples", "--examples and --val must give each corpus at least one window")
        if self.poses < 0 or (self.poses == 0 and not self.scan_whole_map):
            raise bad("poses", "--poses must be at least 1 (0, the planner's own number, only with --scan-whole-map)")
        if self.drive is not None and (not self.scan_whole_map or not all(_finite_positive(s) for s in self.drive)):
            raise bad("drive", "--drive needs --scan-whole-map and finite path steps above 0 cells")
        if not 0 < self.fov <= 360:
            raise bad("fov", f"--fov must lie in (0, 360] degrees, got {self.fov}")
        planned = self.plan_range_cells
        if planned is not None and (not self.scan_whole_map or not _finite_positive(planned)):
            raise bad("plan_range_cells", "--plan-range-cells needs --scan-whole-map and a finite range above 0 cells")
        if self.fov != 360 and self.drive is None:
            raise bad("fov", "--fov applies to driven scans only (--drive); the stops scan 360 degrees")
        for k, unit in (("range_cells", " cells"), ("sigma", " cells"), ("lr", "")):
            if not _finite_positive(getattr(self, k)):
                raise bad(k, f"{_flag(k)} must be finite and above 0{unit}, got {getattr(self, k)}")
        if not self.dilations or any(isinstance(d, bool) or not isinstance(d, int) or d < 1 for d in self.dilations):
            raise bad("dilations", f"--dilations must be one or more whole numbers of at least 1, got {self.dilations}")
        if self.channels > _MAX_CHANNELS:  # the network's own limits, by option before any map is read
            raise bad("channels", f"--channels must be at most {_MAX_CHANNELS}, got {self.channels}")
        if len(self.dilations) > _MAX_LAYERS or max(self.dilations) > _MAX_DILATION:
            raise bad(
                "dilations",
                f"--dilations must be at most {_MAX_LAYERS} layers of at most {_MAX_DILATION}, got {self.dilations}",
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise bad("seed", f"--seed must be a whole number of at least 0, got {self.seed!r}")
        if self.pixel_size is not None and (not self.plan_files or not _finite_positive(self.pixel_size)):
            raise bad("pixel_size", "--pixel-size needs --plan-files and a finite size above 0 m")
        need = self.example_bytes
        if need > MAX_EXAMPLE_BYTES:
            raise bad(
                "examples",
                f"--examples {self.examples} and --val {self.val} windows of {self.window} x {self.window} cells "
                f"take {need / 2**30:.1f} GiB, over the limit of {MAX_EXAMPLE_BYTES / 2**30:.0f} GiB: use fewer "
                "windows or a smaller --window",
            )

    # ------------------------------------------------------------------ derived
    @property
    def sources(self) -> tuple[str, ...]:
        """The map sources in order: the corpora, then :data:`FILES_SOURCE` for the plan files (if any)."""
        return self.corpus + ((FILES_SOURCE,) if self.plan_files else ())

    @property
    def label(self) -> str:
        """The guide's name: ``name``, else the sources joined by ``+`` (``houseexpo+ipa``)."""
        return self.name if self.name is not None else "+".join(self.sources)

    @property
    def example_bytes(self) -> int:
        """Memory of the training and validation windows: ``(examples + val) * window^2 * BYTES_PER_CELL``."""
        return (self.examples + self.val) * self.window**2 * BYTES_PER_CELL

    def fingerprint(self) -> str:
        """The settings a checkpoint must share with the run resuming it, as sorted JSON (all but
        ``checkpoint_every``, how often to save)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "checkpoint_every"}
        return json.dumps(d, sort_keys=True, default=str)

    def command(self, out: Path | str | None, ship: bool = False) -> str:
        """The ``ogm-ppl train-guide`` command line that trains with these settings into ``out`` (``ship``:
        into the package's fitted guides), options left at their defaults omitted."""
        words = ["ogm-ppl", "train-guide"]
        default = GuideTrainingSettings(corpus=(CORPORA[0],))
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "range_cells" and self.range_m is not None:
                continue
            if f.name not in ("corpus", "plan_files") and v == getattr(default, f.name):
                continue
            if f.name == "temperature":
                words.append("--no-temperature")
            elif isinstance(v, bool):
                words.append(_flag(f.name))
            elif isinstance(v, tuple):
                if v:
                    words += [_flag(f.name), *(str(x) for x in v)]
            elif v is not None:
                words += [_flag(f.name), str(v)]
        words += ["--ship"] if ship else ["--out", str(out)]
        return shlex.join(words)


def _finite_positive(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
