"""Atomic file writes: an interrupted run never leaves a half-written file behind.

Every file the library writes (maps, reports, figures, checkpoints, prior tables, datasets) goes through
:func:`atomic_write`: the content is written to a temporary file in the target's folder, flushed to disk,
then renamed over the target with :func:`os.replace` (atomic on POSIX and Windows). A reader therefore sees
the old file or the new one, never a mix; on an exception the temporary file is removed and the old file is
left as it was.

>>> import tempfile, pathlib, numpy as np
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> with atomic_write(d / "a.npz") as f:
...     np.savez(f, x=np.arange(3))
>>> atomic_write_text(d / "a.txt", "hello").read_text()
'hello'
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
import weakref
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = ["StagedFolder", "atomic_write", "atomic_write_bytes", "atomic_write_text", "read_npz", "writable_folder"]


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb", **open_kwargs: Any) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path`` (``mode``: ``"wb"`` or ``"w"``); on leaving the block without
    an exception it is flushed, fsynced and renamed to ``path``; otherwise it is deleted and ``path`` is
    untouched. The parent folder is created if missing. A write that fails (a full disk, a quota, an I/O error:
    an ``OSError`` naming no file) is raised naming ``path``: ``[Errno 28] cannot write it (No space left on
    device): 'PATH'``.

    Anything that writes to a file object works inside the block: ``np.savez(f, ...)``,
    ``fig.savefig(f, format="png")``, ``json.dump(obj, f)`` (text mode), ``img.save(f, format="PNG")``.
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write mode must be 'wb' or 'w', got {mode!r}")
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a folder; give a file name", str(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as e:  # name the file asked for, not the temporary one
        raise _named(e, path) from None
    try:
        os.chmod(tmp, _mode_for(path))  # mkstemp makes 0600: give the file the mode open() would
        try:
            with os.fdopen(fd, mode, **open_kwargs) as f:
                yield f
                f.flush()
                os.fsync(f.fileno())
        except OSError as e:
            if e.errno is None or e.filename is not None:  # not a failed write of this file (or one that names its own)
                raise
            raise _named(e, path) from None  # a full disk, a quota, an I/O error: name the file, not "[Errno 28]"
        try:
            os.replace(tmp, path)
        except OSError as e:
            raise _named(e, path) from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _named(e: OSError, path: Path) -> OSError:
    """``e`` (of the same class) naming ``path``: ``[Errno 13] cannot write it (Permission denied): 'PATH'``."""
    return type(e)(e.errno, f"cannot write it ({e.strerror or e})", str(path))


def read_npz(path: str | os.PathLike, what: str, error: type[Exception] = ValueError) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` archive ``path`` (read with ``allow_pickle=False``: a file from elsewhere cannot
    run code). Raises ``error`` (its message: ``"PATH: ..."``, naming ``what`` was expected) for a missing or
    unreadable file, a file that is not a zip archive (an image, a text file), a single ``.npy`` array, pickled
    objects or a damaged archive."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            magic = f.read(4)
    except FileNotFoundError:
        raise error(f"{p}: no such file") from None
    except OSError as e:
        raise error(f"{p}: cannot read it ({e.strerror or e})") from None
    if magic != b"PK\x03\x04":  # an .npz is a zip archive
        raise error(f"{p}: not an .npz archive (it does not start as a zip file does); expected {what}")
    try:
        z = np.load(p, allow_pickle=False)
    except Exception as e:  # BadZipFile, OSError, EOFError
        raise error(f"{p}: not a readable .npz ({type(e).__name__}: {e}); expected {what}") from None
    if not hasattr(z, "files"):
        raise error(f"{p}: a single array, not an .npz archive; expected {what}")
    with z:
        try:
            return {k: z[k] for k in z.files}
        except ValueError as e:
            if "pickle" in str(e):
                raise error(f"{p}: holds pickled Python objects; refused (expected {what}: plain arrays)") from None
            raise error(f"{p}: damaged archive ({type(e).__name__}: {e})") from None
        except Exception as e:
            raise error(f"{p}: damaged archive ({type(e).__name__}: {e})") from None


def writable_folder(path: str | os.PathLike) -> Path:
    """Create the folder ``path`` (and its parents) and check that a file can be written in it, by writing and
    removing one: call it before a long computation that writes its results there. An ``OSError`` names
    ``path`` and why (a file in the way, no permission, a read-only file system)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder", str(path))
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path, prefix=".ogm-ppl-write-test.")
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise type(e)(e.errno, f"cannot write there ({e.strerror or e})", str(path)) from None
    return path


def _read_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: the process umask, read once at import (``os.umask`` can only be read by setting it, which would race
#: with files created by other threads)
_UMASK = _read_umask()


def _mode_for(path: Path) -> int:
    """The target's current mode if it exists, else ``0o666`` less the umask (as ``open`` gives)."""
    try:
        return os.stat(path).st_mode & 0o7777
    except FileNotFoundError:
        return 0o666 & ~_UMASK


def _dir_mode_for(path: Path) -> int:
    """The folder's current mode if it exists, else ``0o777`` less the umask (as ``mkdir`` gives)."""
    try:
        return os.stat(path).st_mode & 0o7777
    except FileNotFoundError:
        return 0o777 & ~_UMASK


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`); returns the path."""
    with atomic_write(path, "w", encoding=encoding) as f:
        f.write(text)
    return Path(path)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write`); returns the path."""
    with atomic_write(path, "wb") as f:
        f.write(data)
    return Path(path)


class StagedFolder:
    """Write a folder's outputs so that a reader sees all the old ones or all the new ones, never a mix.

    Files go into :attr:`path`, a hidden sibling ``.NAME.staging-XXXX`` of ``target`` (same file system, so
    renames are atomic). :meth:`commit` swaps it in with two renames: ``target -> .NAME.old-XXXX``, then
    staging ``-> target``; entries of the old folder that the new one does not have (caches, checkpoints,
    the user's own files) are then moved across, and the old folder is deleted: an old entry with an
    output's name (file or folder) is replaced by the output. The folder keeps the old one's permissions (a
    new one gets ``0o777`` less the umask). An interruption before the first rename leaves
    ``target`` untouched (the staging folder is removed by :meth:`discard`, when this object is collected, or
    at exit); one between the two renames (two system calls) leaves the old outputs whole in
    ``.NAME.old-XXXX``, which the next :class:`StagedFolder` for ``target`` puts back.

    A folder that must not be swapped is written **in place** (:attr:`in_place`): a symbolic link (written
    through to the folder it names, the link left as it is), the working directory or a folder holding it
    (``--out .``), a mount point, or a folder whose parent takes no new entry. The outputs are then staged in
    ``TARGET/.staging-XXXX`` and :meth:`commit` moves each one over its old version (each output is replaced
    atomically, one after another; the old and new sets can mix for the moment that takes); nothing outside the
    folder is written, moved or replaced.

    As a context manager it commits on leaving the block without an exception, else discards the staged
    outputs; an ``OSError`` naming a staged file is raised naming the file in ``target`` instead.

    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()) / "out"
    >>> s = StagedFolder(d); _ = atomic_write_text(s.path / "a.txt", "new"); _ = s.commit()
    >>> sorted(p.name for p in d.iterdir())
    ['a.txt']
    """

    def __init__(self, target: str | os.PathLike) -> None:
        self.target = Path(target)
        if self.target.is_symlink() and not self.target.is_dir():
            raise NotADirectoryError(
                errno.ENOTDIR, f"a symbolic link to {os.readlink(self.target)}, which is not a folder", str(self.target)
            )
        parent = self.target.parent
        self.in_place = _write_in_place(self.target)
        if self.in_place:
            self.path = Path(tempfile.mkdtemp(dir=self.target, prefix=".staging-"))
        else:
            parent.mkdir(parents=True, exist_ok=True)
            if not self.target.exists():  # a swap interrupted between its two renames: put the old folder back
                olds = sorted(parent.glob(f".{self.target.name}.old-*"))
                if olds:
                    os.replace(olds[-1], self.target)
            self.path = Path(tempfile.mkdtemp(dir=parent, prefix=f".{self.target.name}.staging-"))
        self._done = False
        self._finalizer = weakref.finalize(self, shutil.rmtree, str(self.path), True)

    def __enter__(self) -> StagedFolder:
        return self

    def __exit__(self, kind, error, tb) -> None:
        if kind is None:
            self.commit()
            return
        self.discard()
        if isinstance(error, OSError) and error.filename is not None:
            try:
                inside = Path(error.filename).relative_to(self.path)
            except ValueError:
                return
            raise type(error)(error.errno, error.strerror, str(self.target / inside)) from None

    def discard(self) -> None:
        """Remove the staged outputs now (the target is left as it was)."""
        if not self._done:
            self._done = True
            self._finalizer()

    def commit(self) -> Path:
        """Swap the staged outputs in, or move them in one by one (see the class docstring); returns ``target``."""
        if self._done:
            raise RuntimeError(f"{self.target}: staged outputs already committed or discarded")
        if self.in_place:
            self._commit_in_place()
            return self.target
        # the folder keeps the target's permissions (a new one gets those of mkdir), not mkdtemp's private 0o700
        os.chmod(self.path, _dir_mode_for(self.target))
        old = None
        if self.target.exists():
            old = Path(tempfile.mkdtemp(dir=self.target.parent, prefix=f".{self.target.name}.old-"))
            os.rmdir(old)
            os.replace(self.target, old)
        os.replace(self.path, self.target)
        self._done = True
        self._finalizer.detach()
        if old is not None:
            for entry in old.iterdir():
                if not (self.target / entry.name).exists():
                    os.replace(entry, self.target / entry.name)
            shutil.rmtree(old, ignore_errors=True)
        return self.target

    def _commit_in_place(self) -> None:
        """Each staged entry over its namesake in the target (a folder: the old one moved aside into the staging
        folder, then removed with it)."""
        for entry in sorted(self.path.iterdir()):
            dst = self.target / entry.name
            if dst.is_dir() and not dst.is_symlink():
                aside = self.path / f".old-{entry.name}"
                os.replace(dst, aside)
            elif entry.is_dir() and (dst.exists() or dst.is_symlink()):
                dst.unlink()  # a file (or a link) where a folder goes
            os.replace(entry, dst)
        self.discard()


def _write_in_place(target: Path) -> bool:
    """Whether :class:`StagedFolder` must write ``target`` in place rather than swap it (see its docstring): a
    symbolic link, the working directory or a folder above it, a mount point, or a folder whose parent takes no
    new entry (checked by making and removing one)."""
    if target.is_symlink():
        return True
    if not target.exists():
        return False
    real = target.resolve()
    if Path.cwd().resolve().is_relative_to(real) or os.path.ismount(real) or real.parent == real:
        return True
    try:
        probe = tempfile.mkdtemp(dir=real.parent, prefix=f".{real.name}.probe-")
    except OSError:
        return True
    os.rmdir(probe)
    return False
