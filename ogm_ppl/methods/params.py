r"""Parameters of a map method: a frozen dataclass whose fields declare their kind, range and meaning.

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
ogm_ppl.methods.params.ParamError: sweeps: must be >= 1, got 0
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "INT_LIMIT",
    "Block",
    "Bool",
    "Choice",
    "DeltaName",
    "Float",
    "GuideFile",
    "Int",
    "Kind",
    "Optional",
    "Pair",
    "ParamError",
    "Patch",
    "PriorName",
    "SensorName",
    "Text",
    "param",
    "param_fields",
    "parse_params",
]


class ParamError(ValueError):
    """A bad parameter value: ``key`` names the parameter, ``message`` says what is wrong."""

    def __init__(self, key: str, message: str) -> None:
        self.key, self.message = key, message
        super().__init__(f"{key}: {message}")


class _Bad(Exception):
    """Raised by a kind; :func:`parse_params` turns it into a :class:`ParamError` naming the key."""


class Kind:
    """What values a parameter takes: :meth:`value` checks (and normalises) a TOML / Python value,
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


class StartMap(Kind):
    """A starting map's name: one of ``options``, or ``"guide:CORPUS"`` (the mode of the guide learned on a
    corpus, :func:`~ogm_ppl.inference.variational.corpus_guide`)."""

    def __init__(self, *options: str) -> None:
        self.options = tuple(options)

    def value(self, v):
        if isinstance(v, str) and v.startswith("guide:"):
            from ogm_ppl.inference.variational.amortised import corpus_guides, unknown_corpus_message

            if v.removeprefix("guide:") not in corpus_guides():
                raise _Bad(unknown_corpus_message(v.removeprefix("guide:")))
            return v
        if v not in self.options:
            raise _Bad(f"must be one of {', '.join(map(repr, self.options))} or 'guide:CORPUS', got {v!r}")
        return v

    def describe(self):
        return " | ".join(self.options) + " | guide:CORPUS"


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


def _pos_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= 1


def _hw(s: str) -> list[int] | None:
    parts = s.strip().lower().split("x")
    if len(parts) == 2 and all(p.isdigit() and int(p) > 0 for p in parts):
        return [int(parts[0]), int(parts[1])]
    return None


class Patch(Kind):
    """A patch shape (:func:`~ogm_ppl.inference.tiling.patch_shape`): an int ``L`` (a run of ``L`` cells),
    ``[h, w]`` (at most ``max_cells`` cells; ``HxW`` on the command line), ``"plus"`` or ``"square"``."""

    def __init__(self, max_cells: int = 25) -> None:
        self.max_cells = max_cells

    def value(self, v):
        if isinstance(v, str):
            if v not in ("plus", "square"):
                raise _Bad(f"must be an int L, [h, w], 'plus' or 'square', got {v!r}")
            return v
        if isinstance(v, tuple):
            v = list(v)
        if _pos_int(v):
            return v
        if isinstance(v, list) and len(v) == 2 and all(_pos_int(x) for x in v):
            if v[0] * v[1] > self.max_cells:
                raise _Bad(f"{v[0]} x {v[1]} patches are too large (at most {self.max_cells} cells)")
            return [int(v[0]), int(v[1])]
        raise _Bad(f"must be an int L, [h, w] (positive), 'plus' or 'square', got {v!r}")

    def text(self, s):
        t = s.strip().lower()
        if t.isdigit() and int(t) > 0:
            return int(t)
        hw = _hw(t)
        if hw is not None:
            return self.value(hw)
        if t in ("plus", "square"):
            return t
        raise _Bad(f"expected HxW, a positive int L, 'plus' or 'square', got {s!r}")

    def describe(self):
        return "patch (L, [h, w] / HxW, plus, square)"


class Block(Kind):
    """A proposal block: ``[h, w]`` (``HxW`` on the command line), an int ``w`` (``[1, w]``) or ``"all"``."""

    def value(self, v):
        if v == "all":
            return v
        if _pos_int(v):
            return [1, int(v)]
        if isinstance(v, (list, tuple)) and len(v) == 2 and all(_pos_int(x) for x in v):
            return [int(v[0]), int(v[1])]
        raise _Bad(f"must be [h, w] (positive), an int w or 'all', got {v!r}")

    def text(self, s):
        t = s.strip().lower()
        if t == "all":
            return t
        if t.isdigit():
            return self.value(int(t))
        hw = _hw(t)
        if hw is None:
            raise _Bad(f"expected HxW, a positive int W or 'all', got {s!r}")
        return hw

    def describe(self):
        return "block ([h, w] / HxW, w, all)"


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


class PriorName(Kind):
    """A map prior by name (:func:`~ogm_ppl.priors.named.prior_by_name`: ``independent``, ``mrf:houseexpo``,
    ``border:houseexpo``, ...)."""

    def value(self, v):
        name = Text().value(v)
        from ogm_ppl.priors.named import prior_by_name

        try:
            prior_by_name(name, (8, 8))
        except (ValueError, KeyError, FileNotFoundError) as e:
            raise _Bad(str(e)) from None
        return name

    def describe(self):
        return "prior name"


class SensorName(Kind):
    """A forward sensor model by name (:func:`~ogm_ppl.sensors.sensor_by_name`: ``gaussian``, or a kind
    registered with :func:`~ogm_ppl.sensors.register_sensor`, with its options: ``KIND:KEY=VALUE,...``)."""

    def value(self, v):
        name = Text().value(v)
        from ogm_ppl.sensors import sensor_by_name, sensor_kinds, split_sensor_name

        try:
            kind, _ = split_sensor_name(name)
        except ValueError as e:
            raise _Bad(str(e)) from None
        if kind not in sensor_kinds():
            raise _Bad(
                f"unknown sensor kind {kind!r}; kinds: {', '.join(sensor_kinds())} (a kind of your own: register "
                "it with ogm_ppl.sensors.register_sensor in a module named in $OGM_PPL_METHODS)"
            )
        try:  # a broken factory is found here, before any data is read (a value it refuses is the run's to tell)
            sensor_by_name(name, 1.0, 0.0)
        except TypeError as e:  # its message names the sensor
            raise _Bad(str(e)) from None
        except ValueError:
            pass
        return name

    def describe(self):
        return "sensor name"


class DeltaName(Kind):
    """An update term Delta by name (:func:`~ogm_ppl.models.delta_by_name`: ``haehnel``, ``p21``, ...)."""

    def value(self, v):
        name = Text().value(v)
        from ogm_ppl.models import delta_by_name

        try:
            delta_by_name(name)
        except (ValueError, KeyError, FileNotFoundError) as e:
            raise _Bad(f"unknown update term ({e})") from None
        return name

    def describe(self):
        return "Delta name"


class GuideFile(Kind):
    """An amortised guide: ``"shipped"`` (``ogm_ppl/fitted/guide_amortised.npz``), ``"corpus:CORPUS"`` (the
    guide learned on a corpus's training plans, :func:`~ogm_ppl.inference.variational.corpus_guide`) or the
    path of a guide saved by :meth:`~ogm_ppl.inference.variational.AmortisedGuide.save` (``~`` and ``$VARS``
    expanded; a relative path is read from the working directory, in a spec too). A bare corpus name that is no
    file is refused with a hint at ``"corpus:CORPUS"``."""

    def value(self, v):
        name = Text().value(v)
        if name == "shipped":
            return name
        from ogm_ppl.inference.variational.amortised import corpus_guides, unknown_corpus_message

        if name.startswith("corpus:"):
            if name.removeprefix("corpus:") not in corpus_guides():
                raise _Bad(unknown_corpus_message(name.removeprefix("corpus:")))
            return name
        path = Path(os.path.expandvars(os.path.expanduser(name)))
        if not path.is_file():
            corpus = next((c for c in (name, name.lower()) if c in corpus_guides()), None)
            hint = f"did you mean 'corpus:{corpus}'?" if corpus else f"a guide is {self.describe()}"
            relative = not path.is_absolute() and not corpus
            where = f" (a relative path is read from the working directory, {Path.cwd()})" if relative else ""
            raise _Bad(f"no such guide file: {path}{where}; {hint}")
        return str(path)

    def describe(self):
        return "'shipped', 'corpus:CORPUS' or the path of a guide .npz"


def param(default: Any, kind: Kind, doc: str) -> Any:
    """A parameter field of a method's dataclass: its ``default``, its :class:`Kind` and a one-line doc."""
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata={"kind": kind, "doc": doc})
    return dataclasses.field(default=default, metadata={"kind": kind, "doc": doc})


def param_fields(cls) -> list[tuple[str, Kind, Any, str]]:
    """``(name, kind, default, doc)`` of every parameter of the dataclass ``cls``."""
    out = []
    for f in dataclasses.fields(cls):
        if "kind" not in f.metadata:
            raise TypeError(f"{cls.__name__}.{f.name}: make parameter fields with param(default, kind, doc)")
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc,operator]
        out.append((f.name, f.metadata["kind"], default, f.metadata["doc"]))
    return out


def parse_params(cls, values: Mapping[str, Any], *, text: bool = False, defaults: Mapping[str, Any] | None = None):
    """The dataclass ``cls`` from ``values`` (``text``: command-line strings), over ``defaults`` (values
    replacing the fields' own defaults, already valid). Unknown keys and bad values raise
    :class:`ParamError` naming the key; then ``cls.check(self)``, if defined, checks rules between fields."""
    fields = {name: kind for name, kind, _, _ in param_fields(cls)}
    kw: dict[str, Any] = dict(defaults or {})
    for key, v in values.items():
        if key not in fields:
            raise ParamError(key, f"unknown key (known here: {', '.join(sorted(fields))})")
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
