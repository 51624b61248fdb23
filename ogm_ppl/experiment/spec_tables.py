"""The toolkit every experiment kind reads its spec with: TOML tables whose errors name the file, the table and
the key (:class:`Table`), names that become folders (:func:`check_name`), named entries of an array of tables
(:func:`named_entry`) and seeds derived from task names (:func:`derive_seed`).

An experiment kind of one's own (:func:`ogm_ppl.experiment.register_experiment_kind`) reads its tables with
these, so its errors read as the shipped kinds' do.
"""

from __future__ import annotations

import os
import re
import sys
import zlib
from pathlib import Path

import numpy as np

from ogm_ppl.options import Bool, Choice, Float, Int, Kind, Text, _Bad

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the backport, the same parser (a dependency there)
    import tomli as tomllib

__all__ = ["SpecError", "Table", "check_name", "derive_seed", "named_entry", "read_spec_file"]

_NAME = re.compile(r"[A-Za-z0-9_.-]+\Z")


class SpecError(ValueError):
    """An invalid spec; the message names the file, the entry and the key."""


def derive_seed(root: int, *parts, bits: int = 63) -> int:
    """A seed for the task named by ``parts`` under the experiment seed ``root`` (``bits``-bit, >= 0).

    ``SeedSequence(root, spawn_key=(crc32(part), ...))``: the same names give the same seed in any
    process and on any machine (Python's ``hash`` of a string would not).

    >>> derive_seed(0, "run", "office", "ogm", 0) == derive_seed(0, "run", "office", "ogm", 0)
    True
    """
    key = tuple(zlib.crc32(str(p).encode()) for p in parts)
    state = np.random.SeedSequence(int(root), spawn_key=key).generate_state(2, np.uint64)
    return int(int(state[0]) >> (64 - bits))


def _option_kind(kind: str, lo, hi, lo_open: bool) -> Kind:
    """The option kind that checks a table's ``"int"``, ``"float"``, ``"bool"`` or ``"str"`` value."""
    if kind == "int":
        return Int(None if lo is None else lo + 1 if lo_open else lo, hi)
    if kind == "float":
        return Float(lo, hi, lo_open)
    if kind in ("bool", "str") and lo is None and hi is None:
        return Bool() if kind == "bool" else Text()
    raise ValueError(f"a table value is 'int', 'float', 'bool' or 'str' (bounds for numbers only), got {kind!r}")


class Table:
    """Reads the keys of one TOML table; every error names the source, the table and the key.

    ``get(key, kind, default, required=..., sweep=..., lo=, hi=, lo_open=, choices=)`` reads a value of
    ``kind`` (``"int"``, ``"float"``, ``"bool"``, ``"str"``) within its bounds (a list of values where
    ``sweep``), checked by the library's one option system (:mod:`ogm_ppl.options`: :class:`Int`,
    :class:`Float`, :class:`Bool`, :class:`Text`, :class:`Choice`); ``raw(key)`` reads anything; ``finish()``
    refuses a key nothing read; ``fail(key, msg)`` raises :class:`SpecError` naming the source, the table and
    the key."""

    def __init__(self, source: str, where: str, table) -> None:
        self.source, self.where = source, where
        if not isinstance(table, dict):
            self.fail(None, f"must be a table, got {type(table).__name__}")
        self.table = table
        self.used: set[str] = set()

    def fail(self, key, msg):
        loc = f"{self.where}.{key}" if key else self.where
        raise SpecError(f"{self.source}: {loc}: {msg}")

    def has(self, key) -> bool:
        return key in self.table

    def raw(self, key, default=None):
        self.used.add(key)
        return self.table.get(key, default)

    def _one(self, key, v, kind, lo=None, hi=None, lo_open=False, choices=None):
        """``v`` checked by the option kind (:mod:`ogm_ppl.options`) of ``kind`` within its bounds and choices."""
        try:
            v = _option_kind(kind, lo, hi, lo_open).value(v)
            return v if choices is None else Choice(*choices).value(v)
        except _Bad as e:
            self.fail(key, str(e))

    def get(self, key, kind, default=None, required=False, sweep=False, **check):
        if key not in self.table:
            if required:
                self.fail(key, "is required")
            self.used.add(key)
            return default
        v = self.raw(key)
        if sweep and isinstance(v, list):
            if not v:
                self.fail(key, "an empty list sweeps over nothing")
            vals = [self._one(f"{key}[{i}]", x, kind, **check) for i, x in enumerate(v)]
            if len(set(vals)) != len(vals):
                self.fail(key, f"lists a value twice: {v!r}")
            return vals
        return self._one(key, v, kind, **check)

    def finish(self, optional=()):
        """Refuse a key no ``get``/``raw`` read, listing the keys read and the ``optional`` ones (keys a table
        takes that were read only where present)."""
        known = self.used | set(optional)
        unknown = sorted(set(self.table) - known)
        if unknown:
            self.fail(unknown[0], f"unknown key (known here: {', '.join(sorted(known))})")


def check_name(t: Table, name: str) -> None:
    """A name that becomes a file or folder name under ``--out``: letters, digits, ``_ . -``, not starting
    with a dot (so never ``..``, a path separator or an absolute path: nothing is written outside)."""
    if not _NAME.match(name) or name.startswith("."):
        t.fail("name", f"may hold only letters, digits, '_', '.', '-' and not start with '.', got {name!r}")


def named_entry(source: str, section: str, i: int, entry) -> tuple[Table, str]:
    """The table of ``section[i]`` (named in errors by index and name) and its validated name."""
    where = f"{section}[{i}]"
    if isinstance(entry, dict) and isinstance(entry.get("name"), str):
        where += f" ({entry['name']!r})"
    t = Table(source, where, entry)
    name = t.get("name", "str", required=True)
    check_name(t, name)
    return t, name


def read_spec_file(path: str | os.PathLike) -> dict:
    """The TOML table of a spec file; :class:`SpecError` names the file and what is wrong with it."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(f"{path}: no such spec file") from None
    except UnicodeDecodeError as e:
        raise SpecError(f"{path}: not a UTF-8 text file (byte {e.start}: {e.reason}); a spec is TOML") from None
    except OSError as e:
        raise SpecError(f"{path}: cannot read it ({e.strerror or e})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SpecError(f"{path}: not valid TOML ({e})") from None
    return data
