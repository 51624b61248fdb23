"""The YAML file of a map_server map: :class:`RosMapSettings`, written by hand in the exact form the
:mod:`ogm_ppl.rosmap` docstring shows and read with ruamel.yaml's safe loader."""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ogm_ppl.rosmap._errors import RosMapError

_MODES = ("trinary", "scale", "raw")
_MAX_YAML_BYTES = 1 << 20
_REQUIRED = ("image", "resolution", "origin", "occupied_thresh", "free_thresh", "negate")
_FLOAT_RE = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_INT_RE = re.compile(r"[-+]?\d+")
_TRUE, _FALSE = {"true", "yes", "on", "y"}, {"false", "no", "off", "n"}
_NONFINITE = {".inf", "+.inf", "-.inf", ".nan", "inf", "+inf", "-inf", "nan", "infinity"}


@dataclass(frozen=True)
class RosMapSettings:
    """The YAML fields. ``origin`` is ``(x, y, yaw)``; ``extra`` holds keys map_server ignores."""

    image: str
    resolution: float
    origin: tuple[float, float, float]
    negate: bool = False
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: str = "trinary"
    extra: dict[str, Any] = field(default_factory=dict)

    def to_yaml(self) -> str:
        """The YAML text :func:`save_ros_map` writes (the form the :mod:`ogm_ppl.rosmap` docstring shows)."""
        o = ", ".join(_fmt_float(v) for v in self.origin)
        return (
            f"image: {_fmt_str(self.image)}\nmode: {self.mode}\n"
            f"resolution: {_fmt_float(self.resolution)}\norigin: [{o}]\n"
            f"negate: {int(bool(self.negate))}\noccupied_thresh: {_fmt_float(self.occupied_thresh)}\n"
            f"free_thresh: {_fmt_float(self.free_thresh)}\n"
        )


def _fmt_float(x: float) -> str:
    s = repr(float(x))
    if "e" in s and "." not in s.split("e")[0]:
        mant, exp = s.split("e")
        s = f"{mant}.0e{exp}"
    return s


def _fmt_str(s: str) -> str:
    if re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.\-/]*", s) and _FLOAT_RE.fullmatch(s) is None:
        return s
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


_CORE = "tag:yaml.org,2002:"
_INDENT = re.compile(r"[ \t]*")
#: the tags of a map file's nodes: YAML's own scalar types (implicit or explicit), lists and the mapping
_TAGS = frozenset(_CORE + t for t in ("str", "int", "float", "bool", "null", "timestamp", "seq", "map"))


def _yaml_error(e: Exception, text: str) -> str:
    """A ruamel.yaml error as one line naming the line of the input where it stopped."""
    mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
    if mark is None and isinstance(getattr(e, "position", None), int):  # a character no YAML may hold
        line = text.count("\n", 0, e.position) + 1  # type: ignore[attr-defined]
        return f"line {line}: character #x{getattr(e, 'character', 0):04x}: {getattr(e, 'reason', '')}"
    problem = getattr(e, "problem", None) or " ".join(str(e).split())
    if mark is None:
        return str(problem)
    context, ctx_mark = getattr(e, "context", None), getattr(e, "context_mark", None)
    also = f" ({context} on line {ctx_mark.line + 1})" if context and ctx_mark is not None else ""
    return f"line {mark.line + 1}: {problem}{also}"


def _compose(text: str):
    """The node tree of the first document of ``text`` (None when it holds none), by the safe loader.

    YAML allows tabs between a ``key:`` and its value or before a comment; ruamel.yaml's scanner does not. A
    text it refuses for a tab is read again with every tab that follows other text on its line read as a
    space (a tab that indents stays, and stays refused)."""
    from ruamel.yaml import YAML
    from ruamel.yaml.scanner import ScannerError

    try:
        return next(YAML(typ="safe", pure=True).compose_all(text), None)
    except ScannerError as e:
        if "\\t" not in str(e.problem) or "\t" not in text:
            raise
    return next(YAML(typ="safe", pure=True).compose_all(_tabs_as_spaces(text)), None)


def _tabs_as_spaces(text: str) -> str:
    """``text`` with every tab after the first non-blank character of its line as a space."""
    out = []
    for line in text.split("\n"):
        n = _INDENT.match(line).end()  # type: ignore[union-attr]
        out.append(line[:n] + line[n:].replace("\t", " "))
    return "\n".join(out)


def _line(node) -> str:
    """``"line N"`` of a node whose tag is one of :data:`_TAGS`."""
    if node.tag not in _TAGS:  # !!python/object, !!binary, a local !tag, ...: never constructed
        raise ValueError(f"line {node.start_mark.line + 1}: tag {node.tag.replace(_CORE, '!!')!r} is not allowed")
    return f"line {node.start_mark.line + 1}"


def _scalar(node, what: str) -> str | None:
    """A scalar node's text (quotes and escapes resolved; a null scalar is None)."""
    from ruamel.yaml.nodes import ScalarNode

    where = _line(node)
    if not isinstance(node, ScalarNode):
        raise ValueError(f"{where}: {what} must be a plain value (nested collections are not supported)")
    return None if node.tag == _CORE + "null" else str(node.value)


def _parse_yaml(text: str) -> dict[str, Any]:
    """The first document of a map YAML: ``key: value`` pairs, each value a scalar or a flat list of scalars.

    Parsed by ruamel.yaml's safe loader into its node tree, and read from the nodes: nothing is constructed
    (the file is untrusted), a tag other than YAML's own types is refused, and each scalar keeps its text
    (``resolution: 1`` is ``"1"``, ``negate: false`` is ``"false"``) for :func:`_settings` to validate.
    Raises ``ValueError`` naming the line.
    """
    from ruamel.yaml.error import YAMLError
    from ruamel.yaml.nodes import MappingNode, SequenceNode

    try:
        root = _compose(text)
    except YAMLError as e:
        raise ValueError(_yaml_error(e, text)) from None
    except RecursionError:
        raise ValueError("collections nested too deeply") from None
    if root is None:
        return {}
    where = _line(root)
    if not isinstance(root, MappingNode):
        raise ValueError(f"{where}: expected 'key: value' lines")
    out: dict[str, Any] = {}
    for key_node, node in root.value:
        key = _scalar(key_node, "a key")
        where = f"line {key_node.start_mark.line + 1}"
        if not key:
            raise ValueError(f"{where}: empty key")
        if key in out:
            raise ValueError(f"{where}: duplicate key {key!r}")
        if isinstance(node, SequenceNode):
            _line(node)
            out[key] = [_scalar(item, f"an item of {key!r}") for item in node.value]
        else:
            out[key] = _scalar(node, repr(key))
    return out


def _get_float(doc: dict, key: str, path: Path) -> float:
    v = doc[key]
    if not isinstance(v, str):
        raise RosMapError(path, f"{key!r} must be a number, got {type(v).__name__}")
    return _to_float(v, key, path)


def _to_float(v: str, key: str, path: Path) -> float:
    if v.lower() in _NONFINITE:
        raise RosMapError(path, f"{key!r} must be finite, got {v!r}")
    if _FLOAT_RE.fullmatch(v) is None:
        raise RosMapError(path, f"{key!r} must be a number, got {v!r}")
    x = float(v)
    if not math.isfinite(x):
        raise RosMapError(path, f"{key!r} must be finite, got {v!r}")
    return x


def _settings(doc: dict, path: Path) -> RosMapSettings:
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise RosMapError(path, f"missing required key(s) {', '.join(missing)}")
    image = doc["image"]
    if not isinstance(image, str) or not image:
        raise RosMapError(path, "'image' must be a non-empty file name")
    res = _get_float(doc, "resolution", path)
    if res <= 0:
        raise RosMapError(path, f"'resolution' must be positive, got {res}")
    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise RosMapError(path, "'origin' must be a list of 3 numbers [x, y, yaw]")
    if not all(isinstance(v, str) for v in origin):
        raise RosMapError(path, "'origin' must be a list of 3 numbers [x, y, yaw]")
    ox, oy, oyaw = (_to_float(v, "origin", path) for v in origin)
    origin_t = (ox, oy, oyaw)
    occ, free = _get_float(doc, "occupied_thresh", path), _get_float(doc, "free_thresh", path)
    if not 0.0 <= free < occ <= 1.0:
        raise RosMapError(path, f"thresholds need 0 <= free_thresh < occupied_thresh <= 1, got {free}, {occ}")
    neg = doc["negate"]
    if isinstance(neg, str) and _INT_RE.fullmatch(neg):
        negate = int(neg) != 0
    elif isinstance(neg, str) and neg.lower() in _TRUE | _FALSE:
        negate = neg.lower() in _TRUE
    else:
        raise RosMapError(path, f"'negate' must be 0 or 1, got {neg!r}")
    mode = doc.get("mode", "trinary")
    if mode is None:
        mode = "trinary"
    if mode not in _MODES:
        raise RosMapError(path, f"'mode' must be one of {', '.join(_MODES)}, got {mode!r}")
    extra = {k: v for k, v in doc.items() if k not in (*_REQUIRED, "mode")}
    return RosMapSettings(image, res, origin_t, negate, occ, free, mode, extra)


def read_ros_map_yaml(yaml_path: str | os.PathLike) -> tuple[RosMapSettings, Path]:
    """The YAML of a map_server map, validated as :func:`load_ros_map` reads it: its settings and the path of the
    image it names (a relative ``image`` resolved against the YAML's directory; the image is not read).

    Raises:
        RosMapError: a missing, unreadable or malformed YAML, naming the path and the problem.
    """
    path = Path(yaml_path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise RosMapError(path, "YAML file not found") from None
    except OSError as e:
        raise RosMapError(path, f"cannot read YAML file ({e.strerror or e})") from None
    if len(raw) > _MAX_YAML_BYTES:
        raise RosMapError(path, "YAML file too large for map metadata")
    try:
        doc = _parse_yaml(raw.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise RosMapError(path, "YAML is not UTF-8 text") from None
    except ValueError as e:
        raise RosMapError(path, f"malformed YAML: {e}") from None
    s = _settings(doc, path)
    image_path = Path(os.path.expanduser(s.image))
    return s, image_path if image_path.is_absolute() else path.parent / image_path
