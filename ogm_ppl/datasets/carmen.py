"""Read CARMEN laser logs (plain or gzip) into :class:`~ogm_ppl.scans.Scans`.

Line formats read (one message per line, whitespace separated; ``#`` lines are comments)::

    FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
    ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
                n r_1..r_n m rem_1..rem_m laser_x laser_y laser_theta robot_x robot_y robot_theta
                tv rv forward_safety side_safety turn_axis timestamp host logger_timestamp
    PARAM name value [ipc_timestamp host logger_timestamp]

``x y theta`` of FLASER and ``laser_*`` of ROBOTLASER1 are the pose of the laser (in the ``*-corrected``
logs of the shared data folder the SLAM-corrected pose); it is the scan pose. Other message types (ODOM,
NEFF, RLASER, RAWLASER*, ...) are skipped and counted per type.

**Beam angles.** ROBOTLASER1 carries them: ``start_angle + i * angular_res``. FLASER does not; its beams
span ``fov`` (PARAM ``laser_front_laser_fov``, else ``n * resolution`` from PARAM
``laser_front_laser_resolution`` in degrees, else 180 degrees) starting at ``-fov / 2`` (-90 degrees).
The spacing is ``fov / (n - 1)`` for odd ``n`` (181, 361: both ends are beams, -90 .. +90) and
``fov / n`` for even ``n`` (180, 360: -90 .. +89 at 1 degree). That is what a SICK LMS reports
(181 / 361 beams for the full half-plane, 180 / 360 when the last beam is cut), and it is the rule of
GMapping's own gfs tools, which produced the corrected poses of these logs (beam step pi/180 for 180 or
181 beams, pi/360 for 360 or 361, first beam at -pi/2), so maps built with it agree with the poses.

**No return.** Lasers report "no return" with a sentinel value instead of a range. By default
(``no_return_threshold=None``) a reading is no-return when it is ``>=`` the line's own ``max_range``
(ROBOTLASER1), and for FLASER when it is ``>=`` the lower end of the sentinel band holding the log's
largest reading: SICK centimetre-mode error codes 81.83-81.91 m (Intel, Freiburg, CSAIL, Seattle,
Belgioioso), the 50.5-51.5 m band of the 180-beam logs (51.05-51.16 in Infinite Corridor, FHW,
Edmonton, Acapulco; their largest real readings are 50.1-50.2 m), exactly 50.0 m or 32.767 m (millimetre
mode). The PARAM ``robot_front_laser_max`` is recorded but not used: Edmonton says 10 m while 35 % of
its readings are real readings between 10 and 49 m. ``no_return="drop"`` (default, as the thesis does,
Section 6.2) marks no-return beams invalid; ``"max"`` turns them into max-range readings.

**Usable range.** ``max_usable_range`` drops (``usable_range_rule="drop"``) or clips to max range
(``"max"``) every reading at or beyond it: the Intel protocol of thesis Section 6.2 is
``read_carmen(path, max_usable_range=20.0)``.

>>> import os, tempfile
>>> p = os.path.join(tempfile.mkdtemp(), "tiny.log")
>>> with open(p, "w") as f:
...     _ = f.write("FLASER 3 1.0 81.83 25.0 0 0 0 0 0 0 1.0 host 1.0\\n")
>>> log = read_carmen(p, max_usable_range=20.0)  # the Intel protocol of Section 6.2
>>> log.scans.valid.tolist(), log.counts["no_return"], log.counts["beyond_usable"]
([[True, False, False]], 1, 1)
"""

from __future__ import annotations

import gzip
import math
import os
import re
import warnings
import zlib
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ogm_ppl._validate import finite_number
from ogm_ppl.grid import Grid
from ogm_ppl.scans import Scans

__all__ = ["CarmenFormatError", "CarmenLog", "CarmenReadWarning", "ScanLog", "read_carmen"]

_LASER_TYPES = ("FLASER", "ROBOTLASER1")
_TYPE_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
# (lowest value, highest value) of each known FLASER sentinel band; readings >= lowest are no-return.
_SENTINEL_BANDS = ((81.83, 81.92), (50.5, 51.5), (50.0, 50.0), (32.767, 32.767))
_FLASER_TAIL = ("x", "y", "theta", "odom_x", "odom_y", "odom_theta", "ipc_timestamp", "host", "logger_timestamp")
_RL_HEAD = (
    "laser_type",
    "start_angle",
    "fov",
    "angular_res",
    "max_range",
    "accuracy",
    "remission_mode",
)
_RL_TAIL = (
    "laser_x",
    "laser_y",
    "laser_theta",
    "robot_x",
    "robot_y",
    "robot_theta",
    "tv",
    "rv",
    "forward_safety",
    "side_safety",
    "turn_axis",
    "timestamp",
    "host",
    "logger_timestamp",
)
_MAX_BEAMS = 100_000
# PARAMs read (CARMEN spells the laser ones both ways); value must be finite (and > 0 where True).
_NUMERIC_PARAMS = {
    "laser_front_laser_fov": True,
    "laser_frontlaser_fov": True,
    "laser_front_laser_resolution": True,
    "laser_frontlaser_resolution": True,
    "robot_frontlaser_offset": False,
    "robot_front_laser_max": False,
}


#: metres between two consecutive scans' poses beyond which the reader warns (:class:`CarmenReadWarning`): the
#: corrected logs step at most 1.8 m, and a wrong pose stretches the grid that covers the poses
MAX_POSE_STEP = 25.0


class CarmenReadWarning(UserWarning):
    """Lenient reading stopped early (a damaged gzip stream), or two consecutive poses lie more than
    :data:`MAX_POSE_STEP` apart: the message names the file and the lines."""


class CarmenFormatError(ValueError):
    """A malformed CARMEN log line: ``str`` names the file, the 1-based line number and the field."""

    def __init__(self, path: str | os.PathLike, line_no: int, field: str, message: str) -> None:
        self.path, self.line_no, self.field, self.message = str(path), line_no, field, message
        super().__init__(f"{self.path}, line {line_no}, field {field!r}: {message}")


class ScanLog:
    """What every log reader returns beside its own bookkeeping: ``scans`` (:class:`~ogm_ppl.scans.Scans`), their
    extent and a grid that covers it (:class:`CarmenLog`, :class:`~ogm_ppl.datasets.rosbag.BagLog`)."""

    scans: Scans

    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` in metres of the poses and the end points of all hits."""
        return self.scans.extent()

    def grid(self, resolution: float, margin: float = 1.0) -> Grid:
        """A 2D :class:`Grid` covering :meth:`extent` plus ``margin`` metres on every side."""
        xmin, xmax, ymin, ymax = self.extent()
        cols = math.ceil((xmax - xmin + 2 * margin) / resolution)
        rows = math.ceil((ymax - ymin + 2 * margin) / resolution)
        return Grid((max(rows, 1), max(cols, 1)), resolution, (xmin - margin, ymin - margin))


@dataclass
class CarmenLog(ScanLog):
    """A CARMEN log read into scans (see the module docstring for every rule applied).

    Attributes:
        scans: the laser scans in line order, with ``scans.valid`` marking dropped beams.
        path: the file read.
        num_lines: lines in the file.
        bad_lines: ``(line_no, reason)`` of every line skipped as malformed (lenient mode).
        skipped_types: message type -> number of lines skipped because the type is not read.
        max_range: the ``max_range`` given to :class:`Scans` (metres).
        settings: every option and derived value used (JSON-serialisable).
        line_numbers: ``S`` 1-based line of each scan; ``timestamps``: ``S`` its ipc timestamp.
        counts: beams per outcome: ``no_return``, ``beyond_usable``, ``below_min`` (of the kept scans).
    """

    scans: Scans
    path: str
    num_lines: int
    bad_lines: list[tuple[int, str]]
    skipped_types: dict[str, int]
    max_range: float
    settings: dict
    line_numbers: np.ndarray = field(repr=False)
    timestamps: np.ndarray = field(repr=False)
    counts: dict[str, int] = field(default_factory=dict)


class _LineError(Exception):
    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field, self.message = field, message


# ---------------------------------------------------------------------------------- file -> lines
def _read_text(path: Path, strict: bool, bad: list[tuple[int, str]]) -> str:
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as e:
            raw = _decompress_prefix(raw)
            raw = raw[: raw.rfind(b"\n") + 1]  # the last, cut-off line is not a good line
            stop = raw.count(b"\n") + 1
            if strict:
                msg = f"corrupt or truncated gzip stream ({e}); the {stop - 1} lines before it are whole"
                raise CarmenFormatError(path, stop, "gzip", msg) from None
            msg = f"corrupt or truncated gzip stream ({e}); read the {stop - 1} whole lines before it, "
            msg += f"stopped at line {stop}"
            bad.append((stop, msg))
            warnings.warn(f"{path}: {msg}", CarmenReadWarning, stacklevel=3)
    return raw.decode("latin-1")


def _decompress_prefix(raw: bytes, chunk: int = 256) -> bytes:
    """The bytes a damaged gzip stream yields before the damage: fed ``chunk`` bytes at a time, so a
    corrupt block loses at most the output of its own chunk, never what came before."""
    d = zlib.decompressobj(16 + zlib.MAX_WBITS)
    out: list[bytes] = []
    for i in range(0, len(raw), chunk):
        try:
            out.append(d.decompress(raw[i : i + chunk]))
        except zlib.error:
            break
        if d.eof:
            break
    return b"".join(out)


# ------------------------------------------------------------------------------- line layouts
def _names(key: tuple) -> list[str]:
    """Field name of every token of a laser line with group key ``(type, n)`` / ``(type, n, m)``."""
    n = key[1]
    if key[0] == "FLASER":
        return [key[0], "num_readings", *(f"range[{i}]" for i in range(n)), *_FLASER_TAIL]
    m = key[2]
    return [
        key[0],
        *_RL_HEAD,
        "num_readings",
        *(f"range[{i}]" for i in range(n)),
        "num_remissions",
        *(f"remission[{i}]" for i in range(m)),
        *_RL_TAIL,
    ]


def _fields(key: tuple) -> dict[str, slice]:
    """Columns of the numeric matrix (token index - 1: every field used lies before the host token)."""
    n = key[1]
    if key[0] == "FLASER":
        return {"ranges": slice(1, 1 + n), "pose": slice(1 + n, 4 + n), "ts": slice(7 + n, 8 + n)}
    m = key[2]
    return {
        "ranges": slice(8, 8 + n),
        "pose": slice(9 + n + m, 12 + n + m),
        "ts": slice(20 + n + m, 21 + n + m),
        "geometry": slice(1, 5),
    }


def _group_key(kind: str, t: list[str]) -> tuple:
    """Group key of one laser line, after checking its counts and length; raises _LineError."""

    def count(i: int, name: str) -> int:
        if i >= len(t):
            raise _LineError(name, f"line ends before {name} (only {len(t)} tokens)")
        try:
            v = int(t[i])
        except ValueError:
            raise _LineError(name, f"expected a whole number, got {t[i][:20]!r}") from None
        if not 0 <= v <= _MAX_BEAMS or (name == "num_readings" and v == 0):
            raise _LineError(name, f"{v} is out of range")
        return v

    if kind == "FLASER":
        key: tuple = (kind, count(1, "num_readings"))
    else:
        n = count(8, "num_readings")
        key = (kind, n, count(9 + n, "num_remissions"))
    expected = key[1] + 11 if kind == "FLASER" else key[1] + key[2] + 24  # == len(_names(key))
    if len(t) != expected:
        raise _LineError("line length", f"{expected} tokens expected for these counts, got {len(t)}")
    return key


def _numbers(t: list[str]) -> list[str]:
    """Every token but the type and the host (second to last in both formats)."""
    return t[1:-2] + t[-1:]


def _parse_group(key: tuple, rows: list[list[str]]) -> tuple[np.ndarray, list[int], list[tuple[int, _LineError]]]:
    """Numeric matrix of the rows that parse and hold valid values, their row indices, and
    ``(row, error)`` of the others."""
    try:
        vals = np.array([_numbers(t) for t in rows], dtype=float)
        ok_rows = list(range(len(rows)))
        errors: list[tuple[int, _LineError]] = []
    except ValueError:  # find the bad rows one by one (still vectorised per row)
        out, ok_rows, errors = [], [], []
        for i, t in enumerate(rows):
            try:
                out.append(np.array(_numbers(t), dtype=float))
                ok_rows.append(i)
            except ValueError:
                errors.append((i, _first_non_numeric(t, _names(key))))
        vals = np.array(out) if out else np.zeros((0, len(rows[0]) - 2))
    f = _fields(key)
    good = np.ones(vals.shape, dtype=bool)
    r = vals[:, f["ranges"]]
    good[:, f["ranges"]] = np.isfinite(r) & (r >= 0)
    good[:, f["pose"]] = np.isfinite(vals[:, f["pose"]])
    if "geometry" in f:  # start_angle fov angular_res max_range, and the last beam's angle
        g = vals[:, f["geometry"]]
        good[:, f["geometry"]] = np.isfinite(g)
        with np.errstate(all="ignore"):
            good[:, 3] &= np.isfinite(g[:, 0] + g[:, 2] * (key[1] - 1))
    bad_rows = np.flatnonzero(~good.all(axis=1))
    names = _names(key)
    for row in bad_rows:
        col = int(np.argmin(good[row]))
        errors.append((ok_rows[row], _LineError(names[col + 1], f"{float(vals[row, col])!r} is not a valid value")))
    keep = np.setdiff1d(np.arange(len(ok_rows)), bad_rows)
    return vals[keep], [(ok_rows[k]) for k in keep], errors


def _first_non_numeric(t: list[str], names: list[str]) -> _LineError:
    for tok, name in zip(t[1:], names[1:]):
        if name == "host":
            continue
        try:
            float(tok)
        except ValueError:
            return _LineError(name, f"expected a number, got {tok[:20]!r}")
    return _LineError("line", "does not parse")  # pragma: no cover


# ------------------------------------------------------------------------------------ reader
def read_carmen(
    path: str | os.PathLike,
    *,
    strict: bool = True,
    max_usable_range: float | None = None,
    usable_range_rule: str = "drop",
    no_return: str = "drop",
    no_return_threshold: float | None = None,
    min_range: float = 0.0,
    max_range: float | None = None,
    pose_step: int = 1,
    pose_fraction: float | None = None,
    beam_step: int = 1,
    seed: int = 0,
    messages: str | tuple[str, ...] = "auto",
    apply_laser_offset: bool = False,
) -> CarmenLog:
    """Read a CARMEN log (plain or gzip, detected by its magic bytes) into scans.

    Args:
        path: the log file.
        strict: raise :class:`CarmenFormatError` on the first malformed line (default); with False,
            skip malformed lines and list them in ``bad_lines``. Good lines are never lost.
        max_usable_range: readings at or beyond it (metres) are dropped or clipped (Section 6.2: 20 m).
        usable_range_rule: ``"drop"`` (mark invalid) or ``"max"`` (read as max-range readings).
        no_return: ``"drop"`` (mark no-return sentinel beams invalid) or ``"max"`` (max-range readings).
        no_return_threshold: readings ``>=`` it are no-return; None = auto (module docstring).
        min_range: readings below it are invalid.
        max_range: the sensor max range given to :class:`Scans`; readings above it become max-range
            readings. None: ``max_usable_range`` if given, else the no-return threshold, else just
            above the largest reading (so that no reading is a max-range reading).
        pose_step, pose_fraction, beam_step: subsampling as :meth:`Scans.subsample` (every k-th scan, an
            evenly spaced fraction of the scans, every k-th beam); deterministic.
        seed: recorded in ``settings`` only; nothing here is random.
        messages: laser message types to read: ``"auto"`` reads ROBOTLASER1 if the log has any, else
            FLASER (logs often hold both for the same scans); or a tuple such as
            ``("FLASER", "ROBOTLASER1")`` (scans with fewer beams are padded with invalid beams).
        apply_laser_offset: treat FLASER ``x y theta`` as the robot pose and move it forward by PARAM
            ``robot_frontlaser_offset``. False (default): CARMEN writes the laser pose there.

    Returns:
        a :class:`CarmenLog`.
    """
    path = Path(path)
    for opt, value, lo, strict_lo in (
        ("max_usable_range", max_usable_range, 0.0, True),
        ("no_return_threshold", no_return_threshold, 0.0, True),
        ("max_range", max_range, 0.0, True),
        ("min_range", min_range, 0.0, False),
    ):
        if value is not None:
            finite_number(value, f"read_carmen: {opt}", minimum=lo, strict=strict_lo)
    for name, v, allowed in (
        ("usable_range_rule", usable_range_rule, ("drop", "max")),
        ("no_return", no_return, ("drop", "max")),
    ):
        if v not in allowed:
            raise ValueError(f"read_carmen: {name} must be one of {allowed}, got {v!r}")
    if pose_fraction is not None and pose_step != 1:
        raise ValueError("read_carmen: give pose_step or pose_fraction, not both")
    if pose_step < 1 or beam_step < 1 or not (pose_fraction is None or 0 < pose_fraction <= 1):
        raise ValueError(
            f"read_carmen: need pose_step, beam_step >= 1 and pose_fraction in (0, 1], got "
            f"{pose_step}, {beam_step}, {pose_fraction}"
        )
    bad: list[tuple[int, str]] = []
    lines = _read_text(path, strict, bad).split("\n")
    if lines and lines[-1] == "":
        lines.pop()

    errors: list[tuple[int, _LineError, str]] = []  # (line, error, message type)
    groups: dict[tuple, list[tuple[int, list[str]]]] = defaultdict(list)
    skipped: Counter = Counter()
    params: dict[str, str] = {}
    for no, line in enumerate(lines, 1):
        head = line.split(None, 1)
        if not head or head[0].startswith("#"):
            continue
        kind = head[0]
        if kind in _LASER_TYPES:
            t = line.split()
            try:
                groups[_group_key(kind, t)].append((no, t))
            except _LineError as e:
                errors.append((no, e, kind))
        elif kind == "PARAM":
            t = line.split()
            try:
                params.update([_param(t)])
            except _LineError as e:
                errors.append((no, e, kind))
        elif kind in skipped or _TYPE_RE.match(kind):
            skipped[kind] += 1
        else:
            errors.append((no, _LineError("message type", f"{kind[:20]!r} is not a message type"), ""))

    present = {k[0] for k in groups}
    if messages == "auto":
        use = {"ROBOTLASER1"} if "ROBOTLASER1" in present else {"FLASER"}
    else:
        use = set((messages,) if isinstance(messages, str) else messages)
        if not use <= set(_LASER_TYPES):
            raise ValueError(f"read_carmen: messages must be 'auto' or among {_LASER_TYPES}, got {messages!r}")
    parsed = []
    for key, items in groups.items():
        if key[0] not in use:
            skipped[key[0]] += len(items)
            continue
        vals, rows, errs = _parse_group(key, [t for _, t in items])
        errors += [(items[i][0], e, key[0]) for i, e in errs]
        if rows:
            parsed.append((key, vals, np.array([items[i][0] for i in rows], dtype=np.int64)))

    for no, err, kind in sorted(errors, key=lambda e: e[0]):
        if kind in _LASER_TYPES and kind not in use:  # a laser type not read: skipped, not checked
            skipped[kind] += 1
            continue
        if strict:
            raise CarmenFormatError(path, no, err.field, err.message)
        bad.append((no, f"{err.field}: {err.message}"))
    if not parsed:
        raise CarmenFormatError(path, 0, "file", f"no readable laser scans ({'/'.join(sorted(use))}) found")

    geom = _flaser_geometry(params)
    return _assemble(
        path,
        len(lines),
        bad,
        dict(skipped),
        params,
        geom,
        parsed,
        dict(
            strict=strict,
            max_usable_range=max_usable_range,
            usable_range_rule=usable_range_rule,
            no_return=no_return,
            no_return_threshold=no_return_threshold,
            min_range=min_range,
            max_range=max_range,
            pose_step=pose_step,
            pose_fraction=pose_fraction,
            beam_step=beam_step,
            seed=seed,
            messages=sorted(use),
            apply_laser_offset=apply_laser_offset,
        ),
    )


def _param(t: list[str]) -> tuple[str, str]:
    """``(name, value)`` of a PARAM line; the PARAMs this reader uses must hold valid numbers."""
    if len(t) < 3:
        raise _LineError("value", "PARAM needs a name and a value")
    if t[1] in _NUMERIC_PARAMS:
        try:
            v = float(t[2])
        except ValueError:
            raise _LineError(f"PARAM {t[1]}", f"expected a number, got {t[2][:20]!r}") from None
        if not math.isfinite(v) or (_NUMERIC_PARAMS[t[1]] and v <= 0):
            raise _LineError(f"PARAM {t[1]}", f"{t[2][:20]!r} is not a valid value")
    return t[1], t[2]


def _flaser_geometry(params: dict[str, str]) -> dict:
    """FLASER geometry from the PARAMs (the last value of each in the file wins)."""

    def get(*names: str) -> float | None:
        return next((float(params[k]) for k in names if k in params), None)

    fov = get("laser_front_laser_fov", "laser_frontlaser_fov")
    if fov is not None and fov > 2 * math.pi + 1e-3:
        fov = math.radians(fov)  # given in degrees
    return {
        "fov": fov,
        "resolution_deg": get("laser_front_laser_resolution", "laser_frontlaser_resolution"),
        "frontlaser_offset": get("robot_frontlaser_offset") or 0.0,
        "param_front_laser_max": get("robot_front_laser_max"),
    }


def flaser_angles(n: int, fov: float | None = None, resolution_deg: float | None = None) -> np.ndarray:
    """FLASER beam angles (radians, relative to the laser heading) for ``n`` beams (module docstring).

    >>> np.degrees(flaser_angles(180))[[0, 1, -1]].round(6).tolist()
    [-90.0, -89.0, 89.0]
    >>> np.degrees(flaser_angles(361))[[0, -1]].round(6).tolist()
    [-90.0, 90.0]
    """
    if fov is None:
        fov = math.radians(resolution_deg) * (n - 1 if n % 2 else n) if resolution_deg else math.pi
    step = fov / (n - 1 if n % 2 and n > 1 else n)
    return -fov / 2 + step * np.arange(n)


def _stack(parsed: list, geom: dict, apply_offset: bool) -> tuple[np.ndarray, ...]:
    """Scans of all groups in line order, padded to the most beams: poses, angles, ranges, present
    (beam exists), per-scan threshold from the line (NaN: none), line numbers, timestamps, is_flaser."""
    S = sum(len(p[2]) for p in parsed)
    B = max(p[0][1] for p in parsed)
    poses = np.zeros((S, 3))
    angles = np.zeros((S, B))
    ranges = np.zeros((S, B))
    present = np.zeros((S, B), dtype=bool)
    thr = np.full(S, np.nan)  # per-scan no-return threshold from the line (ROBOTLASER1 max_range)
    nos = np.zeros(S, dtype=np.int64)
    ts = np.zeros(S)
    is_flaser = np.zeros(S, dtype=bool)
    s = 0
    for key, vals, lnos in parsed:
        f = _fields(key)
        k, n = len(lnos), key[1]
        sl = slice(s, s + k)
        ranges[sl, :n] = vals[:, f["ranges"]]
        poses[sl] = vals[:, f["pose"]]
        present[sl, :n] = True
        nos[sl], ts[sl] = lnos, vals[:, f["ts"]][:, 0]
        if key[0] == "FLASER":
            angles[sl, :n] = flaser_angles(n, geom["fov"], geom["resolution_deg"])
            is_flaser[sl] = True
            if apply_offset:
                off = geom["frontlaser_offset"]
                poses[sl, 0] += off * np.cos(poses[sl, 2])
                poses[sl, 1] += off * np.sin(poses[sl, 2])
        else:
            start, _, res, mx = vals[:, f["geometry"]].T
            angles[sl, :n] = start[:, None] + res[:, None] * np.arange(n)
            thr[sl] = np.where(mx > 0, mx, np.nan)
        s += k
    order = np.argsort(nos, kind="stable")
    return tuple(a[order] for a in (poses, angles, ranges, present, thr, nos, ts, is_flaser))


def _assemble(path, num_lines, bad, skipped, params, geom, parsed, settings) -> CarmenLog:
    """Apply the no-return, usable-range, min-range and subsampling rules; build the CarmenLog."""
    poses, angles, ranges, present, thr, nos, ts, is_flaser = _stack(parsed, geom, settings["apply_laser_offset"])
    _warn_pose_jumps(path, np.asarray(poses, dtype=np.float64), nos)
    auto_band = None
    if settings["no_return_threshold"] is not None:
        thr[:] = float(settings["no_return_threshold"])
    elif is_flaser.any():
        auto_band = _sentinel_band(float(ranges[is_flaser[:, None] & present].max()))
        thr[is_flaser] = np.nan if auto_band is None else auto_band
    no_ret = present & (ranges >= np.where(np.isnan(thr), np.inf, thr)[:, None])
    valid = present.copy()
    u = settings["max_usable_range"]
    beyond = valid & ~no_ret & (ranges >= u) if u is not None else np.zeros_like(valid)
    finite_thr = thr[~np.isnan(thr)]
    mr = settings["max_range"]
    if mr is None:
        if u is not None:
            mr = float(u)
        elif finite_thr.size:
            mr = float(finite_thr.max())
        else:
            mr = float(np.nextafter(max(float(ranges[present].max()), settings["min_range"]), np.inf))
    scans, counts, keep = beam_rules(poses, angles, ranges, present, valid, no_ret, beyond, None, mr, settings)
    nos, ts = nos[keep], ts[keep]
    settings = dict(
        settings,
        **geom,
        auto_no_return_threshold=auto_band,
        params=params,
        beam_counts=sorted({int(k[1]) for k, _, _ in parsed}),
    )
    return CarmenLog(scans, str(path), num_lines, bad, skipped, float(scans.max_range), settings, nos, ts, counts)


def _warn_pose_jumps(path, poses: np.ndarray, nos: np.ndarray) -> None:
    """Warn (:class:`CarmenReadWarning`) where consecutive scans' poses (``S x 3``, line order, lines ``nos``)
    lie more than :data:`MAX_POSE_STEP` metres apart, naming the largest step's lines and the number of such
    steps. Timestamps are not checked: corrected logs often hold zeros, and some go back."""
    if len(poses) < 2:
        return
    step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    far = np.flatnonzero(step > MAX_POSE_STEP)
    if far.size:
        i = int(far[np.argmax(step[far])])
        msg = f"the pose moves {step[i]:.1f} m between lines {nos[i]} and {nos[i + 1]}"
        msg += f" ({far.size} steps over {MAX_POSE_STEP:g} m); the grid that covers the poses grows with it"
        warnings.warn(f"{path}: {msg}", CarmenReadWarning, stacklevel=4)


def _sentinel_band(top: float) -> float | None:
    """Lower end of the known FLASER sentinel band holding the log's largest reading, if any."""
    return next((lo for lo, hi in _SENTINEL_BANDS if lo - 1e-9 <= top <= hi + 1e-9), None)


def beam_rules(poses, angles, ranges, present, valid, no_ret, beyond, below_msg, mr: float, settings: dict):
    """The rules every scan reader applies after finding its no-return (``no_ret``) and beyond-usable
    (``beyond``) beams, in this order: no-return beams dropped or read as max range ``mr``
    (``settings["no_return"]``), beyond-usable ones likewise (``usable_range_rule``), readings below
    ``min_range`` counted (with ``below_msg``, the beams a message itself marked too short), then the scans and
    beams kept (``pose_step`` / ``pose_fraction``, ``beam_step``). Arrays are ``S x B``; returns ``(scans,
    counts, keep)``: the :class:`~ogm_ppl.scans.Scans`, the beam counts of the kept scans and the kept scan
    indices."""
    if settings["no_return"] == "drop":
        valid = valid & ~no_ret
    else:
        ranges = np.where(no_ret, mr, ranges)
    if settings["max_usable_range"] is not None:
        if settings["usable_range_rule"] == "drop":
            valid = valid & ~beyond
        else:
            ranges = np.where(beyond, mr, ranges)
    below = valid & (ranges < settings["min_range"])
    if below_msg is not None:
        below = below | below_msg
    keep = _kept_scans(len(poses), settings["pose_step"], settings["pose_fraction"])
    sub = (keep, slice(None, None, settings["beam_step"]))
    angles, ranges, valid, present, no_ret, beyond, below = (
        a[sub] for a in (angles, ranges, valid, present, no_ret, beyond, below)
    )
    scans = Scans(poses[keep], angles, ranges, mr, over_range="max", valid=valid, min_range=settings["min_range"])
    counts = {
        "beams": int(present.sum()),
        "valid": scans.num_valid,
        "no_return": int(no_ret.sum()),
        "beyond_usable": int(beyond.sum()),
        "below_min": int(below.sum()),
        "max_range_readings": int(scans.is_max.sum()),
    }
    return scans, counts, keep


def _kept_scans(S: int, pose_step: int, pose_fraction: float | None) -> np.ndarray:
    """Indices of the scans kept: every ``pose_step``-th, or ``round(S * pose_fraction)`` evenly
    spaced ones (the rule of :meth:`Scans.subsample`, which a test holds this to)."""
    if pose_fraction is None:
        return np.arange(0, S, pose_step)
    n = max(1, round(S * pose_fraction))
    return np.unique(np.floor(np.arange(n) * (S / n)).astype(np.int64))
