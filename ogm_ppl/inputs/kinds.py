"""The table of input kinds: how each is told apart, what options it takes, how it is read and what identifies
one input of it (the package docstring, :mod:`ogm_ppl.inputs`, tells the role)."""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl._registry import Registry
from ogm_ppl.datasets.carmen import ScanLog
from ogm_ppl.grid import Grid
from ogm_ppl.options import param_fields, param_groups, parse_params
from ogm_ppl.scans import Scans

__all__ = [
    "SHIPPED_INPUT_KINDS",
    "InputData",
    "InputError",
    "InputKind",
    "check_readable",
    "detect_input_kind",
    "file_identity",
    "get_input_kind",
    "image_kind",
    "input_kinds",
    "read_input",
    "register_input_kind",
    "resume_key",
    "unregister_input_kind",
]

#: the kinds the library ships, in the order they are listed
SHIPPED_INPUT_KINDS: tuple[str, ...] = ("log", "bag", "npz", "simulated")

#: ``read(path, options) -> InputData``: ``path`` is the file or folder (``None`` for a kind that reads none),
#: ``options`` the kind's parsed options dataclass
ReadFunction = Callable[[Any, Any], "InputData"]


class InputError(ValueError):
    """An input that cannot be told apart or read: the message names the path and what is wrong."""


@dataclass(frozen=True)
class InputKind:
    """One kind of input of a mapping run.

    Attributes:
        name: its name (a spec's dataset ``kind``; :func:`read_input`'s ``kind``).
        options: a frozen dataclass whose fields are made with :func:`ogm_ppl.options.param` (name, kind,
            default, doc): every option the kind takes, declared once. Fields of ``group="reader"`` sit in a
            spec entry's ``reader`` table, fields of ``group="thinning"`` (``pose_step``, ``pose_fraction``,
            ``beam_step``) are set by the command line's thinning flags and not by a spec (whose own
            ``pose_fraction`` / ``beam_step`` thin the read scans); the others are the entry's own keys.
            A ``check()`` method checks rules between options, raising :class:`~ogm_ppl.options.ParamError`.
        read: ``read(path, options) -> InputData`` (scans, and a grid and truth where the input has them).
        doc: one line.
        noun: what one input of the kind is, in messages (``"CARMEN log"``; plural: ``noun + "s"``).
        what: the files it reads, in messages (``"a ROS 1 .bag file, or a ROS 2 bag folder ..."``).
        label: the word reports use for it (``ogm-ppl map``'s ``report.json``, ``ogm-ppl info``); default
            ``name``.
        detect: ``detect(path, head) -> bool``: whether a file (``head``: its first 16 bytes) or a folder
            (``head == b""``) is of this kind; ``None``: never told apart by itself (named by a spec or a call).
        detect_last: ``detect`` claims whatever no other kind claimed (a CARMEN log has no magic bytes).
        identify: ``identify(path, options)``: JSON-able identity of what is read, part of :func:`resume_key`;
            default: :func:`file_identity` of ``path`` (``None`` without one).
        reads_file: whether an input of the kind is a file or folder (``False``: the options are the whole
            input, such as a simulated scene).
    """

    name: str
    options: type
    read: ReadFunction
    doc: str
    noun: str
    what: str = ""
    label: str = ""
    detect: Callable[[Path, bytes], bool] | None = None
    detect_last: bool = False
    identify: Callable[[Any, Any], Any] | None = None
    reads_file: bool = True

    def parse(
        self, values: Mapping[str, Any] | None = None, *, text: bool = False, keys: Collection[str] | None = None
    ):
        """The options dataclass from ``values`` (``text``: command-line strings; ``keys``: the options
        ``values`` may set); :class:`~ogm_ppl.options.ParamError` names a bad or unknown key."""
        return parse_params(self.options, values or {}, text=text, keys=keys)

    def option_names(self, group: str | None = None) -> list[str]:
        """The options' names, in declaration order; ``group``: those of that group only."""
        groups = param_groups(self.options)
        return [n for n, *_ in param_fields(self.options) if group is None or groups[n] == group]

    def describe(self) -> list[str]:
        """Lines for the docs and ``--help`` texts: the name, the doc, each option with kind, default, doc."""
        lines = [f"{self.name}: {self.doc}"]
        for name, kind, default, doc in param_fields(self.options):
            lines.append(f"    {name} = {default!r}  ({kind.describe()}) {doc}")
        return lines

    @property
    def report_label(self) -> str:
        return self.label or self.name


@dataclass
class InputData:
    """An input as read: its scans, and what else it holds.

    Attributes:
        kind: the input kind's name.
        path: the file or folder read (``None`` for a kind that reads none).
        scans: the scans (poses in metres and radians, ranges in metres).
        grid: the input's own grid (a dataset file's, a simulated scene's), else ``None``.
        truth: ``grid.shape`` bool ground-truth occupancy where the input has one, else ``None``.
        settings: every option and derived value the reader used (JSON-able).
        record: the reader's own record (a :class:`~ogm_ppl.datasets.CarmenLog` with its bad lines and counts,
            a :class:`~ogm_ppl.datasets.rosbag.BagLog`, a :class:`~ogm_ppl.datasets.Dataset`, ...).
        resume_key: :func:`resume_key` of this read: what a checkpoint or a cached result of it depends on.
    """

    kind: str
    path: Path | None
    scans: Scans
    grid: Grid | None = None
    truth: np.ndarray | None = None
    settings: dict = field(default_factory=dict)
    record: Any = None
    resume_key: dict = field(default_factory=dict)

    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` in metres of the poses and the end points of all hits."""
        return self.scans.extent()

    def covering_grid(self, resolution: float, margin: float = 1.0) -> Grid:
        """A 2D grid of ``resolution`` metres a cell covering :meth:`extent` plus ``margin`` metres on every side
        (as a log's, :meth:`~ogm_ppl.datasets.carmen.ScanLog.grid`)."""
        return ScanLog.grid(self, resolution, margin)  # type: ignore[arg-type]


def _read_function(kind: InputKind) -> Callable:
    return kind.read


_REGISTRY: Registry[InputKind] = Registry("input", SHIPPED_INPUT_KINDS, origin=_read_function)


def register_input_kind(kind: InputKind) -> None:
    """Add ``kind`` to the table. Its name is a non-empty name without ``:``; a name another kind took is
    refused (:func:`unregister_input_kind` first), and a kind whose ``read`` is defined at the same place (a
    module reloaded) replaces the old one. Its options must be :func:`~ogm_ppl.options.param` fields
    (``TypeError`` otherwise). Test it with :class:`~ogm_ppl.testing.InputKindContract`."""
    if not isinstance(kind, InputKind):
        raise TypeError(f"register_input_kind takes an InputKind, got {type(kind).__name__}")
    if not dataclasses.is_dataclass(kind.options):
        raise TypeError(f"input kind {kind.name!r}: options must be a dataclass of param() fields")
    param_fields(kind.options)  # every field made with param(default, kind, doc)
    _REGISTRY.register(kind.name, kind)


def unregister_input_kind(name: str) -> None:
    """Remove a kind of one's own (a shipped kind cannot be removed)."""
    _REGISTRY.unregister(name)


def input_kinds() -> tuple[str, ...]:
    """The registered kinds' names, the shipped ones first."""
    return _REGISTRY.kinds()


def get_input_kind(name: str) -> InputKind:
    """The kind ``name``; a ``ValueError`` lists the kinds (a kind not registered yet first imports the
    extension modules, :func:`ogm_ppl.extensions.load_extensions`)."""
    return _REGISTRY.get(name, name)


def image_kind(head: bytes) -> str | None:
    """``"PNG"``, ``"JPEG"``, ``"PGM"`` (or another netpbm format), ``"GIF"``, ``"TIFF"`` or ``"BMP"`` from a
    file's first bytes; ``None`` for anything else."""
    if head.startswith(b"\x89PNG"):
        return "PNG"
    if head.startswith(b"\xff\xd8"):
        return "JPEG"
    if head[:1] == b"P" and head[1:2] in b"123456" and head[2:3] in b" \t\r\n#":
        return "PGM" if head[1:2] in b"25" else "netpbm"
    if head.startswith(b"GIF8"):
        return "GIF"
    if head[:4] in (b"II*\x00", b"MM\x00*"):
        return "TIFF"
    if head.startswith(b"BM"):
        return "BMP"
    return None


def check_readable(path: str | os.PathLike) -> bytes:
    """The first 16 bytes of the file ``path``; :class:`InputError` if it is missing, a folder or unreadable."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a log or dataset file")
    try:
        with open(path, "rb") as f:
            return f.read(16)
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror or e})") from None


def detect_input_kind(path: str | os.PathLike) -> str:
    """The kind of the file or folder ``path``, told apart by its kinds' ``detect`` (magic bytes, not names):
    the kinds of one's own first, the shipped ones after them, a ``detect_last`` kind (the CARMEN log) last.
    :class:`InputError` names a missing or unreadable file, a folder or an image no kind reads."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    head = b"" if path.is_dir() else check_readable(path)
    kinds = [get_input_kind(n) for n in input_kinds()]
    order = sorted(kinds, key=lambda k: (k.detect_last, k.name in SHIPPED_INPUT_KINDS))
    for kind in order:
        if kind.detect is not None and kind.detect(path, head):
            return kind.name
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a log or dataset file")
    image = image_kind(head)
    if image:
        raise InputError(
            f"{path}: a {image} image (a floor plan?), not a log, bag or dataset file; ogm-ppl simulate "
            "--map PLAN.png scans a plan into a dataset that ogm-ppl map reads"
        )
    readers = [k.name for k in kinds if k.detect is not None]
    raise InputError(f"{path}: no input kind reads it (kinds told apart by their files: {', '.join(readers)})")


def file_identity(path: str | os.PathLike) -> list:
    """What identifies a file as it is now: ``[resolved path, size in bytes, modification time in ns]``; for a
    folder (a ROS 2 bag) the resolved path and that of each file in it, in name order."""
    path = Path(path).resolve()
    if path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file())
        return [str(path), [[str(p.relative_to(path)), p.stat().st_size, p.stat().st_mtime_ns] for p in files]]
    st = path.stat()
    return [str(path), st.st_size, st.st_mtime_ns]


def _jsonable(value):
    return json.loads(json.dumps(value, default=str))


def resume_key(kind: str | InputKind, path: str | os.PathLike | None, options) -> dict:
    """What a result computed from an input depends on: ``{"kind", "source", "options"}``, JSON-able.
    ``source`` is the kind's ``identify(path, options)`` (by default :func:`file_identity`: the same file,
    unchanged), ``options`` every option's value (a dataclass of the kind's options). ``ogm-ppl map`` keys
    its chains' checkpoints with it, an experiment its base tasks."""
    k = get_input_kind(kind) if isinstance(kind, str) else kind
    if k.identify is not None:
        source = k.identify(path, options)
    else:
        source = file_identity(path) if path is not None else None
    return {"kind": k.name, "source": _jsonable(source), "options": _jsonable(dataclasses.asdict(options))}


def read_input(
    kind: str | None = None, path: str | os.PathLike | None = None, options: Mapping[str, Any] | Any = None
) -> InputData:
    """Read an input: ``kind`` (``None``: told apart by :func:`detect_input_kind`), the file or folder
    ``path`` (``None`` for a kind that reads none) and ``options`` (a mapping checked by the kind's options
    dataclass, :class:`~ogm_ppl.options.ParamError` naming a bad key; or that dataclass). Returns the
    :class:`InputData` with its :func:`resume_key`.

    >>> data = read_input("simulated", None, {"size": 60, "border": 5, "poses": 2, "beams": 36})
    >>> data.scans.beams_per_scan, data.truth.shape, data.resume_key["kind"]
    (36, (60, 60), 'simulated')
    """
    if kind is None:
        if path is None:
            raise InputError("read_input: give a kind or a path to tell it from")
        kind = detect_input_kind(path)
    k = get_input_kind(kind)
    if k.reads_file and path is None:
        raise InputError(f"input kind {k.name!r} reads a {k.noun}: give its path")
    opts = options if isinstance(options, k.options) else k.parse(options)
    p = None if path is None else Path(path)
    data = k.read(p, opts)
    if not isinstance(data, InputData):
        raise TypeError(f"input kind {k.name!r}: read returned {type(data).__name__}, not InputData")
    data.kind, data.path = k.name, p
    data.resume_key = resume_key(k, p, opts)
    return data
