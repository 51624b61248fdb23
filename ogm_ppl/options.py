r"""Options declared once: a frozen dataclass whose fields say their kind, range and meaning.

The one system by which the library checks the settings it is given, wherever they come from (a TOML spec,
the command line, Python): the parameters of a map method (:mod:`ogm_ppl.methods.params`), the options of an
input kind (:mod:`ogm_ppl.inputs`) and the keys of an experiment spec's tables
(:class:`~ogm_ppl.experiment.spec_tables.Table`).

A field is made with :func:`param`; its *kind* (:class:`Int`, :class:`Float`, :class:`Choice`, ...) checks a
value read from TOML or Python (:meth:`Kind.value`) and parses one typed on the command line
(:meth:`Kind.text`). :func:`parse_params` builds the dataclass from a mapping, refusing unknown keys, and
then calls the dataclass's optional ``check()`` for rules between fields. Every error is a
:class:`ParamError` naming the key.

>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class P:
...     sweeps: int = param(100, Int(lo=1), "sweeps counted in the marginals")
>>> parse_params(P, {"sweeps": "20"}, text=True)
P(sweeps=20)
>>> parse_params(P, {"sweeps": 0})
Traceback (most recent call last):
...
ogm_ppl.options.ParamError: sweeps: must be >= 1, got 0

A rule between fields that names other options writes them as ``{option}`` in its message and gives
``refs``, their names as a spec writes them; the command line names them by its flags
(:meth:`ParamError.message_naming`):

>>> e = ParamError("laser_offset", "applies to {pose_topic}", refs={"pose_topic": "pose_topic"})
>>> e.message, e.message_naming(lambda k: "--" + k.replace("_", "-"))
('applies to pose_topic', 'applies to --pose-topic')
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Collection, Mapping
from typing import Any

__all__ = [
    "INT_LIMIT",
    "Bool",
    "Choice",
    "Float",
    "Int",
    "Kind",
    "Numbers",
    "Optional",
    "Pair",
    "ParamError",
    "Text",
    "param",
    "param_fields",
    "param_groups",
    "parse_params",
]


class ParamError(ValueError):
    """A bad option value: ``key`` names the option, ``message`` says what is wrong.

    ``refs`` (optional) maps the ``{name}`` fields of ``message`` to how the options it mentions are named in
    a spec (``{"tf": "tf = true"}``); :meth:`message_naming` names them otherwise."""

    def __init__(self, key: str, message: str, refs: Mapping[str, str] | None = None) -> None:
        self.key = key
        self.refs = dict(refs or {})
        self.template = message
        self.message = message.format(**self.refs) if self.refs else message
        super().__init__(f"{key}: {self.message}")

    def message_naming(self, name: Callable[[str], str]) -> str:
        """The message with each option it mentions named ``name(option)`` (a command-line flag)."""
        if not self.refs:
            return self.message
        return self.template.format(**{k: name(k) for k in self.refs})


class _Bad(Exception):
    """Raised by a kind; :func:`parse_params` turns it into a :class:`ParamError` naming the key."""


class Kind:
    """What values an option takes: :meth:`value` checks (and normalises) a TOML / Python value,
    :meth:`text` parses a command-line string; both raise on a bad value with a message."""

    def value(self, v: Any) -> Any:
        return v

    def text(self, s: str) -> Any:
        return self.value(s)

    def describe(self) -> str:
        return type(self).__name__.lower()


def _range(v, lo, hi, lo_open, hi_open):
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise _Bad(f"must be {'>' if lo_open else '>='} {lo}, got {v!r}")
    if hi is not None and (v >= hi if hi_open else v > hi):
        raise _Bad(f"must be {'<' if hi_open else '<='} {hi}, got {v!r}")
    return v


def _bounds(lo, hi, lo_open, hi_open) -> str:
    a = "" if lo is None else f"{'(' if lo_open else '['}{lo}"
    b = "" if hi is None else f"{hi}{')' if hi_open else ']'}"
    return f" in {a or '(-inf'}, {b or 'inf)'}" if a or b else ""


#: the largest magnitude an integer parameter may have whatever its own range: the int64 that checkpoints,
#: records and arrays hold it in (a larger one would overflow there, hours into a run)
INT_LIMIT = 2**63 - 1


@dataclasses.dataclass(frozen=True)
class Int(Kind):
    """An integer (not a bool) in ``[lo, hi]``, and never beyond :data:`INT_LIMIT` in magnitude."""

    lo: int | None = None
    hi: int | None = None
    #: what the upper bound ``hi`` stands for, said when a value exceeds it
    why: str = ""

    def value(self, v):
        if isinstance(v, bool) or not isinstance(v, int):
            raise _Bad(f"must be an integer, got {v!r}")
        if self.hi is not None and self.why and v > self.hi:
            raise _Bad(f"must be <= {self.hi} ({self.why}), got {v!r}")
        _range(v, self.lo, self.hi, False, False)
        if abs(v) > INT_LIMIT:
            raise _Bad(f"must be at most 2^63 - 1 = {INT_LIMIT} in magnitude (an int64), got {v}")
        return v

    def text(self, s):
        try:
            return self.value(int(s))
        except ValueError:
            raise _Bad(f"expected a whole number, got {s!r}") from None

    def describe(self):
        return "int" + _bounds(self.lo, self.hi, False, False)


@dataclasses.dataclass(frozen=True)
class Float(Kind):
    """A finite number within ``lo`` / ``hi`` (ends open as flagged)."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def value(self, v):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise _Bad(f"must be a finite number, got {v!r}")
        return _range(float(v), self.lo, self.hi, self.lo_open, self.hi_open)

    def text(self, s):
        try:
            return self.value(float(s))
        except ValueError:
            raise _Bad(f"expected a number, got {s!r}") from None

    def describe(self):
        return "float" + _bounds(self.lo, self.hi, self.lo_open, self.hi_open)


class Bool(Kind):
    """``true`` / ``false`` (on the command line also ``yes`` / ``no``, ``1`` / ``0``)."""

    def value(self, v):
        if not isinstance(v, bool):
            raise _Bad(f"must be true or false, got {v!r}")
        return v

    def text(self, s):
        t = s.strip().lower()
        if t in ("true", "yes", "1"):
            return True
        if t in ("false", "no", "0"):
            return False
        raise _Bad(f"must be true or false, got {s!r}")

    def describe(self):
        return "bool"


class Choice(Kind):
    """One of a few strings."""

    def __init__(self, *options: str) -> None:
        self.options = tuple(options)

    def value(self, v):
        if v not in self.options:
            raise _Bad(f"must be one of {', '.join(map(repr, self.options))}, got {v!r}")
        return v

    def describe(self):
        return " | ".join(self.options)


class Text(Kind):
    """A non-empty string."""

    def value(self, v):
        if not isinstance(v, str) or not v:
            raise _Bad(f"must be a non-empty string, got {v!r}")
        return v

    def describe(self):
        return "str"


class Optional(Kind):
    """``kind`` or nothing (``None``; ``none`` on the command line)."""

    def __init__(self, kind: Kind) -> None:
        self.kind = kind

    def value(self, v):
        return None if v is None else self.kind.value(v)

    def text(self, s):
        return None if s.strip().lower() == "none" else self.kind.text(s)

    def describe(self):
        return f"{self.kind.describe()} or none"


class Pair(Kind):
    """Two numbers ``[lo, hi]`` with ``lo < hi`` (``lo,hi`` on the command line)."""

    def __init__(self, what: str = "") -> None:
        self.what = what

    def value(self, v):
        ok = isinstance(v, (list, tuple)) and len(v) == 2
        ok = ok and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
        if not ok or not v[0] < v[1]:
            raise _Bad(f"must be [lo, hi]{' ' + self.what if self.what else ''} with lo < hi, got {v!r}")
        return [float(v[0]), float(v[1])]

    def text(self, s):
        try:
            return self.value([float(x) for x in s.split(",")])
        except ValueError:
            raise _Bad(f"expected two numbers LO,HI, got {s!r}") from None

    def describe(self):
        return f"[lo, hi]{' ' + self.what if self.what else ''}"


class Numbers(Kind):
    """``n`` finite numbers as a list of floats (``a,b,...`` on the command line); ``what`` describes them in
    messages (``"[x, y, yaw] (metres, radians)"``)."""

    def __init__(self, n: int, what: str) -> None:
        self.n, self.what = n, what

    def value(self, v):
        ok = isinstance(v, (list, tuple)) and len(v) == self.n
        if not ok or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
            raise _Bad(f"must be {self.what}, got {v!r}")
        return [float(x) for x in v]

    def text(self, s):
        try:
            return self.value([float(x) for x in s.split(",")])
        except ValueError:
            raise _Bad(f"expected {self.n} numbers separated by commas, got {s!r}") from None

    def describe(self):
        return self.what


def param(default: Any, kind: Kind, doc: str, *, group: str = "") -> Any:
    """An option field of a dataclass: its ``default``, its :class:`Kind` and a one-line doc. ``group``
    sorts options where a surface lays them out apart (an input kind's ``"reader"`` options sit in a spec's
    ``reader`` table, :mod:`ogm_ppl.inputs`)."""
    meta = {"kind": kind, "doc": doc, "group": group}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def param_fields(cls) -> list[tuple[str, Kind, Any, str]]:
    """``(name, kind, default, doc)`` of every option of the dataclass ``cls``."""
    out = []
    for f in dataclasses.fields(cls):
        if "kind" not in f.metadata:
            raise TypeError(f"{cls.__name__}.{f.name}: make parameter fields with param(default, kind, doc)")
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc,operator]
        out.append((f.name, f.metadata["kind"], default, f.metadata["doc"]))
    return out


def param_groups(cls) -> dict[str, str]:
    """Option name -> its ``group`` (``""`` for none) of the dataclass ``cls``."""
    return {f.name: f.metadata.get("group", "") for f in dataclasses.fields(cls)}


def parse_params(
    cls,
    values: Mapping[str, Any],
    *,
    text: bool = False,
    defaults: Mapping[str, Any] | None = None,
    keys: Collection[str] | None = None,
):
    """The dataclass ``cls`` from ``values`` (``text``: command-line strings), over ``defaults`` (values
    replacing the fields' own defaults, already valid). ``keys``: the options ``values`` may set (default:
    every field). Unknown keys and bad values raise :class:`ParamError` naming the key; then
    ``cls.check(self)``, if defined, checks rules between fields."""
    fields = {name: kind for name, kind, _, _ in param_fields(cls)}
    allowed = set(fields) if keys is None else set(keys) & set(fields)
    kw: dict[str, Any] = dict(defaults or {})
    for key, v in values.items():
        if key not in allowed:
            raise ParamError(key, f"unknown key (known here: {', '.join(sorted(allowed))})")
        kind = fields[key]
        try:
            kw[key] = kind.text(v) if text and isinstance(v, str) else kind.value(v)
        except _Bad as e:
            raise ParamError(key, str(e)) from None
    obj = cls(**kw)
    check = getattr(obj, "check", None)
    if check is not None:
        check()
    return obj
