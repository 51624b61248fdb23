"""What every subcommand of ``ogm-ppl`` shares: the error type, the argument types, output folders,
progress and the one-line messages."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.io import writable_folder

if TYPE_CHECKING:
    pass


class CLIError(Exception):
    """A user error: printed as one line ``ogm-ppl: error: ...``, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse that raises :class:`CLIError` instead of printing usage and exiting."""

    def error(self, message: str):
        raise CLIError(message)


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("ogm_ppl")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a source tree
        from ogm_ppl import __version__

        return __version__


# ---------------------------------------------------------------------------------- argument types
def _number(kind, lo=None, lo_open=False, hi=None, hi_open=False):
    """An argparse type: ``kind`` (int/float), finite, within ``[lo, hi]`` (open ends as flagged)."""

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'a whole number' if kind is int else 'a number'}, got {text!r}"
            ) from None
        if kind is float and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            raise argparse.ArgumentTypeError(f"must be {'>' if lo_open else '>='} {lo}, got {text}")
        if hi is not None and (v >= hi if hi_open else v > hi):
            raise argparse.ArgumentTypeError(f"must be {'<' if hi_open else '<='} {hi}, got {text}")
        return v

    parse.__name__ = kind.__name__  # argparse names the type in "invalid <name> value" messages
    return parse


_pos_float = _number(float, 0, True)
_nonneg_float = _number(float, 0)
_pos_int = _number(int, 1)
_nonneg_int = _number(int, 0)
_fraction = _number(float, 0, True, 1)
_probability = _number(float, 0, True, 1, True)
_finite = _number(float)
#: a random seed: chain c of a run is seeded seed + c, and checkpoints store it as an int64
_seed = _number(int, 0, hi=2**62)


# --------------------------------------------------------------------------------------- helpers
def _progress() -> bool:
    """Progress bars only on an interactive stderr (never in pipes, logs or tests)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # pragma: no cover
        return False


def _steps(total: int, desc: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="step", disable=not _progress(), leave=False)


def _check_writable(directory: Path, out: Path) -> None:
    """Create ``directory`` and write and remove a file there, naming ``--out`` on failure."""
    try:
        writable_folder(directory)
    except OSError as e:
        raise CLIError(f"--out {out}: cannot write there ({e.strerror or e})") from None


def _prepare_out_dir(out: Path) -> None:
    """Create ``out`` and make sure a file can be written there (before any long computation). A symbolic link
    to a folder is written through (:class:`~ogm_ppl.io.StagedFolder`); one to nothing is refused."""
    if out.is_symlink() and not out.exists():
        raise CLIError(f"--out {out}: a symbolic link to {os.readlink(out)}, which does not exist")
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out {out}: exists and is not a directory")
    _check_writable(out, out)


def _inputs_of(args) -> list[Path]:
    """The paths a command reads: every ``Path`` value (or list of them) of ``args`` but ``out``."""
    found: list[Path] = []
    for key, value in vars(args).items():
        if key == "out":
            continue
        for v in value if isinstance(value, (list, tuple)) else [value]:
            if isinstance(v, Path):
                found.append(v)
    return found


def _refuse_out_over_inputs(out: Path | None, inputs, writes: tuple[str, ...] = ()) -> None:
    """Refuse (before any work) an ``--out`` that would replace or write into what the command reads: ``out``
    is an input (the same path, through links, or the same file), lies inside one (a bag folder, a folder of
    plan files), or, a folder writing the entries ``writes``, would put one of them over an input inside it."""
    if out is None:
        return
    o = Path(os.path.realpath(out))
    for given in inputs:
        i = Path(os.path.realpath(given))
        same = o == i
        if not same and out.exists() and given.exists():
            with contextlib.suppress(OSError):
                same = os.path.samefile(out, given)
        if same:
            raise CLIError(f"--out {out} is the input {given}: writing it would replace what it is read from")
        if o.is_relative_to(i):
            raise CLIError(f"--out {out} lies inside the input {given}: give a path outside it")
        if writes and i.is_relative_to(o) and i != o and i.relative_to(o).parts[0] in writes:
            entry = i.relative_to(o).parts[0]
            raise CLIError(f"--out {out}: its {entry} would replace the input {given}; give another folder")


def _prepare_out_file(out: Path) -> None:
    """Make sure ``out``'s directory exists and takes a file (before any long computation)."""
    if out.is_dir():
        raise CLIError(f"--out {out}: is a directory; give a file name such as data.npz")
    parent = out.parent
    if parent.exists() and not parent.is_dir():
        raise CLIError(f"--out {out}: {parent} is not a directory")
    _check_writable(parent, out)


def _jsonable(x):
    """Paths, numpy scalars and tuples as plain JSON values."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _size(path: Path) -> int:
    """Bytes of a file, or of every file under a folder (a ROS 2 bag)."""
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _plural(n: int, noun: str) -> str:
    """``"1 scan"``, ``"2 scans"``."""
    return f"{n:,} {noun}{'' if n == 1 else 's'}"


def _fmt_s(x) -> str:
    return "fused with map" if x is None else f"{x:.3f} s"


def _one_line(e: BaseException) -> str:
    if isinstance(e, OSError) and not str(e).strip(": "):
        text = type(e).__name__
    elif isinstance(e, OSError) and e.strerror:
        text = f"{e.filename}: {e.strerror}" if e.filename else e.strerror
    else:
        text = str(e) or type(e).__name__
    return " ".join(text.split())
