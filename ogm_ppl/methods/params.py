r"""Parameters of a map method: a frozen dataclass whose fields declare their kind, range and meaning.

The fields are options of the library's one option system (:mod:`ogm_ppl.options`: :func:`param`, the
kinds :class:`Int`, :class:`Float`, :class:`Choice`, ..., :func:`parse_params` and :class:`ParamError`, all
re-exported here); this module adds the kinds only map methods take: a patch shape (:class:`Patch`), a
proposal block (:class:`Block`), a starting map (:class:`StartMap`) and the names of a prior, a sensor
model, an update term and an amortised guide.

>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class P:
...     patch: object = param([3, 3], Patch(), "patch shape")
>>> parse_params(P, {"patch": "2x4"}, text=True)
P(patch=[2, 4])
"""

from __future__ import annotations

import os
from pathlib import Path

from ogm_ppl.options import (
    INT_LIMIT,
    Bool,
    Choice,
    Float,
    Int,
    Kind,
    Optional,
    Pair,
    ParamError,
    Text,
    _Bad,
    param,
    param_fields,
    parse_params,
)

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
