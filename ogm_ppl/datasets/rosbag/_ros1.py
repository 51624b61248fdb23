"""ROS 1 bags read record by record, without their index (a recording cut short)."""

from __future__ import annotations

import os
from collections import defaultdict
from contextlib import suppress
from pathlib import Path

_ROS1_MAGIC = b"#ROSBAG V2.0\n"


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
