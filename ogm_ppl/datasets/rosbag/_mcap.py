"""MCAP files read record by record, without their summary (a ROS 2 recording cut short)."""

from __future__ import annotations

import os
from contextlib import suppress
from pathlib import Path

from ogm_ppl.datasets.rosbag._ros1 import _LinearRos1

_MCAP_MAGIC = b"\x89MCAP0\r\n"


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
