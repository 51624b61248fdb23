"""Faults for tests: a full disk under every file the library writes (all of them go through ``os.fdopen`` in
:func:`ogm_ppl.io.atomic_write`)."""

from __future__ import annotations

import errno
import io
import os


class _FullDisk(io.FileIO):
    """A file whose every write fails as on a full disk (``OSError`` ENOSPC, naming no file)."""

    def write(self, b) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def full_disk(monkeypatch) -> None:
    """From now on (until ``monkeypatch`` undoes it) every ``os.fdopen`` for writing gives a file that cannot be
    written: the first write that reaches the disk raises ``[Errno 28] No space left on device``."""
    real = os.fdopen

    def fdopen(fd, mode="r", *args, **kwargs):
        if "w" not in mode:
            return real(fd, mode, *args, **kwargs)
        buf = io.BufferedWriter(_FullDisk(fd, "w"))
        return buf if "b" in mode else io.TextIOWrapper(buf, encoding=kwargs.get("encoding"))

    monkeypatch.setattr(os, "fdopen", fdopen)
