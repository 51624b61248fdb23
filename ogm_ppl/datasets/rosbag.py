r"""Read laser scans and poses from ROS bags (ROS 1 ``.bag``, ROS 2 sqlite3 and MCAP) into
:class:`~ogm_ppl.scans.Scans`, with the conventions of :func:`~ogm_ppl.datasets.carmen.read_carmen`.

The bags are read with the pure-Python ``rosbags`` library (no ROS install). One
``sensor_msgs/LaserScan`` topic gives the scans; the laser's pose at each scan comes from a pose topic
(``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or ``geometry_msgs/PoseWithCovarianceStamped``)
or from the transform tree of ``/tf`` and ``/tf_static``.

**Beams.** Beam ``i`` of a scan of ``n`` beams points at ``angle_min + i * angle_increment`` relative
to the laser's heading (the formula of :func:`~ogm_ppl.datasets.carmen.flaser_angles`). LaserScan
stores its fields as float32; a float32 ``angle_min`` / ``angle_increment`` that is the float32 rounding
of ``p * pi / q`` (``q <= 1440``: 1, 0.5, 0.25, 360/1024 degrees, ...) is read as that float64 value, the
laser's own geometry, and other float32 values (ranges, range limits, other angles) are widened through
their shortest decimal representation (``widen="decimal"``: a driver that wrote 1.23 m stored
float32(1.23), and 1.23 is read back; ``widen="binary"`` keeps the float32 value itself). A log written
with decimals therefore reads back bit for bit.

**No return and out of range** (REP 117 and the CARMEN rule together). A beam is *no-return* when its
range is NaN (invalid measurement), +Inf (nothing within range) or ``>= range_max`` of its message (the
ROBOTLASER1 rule of the CARMEN reader: drivers report misses at or above ``range_max``), or ``>=
no_return_threshold`` when that is given. ``no_return="drop"`` (default, thesis Section 6.2) marks such
beams invalid; ``"max"`` makes them max-range readings. -Inf and ranges below the message's
``range_min`` (or the ``min_range`` option) are *below minimum* and invalid. ``max_usable_range`` drops
or clips every other reading at or beyond it. The ``max_range`` given to :class:`Scans` is
``max_range`` if given, else ``max_usable_range``, else the largest ``range_max`` of the scans.

**Poses.** Stamps are the messages' ``header.stamp`` (nanoseconds). The pose of each scan is interpolated
between the last pose sample at or before its stamp and the first at or after it: linear in position
and along the shortest arc in yaw (for a transform tree, each dynamic link is interpolated, its rotation
by slerp, and the links composed in 3D, as tf2 does; the 2D pose is the laser origin's ``x, y`` in the
map frame and the yaw of its rotation). A scan whose stamp is more than ``pose_tolerance`` seconds from
either bracketing sample (or that lies outside the samples) has no pose; it is dropped and counted
(``counts["no_pose"]``). A pose topic gives the robot's pose; ``laser_offset = (x, y, yaw)`` moves it to
the laser (in the robot frame). With ``tf=True`` the chain ``map_frame -> ... -> laser frame`` (the
scans' ``header.frame_id``) is followed through every link, the static laser mounting included; a laser
mounted upside down (its z axis pointing down) has its beam angles negated.

**Errors.** With ``strict=True`` (default) the first malformed message raises :class:`BagFormatError`
naming the file, the topic, the 0-based message index on that topic and the field. With ``strict=False``
a malformed message is skipped and listed in ``bad_messages``; when the storage itself fails part way
(a truncated or corrupted file), every message read before is kept and ``bad_messages`` says where
reading stopped. A ROS 1 bag without a usable index (a recording cut short, ``.bag.active``) or an MCAP
file without its summary is read record by record in lenient mode, keeping every message before the cut;
strict mode refuses it. Other files that cannot be opened (not a bag, a damaged sqlite3 database,
unreadable metadata) raise in both modes.
"""

from __future__ import annotations

import itertools
import math
import os
import shutil
import tempfile
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.carmen import ScanLog, _kept_scans, beam_rules
from ogm_ppl.scans import Scans

__all__ = ["BagFormatError", "BagLog", "bag_info", "bag_kind", "bag_topics", "read_bag", "typestore", "write_bag"]

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POSE_TYPES = (ODOMETRY, POSE_STAMPED, POSE_COV_STAMPED)
STORAGES = ("ros1", "sqlite3", "mcap")
_MAX_BEAMS = 100_000
_MAX_DENOMINATOR = 1440  # pi / 1440 = 0.125 degrees
_ROS1_MAGIC = b"#ROSBAG V2.0\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_MCAP_MAGIC = b"\x89MCAP0\r\n"


class BagFormatError(ValueError):
    """A bag that cannot be read or a malformed message; ``str`` names the file, the topic, the 0-based
    message index on that topic and the field (the parts that apply)."""

    def __init__(
        self,
        path: str | os.PathLike,
        message: str,
        *,
        topic: str | None = None,
        index: int | None = None,
        field: str | None = None,
    ) -> None:
        self.path, self.topic, self.index, self.field, self.message = str(path), topic, index, field, message
        where = [self.path]
        if topic is not None:
            where.append(f"topic {topic}")
        if index is not None:
            where.append(f"message {index}")
        if field is not None:
            where.append(f"field {field!r}")
        super().__init__(", ".join(where) + f": {message}")


@dataclass
class BagLog(ScanLog):
    """Scans read from a bag (every rule applied is in the module docstring).

    Attributes:
        scans: the scans that have a pose, in bag order (receive time), with ``scans.valid`` marking dropped beams.
        path: the bag read; ``storage``: ``"ros1"``, ``"sqlite3"`` or ``"mcap"``.
        scan_topic, pose_source: the LaserScan topic, and the pose topic or ``"tf"``.
        bad_messages: ``(topic, index, reason)`` of every message skipped as malformed (lenient mode).
        max_range: the ``max_range`` given to :class:`Scans` (metres).
        settings: every option and derived value used (JSON-serialisable).
        message_indices: ``S`` 0-based index of each kept scan on the scan topic.
        timestamps: ``S`` scan stamps in seconds; ``pose_timestamps``: the stamps of the pose samples
            (of the first dynamic link for ``tf``).
        counts: ``scans_read``, ``no_pose`` (scans dropped for want of a pose), ``pose_samples``, and beams
            per outcome as :class:`~ogm_ppl.datasets.carmen.CarmenLog`: ``beams``, ``valid``, ``no_return``,
            ``beyond_usable``, ``below_min``, ``max_range_readings`` (of the kept scans).
    """

    scans: Scans
    path: str
    storage: str
    scan_topic: str
    pose_source: str
    bad_messages: list[tuple[str, int, str]]
    max_range: float
    settings: dict
    message_indices: np.ndarray = field(repr=False)
    timestamps: np.ndarray = field(repr=False)
    pose_timestamps: np.ndarray = field(repr=False)
    counts: dict[str, int] = field(default_factory=dict)


# ------------------------------------------------------------------------------------- opening
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
def _library_errors(path: Path, what: str, **where) -> Iterator[None]:
    """Turn any error of the bag library (whose types vary by storage: sqlite, YAML, struct, zstd,
    KeyError on a corrupted index, ...) into one :class:`BagFormatError` naming the file."""
    try:
        yield
    except BagFormatError:
        raise
    except (MemoryError, RecursionError):
        raise BagFormatError(path, f"{what}: the file is corrupted (implausible sizes)", **where) from None
    except Exception as e:
        text = " ".join(str(e).split())[:300] or type(e).__name__
        raise BagFormatError(path, f"{what}: {text}", **where) from None


class _LinearRos1:
    """A ROS 1 bag read record by record from its start, without the index at its end (lenient mode):
    a recording cut short (``.bag.active``, a full disk, a crash) keeps every message before the cut; in
    an uncompressed chunk, every whole record of it. ``note`` says where reading stopped. Serves the
    subset of ``AnyReader`` that :func:`read_bag` uses."""

    def __init__(self, path: Path) -> None:
        import io
        import struct
        from types import SimpleNamespace

        from rosbags.rosbag1.reader import Header, RecordType, decompressors, normalize, read_bytes, read_uint32
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        from rosbags.typesys.msg import normalize_msgtype

        conns: dict[int, SimpleNamespace] = {}
        self._msgs: list[tuple[int, int, bytes]] = []
        self.note: str | None = None

        def records(src, end: int, chunk: int | None) -> None:  # chunk: the file offset of the chunk read
            while src.tell() < end:
                pos = src.tell()
                try:
                    header = Header.read(src)
                    op = header.get_uint8("op")
                    size = read_uint32(src)
                    if op == RecordType.CHUNK and header.get_string("compression") == "none":
                        data = src.read(size)  # a cut chunk: its whole records
                        records(io.BytesIO(data), len(data), pos)
                        if len(data) < size:
                            raise ValueError(f"chunk cut short ({len(data)} of {size} bytes)")
                        continue
                    data = read_bytes(src, size)
                    if op == RecordType.CHUNK:
                        data = decompressors[header.get_string("compression")](data)
                        records(io.BytesIO(data), len(data), pos)
                    elif op == RecordType.CONNECTION:
                        c = Header.read(io.BytesIO(struct.pack("<I", len(data)) + data))
                        conns[header.get_uint32("conn")] = SimpleNamespace(
                            topic=normalize(header.get_string("topic")),
                            msgtype=normalize_msgtype(c.get_string("type")),
                            msgdef=c.get_string("message_definition"),
                        )
                    elif op == RecordType.MSGDATA:
                        self._msgs.append((header.get_uint32("conn"), header.get_time("time"), data))
                except Exception as e:
                    if self.note is None:
                        where = f"at byte {pos}" if chunk is None else f"in the chunk at byte {chunk}, {pos} bytes in"
                        self.note = f"{where}: {' '.join(str(e).split())[:200] or type(e).__name__}"
                    if chunk is not None:
                        raise
                    return

        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            end = f.tell()
            f.seek(len(_ROS1_MAGIC))
            with suppress(Exception):
                records(f, end, None)
        self.connections = list(conns.values())
        self._by_id = conns
        typs: dict = {}
        for c in self.connections:
            with suppress(Exception):  # a definition that does not parse: its messages fail to decode, counted
                typs.update(get_types_from_msg(c.msgdef, c.msgtype))
        self.typestore = get_typestore(Stores.EMPTY)
        self.typestore.register(typs)

    @property
    def topics(self) -> dict:
        from types import SimpleNamespace

        count: dict[int, int] = defaultdict(int)
        for cid, _, _ in self._msgs:
            count[cid] += 1
        out: dict = {}
        for cid, c in self._by_id.items():
            t = out.setdefault(c.topic, SimpleNamespace(msgtype=c.msgtype, msgcount=0))
            t.msgcount += count[cid]
        return out

    def messages(self, connections):
        wanted = {id(c) for c in connections}
        for cid, t, raw in sorted(self._msgs, key=lambda m: m[1]):
            c = self._by_id.get(cid)
            if c is not None and id(c) in wanted:
                yield c, t, raw

    def deserialize(self, raw: bytes, msgtype: str):
        return self.typestore.deserialize_ros1(raw, msgtype)


class _LinearMcap(_LinearRos1):
    """An MCAP file read record by record from its start, without the summary at its end (lenient
    mode): a ROS 2 recording cut short keeps every message before the cut (every whole record of an
    uncompressed chunk). Same interface as :class:`_LinearRos1`; messages are CDR."""

    def __init__(self, path: Path) -> None:
        import io
        import struct
        from types import SimpleNamespace

        from rosbags.rosbag2.storage_mcap import DECOMPRESSORS
        from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

        schemas: dict[int, tuple[str, str, str]] = {}
        conns: dict[int, SimpleNamespace] = {}
        self._msgs: list[tuple[int, int, bytes]] = []
        self.note: str | None = None

        def take(src, n: int) -> bytes:
            b = src.read(n)
            if len(b) != n:
                raise ValueError(f"record cut short ({len(b)} of {n} bytes)")
            return b

        def string(src) -> str:
            return take(src, struct.unpack("<I", take(src, 4))[0]).decode()

        def records(src, end: int, chunk: int | None) -> None:
            while src.tell() < end:
                pos = src.tell()
                try:
                    op = take(src, 1)[0]
                    size = struct.unpack("<Q", take(src, 8))[0]
                    if op == 0x06:  # chunk
                        head = io.BytesIO(take(src, 28))
                        _, _, usize, _ = struct.unpack("<QQQI", head.read(28))
                        comp = string(src)
                        rsize = struct.unpack("<Q", take(src, 8))[0]
                        if comp == "":
                            data = src.read(rsize)
                            records(io.BytesIO(data), len(data), pos)
                            if len(data) < rsize:
                                raise ValueError(f"chunk cut short ({len(data)} of {rsize} bytes)")
                        else:
                            data = DECOMPRESSORS[comp](take(src, rsize), usize)
                            records(io.BytesIO(data), len(data), pos)
                        continue
                    body = io.BytesIO(take(src, size))
                    if op == 0x03:  # schema
                        sid = struct.unpack("<H", body.read(2))[0]
                        name, enc = string(body), string(body)
                        schemas[sid] = (name, enc, take(body, struct.unpack("<I", take(body, 4))[0]).decode())
                    elif op == 0x04:  # channel
                        cid, sid = struct.unpack("<HH", body.read(4))
                        topic = string(body)
                        sch = schemas.get(sid, ("", "", ""))
                        conns[cid] = SimpleNamespace(topic=topic, msgtype=sch[0], msgdef=sch[2], fmt=sch[1])
                    elif op == 0x05:  # message
                        cid, _, log_time, _ = struct.unpack("<HIQQ", take(body, 22))
                        self._msgs.append((cid, log_time, body.read()))
                    elif op == 0x02:  # footer: the end
                        return
                except Exception as e:
                    if self.note is None:
                        where = f"at byte {pos}" if chunk is None else f"in the chunk at byte {chunk}, {pos} bytes in"
                        self.note = f"{where}: {' '.join(str(e).split())[:200] or type(e).__name__}"
                    if chunk is not None:
                        raise
                    return

        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            end = f.tell()
            f.seek(len(_MCAP_MAGIC))
            with suppress(Exception):
                records(f, end, None)
        self.connections = list(conns.values())
        self._by_id = conns
        typs: dict = {}
        for c in self.connections:
            with suppress(Exception):  # a definition that does not parse: its messages fail to decode, counted
                typs.update(get_types_from_idl(c.msgdef) if "idl" in c.fmt else get_types_from_msg(c.msgdef, c.msgtype))
        self.typestore = get_typestore(Stores.EMPTY)
        self.typestore.register(typs)

    def deserialize(self, raw: bytes, msgtype: str):
        return self.typestore.deserialize_cdr(raw, msgtype)


def _mcap_file(path: Path) -> Path | None:
    """The .mcap file of a bag path: itself, or the only one in a bag folder."""
    if path.is_file():
        return path
    files = sorted(path.glob("*.mcap"))
    return files[0] if len(files) == 1 else None


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


def bag_info(
    path: str | os.PathLike, scan_topic: str | None = None, *, laser: bool = True, strict: bool = True
) -> dict:
    """What a bag holds, without poses: its storage, topics, and the laser geometry of ``scan_topic``
    (default: the bag's only LaserScan topic, if it has one): scans, beam counts, angular increments,
    first and last beam angles, ``range_min`` / ``range_max`` values, the no-return beams (NaN, +Inf,
    ``>= range_max``), the stamps' duration and the scan rate; and the candidate pose sources. Malformed
    scan messages are counted, not raised (``bad_scans``). Angles in radians, ranges in metres.
    ``laser=False``: the storage and topics only; ``strict=False``: a ROS 1 bag without its index is read
    record by record (:func:`read_bag`)."""
    path = Path(path)
    with _open_reader(path, lenient=not strict) as (reader, kind):
        with _library_errors(path, "cannot list the topics"):
            topics = sorted((n, str(i.msgtype), int(i.msgcount)) for n, i in reader.topics.items())  # type: ignore[attr-defined]
        lasers = [t for t, typ, _ in topics if typ == LASER_SCAN]
        info: dict = {
            "storage": kind,
            "topics": [{"topic": t, "type": typ, "messages": n} for t, typ, n in topics],
            "laser_topics": lasers,
            "pose_topics": [t for t, typ, _ in topics if typ in POSE_TYPES],
            "tf": any(t in ("/tf", "/tf_static") and typ == TF_MESSAGE for t, typ, _ in topics),
        }
        if not laser:
            return info
        if scan_topic is None:
            if len(lasers) != 1:
                return info
            scan_topic = lasers[0]
        conns = _connections(path, reader, scan_topic, (LASER_SCAN,), "scan")
        recs: list[tuple] = []
        bad: list[tuple[str, int, str]] = []
        _read_messages(path, reader, conns, False, bad, lambda t, i, m, msg: recs.append(_scan_record(msg, "decimal")))
    info["scan_topic"] = scan_topic
    info["scans"] = len(recs)
    info["bad_scans"] = len(bad)
    if not recs:
        return info
    n = np.array([len(r[6]) for r in recs])
    inc = np.array([r[3] for r in recs])
    first = np.array([r[2] for r in recs])
    last = first + inc * (n - 1)
    stamps = np.array([r[0] for r in recs], dtype=np.int64) / 1e9
    thr = np.array([r[5] for r in recs])
    no_ret = sum(int((np.isnan(r[6]) | (r[6] >= np.float32(r[5]))).sum()) for r in recs)
    span = float(stamps.max() - stamps.min())
    info.update(
        beams_per_scan=sorted({int(v) for v in n}),
        angle_increment=sorted({float(v) for v in inc})[:10],
        first_angle=float(first.min()),
        last_angle=float(last.max()),
        field_of_view=float((last - first).max()),
        range_min=sorted({float(r[4]) for r in recs})[:10],
        range_max=sorted({float(v) for v in thr})[:10],
        no_return_beams=no_ret,
        beams=int(n.sum()),
        duration=span,
        scan_rate_hz=(len(recs) - 1) / span if span > 0 else None,
        frames=sorted({r[1] for r in recs}),
    )
    return info


# ------------------------------------------------------------------------------------- numbers
_ANGLE_CACHE: dict[float, float] = {}


def _widen(v: float, widen: str) -> float:
    """A float32 value as float64: its shortest decimal (``"decimal"``) or itself (``"binary"``)."""
    f = np.float32(v)
    return float(f) if widen == "binary" or not np.isfinite(f) else float(str(f))


def _angle64(v: float, widen: str) -> float:
    """A float32 angle as float64: ``p * pi / q`` when its float32 rounding is ``v`` (``q <= 1440``),
    else :func:`_widen` (module docstring)."""
    key = float(v)
    hit = _ANGLE_CACHE.get(key)
    if hit is not None and widen == "decimal":
        return hit
    out = _widen(v, widen)
    if widen == "decimal" and math.isfinite(key):
        fr = Fraction(key / math.pi).limit_denominator(_MAX_DENOMINATOR)
        cand = fr.numerator * math.pi / fr.denominator
        if np.float32(cand) == np.float32(key):
            out = cand
        if len(_ANGLE_CACHE) < 10_000:
            _ANGLE_CACHE[key] = out
    return out


def _widen_array(a: np.ndarray, widen: str) -> np.ndarray:
    """float32 values as float64: themselves (``"binary"``) or their shortest decimal (``"decimal"``): the
    decimal of ``d = 1..9`` significant digits nearest to the value, for the smallest ``d`` whose float32
    rounding is the value (what ``str(np.float32(v))`` prints). Vectorised over ``d`` for magnitudes
    ``1e-13 .. 1e14``, where every power of ten used is exact in float64 and so the rounding is exact;
    other values go through the string."""
    f = np.asarray(a, dtype=np.float32)
    shape = f.shape
    f = f.ravel()
    with np.errstate(invalid="ignore"):  # signalling NaN payloads
        x = f.astype(np.float64)
    if widen == "binary":
        return x.reshape(shape)
    out = x.copy()
    with np.errstate(all="ignore"):
        e_all = np.floor(np.log10(np.abs(x)))
    fast = np.isfinite(x) & (x != 0) & (e_all >= -13) & (e_all <= 13)
    idx = np.flatnonzero(fast)
    xs, fs = x[idx], f[idx]
    e = e_all[idx].astype(np.int64)
    res, done = xs.copy(), np.zeros(len(idx), dtype=bool)
    for d in range(1, 10):
        k = d - 1 - e  # round to k decimals: |k| <= 21, 10^|k| exact
        p10 = 10.0 ** np.abs(k)
        with np.errstate(all="ignore"):
            y = np.where(k >= 0, np.round(xs * p10) / p10, np.round(xs / p10) * p10)
        ok = ~done & (y.astype(np.float32) == fs)
        res[ok], done = y[ok], done | ok
        if done.all():
            break
    res[~done] = fs[~done].astype(str).astype(np.float64)  # not reached: 9 digits always round-trip
    out[idx] = res
    other = np.isfinite(x) & (x != 0) & ~fast
    if other.any():
        out[other] = f[other].astype(str).astype(np.float64)
    return out.reshape(shape)


def _yaw(qx, qy, qz, qw):
    """Yaw (rotation about z) of unit quaternions: ``atan2(2 (w z + x y), 1 - 2 (y^2 + z^2))``."""
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of quaternions ``(..., 4)`` stored ``(x, y, z, w)``."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def _qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` rotated by unit quaternions ``q``: ``v + 2 w (u x v) + 2 u x (u x v)``, ``u = q.xyz``."""
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Shortest-arc spherical interpolation of unit quaternions (rows), weights ``w`` in [0, 1]."""
    d = np.sum(q0 * q1, axis=-1)
    q1 = np.where((d < 0)[:, None], -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-9
    with np.errstate(all="ignore"):
        a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / s)
        b = np.where(small, w, np.sin(w * theta) / s)
    q = a[:, None] * q0 + b[:, None] * q1
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where((w == 0)[:, None], q0, q)


def _bracket(samples: np.ndarray, t: np.ndarray, tol_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For each stamp ``t``: the last sample ``i0`` at or before it, the first ``i1`` at or after it,
    the weight ``w = (t - s[i0]) / (s[i1] - s[i0])`` (0 when they coincide) and whether both lie within
    ``tol_ns``. ``samples`` sorted (int64 ns)."""
    n = len(samples)
    i1 = np.searchsorted(samples, t, side="left")
    i0 = np.searchsorted(samples, t, side="right") - 1
    ok = (i0 >= 0) & (i1 < n)
    i0c, i1c = np.clip(i0, 0, max(n - 1, 0)), np.clip(i1, 0, max(n - 1, 0))
    if n:
        s0, s1 = samples[i0c], samples[i1c]
        ok &= (t - s0 <= tol_ns) & (s1 - t <= tol_ns)
        span = (s1 - s0).astype(np.float64)
        with np.errstate(all="ignore"):
            w = np.where(span > 0, (t - s0).astype(np.float64) / np.where(span > 0, span, 1.0), 0.0)
    else:
        w = np.zeros(len(t))
    return i0c, i1c, w, ok


# ------------------------------------------------------------------------------------- messages
class _MsgError(Exception):
    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field, self.message = field, message


def _stamp(header) -> int:
    sec, nsec = int(header.stamp.sec), int(header.stamp.nanosec)
    if not 0 <= nsec < 1_000_000_000:
        raise _MsgError("header.stamp.nanosec", f"{nsec} is not in [0, 1e9)")
    return sec * 1_000_000_000 + nsec


def _finite(v, name: str) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise _MsgError(name, f"expected a number, got {v!r}") from None
    if not math.isfinite(x):
        raise _MsgError(name, f"{x!r} is not finite")
    return x


def _quat(o, name: str) -> np.ndarray:
    q = np.array([_finite(getattr(o, k), f"{name}.{k}") for k in ("x", "y", "z", "w")])
    norm = float(np.linalg.norm(q))
    if not 0.5 < norm < 1.5:
        raise _MsgError(name, f"not a rotation (quaternion norm {norm:.3g})")
    return q / norm


def _scan_record(msg, widen: str) -> tuple:
    """``(stamp ns, frame, angle_min, angle_increment, range_min, range_max, ranges float32)``."""
    stamp = _stamp(msg.header)
    r = np.asarray(msg.ranges)
    n = r.shape[0] if r.ndim == 1 else 0
    if r.ndim != 1 or n == 0:
        raise _MsgError("ranges", "a scan needs at least one beam")
    if n > _MAX_BEAMS:
        raise _MsgError("ranges", f"{n} beams, more than {_MAX_BEAMS}")
    amin = _finite(msg.angle_min, "angle_min")
    inc = _finite(msg.angle_increment, "angle_increment")
    amax = _finite(msg.angle_max, "angle_max")
    if inc == 0 and n > 1:
        raise _MsgError("angle_increment", f"is 0 for {n} beams")
    if abs(amin + (n - 1) * inc - amax) > 1.01 * abs(inc) + 1e-5:  # some drivers are one increment off
        raise _MsgError(
            "angle_max",
            f"{amax!r} does not match angle_min + (n - 1) * angle_increment = {amin + (n - 1) * inc!r} ({n} beams)",
        )
    rmin = _finite(msg.range_min, "range_min")
    rmax = _finite(msg.range_max, "range_max")
    if rmax <= 0:
        raise _MsgError("range_max", f"must be > 0, got {rmax!r}")
    if not 0 <= rmin < rmax:
        raise _MsgError("range_min", f"must lie in [0, range_max = {rmax!r}), got {rmin!r}")
    r32 = r.astype(np.float32, copy=False)
    neg = np.isfinite(r32) & (r32 < 0)
    if neg.any():
        i = int(np.argmax(neg))
        raise _MsgError(f"ranges[{i}]", f"{float(r32[i])!r} is negative")
    return (
        stamp,
        str(msg.header.frame_id).lstrip("/"),
        _angle64(amin, widen),
        _angle64(inc, widen),
        _widen(rmin, widen),
        _widen(rmax, widen),
        r32,
    )


def _pose_record(msg, msgtype: str) -> tuple[int, float, float, float]:
    """``(stamp ns, x, y, yaw)`` of a pose message."""
    stamp = _stamp(msg.header)
    pose, name = (msg.pose.pose, "pose.pose") if msgtype in (ODOMETRY, POSE_COV_STAMPED) else (msg.pose, "pose")
    x = _finite(pose.position.x, f"{name}.position.x")
    y = _finite(pose.position.y, f"{name}.position.y")
    q = _quat(pose.orientation, f"{name}.orientation")
    return stamp, x, y, float(_yaw(*q))


def _tf_records(msg, static: bool) -> list[tuple]:
    """``(parent, child, stamp ns, translation 3, rotation 4, static)`` of each transform."""
    out = []
    for j, tr in enumerate(msg.transforms):
        name = f"transforms[{j}]"
        parent = str(tr.header.frame_id).lstrip("/")
        child = str(tr.child_frame_id).lstrip("/")
        if not parent or not child or parent == child:
            raise _MsgError(f"{name}.child_frame_id", f"bad link {parent!r} -> {child!r}")
        t = tr.transform.translation
        tv = np.array([_finite(getattr(t, k), f"{name}.transform.translation.{k}") for k in "xyz"])
        q = _quat(tr.transform.rotation, f"{name}.transform.rotation")
        try:
            stamp = _stamp(tr.header)
        except _MsgError as e:
            raise _MsgError(f"{name}.{e.field}", e.message) from None
        out.append((parent, child, stamp, tv, q, static))
    return out


# ------------------------------------------------------------------------------------- reading
def _connections(path: Path, reader, topic: str, types: tuple[str, ...], role: str) -> list:
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        have = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
        raise BagFormatError(path, f"no {role} topic {topic!r} in the bag; its topics: {', '.join(have) or 'none'}")
    bad = sorted({c.msgtype for c in conns if c.msgtype not in types})
    if bad:
        raise BagFormatError(
            path, f"{role} topic {topic!r} holds {', '.join(bad)}, expected {' or '.join(types)}", topic=topic
        )
    return conns


def _read_messages(path: Path, reader, conns: list, strict: bool, bad: list, handle) -> None:
    """Deserialise every message of ``conns`` in bag order and pass ``(topic, index, msgtype, msg)`` to
    ``handle``; message errors and storage failures as the module docstring says."""
    counter: dict[str, int] = defaultdict(int)
    it = reader.messages(connections=conns)
    last = ("", -1)
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except (MemoryError, RecursionError):
            raise BagFormatError(path, "the file is corrupted (implausible sizes)") from None
        except Exception as e:  # the storage failed part way (truncated / corrupted file)
            text = " ".join(str(e).split())[:300] or type(e).__name__
            where = f" after message {last[1]} of {last[0]}" if last[1] >= 0 else " before the first message"
            if strict:
                raise BagFormatError(path, f"storage error{where}: {text}") from None
            bad.append(("", -1, f"reading stopped{where}: {text}"))
            return
        conn, _, raw = item
        index = counter[conn.topic]
        counter[conn.topic] += 1
        last = (conn.topic, index)
        try:
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as e:
                raise _MsgError("message", f"cannot decode {conn.msgtype} ({' '.join(str(e).split())[:200]})") from None
            handle(conn.topic, index, conn.msgtype, msg)
        except _MsgError as e:
            if strict:
                raise BagFormatError(path, e.message, topic=conn.topic, index=index, field=e.field) from None
            bad.append((conn.topic, index, f"field {e.field!r}: {e.message}"))


def _poses_from_topic(samples: list, stamps: np.ndarray, tol_ns: int, offset) -> tuple[np.ndarray, np.ndarray]:
    """Laser poses ``S x 3`` at ``stamps`` and which scans have one (module docstring)."""
    if not samples:
        return np.zeros((len(stamps), 3)), np.zeros(len(stamps), dtype=bool)
    arr = sorted(samples, key=lambda s: s[0])
    st = np.array([s[0] for s in arr], dtype=np.int64)
    p = np.array([s[1:] for s in arr], dtype=np.float64)
    i0, i1, w, ok = _bracket(st, stamps, tol_ns)
    p0, p1 = p[i0], p[i1]
    dyaw = np.mod(p1[:, 2] - p0[:, 2] + np.pi, 2 * np.pi) - np.pi
    out = np.empty((len(stamps), 3))
    out[:, :2] = p0[:, :2] + w[:, None] * (p1[:, :2] - p0[:, :2])
    out[:, 2] = p0[:, 2] + w * dyaw
    ox, oy, oyaw = offset
    if ox or oy or oyaw:
        c, s = np.cos(out[:, 2]), np.sin(out[:, 2])
        out[:, 0] += ox * c - oy * s
        out[:, 1] += ox * s + oy * c
        out[:, 2] += oyaw
    return out, ok


def _poses_from_tf(path: Path, links: list, frames: list[str], stamps: np.ndarray, tol_ns: int, map_frame: str):
    """Laser poses ``S x 3`` through the transform tree, which scans have one, which lasers are mounted
    upside down (their z axis points down in the map: beam angles turn the other way), and the stamps of
    the first dynamic link's samples."""
    by_link: dict[tuple[str, str], list] = defaultdict(list)
    parent: dict[str, str] = {}
    for rec in links:
        p, c = rec[0], rec[1]
        if c in parent and parent[c] != p:
            raise BagFormatError(path, f"frame {c!r} has two parents, {parent[c]!r} and {p!r}", topic="/tf")
        parent[c] = p
        by_link[(p, c)].append(rec)
    out = np.zeros((len(stamps), 3))
    ok = np.zeros(len(stamps), dtype=bool)
    flipped = np.zeros(len(stamps), dtype=bool)
    first_dynamic = np.zeros(0, dtype=np.int64)
    for frame in sorted(set(frames)):
        sel = np.array([f == frame for f in frames], dtype=bool)
        chain = [frame]
        while chain[-1] != map_frame and chain[-1] in parent and len(chain) < 1000:
            chain.append(parent[chain[-1]])
        if chain[-1] != map_frame:
            raise BagFormatError(
                path,
                f"no transform chain from {map_frame!r} to the laser frame {frame!r} in /tf and /tf_static "
                f"(the frames above {frame!r}: {' -> '.join(chain[1:]) or 'none'})",
            )
        t_s = stamps[sel]
        q = np.tile([0.0, 0.0, 0.0, 1.0], (len(t_s), 1))
        tv = np.zeros((len(t_s), 3))
        good = np.ones(len(t_s), dtype=bool)
        for child, par in itertools.pairwise(chain):  # compose map -> ... -> laser from the top
            recs = by_link[(par, child)]
            dyn = [r for r in recs if not r[5]]
            if not dyn:  # a static link: its last value
                lt, lq = np.tile(recs[-1][3], (len(t_s), 1)), np.tile(recs[-1][4], (len(t_s), 1))
            else:
                dyn.sort(key=lambda r: r[2])
                st = np.array([r[2] for r in dyn], dtype=np.int64)
                if not len(first_dynamic):
                    first_dynamic = st
                T = np.array([r[3] for r in dyn])
                Q = np.array([r[4] for r in dyn])
                i0, i1, w, ok_l = _bracket(st, t_s, tol_ns)
                good &= ok_l
                lt = T[i0] + w[:, None] * (T[i1] - T[i0])
                lq = _slerp(Q[i0], Q[i1], w)
            # (tv, q) is the laser in `child`'s frame; the link is `child` in `par`: laser in `par`
            tv = lt + _qrot(lq, tv)
            q = _qmul(lq, q)
        out[sel, 0], out[sel, 1] = tv[:, 0], tv[:, 1]
        out[sel, 2] = _yaw(q[:, 0], q[:, 1], q[:, 2], q[:, 3])  # the heading of the laser's x axis
        ok[sel] = good
        flipped[sel] = _qrot(q, np.array([0.0, 0.0, 1.0]))[:, 2] < 0
    return out, ok, flipped, first_dynamic


def read_bag(
    path: str | os.PathLike,
    scan_topic: str,
    pose_topic: str | None = None,
    *,
    tf: bool = False,
    map_frame: str = "map",
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    pose_tolerance: float = 0.1,
    strict: bool = True,
    max_usable_range: float | None = None,
    usable_range_rule: str = "drop",
    no_return: str = "drop",
    no_return_threshold: float | None = None,
    min_range: float = 0.0,
    max_range: float | None = None,
    pose_step: int = 1,
    pose_fraction: float | None = None,
    beam_step: int = 1,
    widen: str = "decimal",
) -> BagLog:
    """Read the ``sensor_msgs/LaserScan`` messages of ``scan_topic`` and the laser poses of a bag.

    Args:
        path: a ROS 1 ``.bag`` file, a ROS 2 bag folder (sqlite3 or MCAP), or a bare ``.db3`` / ``.mcap``.
        scan_topic: the LaserScan topic.
        pose_topic: a ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or
            ``PoseWithCovarianceStamped`` topic giving the robot pose (give it or ``tf``, not both).
        tf: take the poses from ``/tf`` + ``/tf_static``: ``map_frame -> ... -> the scans' frame_id``.
        map_frame: the world frame of the poses in ``tf`` mode.
        laser_offset: ``(x, y, yaw)`` of the laser in the robot frame (metres, radians), pose-topic mode.
        pose_tolerance: seconds; a scan farther than this from the pose samples around it is dropped.
        strict: raise :class:`BagFormatError` on the first malformed message (default); with False,
            skip malformed messages and list them in ``bad_messages``.
        max_usable_range: as :func:`~ogm_ppl.datasets.carmen.read_carmen`; likewise ``usable_range_rule``,
            ``no_return``, ``no_return_threshold``, ``min_range``, ``max_range``, ``pose_step``,
            ``pose_fraction`` and ``beam_step`` (the no-return rule for bags is in the module docstring).
        widen: ``"decimal"`` or ``"binary"``: how float32 fields become float64 (module docstring).

    Returns:
        a :class:`BagLog`; ``log.scans`` is the same :class:`Scans` that ``read_carmen`` gives for the
        same readings and poses.
    """
    path = Path(path)
    if (pose_topic is None) == (not tf):
        raise ValueError("read_bag: give pose_topic or tf=True (one pose source)")
    for name, v, allowed in (
        ("usable_range_rule", usable_range_rule, ("drop", "max")),
        ("no_return", no_return, ("drop", "max")),
        ("widen", widen, ("decimal", "binary")),
    ):
        if v not in allowed:
            raise ValueError(f"read_bag: {name} must be one of {allowed}, got {v!r}")
    for opt, x in (
        ("max_usable_range", max_usable_range),
        ("no_return_threshold", no_return_threshold),
        ("max_range", max_range),
    ):
        if x is not None and not (isinstance(x, (int, float)) and math.isfinite(x) and x > 0):
            raise ValueError(f"read_bag: {opt} must be a finite number > 0 or None, got {x!r}")
    if not (isinstance(min_range, (int, float)) and math.isfinite(min_range) and min_range >= 0):
        raise ValueError(f"read_bag: min_range must be a finite number >= 0, got {min_range!r}")
    if not (isinstance(pose_tolerance, (int, float)) and math.isfinite(pose_tolerance) and pose_tolerance >= 0):
        raise ValueError(f"read_bag: pose_tolerance must be a finite number of seconds >= 0, got {pose_tolerance!r}")
    off = tuple(laser_offset)
    if len(off) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in off):
        raise ValueError(f"read_bag: laser_offset must be three finite numbers (x, y, yaw), got {laser_offset!r}")
    if pose_fraction is not None and pose_step != 1:
        raise ValueError("read_bag: give pose_step or pose_fraction, not both")
    if pose_step < 1 or beam_step < 1 or not (pose_fraction is None or 0 < pose_fraction <= 1):
        raise ValueError(
            f"read_bag: need pose_step, beam_step >= 1 and pose_fraction in (0, 1], got "
            f"{pose_step}, {beam_step}, {pose_fraction}"
        )
    if not isinstance(scan_topic, str) or not scan_topic:
        raise ValueError(f"read_bag: scan_topic must be a topic name, got {scan_topic!r}")

    bad: list[tuple[str, int, str]] = []
    scans: list[tuple] = []
    poses: list[tuple] = []
    links: list[tuple] = []

    def handle(topic: str, index: int, msgtype: str, msg) -> None:
        if topic == scan_topic:
            scans.append((index, *_scan_record(msg, widen)))
        elif tf:
            links.extend(_tf_records(msg, static=topic == "/tf_static"))
        else:
            poses.append(_pose_record(msg, msgtype))

    with _open_reader(path, lenient=not strict) as (reader, kind):
        if getattr(reader, "note", None):
            bad.append(("", -1, reader.note))  # type: ignore[attr-defined]
        conns = _connections(path, reader, scan_topic, (LASER_SCAN,), "scan")
        if tf:
            tf_conns = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]  # type: ignore[attr-defined]
            if not tf_conns:
                raise BagFormatError(path, "tf=True but the bag has no /tf or /tf_static topic")
            for c in tf_conns:
                if c.msgtype != TF_MESSAGE:
                    raise BagFormatError(path, f"holds {c.msgtype}, expected {TF_MESSAGE}", topic=c.topic)
            conns += tf_conns
        else:
            assert pose_topic is not None
            conns += _connections(path, reader, pose_topic, POSE_TYPES, "pose")
        _read_messages(path, reader, conns, strict, bad, handle)
    if not scans:
        raise BagFormatError(path, "no readable LaserScan messages", topic=scan_topic)

    idx = np.array([s[0] for s in scans], dtype=np.int64)
    stamps = np.array([s[1] for s in scans], dtype=np.int64)
    tol_ns = round(pose_tolerance * 1e9)
    if tf:
        frames = [s[2] for s in scans]
        laser, have, flipped, pose_stamps = _poses_from_tf(path, links, frames, stamps, tol_ns, map_frame.lstrip("/"))
    else:
        flipped = np.zeros(len(stamps), dtype=bool)
        laser, have = _poses_from_topic(poses, stamps, tol_ns, off)
        pose_stamps = np.sort(np.array([p[0] for p in poses], dtype=np.int64))
    keep_pose = np.flatnonzero(have)
    if not len(keep_pose):
        raise BagFormatError(
            path,
            f"none of the {len(scans)} scans has a pose within {pose_tolerance} s "
            f"({'tf' if tf else pose_topic}: {len(pose_stamps)} samples)",
        )
    kept = [scans[i] for i in keep_pose]
    S, B = len(kept), max(len(s[7]) for s in kept)
    present = np.zeros((S, B), dtype=bool)
    r32 = np.zeros((S, B), dtype=np.float32)
    angles = np.zeros((S, B))
    for k, s in enumerate(kept):
        n = len(s[7])
        present[k, :n] = True
        r32[k, :n] = s[7]
        angles[k, :n] = s[3] + s[4] * np.arange(n)
        if flipped[keep_pose[k]]:
            angles[k, :n] = -angles[k, :n]
    rmin_msg = np.array([s[5] for s in kept])
    thr = np.array([s[6] for s in kept])
    ranges = _widen_array(r32, widen)
    settings = dict(
        scan_topic=scan_topic,
        pose_topic=pose_topic,
        tf=tf,
        map_frame=map_frame if tf else None,
        laser_offset=list(off),
        pose_tolerance=pose_tolerance,
        strict=strict,
        max_usable_range=max_usable_range,
        usable_range_rule=usable_range_rule,
        no_return=no_return,
        no_return_threshold=no_return_threshold,
        min_range=min_range,
        max_range=max_range,
        pose_step=pose_step,
        pose_fraction=pose_fraction,
        beam_step=beam_step,
        widen=widen,
        storage=kind,
        range_max=sorted({float(v) for v in thr})[:20],
        range_min=sorted({float(v) for v in rmin_msg})[:20],
        beam_counts=sorted({len(s[7]) for s in kept}),
        frames=sorted({s[2] for s in kept}),
    )
    scans_out, counts = _apply_rules(laser[keep_pose], angles, ranges, present, thr, rmin_msg, settings)
    keep = _kept_scans(S, pose_step, pose_fraction)
    counts = {"scans_read": len(scans), "no_pose": int(len(scans) - S), "pose_samples": len(pose_stamps), **counts}
    return BagLog(
        scans_out,
        str(path),
        kind,
        scan_topic,
        "tf" if tf else str(pose_topic),
        bad,
        float(scans_out.max_range),
        settings,
        idx[keep_pose][keep],
        stamps[keep_pose][keep] / 1e9,
        pose_stamps / 1e9,
        counts,
    )


def _apply_rules(poses, angles, ranges, present, thr, rmin_msg, st) -> tuple[Scans, dict[str, int]]:
    """The no-return, usable-range, min-range and subsampling rules, in the order ``read_carmen``
    applies them; returns the scans and the beam counts of the kept scans."""
    if st["no_return_threshold"] is not None:
        thr = np.minimum(thr, float(st["no_return_threshold"]))
    no_ret = present & (np.isnan(ranges) | (ranges == np.inf) | (ranges >= thr[:, None]))
    below_msg = present & ~no_ret & ((ranges == -np.inf) | (ranges < rmin_msg[:, None]))
    ranges = np.where(np.isfinite(ranges), ranges, 0.0)
    valid = present & ~below_msg
    u = st["max_usable_range"]
    beyond = valid & ~no_ret & (ranges >= u) if u is not None else np.zeros_like(valid)
    mr = st["max_range"]
    if mr is None:
        mr = float(u) if u is not None else float(thr.max())
    scans, counts, _ = beam_rules(poses, angles, ranges, present, valid, no_ret, beyond, below_msg, mr, st)
    return scans, counts


# ------------------------------------------------------------------------------------- writing
def typestore(storage: str):
    """The ``rosbags`` typestore to write a bag of ``storage`` with: ROS 1 Noetic (with
    ``tf2_msgs/TFMessage``, which its store lacks) or ROS 2 Humble."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if storage != "ros1":
        return get_typestore(Stores.ROS2_HUMBLE)
    ts = get_typestore(Stores.ROS1_NOETIC)
    if TF_MESSAGE not in ts.fielddefs:
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_MESSAGE))
    return ts


def write_bag(
    path: str | os.PathLike,
    scans: Scans,
    stamps: np.ndarray,
    *,
    storage: str = "ros1",
    scan_topic: str = "/scan",
    pose_topic: str = "/odom",
    pose_type: str = ODOMETRY,
    tf: bool = False,
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    laser_height: float = 0.0,
    map_to_odom: tuple[float, float, float] = (0.0, 0.0, 0.0),
    map_frame: str = "map",
    laser_frame: str = "laser",
) -> Path:
    """Write ``scans`` as a bag that :func:`read_bag` reads back to the same scans (tests, examples).

    Each scan becomes a LaserScan at ``stamps[s]`` (seconds): ``angle_min = angles[s, 0]``, increment
    ``angles[s, 1] - angles[s, 0]`` (the angles must be evenly spaced), ``range_min = scans.min_range``,
    ``range_max = scans.max_range``; a max-range reading is written as ``range_max`` and an invalid beam as
    NaN (both no-return in the bag). The pose goes to ``pose_topic`` (``pose_type`` one of
    :data:`POSE_TYPES`) as the robot pose ``laser pose (x) laser_offset^-1``; with ``tf=True`` to ``/tf``
    instead (``map -> odom`` = ``map_to_odom`` and ``odom -> base_link`` with each scan) and the laser
    mounting ``base_link -> laser_frame`` (``laser_offset``, ``laser_height``) to ``/tf_static``.

    The bag is written beside ``path`` and swapped in, replacing a bag written there before (a folder that
    is no ROS 2 bag is refused): an interrupted write leaves the old bag or the new one.

    Args:
        storage: ``"ros1"`` (a ``.bag`` file), ``"sqlite3"`` or ``"mcap"`` (a ROS 2 bag folder).
    """
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    if storage not in STORAGES:
        raise ValueError(f"write_bag: storage must be one of {STORAGES}, got {storage!r}")
    if pose_type not in POSE_TYPES:
        raise ValueError(f"write_bag: pose_type must be one of {POSE_TYPES}, got {pose_type!r}")
    stamps = np.asarray(stamps, dtype=np.float64)
    if stamps.shape != (scans.num_scans,) or not np.isfinite(stamps).all() or (stamps < 0).any():
        raise ValueError(f"write_bag: need {scans.num_scans} finite stamps >= 0, got shape {stamps.shape}")
    B = scans.beams_per_scan
    step = scans.angles[:, 1] - scans.angles[:, 0] if B > 1 else np.zeros(scans.num_scans)
    if B > 1 and not np.allclose(scans.angles, scans.angles[:, :1] + step[:, None] * np.arange(B), atol=1e-9):
        raise ValueError("write_bag: beam angles must be evenly spaced in every scan")
    path = Path(path)
    ros1 = storage == "ros1"
    ts = typestore(storage)
    T = ts.types
    ns = np.round(stamps * 1e9).astype(np.int64)
    bag_ns = np.maximum.accumulate(ns)  # receive times never go back; header stamps may (the Intel log's do)
    ox, oy, oyaw = laser_offset
    mx, my, myaw = map_to_odom
    # robot pose = laser pose (x) offset^-1
    yaw_r = scans.poses[:, 2] - oyaw
    c, s = np.cos(yaw_r), np.sin(yaw_r)
    rx = scans.poses[:, 0] - (ox * c - oy * s)
    ry = scans.poses[:, 1] - (ox * s + oy * c)

    def header(t: int, frame: str, seq: int = 0):
        stamp = T["builtin_interfaces/msg/Time"](sec=int(t // 1_000_000_000), nanosec=int(t % 1_000_000_000))
        if ros1:
            return T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def quat(yaw: float):
        return T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def pose(x: float, y: float, yaw: float, z: float = 0.0):
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z), orientation=quat(yaw))

    def transform(t: int, parent: str, child: str, x: float, y: float, z: float, yaw: float):
        v = T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(t, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=v, rotation=quat(yaw)),
        )

    def ser(msg, typ: str):
        return ts.serialize_ros1(msg, typ) if ros1 else ts.serialize_cdr(msg, typ)

    valid, is_max = np.asarray(scans.valid), np.asarray(scans.is_max)
    out = np.where(valid & ~is_max, scans.ranges, np.where(is_max, scans.max_range, np.nan)).astype(np.float32)
    base_frame = "base_link"
    if ros1 and path.is_dir():
        raise ValueError(f"write_bag: {path} is a folder; a ROS 1 bag is a file")
    if not ros1 and path.exists() and not (path / "metadata.yaml").is_file():
        raise ValueError(f"write_bag: {path} exists and is not a ROS 2 bag folder (no metadata.yaml); not replacing it")
    target = path
    target.parent.mkdir(parents=True, exist_ok=True)
    # written beside the target, then swapped in: an interrupted write leaves the old bag or the new one
    stage = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.staging-"))
    path = stage / target.name
    if ros1:
        writer: object = Writer1(path)
    else:
        plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
        writer = Writer2(path, version=9, storage_plugin=plugin)
    try:
        with writer as w:  # type: ignore[attr-defined]
            c_scan = w.add_connection(scan_topic, LASER_SCAN, typestore=ts)
            if tf:
                c_tf = w.add_connection("/tf", TF_MESSAGE, typestore=ts)
                c_static = w.add_connection("/tf_static", TF_MESSAGE, typestore=ts)
                mount = transform(int(ns.min()), base_frame, laser_frame, ox, oy, laser_height, oyaw)
                w.write(c_static, int(ns.min()), ser(T[TF_MESSAGE](transforms=[mount]), TF_MESSAGE))
            else:
                c_pose = w.add_connection(pose_topic, pose_type, typestore=ts)
            for k in range(scans.num_scans):
                t, tb = int(ns[k]), int(bag_ns[k])
                if tf:
                    # odom -> base_link = (map -> odom)^-1 (x) robot pose
                    c0, s0 = math.cos(myaw), math.sin(myaw)
                    dx, dy = float(rx[k]) - mx, float(ry[k]) - my
                    odom = transform(t, map_frame, "odom", mx, my, 0.0, myaw)
                    link = transform(
                        t, "odom", base_frame, c0 * dx + s0 * dy, -s0 * dx + c0 * dy, 0.0, float(yaw_r[k]) - myaw
                    )
                    w.write(c_tf, tb, ser(T[TF_MESSAGE](transforms=[odom, link]), TF_MESSAGE))
                else:
                    h = header(t, map_frame, k)
                    p = pose(float(rx[k]), float(ry[k]), float(yaw_r[k]))
                    if pose_type == POSE_STAMPED:
                        msg = T[POSE_STAMPED](header=h, pose=p)
                    else:
                        cov = T["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36))
                        if pose_type == POSE_COV_STAMPED:
                            msg = T[POSE_COV_STAMPED](header=h, pose=cov)
                        else:
                            z3 = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
                            tw = T["geometry_msgs/msg/TwistWithCovariance"](
                                twist=T["geometry_msgs/msg/Twist"](linear=z3, angular=z3), covariance=np.zeros(36)
                            )
                            msg = T[ODOMETRY](header=h, child_frame_id=base_frame, pose=cov, twist=tw)
                    w.write(c_pose, tb, ser(msg, pose_type))
                n = B
                scan = T[LASER_SCAN](
                    header=header(t, laser_frame, k),
                    angle_min=float(scans.angles[k, 0]),
                    angle_max=float(scans.angles[k, 0] + step[k] * (n - 1)),
                    angle_increment=float(step[k]),
                    time_increment=0.0,
                    scan_time=0.0,
                    range_min=float(scans.min_range),
                    range_max=float(scans.max_range),
                    ranges=out[k],
                    intensities=np.zeros(0, dtype=np.float32),
                )
                w.write(c_scan, tb, ser(scan, LASER_SCAN))
        if target.is_dir():  # a bag folder written before: swap, then drop the old one
            os.replace(target, stage / ".old")
        os.replace(path, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return target
