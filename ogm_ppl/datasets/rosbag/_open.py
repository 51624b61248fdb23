"""Opening a bag: its kind from the magic bytes, a ``rosbags`` reader (or a record-by-record one in lenient
mode) and its topics."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from ogm_ppl.datasets.rosbag._errors import BagFormatError, _library_errors
from ogm_ppl.datasets.rosbag._mcap import _MCAP_MAGIC, _LinearMcap, _mcap_file
from ogm_ppl.datasets.rosbag._ros1 import _ROS1_MAGIC, _LinearRos1

_SQLITE_MAGIC = b"SQLite format 3\x00"


def bag_kind(path: str | os.PathLike) -> str | None:
    """``"ros1"``, ``"sqlite3"`` or ``"mcap"`` for a ROS 1 bag file, a ROS 2 bag folder (its
    ``metadata.yaml`` names the storage) or a bare ROS 2 ``.db3`` / ``.mcap`` file; None otherwise.
    Told apart by the files' magic bytes, not their names."""
    path = Path(path)
    if path.is_dir():
        meta = path / "metadata.yaml"
        if not meta.is_file():
            return None
        try:
            text = meta.read_text(errors="replace")
        except OSError:
            return None
        return "mcap" if "storage_identifier: mcap" in text else "sqlite3"
    try:
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError:
        return None
    if head.startswith(_ROS1_MAGIC):
        return "ros1"
    if head.startswith(_SQLITE_MAGIC):
        return "sqlite3"
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    return None


@contextmanager
def _open_reader(path: Path, lenient: bool = False) -> Iterator[tuple[object, str]]:
    """An open ``rosbags`` AnyReader of ``path`` and its storage kind; with ``lenient``, a ROS 1 bag whose
    index is missing or damaged (or whose name does not end in ``.bag``) is read by :class:`_LinearRos1`."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not path.exists():
        raise BagFormatError(path, "no such file or folder")
    kind = bag_kind(path)
    if kind is None:
        raise BagFormatError(
            path,
            "not a ROS bag (expected a ROS 1 .bag file, or a ROS 2 bag folder with metadata.yaml or its .db3/.mcap)",
        )
    if kind == "ros1" and path.suffix != ".bag":
        if lenient:
            yield _linear(path, kind), kind
            return
        raise BagFormatError(
            path, "a ROS 1 bag must have the suffix .bag (strict=False / --lenient reads it record by record)"
        )
    if not path.is_dir() and kind != "ros1" and path.suffix != {"sqlite3": ".db3", "mcap": ".mcap"}[kind]:
        raise BagFormatError(
            path, f"a bare ROS 2 {kind} file must have the suffix {'.db3' if kind == 'sqlite3' else '.mcap'}"
        )
    hint = "cannot open the bag" + (
        " (a ROS 1 bag cut short has no index: strict=False / --lenient reads it record by record)"
        if kind == "ros1"
        else " (an MCAP file cut short has no summary: strict=False / --lenient reads it record by record)"
        if kind == "mcap"
        else ""
    )
    try:
        with _library_errors(path, hint):
            reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
            reader.open()
    except BagFormatError:
        if not (lenient and (kind == "ros1" or (kind == "mcap" and _mcap_file(path) is not None))):
            raise
        yield _linear(path, kind), kind
        return
    try:
        yield reader, kind
    finally:
        with suppress(Exception):  # closing a half-read corrupted file may fail again; the first error counts
            reader.close()


def _linear(path: Path, kind: str) -> _LinearRos1:
    if kind == "mcap":
        mcap = _mcap_file(path)
        assert mcap is not None
        linear: _LinearRos1 = _LinearMcap(mcap)
    else:
        linear = _LinearRos1(path)
    if not linear.connections:
        raise BagFormatError(path, f"no connection records found reading record by record ({linear.note})")
    what = "index" if kind == "ros1" else "summary"
    linear.note = f"no usable {what}, read record by record" + (
        f"; reading stopped {linear.note}" if linear.note else ""
    )
    return linear


def bag_topics(path: str | os.PathLike) -> list[tuple[str, str, int]]:
    """``(topic, message type, message count)`` of every topic of a bag, sorted by topic."""
    path = Path(path)
    with _open_reader(path) as (reader, _):
        with _library_errors(path, "cannot list the topics"):
            return sorted(
                (name, str(info.msgtype), int(info.msgcount))
                for name, info in reader.topics.items()  # type: ignore[attr-defined]
            )
