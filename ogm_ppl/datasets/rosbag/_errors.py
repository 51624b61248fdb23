"""The errors of the ROS bag reader: :class:`BagFormatError` (naming the file, topic, message and field)
and the conversions into it."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


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


class _MsgError(Exception):
    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field, self.message = field, message
